// The real `tempokey` binary with hostile or careless files: an output that is the input (by
// path, another path, a hard or symbolic link) is refused unless --overwrite; inputs are read
// with bounded memory (a 1 GiB sparse file, a sparse file under the cap, /dev/zero under an
// address-space limit, a FIFO nobody writes to); and SIGINT or SIGTERM during an output's write
// leaves no "*.tmp-*" file and the old output untouched.
#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

constexpr char kWalk[] = "bandai/dataset-1_walk_active_001.bvh";

std::string Slurp(const std::string& path) { return ReadOrEmpty(path); }

void CopyFile(const std::string& from, const std::string& to) {
  std::filesystem::copy_file(from, to, std::filesystem::copy_options::overwrite_existing);
}

std::vector<std::string> TempFilesIn(const std::string& dir) {
  std::vector<std::string> found;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.find(".tmp-") != std::string::npos) found.push_back(name);
  }
  return found;
}

// Peak resident set of the children this process has waited for, in KiB (the CLI runs below are
// its only waited-for children: each test runs in a process of its own under CTest).
long ChildrenPeakRssKiB() {
  rusage usage{};
  getrusage(RUSAGE_CHILDREN, &usage);
  return usage.ru_maxrss;
}

// A freshly built CLI with gRPC loaded takes some 20 MiB; a file read whole would take its size.
constexpr long kBoundedRssKiB = 96 * 1024;

// ---- output equal to the input -----------------------------------------------------------------

class OverwriteTest : public ServerProcessTest {
 protected:
  void SetUp() override {
    ServerProcessTest::SetUp();
    input_ = Path("walk.bvh");
    CopyFile(SharedBvh(kWalk), input_);
    original_ = Slurp(input_);
    ASSERT_FALSE(original_.empty());
  }

  ProcessResult Retime(const std::string& output, std::vector<std::string> extra = {}) {
    std::vector<std::string> args = {"--server", server_->target(), "retime", input_, "-o",
                                     output,     "--speed",          "0s:0.5"};
    args.insert(args.end(), extra.begin(), extra.end());
    return RunTempokey(args, dir_);
  }

  std::string input_;
  std::string original_;
};

TEST_F(OverwriteTest, OutputThatIsTheInputPathIsRefusedAndTheInputKept) {
  const ProcessResult run = Retime(input_);

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "error: -o " + input_ +
                         " is the input (the same file); choose another output, or give "
                         "--overwrite to replace the input\n");
  EXPECT_EQ(Slurp(input_), original_);
}

TEST_F(OverwriteTest, AnotherPathAHardLinkOrASymbolicLinkToTheInputIsRefused) {
  const std::string dotted = dir_ + "/./sub/../walk.bvh";
  std::filesystem::create_directory(Path("sub"));
  ASSERT_EQ(::link(input_.c_str(), Path("hard.bvh").c_str()), 0);
  ASSERT_EQ(::symlink(input_.c_str(), Path("soft.bvh").c_str()), 0);

  for (const std::string& output : {dotted, Path("hard.bvh"), Path("soft.bvh")}) {
    const ProcessResult run = Retime(output);

    EXPECT_EQ(run.exit_code, 2) << output;
    EXPECT_EQ(run.err, "error: -o " + output + " is the input " + input_ +
                           " (the same file); choose another output, or give --overwrite to "
                           "replace the input\n");
  }
  EXPECT_EQ(Slurp(input_), original_);
}

TEST_F(OverwriteTest, ReduceRunAndBatchRefuseToo) {
  const ProcessResult reduce = RunTempokey(
      {"--server", server_->target(), "reduce", input_, "-o", input_}, dir_);
  const ProcessResult run =
      RunTempokey({"--server", server_->target(), "run", input_, "-o", input_}, dir_);
  {
    std::ofstream ops(Path("ops.json"));
    ops << R"({"operations": [{"convert": {}}]})";
  }
  const ProcessResult batch = RunTempokey(
      {"--server", server_->target(), "batch", dir_, "-o", dir_, "--ops", Path("ops.json")}, dir_);

  EXPECT_EQ(reduce.exit_code, 2);
  EXPECT_THAT(reduce.err, StartsWith("error: -o " + input_ + " is the input (the same file)"));
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_THAT(run.err, StartsWith("error: -o " + input_ + " is the input (the same file)"));
  EXPECT_EQ(batch.exit_code, 2);
  EXPECT_THAT(batch.err, StartsWith("error: batch: output " + input_ + " is the input (the same "
                                    "file)"));
  EXPECT_EQ(Slurp(input_), original_);
}

TEST_F(OverwriteTest, OverwriteFlagReplacesTheInput) {
  const ProcessResult run = Retime(input_, {"--overwrite"});

  EXPECT_EQ(run.exit_code, 0) << run.err;
  const std::string replaced = Slurp(input_);
  EXPECT_NE(replaced, original_);
  EXPECT_NE(replaced.find("\nFrames: 291\n"), std::string::npos);  // 146 frames at half speed
}

// A batch that replaced its inputs (--overwrite) and runs again finds them done: the manifest's
// record of each output, not the input id of a clip that no longer exists, says so. Before, the
// second run slowed every clip once more and reported it "ok".
TEST_F(OverwriteTest, AnOverwritingBatchRunAgainSkipsTheFilesItReplaced) {
  std::filesystem::create_directory(Path("in"));
  CopyFile(input_, Path("in/walk.bvh"));
  {
    std::ofstream ops(Path("ops.json"));
    ops << R"({"operations": [{"retime": {"speed": "0s:0.5"}}]})";
  }
  const std::vector<std::string> batch = {"--server", server_->target(), "batch", Path("in"),
                                          "-o", Path("in"), "--ops", Path("ops.json"),
                                          "--overwrite"};

  const ProcessResult first = RunTempokey(batch, dir_);
  const std::string once = Slurp(Path("in/walk.bvh"));
  const ProcessResult second = RunTempokey(batch, dir_);

  EXPECT_EQ(first.exit_code, 0) << first.err;
  EXPECT_NE(once.find("\nFrames: 291\n"), std::string::npos);  // 146 frames at half speed
  EXPECT_EQ(second.exit_code, 0) << second.err;
  EXPECT_THAT(second.out, HasSubstr(R"("status": "skipped")"));
  EXPECT_EQ(Slurp(Path("in/walk.bvh")), once);
}

// --summary is written besides the outputs: it never replaces the pipeline, an input, an output
// or the manifest, and the refusal comes before any work (before, a batch whose server was down
// wrote its summary over its own --ops file).
TEST_F(OverwriteTest, ASummaryThatWouldReplaceAnInputIsRefusedBeforeAnyWork) {
  const std::string ops = Path("ops.json");
  {
    std::ofstream out(ops);
    out << R"({"operations": [{"convert": {}}]})";
  }
  const std::string ops_text = Slurp(ops);
  std::filesystem::create_directory(Path("in"));
  CopyFile(input_, Path("in/walk.bvh"));
  auto batch = [&](const std::string& summary) {
    return RunTempokey({"--server", "127.0.0.1:1", "batch", Path("in"), "-o", Path("out"),
                        "--ops", ops, "--attempts", "1", "--summary", summary},
                       dir_);
  };

  const ProcessResult over_ops = batch(ops);
  const ProcessResult over_input = batch(Path("in/walk.bvh"));
  const ProcessResult over_output = batch(Path("out/walk.bvh"));
  std::filesystem::create_directory(Path("out"));
  const ProcessResult over_records = batch(Path("out/.tempokey-batch.shard-1-of-2.json"));

  EXPECT_EQ(over_ops.exit_code, 2);
  EXPECT_EQ(over_ops.err, "error: --summary " + ops + " is the pipeline; choose another file\n");
  EXPECT_EQ(Slurp(ops), ops_text);
  EXPECT_EQ(over_input.exit_code, 2);
  EXPECT_EQ(over_input.err,
            "error: --summary " + Path("in/walk.bvh") + " is the input; choose another file\n");
  EXPECT_EQ(Slurp(Path("in/walk.bvh")), original_);
  EXPECT_EQ(over_output.exit_code, 2);
  EXPECT_EQ(over_output.err, "error: --summary " + Path("out/walk.bvh") +
                                 " is the output of walk.bvh; choose another file\n");
  EXPECT_EQ(over_records.exit_code, 2);
  EXPECT_EQ(over_records.err, "error: --summary " + Path("out/.tempokey-batch.shard-1-of-2.json") +
                                  " is a name the batch keeps its records under in OUTDIR; choose "
                                  "another file\n");
}

TEST_F(OverwriteTest, BatchSummaryRefusesToWriteOverASummaryItMerges) {
  const std::string summary = Path("s0.json");
  {
    std::ofstream out(summary);
    out << R"({"shard": "0/1", "results": []})";
  }
  const std::string text = Slurp(summary);

  const ProcessResult run = RunTempokey({"batch-summary", summary, "-o", summary}, dir_);

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err,
            "error: -o " + summary + " is a summary to merge; choose another file\n");
  EXPECT_EQ(Slurp(summary), text);
}

// Two inputs with one output name would overwrite each other's result on every run (and the
// manifest would keep one); an output that is another input (a recursive batch whose OUTDIR,
// inside DIR, holds a clip, or last run's .bvh outputs) would write over it. An OUTDIR inside
// DIR is fine otherwise: keyed outputs are never inputs.
TEST_F(OverwriteTest, BatchOutputsThatCollideWithEachOtherOrWithInputsAreRefused) {
  std::filesystem::create_directories(Path("in/sub"));
  CopyFile(input_, Path("in/walk.bvh"));
  CopyFile(input_, Path("in/walk.BVH"));
  CopyFile(input_, Path("in/sub/walk.bvh"));
  {
    std::ofstream ops(Path("ops.json"));
    ops << R"({"operations": [{"convert": {}}]})";
  }
  auto batch = [&](const std::string& in, const std::string& out, bool recursive) {
    std::vector<std::string> args = {"--server", server_->target(), "batch", in,
                                     "-o",       out,               "--ops", Path("ops.json")};
    if (recursive) args.push_back("-r");
    return RunTempokey(args, dir_);
  };

  const ProcessResult same_name = batch(Path("in"), Path("out"), false);
  std::filesystem::remove(Path("in/walk.BVH"));
  const ProcessResult inside = batch(Path("in"), Path("in/sub"), true);
  {
    std::ofstream ops(Path("ops.json"));
    ops << R"({"operations": [{"reduce": {}}]})";
  }
  const ProcessResult keyed_inside = batch(Path("in"), Path("in/curves"), true);
  const ProcessResult keyed_again = batch(Path("in"), Path("in/curves"), true);

  EXPECT_EQ(same_name.exit_code, 2);
  EXPECT_EQ(same_name.err, "error: batch: walk.BVH and walk.bvh would both be written to " +
                               Path("out/walk.bvh") +
                               "; rename one, or run them in separate batches\n");
  EXPECT_FALSE(std::filesystem::exists(Path("out")));
  EXPECT_EQ(inside.exit_code, 2);
  EXPECT_EQ(inside.err, "error: batch: the output of walk.bvh, " + Path("in/sub/walk.bvh") +
                            ", is the input sub/walk.bvh; choose another OUTDIR\n");
  EXPECT_EQ(Slurp(Path("in/sub/walk.bvh")), original_);
  EXPECT_EQ(keyed_inside.exit_code, 0) << keyed_inside.err;
  EXPECT_EQ(keyed_again.exit_code, 0) << keyed_again.err;
  EXPECT_THAT(keyed_again.out, HasSubstr(R"("skipped": 2)"));
}

// A recursive batch whose OUTDIR lies inside DIR, with outputs of an input format (.bvh): its
// recorded outputs are not the next run's inputs, so a re-run skips what is done instead of
// being refused (or, before, processing its outputs a folder deeper each time).
TEST_F(OverwriteTest, ARecursiveBatchIntoAFolderInsideItsInputsRunsAgain) {
  std::filesystem::create_directory(Path("in"));
  CopyFile(input_, Path("in/walk.bvh"));
  {
    std::ofstream ops(Path("ops.json"));
    ops << R"({"operations": [{"convert": {}}]})";
  }
  const std::vector<std::string> batch = {"--server", server_->target(), "batch", Path("in"), "-r",
                                          "-o", Path("in/conv"), "--ops", Path("ops.json")};

  const ProcessResult first = RunTempokey(batch, dir_);
  const ProcessResult second = RunTempokey(batch, dir_);

  EXPECT_EQ(first.exit_code, 0) << first.err;
  EXPECT_EQ(second.exit_code, 0) << second.err;
  EXPECT_THAT(second.out, HasSubstr(R"("files": 1)"));
  EXPECT_THAT(second.out, HasSubstr(R"("skipped": 1)"));
  EXPECT_FALSE(std::filesystem::exists(Path("in/conv/conv")));
}

// An output that is a FIFO (a process reading the result) gets the bytes and stays a FIFO;
// with nobody reading, the CLI says so at once instead of replacing it with a plain file.
TEST_F(OverwriteTest, AnOutputFifoIsWrittenIntoAndNeverReplaced) {
  const std::string fifo = Path("out.bvh");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);

  const ProcessResult unread = Retime(fifo);
  const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0);
  std::string received;
  std::atomic<bool> cli_done{false};
  std::thread drain([&] {
    // Reads until the CLI has exited and the pipe is empty: before its write end opens (and
    // after it closes) a read finds no data, which is no reason to stop until then.
    char buffer[65536];
    for (;;) {
      const ssize_t got = ::read(reader, buffer, sizeof buffer);
      if (got > 0) {
        received.append(buffer, static_cast<std::size_t>(got));
      } else if (cli_done.load()) {
        break;
      } else {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
    }
  });
  const ProcessResult read = Retime(fifo);
  cli_done.store(true);
  drain.join();
  ::close(reader);

  EXPECT_EQ(unread.exit_code, 1);
  EXPECT_EQ(unread.err, "error: " + fifo + ": is a FIFO with no reader\n");
  EXPECT_EQ(read.exit_code, 0) << read.err;
  EXPECT_NE(received.find("\nFrames: 291\n"), std::string::npos);
  struct stat info {};
  ASSERT_EQ(::stat(fifo.c_str(), &info), 0);
  EXPECT_TRUE(S_ISFIFO(info.st_mode));
}

// A device has no extension to choose the format by: /dev/null is refused naming the link that
// gives it one, and through that link it takes the result as a stream and stays the device.
TEST_F(OverwriteTest, ADeviceTakesTheFormatOfALinksNameToIt) {
  const std::string link = Path("discard.bvh");
  ASSERT_EQ(::symlink("/dev/null", link.c_str()), 0);

  const ProcessResult bare = Retime("/dev/null");
  const ProcessResult linked = Retime(link);

  EXPECT_EQ(bare.exit_code, 2);
  EXPECT_EQ(bare.err,
            "error: -o /dev/null: no extension (expected .bvh, .csv, .gltf, .glb); a device or FIFO "
            "takes the format of a link's name to it: ln -s /dev/null out.bvh\n");
  EXPECT_EQ(linked.exit_code, 0) << linked.err;
  struct stat info {};
  ASSERT_EQ(::stat("/dev/null", &info), 0);
  EXPECT_TRUE(S_ISCHR(info.st_mode));
}

// ---- inputs read with bounded memory -------------------------------------------------------------

class InputTest : public ::testing::Test {
 protected:
  std::string dir_ = MakeTempDir();
  std::string Path(const std::string& name) const { return dir_ + "/" + name; }
};

TEST_F(InputTest, OneGibibyteSparseFileIsRefusedByItsSizeWithoutReadingIt) {
  const std::string path = Path("big.bvh");
  { std::ofstream touch(path); }
  ASSERT_EQ(::truncate(path.c_str(), std::int64_t{1} << 30), 0);

  const ProcessResult run = RunTempokey({"info", path}, dir_);

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.err, "error: " + path +
                         ": file is 1073741824 bytes, over the limit of 268435456\n");
  EXPECT_LT(ChildrenPeakRssKiB(), kBoundedRssKiB);
}

TEST_F(InputTest, SparseFileUnderTheCapIsRefusedAtItsFirstChunk) {
  const std::string path = Path("holes.bvh");
  { std::ofstream touch(path); }
  ASSERT_EQ(::truncate(path.c_str(), std::int64_t{200} << 20), 0);

  const ProcessResult run = RunTempokey({"info", path}, dir_);

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.err,
            "error: " + path + ":1:1: unexpected byte 0x00; the file looks binary, not text\n");
  EXPECT_LT(ChildrenPeakRssKiB(), kBoundedRssKiB);
}

TEST_F(InputTest, DevZeroUnderAnAddressSpaceLimitIsRefusedNotAborted) {
  // Read whole, /dev/zero once ran the CLI into std::bad_alloc and SIGABRT.
  const std::string path = Path("zero.bvh");
  ASSERT_EQ(::symlink("/dev/zero", path.c_str()), 0);

  const ProcessResult run = RunProcess(
      {"/usr/bin/prlimit", "--as=1073741824", TempokeyBinary(), "info", path}, dir_);

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.err, "error: " + path + ": is a character device, not a file\n");
}

TEST_F(InputTest, FifoNobodyWritesToIsRefusedInsteadOfWaitedForForever) {
  const std::string path = Path("silent.bvh");
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);

  const ProcessResult run = RunTempokey({"info", path}, dir_);

  EXPECT_FALSE(run.timed_out);
  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.err,
            "error: " + path + ": is a FIFO and nothing arrived for 10 s (no writer?)\n");
}

TEST_F(InputTest, FifoWithAWriterIsReadLikeAFile) {
  const std::string path = Path("piped.bvh");
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  const std::string clip = Slurp(SharedBvh(kWalk));
  std::thread writer([&] {
    std::ofstream out(path, std::ios::binary);  // blocks until the CLI opens its end
    out << clip;
  });

  const ProcessResult run = RunTempokey({"info", path}, dir_);
  writer.join();

  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_THAT(run.out, HasSubstr("frames:"));
  EXPECT_THAT(run.out, HasSubstr("146"));
}

// ---- a signal during the write ---------------------------------------------------------------------

// Waits (bounded) for `pid` to end; the signal that killed it, 0 for a normal exit, -1 on timeout.
int WaitForSignalDeath(pid_t pid) {
  const auto deadline = std::chrono::steady_clock::now() + kProcessTimeout;
  while (std::chrono::steady_clock::now() < deadline) {
    int status = 0;
    const pid_t done = waitpid(pid, &status, WNOHANG);
    if (done == pid) return WIFSIGNALED(status) ? WTERMSIG(status) : 0;
    if (done < 0) return -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  kill(pid, SIGKILL);
  return -1;
}

class InterruptedWriteTest : public ServerProcessTest, public ::testing::WithParamInterface<int> {};

TEST_P(InterruptedWriteTest, SignalDuringTheWriteLeavesNoTemporaryAndTheOldOutput) {
  const int signal_number = GetParam();
  const std::string out_dir = Path("out");
  std::filesystem::create_directory(out_dir);
  const std::string output = out_dir + "/slow.bvh";
  {
    std::ofstream old(output);
    old << "the previous output\n";
  }
  // The test hook stops the CLI with SIGSTOP right after the temporary file is created: the
  // signal below then lands in the middle of the write, with no race.
  absl::StatusOr<pid_t> pid =
      Spawn({TempokeyBinary(), "--server", server_->target(), "retime", SharedBvh(kWalk), "-o",
             output, "--speed", "0s:0.25"},
            Path("cli.out"), Path("cli.err"), {"TEMPOKEY_TEST_STOP_IN_WRITE=1"});
  ASSERT_TRUE(pid.ok()) << pid.status();

  ASSERT_TRUE(WaitUntilStopped(*pid)) << Slurp(Path("cli.err"));
  const std::vector<std::string> during = TempFilesIn(out_dir);
  kill(*pid, signal_number);
  kill(*pid, SIGCONT);
  const int killed_by = WaitForSignalDeath(*pid);

  EXPECT_EQ(during.size(), 1u);  // the write was in flight
  EXPECT_EQ(killed_by, signal_number);
  EXPECT_THAT(TempFilesIn(out_dir), ::testing::IsEmpty());
  EXPECT_EQ(Slurp(output), "the previous output\n");
}

INSTANTIATE_TEST_SUITE_P(Signals, InterruptedWriteTest, ::testing::Values(SIGINT, SIGTERM),
                         [](const ::testing::TestParamInfo<int>& param) {
                           return param.param == SIGINT ? std::string("Sigint")
                                                        : std::string("Sigterm");
                         });

}  // namespace
}  // namespace tempokey::testing
