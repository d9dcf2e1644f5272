// Writes the seed corpus of every fuzz target into OUT/<target>/ (the build tree; nothing here is
// committed): the real captures of ../shared/data/bvh cut to a few frames (as BVH, CSV, keyed JSON
// of their reductions, wire messages and upload streams), the pipelines of the README and of the
// CLI's options, and the tables of bad retimes and bad paper parameters the tests use.
//
//   seed_corpus OUT
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <fstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/pipeline_file.h"
#include "fuzz/fuzz_util.h"
#include "proto/clip_convert.h"
#include "proto/operations_convert.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/csv.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/v1/motion_service.pb.h"
#include "tests/core/reduce/reduce_invalid_cases.h"
#include "tests/core/retime/retime_invalid_cases.h"

namespace tempokey::fuzz {
namespace {

namespace fs = std::filesystem;

class Corpus {
 public:
  explicit Corpus(fs::path root) : root_(std::move(root)) {}

  void Add(const std::string& target, std::string_view bytes) {
    const fs::path dir = root_ / target;
    fs::create_directories(dir);
    const int n = counts_[target]++;
    std::ofstream out(dir / absl::StrCat("seed-", n), std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }

  void Report() const {
    for (const auto& [target, count] : counts_) std::printf("%s: %d seeds\n", target.c_str(), count);
  }

 private:
  fs::path root_;
  std::map<std::string, int> counts_;
};

// The first `frames` frames of `clip`.
core::Clip Cut(core::Clip clip, std::int64_t frames) {
  frames = std::min(frames, clip.frame_count);
  clip.frame_count = frames;
  for (core::Channel& channel : clip.channels) channel.samples.resize(static_cast<std::size_t>(frames));
  clip.markers.clear();
  return clip;
}

std::vector<std::string> SharedBvhFiles() {
  std::vector<std::string> files;
  const fs::path dir = fs::path(TEMPOKEY_SHARED_DIR) / "data" / "bvh";
  if (!fs::exists(dir)) return files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.path().extension() == ".bvh") files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Pipelines in the batch file syntax: the README's, and one per option of every operation.
const std::vector<std::string>& PipelineDocuments() {
  static const std::vector<std::string> documents = {
      R"({"operations": [{"retime": {"speed": "0s:1,2s:0.5,4s:1", "fps": 30}}, {"reduce": {"tolerance": 0.5}}]})",
      R"({"operations": [{"retime": {"speed": "0s:1,1s:1,1s:0.5,2s:0.5,2s:1", "filter": "lanczos3"}}]})",
      R"({"operations": [{"retime": {"speed": "0s:0.5", "speed-over": "output", "reverse": true}}]})",
      R"({"operations": [{"retime": {"fit-frames": 60, "hold": ["0.5s:0.25"], "pin": ["0.2s:5"]}}]})",
      R"({"operations": [{"retime": {"fit-seconds": 2, "fps": "24000/1001", "rotation": "euler"}}]})",
      R"({"operations": [{"retime": {"speed": "0f:2,20f:0.25", "method": "paper", "filter": "box"}}]})",
      R"({"operations": [{"retime": {"filter": "cubic", "speed": "0s:0.1"}}, {"convert": {"wrap-rotations": true}}]})",
      R"({"operations": [{"reduce": {"method": "paper", "iterations": 2, "accuracy": 0.1}}, {"bake": {"fps": 60}}]})",
      R"({"operations": [{"reduce": {"key-budget": 40, "pose-align": "joint"}}, {"bake": {}}]})",
      R"({"operations": [{"reduce": {"tolerance": 0.1, "position-tolerance": 0.2, "scalar-tolerance": 0.05, "pose-align": "clip"}}]})",
      R"({"operations": [{"reduce": {"method": "paper", "step-x": 2, "step-y": 1, "step-tangent-x": 0.5, "step-tangent-y": 0.25, "smoothing-sigma": 0, "min-key-spacing": 1, "iterations": 1}}]})",
      R"({"operations": [{"convert": {}}, {"retime": {"speed": "0s:3"}}, {"reduce": {}}, {"bake": {"fps": 120}}, {"retime": {"speed": "0s:0.5"}}]})",
  };
  return documents;
}

// Knots in the CLI syntax, valid and not.
const std::vector<std::string> kSpeedTexts = {
    "0s:1", "0s:0.5", "0s:1,2s:0.5,4s:1", "0s:1,2s:1,2s:0.5,4s:0.5,4s:1", "75f:0.5,150f:2",
    " 0s : 1 , 1s : 2 ", "+1e-3s:2", "0s:100,0.01s:0.01", "1s:1,0s:1", "0s:0", "2x:0.5",
    "0s:1x", "0s:1e-400", "0f:1,1e17f:1", "-1s:0.25,1s:4",
};

void AddClipSeeds(Corpus& corpus, const core::Clip& clip) {
  if (absl::StatusOr<std::string> bvh = core::FormatBvh(clip); bvh.ok()) corpus.Add("bvh_fuzz", *bvh);
  if (absl::StatusOr<std::string> csv = core::FormatCsv(clip); csv.ok()) {
    corpus.Add("csv_fuzz", std::string(1, '\0') + *csv);
  }
  // An upload stream: the header, then slices and batches of slices.
  std::string stream;
  AppendRecord(stream, 0, wire::ClipHeaderToProto(clip).SerializeAsString());
  (void)wire::ForEachSamplesSlice(clip, 512, [&](v1::ChannelSamples&& samples) {
    AppendRecord(stream, 1, samples.SerializeAsString());
    return absl::OkStatus();
  });
  corpus.Add("clip_assembler_fuzz", stream);
  std::string batched;
  AppendRecord(batched, 0, wire::ClipHeaderToProto(clip).SerializeAsString());
  (void)wire::ForEachSamplesBatch(clip, 2048, [&](v1::SampleSlices&& slices) {
    AppendRecord(batched, 2, slices.SerializeAsString());
    return absl::OkStatus();
  });
  corpus.Add("clip_assembler_fuzz", batched);

  // Its reductions, as keyed JSON and keyed messages.
  core::ReduceOptions paper;
  paper.method = core::ReduceMethod::kPaper;
  paper.paper.max_iterations = 1;
  for (const core::ReduceOptions& options : {core::ReduceOptions{}, paper}) {
    absl::StatusOr<core::ReduceResult> reduced = core::ReduceKeys(clip, options);
    if (!reduced.ok()) continue;
    if (absl::StatusOr<std::string> json = core::FormatKeyedClipJson(reduced->keyed); json.ok()) {
      corpus.Add("keyed_json_fuzz", *json);
    }
    corpus.Add("keyed_proto_fuzz", wire::KeyedClipToProto(reduced->keyed).SerializeAsString());
  }
}

void AddRequestSeeds(Corpus& corpus, const core::Clip& clip,
                     const google::protobuf::RepeatedPtrField<v1::Operation>& operations) {
  v1::SubmitJobRequest submit;
  *submit.mutable_inline_clip() = wire::ClipToProto(clip);
  *submit.mutable_operations() = operations;
  submit.set_request_id("seed");
  (*submit.mutable_labels())["stage"] = "fuzz";
  corpus.Add("requests_fuzz", std::string(1, '\0') + submit.SerializeAsString());

  std::string process(1, '\1');
  v1::ProcessRequest header;
  *header.mutable_header() = wire::ClipHeaderToProto(clip);
  AppendRecord(process, 0, header.SerializeAsString());
  (void)wire::ForEachSamplesSlice(clip, 1024, [&](v1::ChannelSamples&& samples) {
    v1::ProcessRequest request;
    *request.mutable_samples() = std::move(samples);
    AppendRecord(process, 0, request.SerializeAsString());
    return absl::OkStatus();
  });
  v1::ProcessRequest start;
  *start.mutable_start()->mutable_operations() = operations;
  AppendRecord(process, 0, start.SerializeAsString());
  corpus.Add("requests_fuzz", process);
}

google::protobuf::RepeatedPtrField<v1::Operation> ToProto(const std::vector<core::PipelineStep>& steps) {
  google::protobuf::RepeatedPtrField<v1::Operation> operations;
  for (const core::PipelineStep& step : steps) *operations.Add() = wire::PipelineStepToProto(step);
  return operations;
}

int Run(const char* out) {
  Corpus corpus{fs::path(out)};

  // Real captures, cut short so an execution stays fast.
  const core::Clip small = SmallClip();
  AddClipSeeds(corpus, small);
  for (const std::string& path : SharedBvhFiles()) {
    absl::StatusOr<core::Clip> clip = core::ReadBvhFile(path);
    if (!clip.ok()) continue;
    AddClipSeeds(corpus, Cut(*clip, 12));
    // The file's own text up to a few kilobytes: its header as written by its exporter.
    std::ifstream in(path, std::ios::binary);
    std::string head(4096, '\0');
    in.read(head.data(), static_cast<std::streamsize>(head.size()));
    head.resize(static_cast<std::size_t>(in.gcount()));
    corpus.Add("bvh_fuzz", head);
  }

  for (std::size_t i = 0; i < kSpeedTexts.size(); ++i) {
    corpus.Add("speed_knots_fuzz", std::string(1, static_cast<char>(i * 37)) + kSpeedTexts[i]);
  }

  // Pipelines: as batch files, as wire operations, inside requests.
  for (const std::string& document : PipelineDocuments()) {
    corpus.Add("pipeline_file_fuzz", document);
    absl::StatusOr<std::vector<core::PipelineStep>> steps =
        client::ParsePipelineJson(document, "seed.json");
    if (!steps.ok()) {
      std::fprintf(stderr, "seed pipeline refused: %s\n", std::string(steps.status().message()).c_str());
      return 1;
    }
    v1::ProcessStart start;
    *start.mutable_operations() = ToProto(*steps);
    corpus.Add("pipeline_proto_fuzz", start.SerializeAsString());
    AddRequestSeeds(corpus, small, start.operations());
  }
  // The tests' tables of bad retimes and bad paper parameters.
  for (const core::retime_cases::BadRetime& bad : core::retime_cases::BadRetimes()) {
    core::RetimeStep step;
    step.warp = bad.warp;
    step.options = bad.options;
    v1::ProcessStart start;
    *start.add_operations() = wire::PipelineStepToProto(step);
    corpus.Add("pipeline_proto_fuzz", start.SerializeAsString());
  }
  for (const core::reduce_cases::BadPaperParams& bad :
       core::reduce_cases::BadPaperParamsTable()) {
    core::ReduceStep step;
    step.options.method = core::ReduceMethod::kPaper;
    bad.mutate(step.options.paper);
    v1::ProcessStart start;
    *start.add_operations() = wire::PipelineStepToProto(step);
    corpus.Add("pipeline_proto_fuzz", start.SerializeAsString());
  }
  corpus.Report();
  return 0;
}

}  // namespace
}  // namespace tempokey::fuzz

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: seed_corpus OUT\n");
    return 2;
  }
  return tempokey::fuzz::Run(argv[1]);
}
