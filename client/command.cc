#include "client/command.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "client/cli_errors.h"
#include "client/clip_files.h"
#include "client/clip_summary.h"
#include "proto/bearer_token.h"
#include "proto/pem_check.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;

constexpr FlagSpec kGlobalFlags[] = {
    {"--server", "", "TARGET",
     "host:port, dns:///host:port or ipv4:H:P,H:P (default 127.0.0.1:50051)"},
    {"--timeout", "", "SECONDS", "deadline of each server call, retries included (default 60; 0: none)"},
    {"--tls", "", "", "connect with TLS (system roots unless --ca)"},
    {"--ca", "", "FILE", "PEM roots that sign the server's certificate (implies --tls)"},
    {"--cert", "", "FILE", "PEM client certificate for mutual TLS, with --key (implies --tls)"},
    {"--key", "", "FILE", "PEM private key of --cert"},
    {"--tls-server-name", "", "NAME", "name expected in the server's certificate (implies --tls)"},
    {"--token-file", "", "FILE",
     "bearer token for every call (default: $TEMPOKEY_TOKEN); sent only over TLS or to this "
     "machine"},
    {"--allow-plaintext-token", "", "",
     "send the token without TLS to another machine (a network that encrypts it itself)"},
};

std::string TrimWhitespace(std::string text) {
  const auto not_space = [](unsigned char c) { return !std::isspace(c); };
  text.erase(text.begin(), std::find_if(text.begin(), text.end(), not_space));
  text.erase(std::find_if(text.rbegin(), text.rend(), not_space).base(), text.end());
  return text;
}

// The token in `text`, read from `source` (a token file, or $TEMPOKEY_TOKEN): the text without
// a UTF-8 byte order mark (editors write one) and whitespace around it, one line of printable
// ASCII (wire::CheckBearerToken()), or why not, named by its source. A server's --auth_token_file
// lists several tokens, one a line: given to the client, it is refused by its line count, where
// a token holding line breaks made gRPC abort the process without a word.
absl::StatusOr<std::string> TokenFrom(std::string_view text, std::string_view source) {
  std::string token = TrimWhitespace(std::string(wire::TokenFileText(text)));
  if (const auto lines = std::count(token.begin(), token.end(), '\n'); lines > 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        core::AsAbsl(source), ": holds ", lines + 1, " lines; the client sends one token (a server's "
        "--auth_token_file lists several: give the client a file with its own alone)"));
  }
  if (absl::Status valid = wire::CheckBearerToken(token); !valid.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(core::AsAbsl(source), ": ", valid.message()));
  }
  return token;
}

constexpr std::int64_t kMaxPemBytes = 1 << 20;

}  // namespace

std::span<const Command* const> AllCommands() {
  static const Command* const kCommands[] = {
      &InfoCommand(),        &UploadCommand(),     &RunCommand(),       &RetimeCommand(),
      &ReduceCommand(),      &BatchCommand(),      &BatchSummaryCommand(),
      &HealthCommand(),      &ServerInfoCommand(),
      &JobsListCommand(),    &JobsGetCommand(),    &JobsWatchCommand(), &JobsResultCommand(),
      &JobsCancelCommand(),  &JobsDeleteCommand(),
  };
  return kCommands;
}

std::span<const FlagSpec> GlobalFlags() { return kGlobalFlags; }

absl::StatusOr<ClientOptions> ClientOptionsFromFlags(const ParsedArgs& args) {
  ClientOptions options;
  if (std::optional<std::string> server = args.Value("--server")) {
    if (server->empty()) return UsageError("--server: expected a gRPC target, got ''");
    options.target = *server;
  }
  if (std::optional<std::string> timeout = args.Value("--timeout")) {
    TEMPOKEY_ASSIGN_OR_RETURN(options.timeout_seconds, ParseDouble("--timeout", *timeout));
    if (options.timeout_seconds < 0) {
      return UsageError(absl::StrCat("--timeout: expected seconds >= 0, got '", *timeout, "'"));
    }
  }
  TlsOptions& tls = options.tls;
  tls.enabled = args.Has("--tls") || args.Has("--ca") || args.Has("--cert") ||
                args.Has("--tls-server-name");
  if (args.Has("--cert") != args.Has("--key")) {
    return UsageError("--cert and --key go together (mutual TLS needs both)");
  }
  // The files are checked here: gRPC takes a bad one as a channel with "empty address list",
  // which the CLI could only report as the server's UNAVAILABLE.
  if (std::optional<std::string> ca = args.Value("--ca")) {
    TEMPOKEY_ASSIGN_OR_RETURN(tls.root_ca_pem, core::ReadTextFile(*ca, kMaxPemBytes));
    TEMPOKEY_RETURN_IF_ERROR(
        wire::CheckPemCertificates(absl::StrCat("--ca ", *ca), tls.root_ca_pem));
  }
  if (std::optional<std::string> cert = args.Value("--cert")) {
    const std::string key = *args.Value("--key");
    TEMPOKEY_ASSIGN_OR_RETURN(tls.cert_chain_pem, core::ReadTextFile(*cert, kMaxPemBytes));
    TEMPOKEY_ASSIGN_OR_RETURN(tls.private_key_pem, core::ReadTextFile(key, kMaxPemBytes));
    TEMPOKEY_RETURN_IF_ERROR(wire::CheckPemKeyPair(absl::StrCat("--cert ", *cert),
                                                   tls.cert_chain_pem,
                                                   absl::StrCat("--key ", key),
                                                   tls.private_key_pem));
  }
  if (std::optional<std::string> name = args.Value("--tls-server-name")) {
    // Empty, gRPC would check the target's own name instead, silently.
    if (name->empty()) return UsageError("--tls-server-name: expected a host name, got ''");
    tls.target_name_override = *name;
  }
  if (std::optional<std::string> token_file = args.Value("--token-file")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string text, core::ReadTextFile(*token_file, kMaxPemBytes));
    TEMPOKEY_ASSIGN_OR_RETURN(options.bearer_token, TokenFrom(text, *token_file));
    if (options.bearer_token.empty()) {
      return absl::InvalidArgumentError(absl::StrCat(*token_file, ": the token file is empty"));
    }
  } else if (const char* env = std::getenv("TEMPOKEY_TOKEN"); env != nullptr && *env != '\0') {
    TEMPOKEY_ASSIGN_OR_RETURN(options.bearer_token, TokenFrom(env, "$TEMPOKEY_TOKEN"));
  }
  options.allow_plaintext_token = args.Has("--allow-plaintext-token");
  return options;
}

// ---- CommandContext -----------------------------------------------------------------------------

absl::StatusOr<std::vector<std::string>> CommandContext::Positionals(
    std::span<const std::string_view> names) const {
  const std::vector<std::string>& given = args_.positionals();
  const std::string hint = absl::StrCat(" (see tempokey ", AsAbsl(command_.name), " --help)");
  if (given.size() < names.size()) {
    return UsageError(absl::StrCat(AsAbsl(command_.name), ": missing ",
                                   AsAbsl(names[given.size()]), hint));
  }
  if (given.size() > names.size()) {
    return UsageError(absl::StrCat(AsAbsl(command_.name), ": unexpected argument '",
                                   given[names.size()], "'", hint));
  }
  return given;
}

absl::StatusOr<std::string> CommandContext::Required(std::string_view flag) const {
  if (std::optional<std::string> value = args_.Value(flag)) return *value;
  std::string spelled(flag);
  std::string_view value_name;
  for (const FlagSpec& spec : command_.flags) {
    if (spec.name != flag) continue;
    if (!spec.short_name.empty()) spelled = absl::StrCat(AsAbsl(spec.short_name), "/", spelled);
    value_name = spec.value_name;
  }
  return UsageError(absl::StrCat(AsAbsl(command_.name), ": missing ", spelled, " ",
                                 AsAbsl(value_name), " (see tempokey ", AsAbsl(command_.name),
                                 " --help)"));
}

absl::StatusOr<const Client*> CommandContext::Connect() {
  if (client_ == nullptr) {
    TEMPOKEY_ASSIGN_OR_RETURN(ClientOptions options, ClientOptionsFromFlags(args_));
    absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(options);
    if (!client.ok()) return AsUsageError(client.status());
    client_ = *std::move(client);
  }
  return client_.get();
}

// ---- shared pieces ------------------------------------------------------------------------------

void ProgressLine::Update(double fraction, std::string_view stage) {
  if (!context_.show_progress()) return;
  const int percent = static_cast<int>(std::floor(std::clamp(fraction, 0.0, 1.0) * 100.0));
  if (percent == last_percent_ && stage == last_stage_) return;
  last_percent_ = percent;
  last_stage_ = std::string(stage);
  std::string text = absl::StrFormat("%3d%%  %s", percent, AsAbsl(stage));
  const std::size_t width = text.size();
  if (text.size() < width_) text.resize(width_, ' ');
  context_.err() << '\r' << text << std::flush;
  width_ = width;
}

void ProgressLine::Clear() {
  if (!context_.show_progress() || width_ == 0) return;
  context_.err() << '\r' << std::string(width_, ' ') << '\r' << std::flush;
  width_ = 0;
  last_percent_ = -1;
}

absl::StatusOr<std::optional<double>> InputFrameTimeFromFlags(const ParsedArgs& args) {
  std::optional<std::string> fps = args.Value("--input-fps");
  if (!fps) return std::optional<double>();
  TEMPOKEY_ASSIGN_OR_RETURN(core::FrameRate rate, ParseFrameRate("--input-fps", *fps));
  const double seconds = static_cast<double>(rate.denominator) / static_cast<double>(rate.numerator);
  // The clip's own limits on its frame time, said as rates.
  if (!core::CheckFrameTime(seconds).ok()) {
    return UsageError(absl::StrCat("--input-fps ", *fps,
                                   ": must be from 1/3600 (a frame an hour) to 1000000 frames per "
                                   "second"));
  }
  return seconds;
}

absl::StatusOr<core::Clip> ReadInputClip(const CommandContext& context, const std::string& path) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::optional<double> csv_frame_time,
                            InputFrameTimeFromFlags(context.args()));
  // A rate given for a file that stores its own would be ignored without a word. (A batch may
  // mix CSV and BVH inputs: there the flag is for its CSV files.)
  if (csv_frame_time && FormatForPath("", path, kSampledFormats).value_or(FileFormat::kCsv) ==
                            FileFormat::kBvh) {
    return UsageError(absl::StrCat("--input-fps is for CSV input: ", path,
                                   " stores its own frame time (retime --fps changes the rate)"));
  }
  return ReadClipFile(path, csv_frame_time);
}

absl::StatusOr<std::map<std::string, std::string>> LabelsFromFlags(const ParsedArgs& args) {
  std::map<std::string, std::string> labels;
  for (const std::string& label : args.Values("--label")) {
    TEMPOKEY_ASSIGN_OR_RETURN(auto pair, ParseLabel("--label", label));
    labels[pair.first] = pair.second;
  }
  return labels;
}

absl::StatusOr<ExecutionMode> ExecutionModeFromFlags(const ParsedArgs& args) {
  ExecutionMode mode;
  mode.detach = args.Has("--detach");
  mode.as_job = args.Has("--job") || mode.detach;
  TEMPOKEY_ASSIGN_OR_RETURN(mode.labels, LabelsFromFlags(args));
  if (!mode.labels.empty() && !mode.as_job) {
    return UsageError("--label applies to jobs: add --job or --detach");
  }
  return mode;
}

std::string JobStateName(int state) {
  std::string name = v1::JobState_Name(static_cast<v1::JobState>(state));
  constexpr std::string_view kPrefix = "JOB_STATE_";
  if (name.rfind(kPrefix, 0) == 0) name.erase(0, kPrefix.size());
  if (name.empty()) name = absl::StrCat("STATE_", state);
  return name;
}

absl::Status JobOutcome(const v1::Job& job) {
  switch (job.state()) {
    case v1::JOB_STATE_SUCCEEDED:
      return absl::OkStatus();
    case v1::JOB_STATE_FAILED:
    case v1::JOB_STATE_CANCELLED: {
      absl::StatusCode code = static_cast<absl::StatusCode>(job.error_code());
      if (code == absl::StatusCode::kOk) {
        code = job.state() == v1::JOB_STATE_CANCELLED ? absl::StatusCode::kCancelled
                                                      : absl::StatusCode::kUnknown;
      }
      return absl::Status(code, absl::StrCat("job ", job.job_id(), " ", JobStateName(job.state()),
                                             ": ", absl::StatusCodeToString(code), ": ",
                                             job.error_message()));
    }
    default:
      return absl::UnavailableError(absl::StrCat("job ", job.job_id(), " is still ",
                                                 JobStateName(job.state()),
                                                 ": the server ended the watch early"));
  }
}

absl::StatusOr<std::optional<core::PipelineResult>> ExecutePipeline(
    CommandContext& context, const core::Clip& clip, std::span<const core::PipelineStep> steps,
    const ExecutionMode& mode) {
  // What core can tell from the clip and the steps is refused here, before any upload; the
  // server checks again against its own limits.
  TEMPOKEY_RETURN_IF_ERROR(core::ValidatePipeline(clip, steps));
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  ProgressLine progress(context);
  if (!mode.as_job) {
    absl::StatusOr<core::PipelineResult> result =
        client->Process(clip, steps, [&](double fraction, std::string_view stage) {
          progress.Update(fraction, stage);
        });
    progress.Clear();
    if (!result.ok()) return ServerError(result.status());
    return std::optional<core::PipelineResult>(*std::move(result));
  }

  absl::StatusOr<v1::UploadClipResponse> uploaded = client->UploadClip(clip);
  if (!uploaded.ok()) return ServerError(uploaded.status());
  context.out() << SummaryLine("clip id", uploaded->clip_id());
  SubmitOptions submit;
  submit.labels = mode.labels;
  absl::StatusOr<v1::Job> job = client->SubmitJob(uploaded->clip_id(), steps, submit);
  if (!job.ok()) return ServerError(job.status());
  context.out() << SummaryLine("job", job->job_id());
  if (mode.detach) return std::optional<core::PipelineResult>();

  absl::StatusOr<v1::Job> final_job = client->WatchJob(
      job->job_id(), [&](const v1::Job& update) { progress.Update(update.progress(), update.stage()); });
  progress.Clear();
  if (!final_job.ok()) return ServerError(final_job.status());
  TEMPOKEY_RETURN_IF_ERROR(JobOutcome(*final_job));
  absl::StatusOr<core::PipelineResult> result = client->GetJobResult(job->job_id());
  if (!result.ok()) return ServerError(result.status());
  return std::optional<core::PipelineResult>(*std::move(result));
}

}  // namespace tempokey::client
