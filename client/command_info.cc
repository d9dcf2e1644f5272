// `tempokey info FILE` and `tempokey upload FILE`.
#include "absl/strings/str_cat.h"
#include "client/cli_errors.h"
#include "client/clip_summary.h"
#include "client/command.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

constexpr std::string_view kFileArgument[] = {"FILE"};

constexpr FlagSpec kInfoFlags[] = {kInputFpsFlag};

absl::Status Info(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> files, context.Positionals(kFileArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, ReadInputClip(context, files[0]));
  context.out() << FormatClipSummary(clip);
  return absl::OkStatus();
}

absl::Status Upload(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> files, context.Positionals(kFileArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, ReadInputClip(context, files[0]));
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  absl::StatusOr<v1::UploadClipResponse> uploaded = client->UploadClip(clip);
  if (!uploaded.ok()) return ServerError(uploaded.status());
  context.out() << SummaryLine("clip id", uploaded->clip_id())
                << SummaryLine("stored", uploaded->already_stored() ? "already stored" : "new")
                << FormatClipSummary(clip);
  return absl::OkStatus();
}

}  // namespace

const Command& InfoCommand() {
  static const Command command{
      .name = "info",
      .synopsis = "FILE [--input-fps RATE]",
      .summary = "print a clip's summary (reads the file here, no server)",
      .description =
          "Reads FILE (.bvh, or .csv with --input-fps) and prints its name, frame count, frame\n"
          "rate and frame time, duration, joints, channels and rotation orders.\n",
      .flags = kInfoFlags,
      .run = Info,
  };
  return command;
}

const Command& UploadCommand() {
  static const Command command{
      .name = "upload",
      .synopsis = "FILE [--input-fps RATE]",
      .summary = "upload a clip to the server; print its id and summary",
      .description =
          "Reads FILE here, streams it to the server and prints the clip id the server gives\n"
          "it (a content digest: uploading the same clip again is free) and its summary.\n",
      .flags = kInfoFlags,
      .run = Upload,
  };
  return command;
}

}  // namespace tempokey::client
