// Whole-file reads with a cap; atomic writes that leave the old file or the new one, and write
// into a FIFO or character device rather than replace it.
#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

using ::testing::HasSubstr;

std::vector<std::string> DirectoryEntries(const std::string& directory) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(directory)) {
    names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

void WritePlain(const std::string& path, const std::string& contents) {
  std::ofstream out(path, std::ios::binary);
  out << contents;
}

TEST(ReadFileTest, ReadsEveryByte) {
  const std::string path = testing::MakeTempDir() + "/data.bin";
  const std::string contents("a\0b\r\nc\xff", 7);
  WritePlain(path, contents);

  absl::StatusOr<std::string> read = ReadFile(path);

  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, contents);
}

TEST(ReadFileTest, ReadsEmptyFile) {
  const std::string path = testing::MakeTempDir() + "/empty";
  WritePlain(path, "");

  absl::StatusOr<std::string> read = ReadFile(path);

  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, "");
}

TEST(ReadFileTest, ReadsLargerThanOneChunk) {
  const std::string path = testing::MakeTempDir() + "/big";
  std::string contents;
  for (int i = 0; i < 300000; ++i) contents += static_cast<char>('a' + i % 26);
  WritePlain(path, contents);

  absl::StatusOr<std::string> read = ReadFile(path);

  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, contents);
}

TEST(ReadFileTest, RegularFileBufferIsSizedOnceToTheFile) {
  // Growing by doubling would leave twice the capacity (and copy the file on the way).
  const std::string path = testing::MakeTempDir() + "/sized";
  const std::string contents(300000, 'x');
  WritePlain(path, contents);

  absl::StatusOr<std::string> read = ReadFile(path);

  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, contents);
  EXPECT_LE(read->capacity(), contents.size() + 1);
}

TEST(ReadFileTest, StreamLargerThanOneChunkIsReadWholeWithoutSpareCapacity) {
  const std::string path = testing::MakeTempDir() + "/fifo";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  std::string contents;
  for (int i = 0; i < 200000; ++i) contents += static_cast<char>('a' + i % 26);
  std::thread writer([&] { WritePlain(path, contents); });

  absl::StatusOr<std::string> read = ReadFile(path);
  writer.join();

  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, contents);
  EXPECT_LE(read->capacity(), contents.size() + 1);
}

TEST(ReadFileTest, MissingFileIsNotFoundAndNamesThePath) {
  const std::string path = testing::MakeTempDir() + "/missing.bvh";

  absl::StatusOr<std::string> read = ReadFile(path);

  EXPECT_EQ(read.status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(std::string(read.status().message()), path + ": no such file");
}

TEST(ReadFileTest, DirectoryIsInvalidArgument) {
  const std::string directory = testing::MakeTempDir();

  absl::StatusOr<std::string> read = ReadFile(directory);

  EXPECT_EQ(read.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(read.status().message()), directory + ": is a directory, not a file");
}

TEST(ReadFileTest, FileOverTheCapIsRefusedWithItsSize) {
  const std::string path = testing::MakeTempDir() + "/walk.bvh";
  WritePlain(path, std::string(101, 'x'));

  absl::StatusOr<std::string> read = ReadFile(path, 100);

  EXPECT_EQ(read.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(read.status().message()),
            path + ": file is 101 bytes, over the limit of 100");
}

TEST(ReadFileTest, FileExactlyAtTheCapIsRead) {
  const std::string path = testing::MakeTempDir() + "/walk.bvh";
  WritePlain(path, std::string(100, 'x'));

  absl::StatusOr<std::string> read = ReadFile(path, 100);

  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->size(), 100u);
}

TEST(ReadFileTest, StreamWithoutSizeIsCappedOnWhatArrives) {
  // /proc files report size 0, so the cap must hold on the bytes actually read.
  absl::StatusOr<std::string> read = ReadFile("/proc/self/maps", 10);

  EXPECT_EQ(read.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(read.status().message()),
            "/proc/self/maps: file is over the limit of 10 bytes");
}

TEST(ReadFileTest, DevicesAreRefusedWithoutReadingThem) {
  // /dev/zero never ends: once read whole until memory ran out.
  absl::StatusOr<std::string> zero = ReadFile("/dev/zero");
  absl::StatusOr<std::string> null = ReadTextFile("/dev/null");

  EXPECT_EQ(zero.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(zero.status().message()), "/dev/zero: is a character device, not a file");
  EXPECT_EQ(std::string(null.status().message()), "/dev/null: is a character device, not a file");
}

TEST(ReadFileTest, FifoWithoutAWriterIsRefusedInsteadOfWaitedForForever) {
  const std::string path = testing::MakeTempDir() + "/silent";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);

  absl::StatusOr<std::string> read = ReadFile(path);

  EXPECT_EQ(read.status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_EQ(std::string(read.status().message()),
            path + ": is a FIFO and nothing arrived for 10 s (no writer?)");
}

TEST(ReadTextFileTest, ReadsTextLikeReadFile) {
  const std::string path = testing::MakeTempDir() + "/clip.bvh";
  std::string contents;
  for (int i = 0; i < 300000; ++i) contents += static_cast<char>('a' + i % 26);
  WritePlain(path, contents);

  absl::StatusOr<std::string> read = ReadTextFile(path);

  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, contents);
}

TEST(ReadTextFileTest, NulByteIsRefusedWithItsLineAndColumn) {
  const std::string path = testing::MakeTempDir() + "/binary.bvh";
  WritePlain(path, std::string("HIERARCHY\nROOT \0x\n", 18));

  absl::StatusOr<std::string> read = ReadTextFile(path);

  EXPECT_EQ(read.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(read.status().message()),
            path + ":2:6: unexpected byte 0x00; the file looks binary, not text");
}

TEST(ReadTextFileTest, SparseFileUnderTheCapIsRefusedAtItsFirstChunk) {
  // 512 MiB of holes: refused after one 64 KiB read, so memory stays at a chunk, not the size.
  const std::string path = testing::MakeTempDir() + "/sparse.bvh";
  { std::ofstream touch(path); }
  ASSERT_EQ(::truncate(path.c_str(), std::int64_t{512} << 20), 0);

  absl::StatusOr<std::string> read = ReadTextFile(path, std::int64_t{1} << 30);

  EXPECT_EQ(std::string(read.status().message()),
            path + ":1:1: unexpected byte 0x00; the file looks binary, not text");
}

TEST(RemovePendingTempFilesTest, RemovesAWriteInFlightAndTheWriteThenFails) {
  // The hook runs inside WriteFileAtomically() with its temporary registered: what a signal
  // handler calling RemovePendingTempFiles() at that moment does.
  const std::string dir = testing::MakeTempDir();
  SetTempFileCreatedHookForTesting([] { RemovePendingTempFiles(); });

  const absl::Status status = WriteFileAtomically(dir + "/out.bvh", "data");
  SetTempFileCreatedHookForTesting(nullptr);

  EXPECT_FALSE(status.ok());
  EXPECT_TRUE(DirectoryEntries(dir).empty());
}

TEST(RemovePendingTempFilesTest, LeavesFinishedWritesAlone) {
  const std::string dir = testing::MakeTempDir();
  ASSERT_TRUE(WriteFileAtomically(dir + "/a.bvh", "a").ok());

  RemovePendingTempFiles();

  EXPECT_EQ(DirectoryEntries(dir), std::vector<std::string>{"a.bvh"});
}

TEST(WriteFileAtomicallyTest, WritesNewFileAndLeavesNoTemporary) {
  const std::string directory = testing::MakeTempDir();
  const std::string path = directory + "/out.bvh";

  absl::Status written = WriteFileAtomically(path, "hello\n");

  ASSERT_TRUE(written.ok()) << written;
  EXPECT_EQ(*ReadFile(path), "hello\n");
  EXPECT_EQ(DirectoryEntries(directory), std::vector<std::string>{"out.bvh"});
}

TEST(WriteFileAtomicallyTest, ReplacesExistingFileAndKeepsItsPermissions) {
  const std::string directory = testing::MakeTempDir();
  const std::string path = directory + "/out.bvh";
  WritePlain(path, "old contents that are longer than the new ones\n");
  ASSERT_EQ(::chmod(path.c_str(), 0640), 0);

  absl::Status written = WriteFileAtomically(path, "new\n");

  ASSERT_TRUE(written.ok()) << written;
  EXPECT_EQ(*ReadFile(path), "new\n");
  struct stat info {};
  ASSERT_EQ(::stat(path.c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 07777, 0640u);
  EXPECT_EQ(DirectoryEntries(directory), std::vector<std::string>{"out.bvh"});
}

// A link is written through, as a shell's `>` does: it stays a link and its target gets the
// bytes (it used to become a plain file, the target left as it was: `-o link-to-input.bvh
// --overwrite` left the input unchanged). Relative, chained and dangling links; a loop is an
// error naming it, and writes nothing.
TEST(WriteFileAtomicallyTest, WritesThroughSymbolicLinks) {
  namespace fs = std::filesystem;
  const std::string directory = testing::MakeTempDir();
  fs::create_directories(directory + "/assets");
  WritePlain(directory + "/assets/hero.bvh", "old\n");
  fs::create_symlink("assets/hero.bvh", directory + "/relative.bvh");
  fs::create_symlink(directory + "/relative.bvh", directory + "/chained.bvh");
  fs::create_symlink("assets/new.bvh", directory + "/dangling.bvh");
  fs::create_symlink("loop-b.bvh", directory + "/loop-a.bvh");
  fs::create_symlink("loop-a.bvh", directory + "/loop-b.bvh");

  const absl::Status through_chain = WriteFileAtomically(directory + "/chained.bvh", "new\n");
  const absl::Status dangling = WriteFileAtomically(directory + "/dangling.bvh", "created\n");
  const absl::Status loop = WriteFileAtomically(directory + "/loop-a.bvh", "x\n");

  ASSERT_TRUE(through_chain.ok()) << through_chain;
  ASSERT_TRUE(dangling.ok()) << dangling;
  EXPECT_EQ(*ReadFile(directory + "/assets/hero.bvh"), "new\n");
  EXPECT_EQ(*ReadFile(directory + "/assets/new.bvh"), "created\n");
  EXPECT_TRUE(fs::is_symlink(directory + "/chained.bvh"));
  EXPECT_TRUE(fs::is_symlink(directory + "/relative.bvh"));
  EXPECT_TRUE(fs::is_symlink(directory + "/dangling.bvh"));
  EXPECT_THAT(std::string(loop.message()), HasSubstr("too many levels of symbolic links"));
  EXPECT_EQ(DirectoryEntries(directory + "/assets"),
            (std::vector<std::string>{"hero.bvh", "new.bvh"}));
}

// /proc's links report a size of 64 whatever their length (a longer target was cut, the
// output written to a truncated path with exit 0), and /dev/stdout on a pipe names "pipe:[N]":
// a stream is written by the name given, a regular file through its whole path.
TEST(WriteFileAtomicallyTest, ProcLinksAreReadWholeAndStreamsWrittenByTheirName) {
  namespace fs = std::filesystem;
  const std::string directory =
      testing::MakeTempDir() + "/a-folder-whose-name-is-long-enough-to-pass-sixty-four-bytes";
  fs::create_directories(directory);
  const std::string file = directory + "/out.bvh";
  WritePlain(file, "old\n");
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  ASSERT_GE(fd, 0);
  int pipe_ends[2] = {-1, -1};
  ASSERT_EQ(::pipe2(pipe_ends, O_CLOEXEC), 0);

  const absl::Status through_proc =
      WriteFileAtomically("/proc/self/fd/" + std::to_string(fd), "new\n");
  const absl::Status into_pipe =
      WriteFileAtomically("/proc/self/fd/" + std::to_string(pipe_ends[1]), "piped\n");
  char piped[16] = {0};
  const ssize_t got = ::read(pipe_ends[0], piped, sizeof piped);
  ::close(fd);
  ::close(pipe_ends[0]);
  ::close(pipe_ends[1]);

  ASSERT_TRUE(through_proc.ok()) << through_proc;
  EXPECT_EQ(*ReadFile(file), "new\n");
  EXPECT_EQ(DirectoryEntries(directory), std::vector<std::string>{"out.bvh"});
  ASSERT_TRUE(into_pipe.ok()) << into_pipe;
  EXPECT_EQ(std::string(piped, static_cast<std::size_t>(std::max<ssize_t>(got, 0))), "piped\n");
}

// As the kernel's fs.protected_symlinks: another user's link in a sticky world-writable folder
// (/tmp) is not followed, or a link planted there would redirect our write to one of our files.
TEST(WriteFileAtomicallyTest, AnotherUsersLinkInASharedFolderIsNotFollowed) {
  namespace fs = std::filesystem;
  const std::string shared = testing::MakeTempDir() + "/shared";
  fs::create_directories(shared);
  ASSERT_EQ(::chmod(shared.c_str(), 01777), 0);
  const std::string victim = testing::MakeTempDir() + "/precious.bvh";
  WritePlain(victim, "precious\n");
  const std::string link = shared + "/out.bvh";
  fs::create_symlink(victim, link);
  if (::lchown(link.c_str(), 12345, 12345) != 0) GTEST_SKIP() << "needs root to own a link";

  const absl::Status written = WriteFileAtomically(link, "clobbered\n");

  EXPECT_EQ(written.code(), absl::StatusCode::kPermissionDenied) << written;
  EXPECT_EQ(*ReadFile(victim), "precious\n");
}

TEST(WriteFileAtomicallyTest, WritesEmptyContents) {
  const std::string path = testing::MakeTempDir() + "/empty";

  absl::Status written = WriteFileAtomically(path, "");

  ASSERT_TRUE(written.ok()) << written;
  EXPECT_EQ(*ReadFile(path), "");
}

TEST(WriteFileAtomicallyTest, MissingDirectoryFailsClearlyAndCreatesNothing) {
  const std::string parent = testing::MakeTempDir();
  const std::string path = parent + "/no/such/dir/out.bvh";

  absl::Status written = WriteFileAtomically(path, "data");

  EXPECT_EQ(written.code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(std::string(written.message()),
            path + ": cannot create a temporary file in " + parent +
                "/no/such/dir: no such file or directory");
  EXPECT_TRUE(DirectoryEntries(parent).empty());
}

TEST(WriteFileAtomicallyTest, DirectoryThatIsAFileFailsClearly) {
  const std::string parent = testing::MakeTempDir();
  WritePlain(parent + "/plain", "x");
  const std::string path = parent + "/plain/out.bvh";

  absl::Status written = WriteFileAtomically(path, "data");

  EXPECT_EQ(written.code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(std::string(written.message()),
            path + ": cannot create a temporary file in " + parent + "/plain: not a directory");
  EXPECT_EQ(DirectoryEntries(parent), std::vector<std::string>{"plain"});
}

TEST(WriteFileAtomicallyTest, TargetThatIsADirectoryFailsAndRemovesTheTemporary) {
  const std::string parent = testing::MakeTempDir();
  const std::string path = parent + "/taken";
  std::filesystem::create_directory(path);

  absl::Status written = WriteFileAtomically(path, "data");

  // Not UNAVAILABLE, which the clients take as a server's outage (a batch retried it).
  EXPECT_EQ(written.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(std::string(written.message()), path + ": cannot replace the file: is a directory");
  EXPECT_EQ(DirectoryEntries(parent), std::vector<std::string>{"taken"});
}

// A batch's summary named these "UNAVAILABLE", the code of an unreachable server, which a CI
// script keyed on the code would take for an outage: each now has the code of what it is.
TEST(WriteFileAtomicallyTest, LocalFailuresHaveCodesOfTheirOwnNotAnOutages) {
  const std::string parent = testing::MakeTempDir();
  ASSERT_EQ(::symlink("loop.bvh", (parent + "/loop.bvh").c_str()), 0);

  const absl::Status too_long = WriteFileAtomically(parent + "/" + std::string(300, 'a'), "x");
  const absl::Status loop = ReadFile(parent + "/loop.bvh", 1 << 20).status();

  EXPECT_EQ(too_long.code(), absl::StatusCode::kFailedPrecondition) << too_long;
  EXPECT_THAT(std::string(too_long.message()), ::testing::HasSubstr("file name too long"));
  EXPECT_EQ(loop.code(), absl::StatusCode::kFailedPrecondition) << loop;
  EXPECT_THAT(std::string(loop.message()), ::testing::HasSubstr("too many levels of symbolic links"));
}

// A FIFO is not renamed over (its reader would never see the bytes, and the FIFO would be gone):
// it takes the bytes as a stream and stays a FIFO.
TEST(WriteFileAtomicallyTest, FifoWithAReaderIsWrittenIntoAndStaysAFifo) {
  const std::string parent = testing::MakeTempDir();
  const std::string path = parent + "/pipe";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  // The reader's end open first (a non-blocking open needs no writer), so the write finds it;
  // the bytes wait in the pipe's buffer until read.
  const int reader = ::open(path.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0);

  absl::Status written = WriteFileAtomically(path, "HIERARCHY\n");
  char buffer[64] = {};
  const ssize_t got = ::read(reader, buffer, sizeof buffer);
  ::close(reader);

  ASSERT_TRUE(written.ok()) << written;
  EXPECT_EQ(std::string(buffer, got > 0 ? static_cast<std::size_t>(got) : 0), "HIERARCHY\n");
  struct stat info {};
  ASSERT_EQ(::stat(path.c_str(), &info), 0);
  EXPECT_TRUE(S_ISFIFO(info.st_mode));
  EXPECT_EQ(DirectoryEntries(parent), std::vector<std::string>{"pipe"});
}

TEST(WriteFileAtomicallyTest, FifoNobodyReadsIsRefusedAtOnceAndStaysAFifo) {
  const std::string parent = testing::MakeTempDir();
  const std::string path = parent + "/pipe";
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);

  absl::Status written = WriteFileAtomically(path, "data");

  EXPECT_EQ(written.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(std::string(written.message()), path + ": is a FIFO with no reader");
  struct stat info {};
  ASSERT_EQ(::stat(path.c_str(), &info), 0);
  EXPECT_TRUE(S_ISFIFO(info.st_mode));
  EXPECT_EQ(DirectoryEntries(parent), std::vector<std::string>{"pipe"});
}

// /dev/null takes the bytes and stays the device (renaming over it, as root, made it a file).
TEST(WriteFileAtomicallyTest, CharacterDeviceIsWrittenIntoNotReplaced) {
  absl::Status written = WriteFileAtomically("/dev/null", "data");

  ASSERT_TRUE(written.ok()) << written;
  struct stat info {};
  ASSERT_EQ(::stat("/dev/null", &info), 0);
  EXPECT_TRUE(S_ISCHR(info.st_mode));
}

TEST(WriteFileAtomicallyTest, SocketIsRefusedAndLeftAlone) {
  const std::string parent = testing::MakeTempDir();
  const std::string path = parent + "/sock";
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  ASSERT_LT(path.size(), sizeof(address.sun_path));
  std::copy(path.begin(), path.end(), address.sun_path);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0);

  absl::Status written = WriteFileAtomically(path, "data");
  ::close(fd);

  EXPECT_EQ(written.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(std::string(written.message()),
            path + ": is a socket, not a regular file; not replaced (write to a regular file)");
  EXPECT_EQ(DirectoryEntries(parent), std::vector<std::string>{"sock"});
}

TEST(WriteFileAtomicallyTest, PathWithoutDirectoryWritesInTheWorkingDirectory) {
  const std::string directory = testing::MakeTempDir();
  const std::filesystem::path previous = std::filesystem::current_path();
  std::filesystem::current_path(directory);

  absl::Status written = WriteFileAtomically("bare.txt", "x");
  std::filesystem::current_path(previous);

  ASSERT_TRUE(written.ok()) << written;
  EXPECT_EQ(DirectoryEntries(directory), std::vector<std::string>{"bare.txt"});
}

// A name of 243 to 255 bytes is a file name Linux takes, but "<name>.tmp-xxxxxxxx" was not: the
// write failed with "file name too long". Its temporary starts with as much of the name as fits,
// cut before a UTF-8 character, and is still known as that name's temporary.
TEST(WriteFileAtomicallyTest, ANameUpToTheLongestTheFileSystemTakesIsWritten) {
  const std::string parent = testing::MakeTempDir();
  const std::string longest = std::string(250, 'a') + ".bvh";        // 254 bytes
  const std::string accented = std::string(241, 'b') + "\xC3\xA9.bvh";  // 247 bytes, é at 242

  const absl::Status written = WriteFileAtomically(parent + "/" + longest, "one");
  const absl::Status written_accented = WriteFileAtomically(parent + "/" + accented, "two");

  ASSERT_TRUE(written.ok()) << written;
  ASSERT_TRUE(written_accented.ok()) << written_accented;
  EXPECT_EQ(DirectoryEntries(parent), (std::vector<std::string>{longest, accented}));
  EXPECT_TRUE(IsAtomicWriteTemporary(std::string(242, 'a') + ".tmp-ab12cd34", longest));
  EXPECT_FALSE(IsAtomicWriteTemporary(longest + ".tmp-ab12cd34", longest));
  // The é would be cut in two at byte 242: the stem stops before it.
  EXPECT_TRUE(IsAtomicWriteTemporary(std::string(241, 'b') + ".tmp-ab12cd34", accented));
}

TEST(IsAtomicWriteTemporaryTest, MatchesOnlyTheTemporaryNamesOfTheTarget) {
  EXPECT_TRUE(IsAtomicWriteTemporary("walk.json.tmp-ab12cd34", "walk.json"));
  EXPECT_TRUE(IsAtomicWriteTemporary(".m.json.tmp-zzzzzzzz", ".m.json"));
  EXPECT_FALSE(IsAtomicWriteTemporary("walk.json.tmp-AB12CD34", "walk.json"));
  EXPECT_FALSE(IsAtomicWriteTemporary("walk.json.tmp-ab12cd3", "walk.json"));
  EXPECT_FALSE(IsAtomicWriteTemporary("walk.json.tmp-ab12cd345", "walk.json"));
  EXPECT_FALSE(IsAtomicWriteTemporary("run.json.tmp-ab12cd34", "walk.json"));
  EXPECT_FALSE(IsAtomicWriteTemporary("walk.json.bak-ab12cd34", "walk.json"));
  EXPECT_FALSE(IsAtomicWriteTemporary("walk.json", "walk.json"));
}

}  // namespace
}  // namespace tempokey::core
