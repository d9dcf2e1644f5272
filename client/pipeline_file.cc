#include "client/pipeline_file.h"

#include <algorithm>
#include <span>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "client/args.h"
#include "client/cli_errors.h"
#include "client/step_flags.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;
using core::JsonValue;

constexpr std::int64_t kMaxPipelineFileBytes = 1 << 20;

// One kind of operation: its name in the file, its flags and the parser of its step.
struct OperationKind {
  std::string_view name;
  std::span<const FlagSpec> flags;
  absl::StatusOr<core::PipelineStep> (*parse)(const ParsedArgs& args);
};

template <typename Step, absl::StatusOr<Step> (*FromArgs)(const ParsedArgs&)>
absl::StatusOr<core::PipelineStep> AsStep(const ParsedArgs& args) {
  TEMPOKEY_ASSIGN_OR_RETURN(Step step, FromArgs(args));
  return core::PipelineStep(std::move(step));
}

const OperationKind kOperationKinds[] = {
    {"retime", kRetimeStepFlags, AsStep<core::RetimeStep, RetimeStepFromArgs>},
    {"reduce", kReduceStepFlags, AsStep<core::ReduceStep, ReduceStepFromArgs>},
    {"bake", kBakeStepFlags, AsStep<core::BakeStep, BakeStepFromArgs>},
    {"convert", kConvertStepFlags, AsStep<core::ConvertStep, ConvertStepFromArgs>},
};

// Reports problems at a value of the document.
class Locator {
 public:
  explicit Locator(std::string_view source) : source_(source) {}

  absl::Status Fail(const JsonValue& at, std::string_view what) const {
    return AsUsageError(core::JsonErrorAt(source_, at, what));
  }

 private:
  std::string_view source_;
};

// "fit_frames" and "fit-frames" both name --fit-frames.
std::string FlagNameFor(std::string_view member) {
  std::string name = absl::StrCat("--", AsAbsl(member));
  std::replace(name.begin(), name.end(), '_', '-');
  return name;
}

std::string OptionList(std::span<const FlagSpec> flags) {
  std::vector<std::string> names;
  for (const FlagSpec& flag : flags) names.emplace_back(flag.name.substr(2));
  return absl::StrJoin(names, ", ");
}

// The text a flag value is given as: strings as they are, numbers exactly as written.
absl::StatusOr<std::string> ScalarText(const Locator& at, const JsonValue& value,
                                       std::string_view what) {
  if (value.type == JsonValue::Type::kString || value.type == JsonValue::Type::kNumber) {
    return value.text;
  }
  return at.Fail(value, absl::StrCat(AsAbsl(what), ": expected a string or a number"));
}

// Appends the command-line words one option stands for ("--fps", "30"; "--reverse"; nothing for
// a false switch; "--hold", "1s:0.5", "--hold", "3s:1" for an array).
absl::Status AppendOptionWords(const Locator& at, const FlagSpec& flag, const JsonValue& value,
                               std::string_view what, std::vector<std::string>& words) {
  if (flag.value_name.empty()) {
    if (value.type != JsonValue::Type::kBool) {
      return at.Fail(value, absl::StrCat(AsAbsl(what), ": expected true or false"));
    }
    if (value.boolean) words.emplace_back(flag.name);
    return absl::OkStatus();
  }
  if (value.type == JsonValue::Type::kArray) {
    if (!flag.repeatable) {
      return at.Fail(value, absl::StrCat(AsAbsl(what), ": takes one value, not a list"));
    }
    for (const JsonValue& item : *value.array) {
      TEMPOKEY_ASSIGN_OR_RETURN(std::string text, ScalarText(at, item, what));
      words.emplace_back(flag.name);
      words.push_back(std::move(text));
    }
    return absl::OkStatus();
  }
  TEMPOKEY_ASSIGN_OR_RETURN(std::string text, ScalarText(at, value, what));
  words.emplace_back(flag.name);
  words.push_back(std::move(text));
  return absl::OkStatus();
}

// The option of `options` a step parser's message is about ("--fps: ..." is about "fps"), so
// the error can point at it; the operation itself otherwise.
const JsonValue& ValueBlamedBy(const absl::Status& status, const JsonValue& options,
                               const JsonValue& operation) {
  for (const auto& [member, value] : *options.object) {
    const std::string flag = FlagNameFor(member);
    const std::string_view message = core::AsStd(status.message());
    if (message.rfind(flag, 0) == 0 &&
        (message.size() == flag.size() || message[flag.size()] == ':' ||
         message[flag.size()] == ' ')) {
      return value;
    }
  }
  return operation;
}

absl::StatusOr<core::PipelineStep> ParseOperation(const Locator& at, const JsonValue& operation,
                                                  std::size_t index) {
  const std::string label = absl::StrCat("operation ", index + 1);
  if (operation.type != JsonValue::Type::kObject || operation.object->size() != 1) {
    return at.Fail(operation, absl::StrCat(label, ": expected an object with one member, such as "
                                                  "{\"retime\": {...}}"));
  }
  // Plain references, not a structured binding: clang 14 cannot capture those in a lambda.
  const std::string& name = operation.object->front().first;
  const JsonValue& options = operation.object->front().second;
  const auto kind = std::find_if(std::begin(kOperationKinds), std::end(kOperationKinds),
                                 [&](const OperationKind& k) { return k.name == name; });
  if (kind == std::end(kOperationKinds)) {
    return at.Fail(operation, absl::StrCat(label, ": expected one of retime, reduce, bake, "
                                                  "convert, got '", name, "'"));
  }
  const std::string context = absl::StrCat(label, " (", name, ")");
  if (options.type != JsonValue::Type::kObject) {
    return at.Fail(options, absl::StrCat(context, ": expected an object of options"));
  }
  std::vector<std::string> words;
  for (const auto& [member, value] : *options.object) {
    const std::string flag_name = FlagNameFor(member);
    const auto flag = std::find_if(kind->flags.begin(), kind->flags.end(),
                                   [&](const FlagSpec& f) { return f.name == flag_name; });
    if (flag == kind->flags.end()) {
      return at.Fail(value, absl::StrCat(context, ": no option '", member, "' (options: ",
                                         OptionList(kind->flags), ")"));
    }
    TEMPOKEY_RETURN_IF_ERROR(
        AppendOptionWords(at, *flag, value, absl::StrCat(context, ": ", member), words));
  }
  absl::StatusOr<ParsedArgs> args = ParseArgs(words, kind->flags, name);
  if (!args.ok()) {  // an option given twice under its two spellings
    return at.Fail(options, absl::StrCat(context, ": ", args.status().message()));
  }
  absl::StatusOr<core::PipelineStep> step = kind->parse(*args);
  if (!step.ok()) {
    return at.Fail(ValueBlamedBy(step.status(), options, operation),
                   absl::StrCat(context, ": ", step.status().message()));
  }
  return step;
}

}  // namespace

absl::StatusOr<std::vector<core::PipelineStep>> ParsePipelineJson(std::string_view text,
                                                                  std::string_view source) {
  absl::StatusOr<JsonValue> root = core::ParseJson(text, source);
  if (!root.ok()) return AsUsageError(root.status());
  const Locator at(source);
  if (root->type != JsonValue::Type::kObject) {
    return at.Fail(*root, "expected an object {\"operations\": [...]}");
  }
  const JsonValue* operations = nullptr;
  for (const auto& [name, value] : *root->object) {
    if (name != "operations") {
      return at.Fail(value, absl::StrCat("unknown member '", name, "' (expected \"operations\")"));
    }
    if (operations != nullptr) return at.Fail(value, "\"operations\" given twice");
    operations = &value;
  }
  if (operations == nullptr) return at.Fail(*root, "missing \"operations\"");
  if (operations->type != JsonValue::Type::kArray) {
    return at.Fail(*operations, "\"operations\" must be an array");
  }
  std::vector<core::PipelineStep> steps;
  steps.reserve(operations->array->size());
  for (std::size_t i = 0; i < operations->array->size(); ++i) {
    // Emplaced from the StatusOr in place: moving the variant out through a local made g++ 12
    // report -Wmaybe-uninitialized on its inactive alternatives (a false positive).
    absl::StatusOr<core::PipelineStep> step = ParseOperation(at, (*operations->array)[i], i);
    if (!step.ok()) return step.status();
    steps.emplace_back(*std::move(step));
  }
  absl::Status chain = core::ValidateStepChain(steps);
  if (!chain.ok()) return at.Fail(*operations, core::AsStd(chain.message()));
  return steps;
}

absl::StatusOr<std::vector<core::PipelineStep>> ReadPipelineFile(const std::string& path) {
  absl::StatusOr<std::string> text = core::ReadTextFile(path, kMaxPipelineFileBytes);
  if (!text.ok()) return AsUsageError(text.status());
  return ParsePipelineJson(*text, path);
}

}  // namespace tempokey::client
