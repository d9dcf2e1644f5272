// The resume manifest of `tempokey batch` (client/batch_manifest.h) on real files in a temporary
// folder: which records let a file be skipped, what a run keeps and drops, the document's
// syntax and its refusals, the pipeline digest, and the cleanup of a killed run's temporaries.
#include "client/batch_manifest.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <thread>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/pipeline_file.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/test_paths.h"

namespace tempokey::client {
namespace {

namespace fs = std::filesystem;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

constexpr char kInputId[] = "sha256:1111111111111111111111111111111111111111111111111111111111111111";
constexpr char kOtherInputId[] =
    "sha256:2222222222222222222222222222222222222222222222222222222222222222";
constexpr char kPipeline[] = "sha256:aaaa";
constexpr char kOtherPipeline[] = "sha256:bbbb";

std::vector<core::PipelineStep> Steps(const std::string& json) {
  absl::StatusOr<std::vector<core::PipelineStep>> steps = ParsePipelineJson(json, "ops.json");
  EXPECT_TRUE(steps.ok()) << steps.status();
  return steps.ok() ? *steps : std::vector<core::PipelineStep>{};
}

std::string Digest(const std::string& json, std::optional<FileFormat> format) {
  return PipelineDigest(Steps(json), format);
}

TEST(PipelineDigestTest, SameOptionsSpelledDifferentlyGiveTheSameDigest) {
  const std::string a = Digest(R"({"operations": [{"retime": {"speed": "0s:2", "fit_frames": 90}}]})",
                               FileFormat::kBvh);
  const std::string b = Digest(
      R"({"operations": [{"retime": {"fit-frames": "90", "speed": "0s:2.0"}}]})", FileFormat::kBvh);

  EXPECT_EQ(a, b);
  EXPECT_THAT(a, ::testing::MatchesRegex("sha256:[0-9a-f]{64}"));
}

TEST(PipelineDigestTest, AnyChangeOfValueStepOrFormatChangesTheDigest) {
  const std::string base = R"({"operations": [{"reduce": {"tolerance": 0.5}}]})";
  const std::vector<std::string> digests = {
      Digest(base, FileFormat::kKeyedJson),
      Digest(base, FileFormat::kMayaAnim),
      Digest(base, std::nullopt),
      Digest(R"({"operations": [{"reduce": {"tolerance": 0.4}}]})", FileFormat::kKeyedJson),
      Digest(R"({"operations": [{"retime": {"speed": "0s:2"}}, {"reduce": {"tolerance": 0.5}}]})",
             FileFormat::kKeyedJson),
      Digest(R"({"operations": [{"reduce": {"tolerance": 0.5, "pose-align": "joint"}}]})",
             FileFormat::kKeyedJson),
  };

  for (std::size_t i = 0; i < digests.size(); ++i) {
    for (std::size_t j = i + 1; j < digests.size(); ++j) {
      EXPECT_NE(digests[i], digests[j]) << i << " and " << j;
    }
  }
}

TEST(ManifestDocumentTest, FormatThenParseGivesTheRecordsBackSorted) {
  const std::vector<ManifestRecord> records = {
      {.output = "sub/b.json", .input = "sub/b.bvh", .input_id = kInputId, .pipeline = kPipeline,
       .output_bytes = 10, .output_id = "sha256:cc", .keys = 3, .max_error = 0.49977981950762285},
      {.output = "a \"quoted\".bvh", .input = "a \"quoted\".bvh", .input_id = kOtherInputId,
       .pipeline = kPipeline, .output_bytes = 0, .output_id = "sha256:dd", .frames = 90},
  };

  const std::string text = FormatManifest(records, BatchShard{.index = 1, .count = 4});
  absl::StatusOr<std::vector<ManifestRecord>> parsed = ParseManifest(text, "m.json");

  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_THAT(*parsed, ElementsAre(records[1], records[0]));
  EXPECT_THAT(text, ::testing::StartsWith(
                        "{\"format\": \"tempokey.batch_manifest\", \"version\": 1, \"shard\": "
                        "\"1/4\", \"outputs\": {\n  \"a \\\"quoted\\\".bvh\": {\"input\": "));
  EXPECT_EQ(FormatManifest({}, std::nullopt),
            "{\"format\": \"tempokey.batch_manifest\", \"version\": 1, \"outputs\": {}}\n");
}

TEST(ManifestDocumentTest, MalformedManifestsAreRefusedWithTheirPlace) {
  const std::string head = R"({"format": "tempokey.batch_manifest", "version": 1, "outputs": )";
  const std::string good =
      R"({"input": "a.bvh", "input_id": "sha256:1", "pipeline": "sha256:2", "output_bytes": 3, "output_id": "sha256:4"})";
  struct Case {
    std::string text;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"[]", "m.json:1:1: expected an object"},
      {R"({"format": "tempokey.keyed_clip", "version": 1, "outputs": {}})",
       "m.json:1:12: not a batch manifest (\"format\" must be \"tempokey.batch_manifest\")"},
      {R"({"format": "tempokey.batch_manifest", "version": 2, "outputs": {}})",
       "m.json:1:50: unsupported manifest version (this tempokey reads 1)"},
      {R"({"format": "tempokey.batch_manifest", "version": 1})",
       "m.json:1:1: \"outputs\" must be an object"},
      {head + R"({"a.json": 5}})", "m.json:1:75: an output's record must be an object"},
      {head + R"({"a.json": {"input": "a.bvh"}}})", "m.json:1:75: missing \"input_id\""},
      {head + R"({"a.json": )" + good + R"(, "a.json": )" + good + "}}",
       "m.json:1:197: output \"a.json\" is listed twice"},
      {head + R"({"a.json": {"input": "a.bvh", "input_id": "sha256:1", "pipeline": "sha256:2", "output_bytes": -3, "output_id": "x"}}})",
       "m.json:1:158: \"output_bytes\" must be a whole number from 0 to 9007199254740992"},
      {head + "{", "m.json:1:65: expected a member name, got the end of the text"},
  };
  for (const Case& c : cases) {
    absl::StatusOr<std::vector<ManifestRecord>> parsed = ParseManifest(c.text, "m.json");

    ASSERT_FALSE(parsed.ok()) << c.text;
    EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(parsed.status().message()), ::testing::StartsWith(c.message))
        << c.text;
  }
}

class BatchManifestTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::MakeTempDir();
    out_ = dir_ + "/out";
    fs::create_directories(out_);
  }

  BatchItem Item(const std::string& stem) const {
    return BatchItem{.name = stem + ".bvh", .input_path = dir_ + "/in/" + stem + ".bvh",
                     .output_path = out_ + "/" + stem + ".json",
                     .output_format = FileFormat::kKeyedJson};
  }

  // Writes `item`'s output and records it in `manifest`.
  void Produce(BatchManifest& manifest, const BatchItem& item, const std::string& contents,
               const char* input_id = kInputId, const char* pipeline = kPipeline) {
    ASSERT_TRUE(core::WriteFileAtomically(item.output_path, contents).ok());
    ASSERT_TRUE(manifest.RecordWritten(item, input_id, pipeline, {.keys = 7}).ok());
  }

  std::unique_ptr<BatchManifest> Open(std::optional<BatchShard> shard = std::nullopt,
                                      bool force = false) {
    absl::StatusOr<std::unique_ptr<BatchManifest>> manifest = BatchManifest::Open(out_, shard, force);
    EXPECT_TRUE(manifest.ok()) << manifest.status();
    return manifest.ok() ? *std::move(manifest) : nullptr;
  }

  std::vector<ManifestRecord> OnDisk(const std::string& name) {
    absl::StatusOr<std::string> text = core::ReadFile(out_ + "/" + name);
    if (!text.ok()) return {};
    absl::StatusOr<std::vector<ManifestRecord>> records = ParseManifest(*text, name);
    EXPECT_TRUE(records.ok()) << records.status();
    return records.ok() ? *records : std::vector<ManifestRecord>{};
  }

  std::string dir_;
  std::string out_;
};

TEST_F(BatchManifestTest, RecordedOutputIsUpToDateForTheSameInputAndPipelineOnly) {
  const BatchItem walk = Item("walk");
  {
    std::unique_ptr<BatchManifest> first = Open();
    Produce(*first, walk, "curves");
    ASSERT_TRUE(first->Finish(std::vector<BatchItem>{walk}).ok());
  }

  std::unique_ptr<BatchManifest> second = Open();
  std::optional<ManifestRecord> same = second->FindUpToDate(walk, kInputId, kPipeline);
  BatchItem renamed = walk;
  renamed.name = "walk2.bvh";

  ASSERT_TRUE(same.has_value());
  EXPECT_EQ(same->output, "walk.json");
  EXPECT_EQ(same->output_bytes, 6);
  EXPECT_EQ(same->keys, 7);
  // The SHA-256 of "curves", as `printf curves | sha256sum` prints it.
  EXPECT_EQ(same->output_id,
            "sha256:ba27dd05387c293ca07c49aaf6583d75f77802ba731aaabdea57773d7de38416");
  EXPECT_FALSE(second->FindUpToDate(walk, kOtherInputId, kPipeline));
  EXPECT_FALSE(second->FindUpToDate(walk, kInputId, kOtherPipeline));
  EXPECT_FALSE(second->FindUpToDate(renamed, kInputId, kPipeline));
}

// An output written over its own input goes to the journal at once, a line each (a save of the
// whole manifest per file took 16 s for 3 000 files, 61 s for 6 000): a run killed before its
// manifest was saved still knows the file is done, and a line cut short by the kill is left out.
TEST_F(BatchManifestTest, AnOutputWrittenOverItsInputIsJournaledAndFoundAfterAKill) {
  BatchItem walk = Item("walk");
  walk.input_path = walk.output_path;  // in place (--overwrite)
  BatchItem run = Item("run");
  run.input_path = run.output_path;
  {
    std::unique_ptr<BatchManifest> killed = Open();
    Produce(*killed, walk, "curves");
    Produce(*killed, run, "curves");
    // No Finish(): the process dies here.
  }
  // Whether or not the saving thread got to it, the manifest is lost with the process.
  fs::remove(out_ + "/.tempokey-batch.json");
  std::string journal = core::ReadFile(out_ + "/.tempokey-batch.journal").value_or("");
  ASSERT_EQ(std::count(journal.begin(), journal.end(), '\n'), 2) << journal;
  journal.resize(journal.size() - 9);  // the last line cut short
  ASSERT_TRUE(core::WriteFileAtomically(out_ + "/.tempokey-batch.journal", journal).ok());

  // The next run (killed too) appends after the torn line: its record starts a line of its own.
  BatchItem bow = Item("bow");
  bow.input_path = bow.output_path;
  {
    std::unique_ptr<BatchManifest> again = Open();
    Produce(*again, bow, "curves");
  }
  fs::remove(out_ + "/.tempokey-batch.json");

  std::unique_ptr<BatchManifest> next = Open();
  const std::optional<ManifestRecord> done = next->FindUpToDate(walk, kOtherInputId, kPipeline);
  const std::optional<ManifestRecord> lost = next->FindUpToDate(run, kOtherInputId, kPipeline);
  const std::optional<ManifestRecord> after = next->FindUpToDate(bow, kOtherInputId, kPipeline);
  ASSERT_TRUE(next->Finish(std::vector<BatchItem>{walk, run, bow}).ok());

  // In place, the input id is the output's own: the record's output on disk says done.
  ASSERT_TRUE(done.has_value());
  EXPECT_EQ(done->output, "walk.json");
  EXPECT_FALSE(lost.has_value());
  ASSERT_TRUE(after.has_value());
  EXPECT_EQ(after->output, "bow.json");
  EXPECT_FALSE(fs::exists(out_ + "/.tempokey-batch.journal"));  // folded into the manifest
}

// A name JSON cannot hold (not UTF-8) is not recorded: it could never match again, and two such
// names differing only in those bytes made one key listed twice, which stopped every later run.
// Nor is an output that is no regular file (a FIFO): there is nothing to read back.
TEST_F(BatchManifestTest, NamesThatAreNotUtf8AndOutputsThatAreNotFilesAreNotRecorded) {
  const BatchItem e9 = Item("caf\xe9");
  const BatchItem e8 = Item("caf\xe8");
  BatchItem null_output = Item("null");
  null_output.output_path = "/dev/null";
  {
    std::unique_ptr<BatchManifest> first = Open();
    Produce(*first, e9, "curves");
    Produce(*first, e8, "curves");
    ASSERT_TRUE(first->RecordWritten(null_output, kInputId, kPipeline, {}).ok());
    ASSERT_TRUE(first->Finish(std::vector<BatchItem>{e9, e8, null_output}).ok());
  }

  EXPECT_TRUE(OnDisk(".tempokey-batch.json").empty());
  std::unique_ptr<BatchManifest> second = Open();  // opens: no key listed twice
  ASSERT_NE(second, nullptr);
  EXPECT_FALSE(second->FindUpToDate(e9, kInputId, kPipeline));
}

TEST_F(BatchManifestTest, AlteredOrMissingOutputIsNotUpToDate) {
  const BatchItem walk = Item("walk");
  const BatchItem run = Item("run");
  {
    std::unique_ptr<BatchManifest> first = Open();
    Produce(*first, walk, "curves");
    Produce(*first, run, "curves");
    ASSERT_TRUE(first->Finish(std::vector<BatchItem>{walk, run}).ok());
  }
  ASSERT_TRUE(core::WriteFileAtomically(walk.output_path, "curvez").ok());  // same size
  fs::remove(run.output_path);

  std::unique_ptr<BatchManifest> second = Open();

  EXPECT_FALSE(second->FindUpToDate(walk, kInputId, kPipeline));
  EXPECT_FALSE(second->FindUpToDate(run, kInputId, kPipeline));
}

TEST_F(BatchManifestTest, RecordsOfOtherShardsCountAndAreKeptByTheRunThatSkips) {
  const BatchItem walk = Item("walk");
  {
    std::unique_ptr<BatchManifest> shard = Open(BatchShard{.index = 2, .count = 4});
    Produce(*shard, walk, "curves");
    ASSERT_TRUE(shard->Finish(std::vector<BatchItem>{walk}).ok());
  }

  std::unique_ptr<BatchManifest> whole = Open();
  std::optional<ManifestRecord> record = whole->FindUpToDate(walk, kInputId, kPipeline);
  ASSERT_TRUE(record.has_value());
  whole->Keep(*record);
  ASSERT_TRUE(whole->Finish(std::vector<BatchItem>{walk}).ok());

  EXPECT_EQ(whole->path(), out_ + "/.tempokey-batch.json");
  EXPECT_THAT(OnDisk(".tempokey-batch.json"), ElementsAre(*record));
  EXPECT_THAT(OnDisk(".tempokey-batch.shard-2-of-4.json"), ElementsAre(*record));
}

TEST_F(BatchManifestTest, ForceFindsNothingAndKeepsOnlyWhatItWrote) {
  const BatchItem walk = Item("walk");
  const BatchItem run = Item("run");
  {
    std::unique_ptr<BatchManifest> first = Open();
    Produce(*first, walk, "curves");
    Produce(*first, run, "curves");
    ASSERT_TRUE(first->Finish(std::vector<BatchItem>{walk, run}).ok());
  }

  std::unique_ptr<BatchManifest> forced = Open(std::nullopt, /*force=*/true);
  EXPECT_FALSE(forced->FindUpToDate(walk, kInputId, kPipeline));
  Produce(*forced, walk, "new curves", kOtherInputId);
  ASSERT_TRUE(forced->Finish(std::vector<BatchItem>{walk, run}).ok());

  const std::vector<ManifestRecord> records = OnDisk(".tempokey-batch.json");
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].output, "walk.json");
  EXPECT_EQ(records[0].input_id, kOtherInputId);
  EXPECT_EQ(records[0].output_bytes, 10);
}

TEST_F(BatchManifestTest, FailedFilesAndRemovedInputsLoseTheirRecords) {
  const BatchItem walk = Item("walk");
  const BatchItem run = Item("run");
  const BatchItem jump = Item("jump");
  {
    std::unique_ptr<BatchManifest> first = Open();
    for (const BatchItem& item : {walk, run, jump}) Produce(*first, item, "curves");
    ASSERT_TRUE(first->Finish(std::vector<BatchItem>{walk, run, jump}).ok());
  }

  // jump.bvh is gone from the folder; walk failed this time.
  std::unique_ptr<BatchManifest> second = Open();
  second->Forget(walk);
  ASSERT_TRUE(second->Finish(std::vector<BatchItem>{walk, run}).ok());

  const std::vector<ManifestRecord> records = OnDisk(".tempokey-batch.json");
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].output, "run.json");
}

TEST_F(BatchManifestTest, ManifestIsSavedAsFilesFinishNotOnlyAtTheEnd) {
  const BatchItem walk = Item("walk");
  std::unique_ptr<BatchManifest> manifest = Open();

  Produce(*manifest, walk, "curves");

  // The saving thread writes it soon; the deadline only bounds a hang.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (OnDisk(".tempokey-batch.json").empty() && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const std::vector<ManifestRecord> records = OnDisk(".tempokey-batch.json");
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].output, "walk.json");
}

TEST_F(BatchManifestTest, RunThatRecordedNothingLeavesNoManifest) {
  std::unique_ptr<BatchManifest> manifest = Open();

  ASSERT_TRUE(manifest->Finish(std::vector<BatchItem>{Item("walk")}).ok());

  EXPECT_FALSE(fs::exists(manifest->path()));
}

TEST_F(BatchManifestTest, UnreadableManifestStopsTheRunWithItsPlaceAndTheWayOut) {
  ASSERT_TRUE(core::WriteFileAtomically(out_ + "/.tempokey-batch.shard-0-of-2.json", "{\"format\"").ok());

  absl::StatusOr<std::unique_ptr<BatchManifest>> manifest = BatchManifest::Open(out_, std::nullopt, false);
  absl::StatusOr<std::unique_ptr<BatchManifest>> forced = BatchManifest::Open(out_, std::nullopt, true);

  ASSERT_FALSE(manifest.ok());
  EXPECT_EQ(manifest.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(manifest.status().message()),
              ::testing::StartsWith(out_ + "/.tempokey-batch.shard-0-of-2.json:1:"));
  EXPECT_THAT(std::string(manifest.status().message()),
              HasSubstr("; remove the file or run with --force"));
  EXPECT_TRUE(forced.ok()) << forced.status();
}

TEST_F(BatchManifestTest, LeftoverTemporariesOfTheRunsOwnFilesAreRemovedOnly) {
  const std::vector<BatchItem> items = {Item("walk")};
  std::unique_ptr<BatchManifest> manifest = Open();
  ASSERT_NE(manifest, nullptr);
  const absl::StatusOr<std::string> staged = manifest->StagingPath(items[0]);
  ASSERT_TRUE(staged.ok()) << staged.status();
  const std::string own_staged = fs::path(*staged).filename().string();
  const std::vector<std::string> removed_names = {
      "walk.json.tmp-ab12cd34", ".tempokey-batch.json.tmp-zzzzzzzz", own_staged,
      own_staged + ".tmp-ab12cd34"};
  // Another manifest's staging files (another shard's, or another folder's manifest replacing
  // files here) look alike but are not this run's.
  const std::vector<std::string> kept_names = {
      "walk.json.tmp-AB12CD34", "walk.json.tmp-ab12", "run.json.tmp-ab12cd34", "walk.json",
      ".tempokey-batch.shard-0-of-2.json.tmp-ab12cd34",
      ".tempokey-batch.shard-0-of-2.staged-0123456789abcdef",
      ".tempokey-batch.staged-0123456789abcdef"};
  for (const std::string& name : removed_names) {
    ASSERT_TRUE(core::WriteFileAtomically(out_ + "/" + name, "x").ok());
  }
  for (const std::string& name : kept_names) {
    ASSERT_TRUE(core::WriteFileAtomically(out_ + "/" + name, "x").ok());
  }

  const int removed = manifest->RemoveLeftoverTemporaries(items);

  EXPECT_EQ(removed, 4);
  for (const std::string& name : removed_names) EXPECT_FALSE(fs::exists(out_ + "/" + name)) << name;
  for (const std::string& name : kept_names) EXPECT_TRUE(fs::exists(out_ + "/" + name)) << name;
}

// An output name of 250 bytes has temporaries named by its first 242 (the longest name is 255):
// a killed run's are still found as its own, and removed.
TEST_F(BatchManifestTest, LeftoverTemporariesOfALongOutputNameAreFoundByItsStem) {
  const std::string stem(245, 'w');  // "<245 w>.json": 250 bytes
  const std::vector<BatchItem> items = {Item(stem)};
  std::unique_ptr<BatchManifest> manifest = Open();
  ASSERT_NE(manifest, nullptr);
  const std::string leftover = std::string(242, 'w') + ".tmp-ab12cd34";
  const std::string other = std::string(241, 'w') + ".tmp-ab12cd34";
  ASSERT_TRUE(core::WriteFileAtomically(out_ + "/" + leftover, "x").ok());
  ASSERT_TRUE(core::WriteFileAtomically(out_ + "/" + other, "x").ok());

  const int removed = manifest->RemoveLeftoverTemporaries(items);

  EXPECT_EQ(removed, 1);
  EXPECT_FALSE(fs::exists(out_ + "/" + leftover));
  EXPECT_TRUE(fs::exists(out_ + "/" + other));
}

// One writer per manifest: a second Open() of the same manifest (same folder, same shard) is
// refused while the first is open, naming the lock; another shard's opens beside it; once the
// first is gone the manifest opens again and no lock file is left behind.
TEST_F(BatchManifestTest, SecondOpenOfTheSameManifestIsRefusedWhileTheFirstIsOpen) {
  std::unique_ptr<BatchManifest> first = Open();
  ASSERT_NE(first, nullptr);

  absl::StatusOr<std::unique_ptr<BatchManifest>> second = BatchManifest::Open(out_, std::nullopt, false);
  absl::StatusOr<std::unique_ptr<BatchManifest>> forced = BatchManifest::Open(out_, std::nullopt, true);
  absl::StatusOr<std::unique_ptr<BatchManifest>> shard =
      BatchManifest::Open(out_, BatchShard{.index = 0, .count = 2}, false);

  EXPECT_EQ(second.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(second.status().message()),
              ::testing::StartsWith(out_ + "/.tempokey-batch.lock: another tempokey batch is "
                                           "running with this manifest (.tempokey-batch.json)"));
  EXPECT_EQ(forced.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(shard.ok()) << shard.status();
  first.reset();
  shard = absl::UnknownError("closed");
  EXPECT_FALSE(fs::exists(out_ + "/.tempokey-batch.lock"));
  EXPECT_FALSE(fs::exists(out_ + "/.tempokey-batch.shard-0-of-2.lock"));
  std::unique_ptr<BatchManifest> again = Open();
  EXPECT_NE(again, nullptr);
}

}  // namespace
}  // namespace tempokey::client
