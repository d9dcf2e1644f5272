#include "tempokey/core/io/file_io.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <random>
#include <string_view>
#include <utility>

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

// The status code of a failed file operation (the FileErrorCode() of file_io.h's comments).
// UNAVAILABLE is kept for a state of the file that may pass (a lock, a FIFO's reader, an
// interrupted call): the clients take it as a server's outage (a batch retries it, the CLI probes
// the connection's TLS), so a path that is a folder, a name too long or a loop of links is not
// it (a batch's summary reported those as "UNAVAILABLE", the code of an unreachable server);
// RESOURCE_EXHAUSTED is the machine's room (disk, descriptors, memory).
absl::StatusCode FileErrorCode(int error) {
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
    case EMFILE:
    case ENFILE:
    case ENOMEM:
      return absl::StatusCode::kResourceExhausted;
    case EISDIR:
    case ENAMETOOLONG:
    case ELOOP:
    case EEXIST:
    case ENOTEMPTY:
    case EXDEV:
    case ETXTBSY:
    case EMLINK:
    case ESPIPE:
      return absl::StatusCode::kFailedPrecondition;
    case EINVAL:
      return absl::StatusCode::kInvalidArgument;
    case ENXIO:  // a FIFO with no reader yet
    case EAGAIN:
    case EBUSY:
    case EINTR:
    case ESTALE:
    case ENOLCK:
    case ETIMEDOUT:
      return absl::StatusCode::kUnavailable;
    case EIO:
      return absl::StatusCode::kDataLoss;
    default:
      return absl::StatusCode::kUnknown;
  }
}

absl::Status ErrnoError(int error, std::string_view path, std::string_view what) {
  return absl::Status(FileErrorCode(error),
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

namespace {

std::string_view KindOfFile(mode_t mode) {
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISFIFO(mode)) return "a FIFO";
  return "not a regular file";
}

}  // namespace

// The file `path` names once its symbolic links are followed (at most kMaxLinks of them, as
// the kernel's ELOOP): a write through a link reaches its target and the link stays. A link
// whose target does not exist yet names that target. Not a link: `path`. As the kernel's
// fs.protected_symlinks, a link in a sticky world-writable folder (/tmp) is followed only when
// this process's user or the folder's owner owns it: another user's link planted there must not
// redirect a write to one of our files.
absl::StatusOr<std::string> FollowLinks(std::string path) {
  constexpr int kMaxLinks = 40;
  for (int hop = 0; hop < kMaxLinks; ++hop) {
    struct stat link {};
    if (::lstat(path.c_str(), &link) != 0 || !S_ISLNK(link.st_mode)) return path;
    const std::string directory = DirectoryOf(path);
    if (struct stat folder {}; ::stat(directory.c_str(), &folder) == 0 &&
                               (folder.st_mode & S_ISVTX) != 0 && (folder.st_mode & S_IWOTH) != 0 &&
                               link.st_uid != ::geteuid() && link.st_uid != folder.st_uid) {
      return absl::PermissionDeniedError(absl::StrCat(
          path, ": a symbolic link another user owns in a shared folder is not followed"));
    }
    // /proc's links report a size of 64 whatever their length: read until the buffer had room.
    std::string target(std::max<std::size_t>(static_cast<std::size_t>(link.st_size), 64) + 1, '\0');
    ssize_t length = 0;
    while ((length = ::readlink(path.c_str(), target.data(), target.size())) >= 0 &&
           static_cast<std::size_t>(length) == target.size()) {
      target.resize(target.size() * 2);
    }
    if (length <= 0) return ErrnoError(length < 0 ? errno : ENOENT, path, "cannot read the link: ");
    target.resize(static_cast<std::size_t>(length));
    path = target.front() == '/' ? target : absl::StrCat(directory, "/", target);
  }
  return ErrnoError(ELOOP, path, "cannot write: ");
}

namespace {

// WriteFileAtomically() into a FIFO or character device: opened without waiting for a reader
// (a FIFO nobody reads is an error, not a hang), then written in full.
absl::Status WriteToStream(const std::string& path, std::string_view contents) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_NONBLOCK | O_NOCTTY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENXIO) {
      return absl::UnavailableError(absl::StrCat(path, ": is a FIFO with no reader"));
    }
    return ErrnoError(errno, path, "cannot open: ");
  }
  FdCloser closer(fd);
  // Blocking writes from here: a reader slower than us is waited for.
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags < 0 || ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) != 0) {
    return ErrnoError(errno, path, "cannot set up the write: ");
  }
  TEMPOKEY_RETURN_IF_ERROR(WriteAll(fd, contents, path));
  if (closer.Close() != 0) return ErrnoError(errno, path, "cannot close: ");
  return absl::OkStatus();
}

// Line and column (from 1) of byte `offset` of `text`.
std::pair<std::int64_t, std::int64_t> LineAndColumn(std::string_view text, std::size_t offset) {
  std::int64_t line = 1;
  std::size_t line_start = 0;
  for (std::size_t i = 0; i < offset; ++i) {
    if (text[i] == '\n') {
      ++line;
      line_start = i + 1;
    }
  }
  return {line, static_cast<std::int64_t>(offset - line_start) + 1};
}

absl::StatusOr<std::string> ReadWhole(const std::string& path, std::int64_t max_bytes, bool text) {
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer, forever if none
  // comes. Reads then block as usual (the flag is cleared below), and a FIFO without a writer
  // reads as empty.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
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
  if (!S_ISREG(info.st_mode) && !S_ISFIFO(info.st_mode)) {
    // /dev/zero and friends never end; sockets and terminals are not files to read whole.
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": is ", AsAbsl(KindOfFile(info.st_mode)), ", not a file"));
  }
  if (S_ISREG(info.st_mode) && info.st_size > max_bytes) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": file is ", info.st_size,
                                                   " bytes, over the limit of ", max_bytes));
  }
  const bool stream = S_ISFIFO(info.st_mode);
  if (!stream) {
    const int flags = ::fcntl(fd, F_GETFL);
    if (flags < 0 || ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) != 0) {
      return ErrnoError(errno, path, "cannot read: ");
    }
  }

  // Read to the end rather than trusting st_size: pipes and /proc files report 0, and a file
  // may grow while we read it. The cap is enforced on what actually arrives. A regular file's
  // buffer is its size plus one byte, so the read that meets the end needs no more room and a
  // file that grew shows at once; the buffer grows (doubling) only when more bytes arrive.
  // Text is checked chunk by chunk as it arrives, so a binary file stops at its first chunk.
  std::string contents;
  const bool sized = S_ISREG(info.st_mode) && info.st_size > 0;
  contents.resize(sized && !text ? static_cast<std::size_t>(info.st_size) + 1 : kReadChunk);
  std::size_t used = 0;
  for (;;) {
    if (used == contents.size()) {
      const std::size_t grown = sized ? std::min<std::size_t>(
                                            std::max(2 * used, used + kReadChunk),
                                            static_cast<std::size_t>(info.st_size) + 1)
                                      : std::max(2 * used, used + kReadChunk);
      contents.resize(std::max(grown, used + 1));
    }
    const std::size_t room = text ? std::min(contents.size() - used, kReadChunk)
                                  : contents.size() - used;
    if (stream) {
      // A FIFO stays non-blocking: wait for data (or its writer closing) a bounded time, so one
      // that nobody writes to is refused instead of read forever.
      pollfd ready{fd, POLLIN, 0};
      const int polled = ::poll(&ready, 1, kStreamIdleTimeoutMs);
      if (polled < 0) {
        if (errno == EINTR) continue;
        return ErrnoError(errno, path, "cannot read: ");
      }
      if (polled == 0) {
        return absl::DeadlineExceededError(absl::StrCat(
            path, ": is a FIFO and nothing arrived for ", kStreamIdleTimeoutMs / 1000,
            " s (no writer?)"));
      }
    }
    const ssize_t n = ::read(fd, contents.data() + used, room);
    if (n < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      return ErrnoError(errno, path, "cannot read: ");
    }
    if (n == 0) break;
    if (text) {
      const std::string_view chunk(contents.data() + used, static_cast<std::size_t>(n));
      if (const std::size_t nul = chunk.find('\0'); nul != std::string_view::npos) {
        const auto [line, column] =
            LineAndColumn(std::string_view(contents.data(), used + nul), used + nul);
        return absl::InvalidArgumentError(absl::StrCat(
            path, ":", line, ":", column, ": unexpected byte 0x00; the file looks binary, not text"));
      }
    }
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

}  // namespace

absl::StatusOr<std::string> ReadFile(const std::string& path, std::int64_t max_bytes) {
  return ReadWhole(path, max_bytes, /*text=*/false);
}

absl::StatusOr<std::string> ReadTextFile(const std::string& path, std::int64_t max_bytes) {
  return ReadWhole(path, max_bytes, /*text=*/true);
}

// ---- temporary files a signal handler may remove --------------------------------------------

namespace {

// A slot holds a temporary file's path while its write is in flight. States: free, claimed (the
// writer fills the path), live (a signal handler may unlink it). Lock-free atomics only, so
// RemovePendingTempFiles() is async-signal-safe.
struct TempSlot {
  enum : int { kFree = 0, kClaimed = 1, kLive = 2 };
  std::atomic<int> state{kFree};
  char path[4096];
};
static_assert(std::atomic<int>::is_always_lock_free);
TempSlot g_temp_slots[kTrackedTempFiles];
std::atomic<void (*)()> g_temp_created_hook{nullptr};

// Registers `path`; returns its slot, or -1 when every slot is taken or the path is too long.
int RegisterTemp(const std::string& path) {
  if (path.size() >= sizeof(TempSlot::path)) return -1;
  for (int i = 0; i < kTrackedTempFiles; ++i) {
    int expected = TempSlot::kFree;
    if (g_temp_slots[i].state.compare_exchange_strong(expected, TempSlot::kClaimed)) {
      std::memcpy(g_temp_slots[i].path, path.c_str(), path.size() + 1);
      g_temp_slots[i].state.store(TempSlot::kLive, std::memory_order_release);
      return i;
    }
  }
  return -1;
}

void UnregisterTemp(int slot) {
  if (slot >= 0) g_temp_slots[slot].state.store(TempSlot::kFree, std::memory_order_release);
}

}  // namespace

void RemovePendingTempFiles() {
  for (TempSlot& slot : g_temp_slots) {
    if (slot.state.load(std::memory_order_acquire) == TempSlot::kLive) ::unlink(slot.path);
  }
}

PendingFile::PendingFile(const std::string& path) : slot_(RegisterTemp(path)) {}

PendingFile::~PendingFile() { UnregisterTemp(slot_); }

void SetTempFileCreatedHookForTesting(void (*hook)()) { g_temp_created_hook.store(hook); }

namespace {

constexpr std::string_view kTempMark = ".tmp-";
// The longest file name Linux file systems take (NAME_MAX).
constexpr std::size_t kMaxFileName = 255;

}  // namespace

// The part of a target's file name its temporaries start with: the whole name, or for a name
// within 13 bytes of kMaxFileName its first bytes, cut before a UTF-8 character rather than
// inside one, so that "<that>.tmp-xxxxxxxx" is a name the file system takes (names of 243 to 255
// bytes were refused: "cannot create a temporary file: file name too long").
std::string_view AtomicWriteTemporaryStem(std::string_view target_name) {
  constexpr std::size_t kMaxStem = kMaxFileName - kTempMark.size() - kTempSuffixLength;
  if (target_name.size() <= kMaxStem) return target_name;
  std::size_t cut = kMaxStem;
  while (cut > 0 && (static_cast<unsigned char>(target_name[cut]) & 0xC0) == 0x80) --cut;
  return target_name.substr(0, cut);
}

bool IsAtomicWriteTemporary(std::string_view file_name, std::string_view target_name) {
  target_name = AtomicWriteTemporaryStem(target_name);
  if (file_name.size() != target_name.size() + kTempMark.size() + kTempSuffixLength ||
      !file_name.starts_with(target_name) ||
      file_name.substr(target_name.size(), kTempMark.size()) != kTempMark) {
    return false;
  }
  const std::string_view suffix = file_name.substr(target_name.size() + kTempMark.size());
  return std::all_of(suffix.begin(), suffix.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9');
  });
}

absl::Status WriteFileAtomically(const std::string& requested, std::string_view contents) {
  // What is not a regular file (or a link to one) is not renamed over: that would put a plain
  // file in its place, and its reader (or the device) would never see the bytes. A FIFO or a
  // character device (/dev/null, a terminal, /dev/stdout on a pipe) takes them as a stream,
  // opened by the name given; a block device or a socket is refused. A directory is left to the
  // rename, which refuses it.
  if (struct stat target {}; ::stat(requested.c_str(), &target) == 0 &&
                             !S_ISREG(target.st_mode) && !S_ISDIR(target.st_mode)) {
    if (S_ISFIFO(target.st_mode) || S_ISCHR(target.st_mode)) {
      return WriteToStream(requested, contents);
    }
    return absl::FailedPreconditionError(
        absl::StrCat(requested, ": is ", AsAbsl(KindOfFile(target.st_mode)),
                     ", not a regular file; not replaced (write to a regular file)"));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(const std::string path, FollowLinks(requested));
  const std::string directory = DirectoryOf(path);
  std::string temp_path;
  int fd = -1;
  for (int attempt = 0; attempt < kTempNameAttempts && fd < 0; ++attempt) {
    const std::size_t name_start = path.rfind('/') + 1;  // npos + 1 == 0: no folder
    temp_path = absl::StrCat(AsAbsl(std::string_view(path).substr(0, name_start)),
                             AsAbsl(AtomicWriteTemporaryStem(std::string_view(path).substr(name_start))),
                             AsAbsl(kTempMark), RandomSuffix());
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
  // From here until the rename (or the unlink on failure), a signal handler may remove it.
  const int slot = RegisterTemp(temp_path);
  if (void (*hook)() = g_temp_created_hook.load(); hook != nullptr) hook();
  auto fail = [&](absl::Status status) {
    ::unlink(temp_path.c_str());
    UnregisterTemp(slot);
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
  // A signal between the rename and this line unlinks a name that no longer exists: harmless.
  UnregisterTemp(slot);
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
