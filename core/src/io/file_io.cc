#include "tempokey/core/io/file_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <random>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

// Attempts at a fresh temporary name before giving up (a clash needs 36^8 bad luck).
constexpr int kTempNameAttempts = 16;
constexpr std::size_t kTempSuffixLength = 8;
constexpr std::size_t kReadChunk = std::size_t{1} << 16;

// strerror() starts with a capital letter; our messages are one lower-case sentence.
std::string ErrnoText(int error) {
  std::string text = std::strerror(error);
  if (!text.empty()) text[0] = absl::ascii_tolower(static_cast<unsigned char>(text[0]));
  return text;
}

absl::StatusCode ErrnoCode(int error) {
  switch (error) {
    case ENOENT:
    case ENOTDIR:
      return absl::StatusCode::kNotFound;
    case EACCES:
    case EPERM:
    case EROFS:
      return absl::StatusCode::kPermissionDenied;
    case ENOSPC:
    case EDQUOT:
    case EFBIG:
      return absl::StatusCode::kResourceExhausted;
    default:
      return absl::StatusCode::kUnavailable;
  }
}

absl::Status ErrnoError(int error, std::string_view path, std::string_view what) {
  return absl::Status(ErrnoCode(error),
                      absl::StrCat(AsAbsl(path), ": ", AsAbsl(what), ErrnoText(error)));
}

// Closes a descriptor on scope exit unless released.
class FdCloser {
 public:
  explicit FdCloser(int fd) : fd_(fd) {}
  FdCloser(const FdCloser&) = delete;
  FdCloser& operator=(const FdCloser&) = delete;
  ~FdCloser() {
    if (fd_ >= 0) ::close(fd_);
  }
  // Closes now and reports close()'s error (a failed close can mean lost writes).
  int Close() {
    const int fd = fd_;
    fd_ = -1;
    return ::close(fd);
  }

 private:
  int fd_;
};

std::string DirectoryOf(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

std::string RandomSuffix() {
  static constexpr char kAlphabet[] = "abcdefghijklmnopqrstuvwxyz0123456789";
  thread_local std::mt19937_64 engine(
      std::random_device{}() ^
      static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count()) ^
      (static_cast<std::uint64_t>(::getpid()) << 32));
  std::string suffix(kTempSuffixLength, 'x');
  for (char& c : suffix) c = kAlphabet[engine() % (sizeof(kAlphabet) - 1)];
  return suffix;
}

absl::Status WriteAll(int fd, std::string_view contents, const std::string& path) {
  const char* p = contents.data();
  std::size_t left = contents.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      return ErrnoError(errno, path, "cannot write: ");
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::string> ReadFile(const std::string& path, std::int64_t max_bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int error = errno;
    if (error == ENOENT) return absl::NotFoundError(absl::StrCat(path, ": no such file"));
    return ErrnoError(error, path, "cannot open: ");
  }
  FdCloser closer(fd);
  struct stat info {};
  if (::fstat(fd, &info) != 0) return ErrnoError(errno, path, "cannot stat: ");
  if (S_ISDIR(info.st_mode)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": is a directory, not a file"));
  }
  if (S_ISREG(info.st_mode) && info.st_size > max_bytes) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": file is ", info.st_size,
                                                   " bytes, over the limit of ", max_bytes));
  }

  // Read to the end rather than trusting st_size: pipes and /proc files report 0, and a file
  // may grow while we read it. The cap is enforced on what actually arrives. A regular file's
  // buffer is its size plus one byte, so the read that meets the end needs no more room and a
  // file that grew shows at once; the buffer grows (doubling) only when more bytes arrive.
  std::string contents;
  contents.resize(S_ISREG(info.st_mode) && info.st_size > 0
                      ? static_cast<std::size_t>(info.st_size) + 1
                      : kReadChunk);
  std::size_t used = 0;
  for (;;) {
    if (used == contents.size()) contents.resize(std::max(2 * used, used + kReadChunk));
    const ssize_t n = ::read(fd, contents.data() + used, contents.size() - used);
    if (n < 0) {
      if (errno == EINTR) continue;
      return ErrnoError(errno, path, "cannot read: ");
    }
    if (n == 0) break;
    used += static_cast<std::size_t>(n);
    if (static_cast<std::int64_t>(used) > max_bytes) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": file is over the limit of ",
                                                     max_bytes, " bytes"));
    }
  }
  contents.resize(used);
  // Give back what growing reserved (a stream, a file that grew); the spare byte of a regular
  // file is not worth a copy of the whole file.
  if (contents.capacity() > used + 1) contents.shrink_to_fit();
  return contents;
}

bool IsAtomicWriteTemporary(std::string_view file_name, std::string_view target_name) {
  constexpr std::string_view kMark = ".tmp-";
  if (file_name.size() != target_name.size() + kMark.size() + kTempSuffixLength ||
      !file_name.starts_with(target_name) ||
      file_name.substr(target_name.size(), kMark.size()) != kMark) {
    return false;
  }
  const std::string_view suffix = file_name.substr(target_name.size() + kMark.size());
  return std::all_of(suffix.begin(), suffix.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9');
  });
}

absl::Status WriteFileAtomically(const std::string& path, std::string_view contents) {
  const std::string directory = DirectoryOf(path);
  std::string temp_path;
  int fd = -1;
  for (int attempt = 0; attempt < kTempNameAttempts && fd < 0; ++attempt) {
    temp_path = absl::StrCat(path, ".tmp-", RandomSuffix());
    // 0666 lets the umask decide, as for any newly created file.
    fd = ::open(temp_path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0 && errno != EEXIST) {
      return ErrnoError(errno, path,
                        absl::StrCat("cannot create a temporary file in ", directory, ": "));
    }
  }
  if (fd < 0) {
    return absl::UnavailableError(
        absl::StrCat(path, ": cannot find an unused temporary file name in ", directory));
  }

  FdCloser closer(fd);
  auto fail = [&](absl::Status status) {
    ::unlink(temp_path.c_str());
    return status;
  };
  // Replacing a file keeps its permission bits.
  struct stat existing {};
  if (::stat(path.c_str(), &existing) == 0 && S_ISREG(existing.st_mode)) {
    if (::fchmod(fd, existing.st_mode & 07777) != 0) {
      return fail(ErrnoError(errno, path, "cannot set permissions: "));
    }
  }
  if (absl::Status written = WriteAll(fd, contents, path); !written.ok()) {
    return fail(written);
  }
  if (::fsync(fd) != 0) return fail(ErrnoError(errno, path, "cannot flush: "));
  if (closer.Close() != 0) return fail(ErrnoError(errno, path, "cannot close: "));
  if (::rename(temp_path.c_str(), path.c_str()) != 0) {
    return fail(ErrnoError(errno, path, "cannot replace the file: "));
  }
  // Make the rename itself durable. Some file systems refuse fsync on a directory; the data is
  // already safe in the file, so that is not an error.
  const int dir_fd = ::open(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir_fd >= 0) {
    ::fsync(dir_fd);
    ::close(dir_fd);
  }
  return absl::OkStatus();
}

}  // namespace tempokey::core
