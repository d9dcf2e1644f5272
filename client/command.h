// What every CLI command is made of: its flags, its help text and a function that runs it with a
// CommandContext. The commands themselves live in command_*.cc; cli.cc dispatches.
#ifndef TEMPOKEY_CLIENT_COMMAND_H_
#define TEMPOKEY_CLIENT_COMMAND_H_

#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "client/args.h"
#include "client/cli.h"
#include "client/client.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::client {

class CommandContext;

struct Command {
  std::string_view name;         // "retime", "jobs list"
  std::string_view synopsis;     // "IN -o OUT [--speed KNOTS] [options]"
  std::string_view summary;      // one line for the command list
  std::string_view description;  // paragraphs for `--help`, lines ending in '\n'
  std::span<const FlagSpec> flags;
  absl::Status (*run)(CommandContext& context);
};

// Every command, in the order `tempokey --help` lists them.
std::span<const Command* const> AllCommands();

// The flags every command accepts (server connection), documented in `tempokey --help`.
std::span<const FlagSpec> GlobalFlags();

// Client options from the global flags in `args`: --server, --timeout, --tls, --ca, --cert,
// --key, --tls-server-name, --token-file, and the TEMPOKEY_TOKEN environment variable.
// Errors: usage errors for bad values; file read errors for the PEM and token files.
absl::StatusOr<ClientOptions> ClientOptionsFromFlags(const ParsedArgs& args);

// A command's view of its invocation.
class CommandContext {
 public:
  CommandContext(const CliIo& io, const Command& command, ParsedArgs args)
      : io_(io), command_(command), args_(std::move(args)) {}

  std::ostream& out() const { return io_.out; }
  std::ostream& err() const { return io_.err; }
  bool show_progress() const { return io_.show_progress; }
  const Command& command() const { return command_; }
  const ParsedArgs& args() const { return args_; }

  // The positional arguments, checked to number exactly `names.size()`.
  // Errors: a usage error "retime: expected IN, got 2 arguments" or "... missing IN".
  absl::StatusOr<std::vector<std::string>> Positionals(
      std::span<const std::string_view> names) const;

  // The value of a flag the command requires. Errors: a usage error "retime: -o/--output is
  // required".
  absl::StatusOr<std::string> Required(std::string_view flag) const;

  // A client for the global flags' server (created once, reused).
  absl::StatusOr<const Client*> Connect();

  // The client Connect() created, or null before (or when its options were refused).
  const Client* client() const { return client_.get(); }

 private:
  const CliIo& io_;
  const Command& command_;
  ParsedArgs args_;
  std::unique_ptr<Client> client_;
};

// ---- pieces shared by commands ------------------------------------------------------------------

// Shows "stage  42%" on one self-rewriting line of stderr when the context shows progress, and
// nothing otherwise. Clear() erases the line (also done on destruction).
class ProgressLine {
 public:
  explicit ProgressLine(const CommandContext& context) : context_(context) {}
  ~ProgressLine() { Clear(); }
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  void Update(double fraction, std::string_view stage);
  void Clear();

 private:
  const CommandContext& context_;
  std::size_t width_ = 0;
  int last_percent_ = -1;
  std::string last_stage_;
};

// The frame time (seconds) of .csv inputs from --input-fps; nullopt when not given.
absl::StatusOr<std::optional<double>> InputFrameTimeFromFlags(const ParsedArgs& args);

// Reads the input clip of a command: `path` (.bvh, or .csv with --input-fps).
absl::StatusOr<core::Clip> ReadInputClip(const CommandContext& context, const std::string& path);

// How a pipeline runs on the server: one stateless Process call (default), or upload + submit +
// watch + result (`--job`), or upload + submit only (`--detach`: prints the job id).
struct ExecutionMode {
  bool as_job = false;
  bool detach = false;
  std::map<std::string, std::string> labels;
};

// --job, --detach and --label from the command's flags.
absl::StatusOr<ExecutionMode> ExecutionModeFromFlags(const ParsedArgs& args);

// Every --label KEY=VALUE given. Errors: a usage error naming the malformed label.
absl::StatusOr<std::map<std::string, std::string>> LabelsFromFlags(const ParsedArgs& args);

// The flag specs of ExecutionModeFromFlags(), for commands that offer them.
inline constexpr FlagSpec kJobFlag{"--job", "", "",
                                   "run as a stored job (upload, submit, watch, fetch)"};
inline constexpr FlagSpec kDetachFlag{"--detach", "", "",
                                      "submit the job, print its id and exit without waiting "
                                      "(implies --job)"};
inline constexpr FlagSpec kLabelFlag{"--label", "", "KEY=VALUE",
                                     "label the job (with --job or --detach)", true};
inline constexpr FlagSpec kInputFpsFlag{"--input-fps", "", "RATE",
                                        "frame rate of a .csv input (CSV files do not store it)"};
inline constexpr FlagSpec kOutputFlag{"--output", "-o", "FILE",
                                      "output file; its extension chooses the format"};
inline constexpr FlagSpec kOverwriteFlag{"--overwrite", "", "",
                                         "allow the output to be the input file itself"};

// Runs `steps` on `clip` through the server as `mode` says, showing progress. Returns the result,
// or nullopt when detached (the job id has been printed as "job: <id>").
// Errors: ServerError()s of the calls; "job <id> FAILED: <CODE>: <message>" when a watched job
// does not succeed.
absl::StatusOr<std::optional<core::PipelineResult>> ExecutePipeline(
    CommandContext& context, const core::Clip& clip, std::span<const core::PipelineStep> steps,
    const ExecutionMode& mode);

// "RUNNING" for JOB_STATE_RUNNING.
std::string JobStateName(int state);

// The error a job that ended without success stands for: its own code, message
// "job <id> FAILED: <CODE>: <message>"; OK for a succeeded job.
absl::Status JobOutcome(const v1::Job& job);

// The commands, one file each (command_<name>.cc).
const Command& InfoCommand();
const Command& UploadCommand();
const Command& RunCommand();
const Command& RetimeCommand();
const Command& ReduceCommand();
const Command& HealthCommand();
const Command& ServerInfoCommand();
const Command& JobsListCommand();
const Command& JobsGetCommand();
const Command& JobsCancelCommand();
const Command& JobsDeleteCommand();
const Command& JobsWatchCommand();
const Command& JobsResultCommand();
const Command& BatchCommand();
const Command& BatchSummaryCommand();

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_COMMAND_H_
