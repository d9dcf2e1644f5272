// `tempokey health` and `tempokey server-info`.
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "client/cli_errors.h"
#include "client/clip_summary.h"
#include "client/command.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

// The health of one service as printed: a state name, or NOT_FOUND for a service the server
// does not know.
absl::StatusOr<std::string> ServiceHealth(const Client& client, const std::string& service,
                                          bool& serving) {
  absl::StatusOr<HealthState> state = client.CheckHealth(service);
  if (state.status().code() == absl::StatusCode::kNotFound) {
    serving = false;
    return std::string("NOT_FOUND");
  }
  if (!state.ok()) return ServerError(state.status());
  serving = *state == HealthState::kServing;
  return std::string(HealthStateName(*state));
}

absl::Status Health(CommandContext& context) {
  TEMPOKEY_RETURN_IF_ERROR(context.Positionals({}).status());
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  bool overall_serving = false;
  bool service_serving = false;
  TEMPOKEY_ASSIGN_OR_RETURN(std::string overall, ServiceHealth(*client, "", overall_serving));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string service,
                            ServiceHealth(*client, kMotionServiceName, service_serving));
  context.out() << SummaryLine("overall", overall) << SummaryLine(kMotionServiceName, service);
  if (!overall_serving) {
    return absl::UnavailableError(absl::StrCat("the server is ", overall));
  }
  if (!service_serving) {
    return absl::UnavailableError(absl::StrCat(kMotionServiceName, " is ", service));
  }
  return absl::OkStatus();
}

absl::Status ServerInfo(CommandContext& context) {
  TEMPOKEY_RETURN_IF_ERROR(context.Positionals({}).status());
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  absl::StatusOr<v1::ServerInfo> info = client->GetServerInfo();
  if (!info.ok()) return ServerError(info.status());
  context.out() << SummaryLine("version", info->version())
                << SummaryLine("workers", absl::StrCat(info->worker_count()))
                << SummaryLine("queue capacity", absl::StrCat(info->queue_capacity()))
                << SummaryLine("max message", absl::StrCat(info->max_message_bytes(), " bytes"))
                << SummaryLine("max clip", absl::StrCat(info->max_clip_samples(), " samples"))
                << SummaryLine("stored clips", absl::StrCat("up to ", info->max_stored_clips()))
                << SummaryLine("stored results", absl::StrCat("up to ", info->max_stored_results()))
                << SummaryLine("operations", absl::StrJoin(info->operations(), ", "))
                << SummaryLine("wire features", absl::StrJoin(info->features(), ", "));
  return absl::OkStatus();
}

}  // namespace

const Command& HealthCommand() {
  static const Command command{
      .name = "health",
      .synopsis = "",
      .summary = "check that the server is serving (exit 0 only if it is)",
      .description =
          "Asks the server's grpc.health.v1 service about the server overall (live) and about\n"
          "tempokey.v1.MotionService (ready for jobs) and prints both states: SERVING,\n"
          "NOT_SERVING, UNKNOWN, or NOT_FOUND for a service the server does not report.\n"
          "Exits 0 when both are SERVING, 1 otherwise.\n",
      .flags = {},
      .run = Health,
  };
  return command;
}

const Command& ServerInfoCommand() {
  static const Command command{
      .name = "server-info",
      .synopsis = "",
      .summary = "print the server's version, limits and operations",
      .description = "Prints what GetServerInfo reports: version, worker pool, limits, operations and\n"
          "the wire features added to v1 after its first release.\n",
      .flags = {},
      .run = ServerInfo,
  };
  return command;
}

}  // namespace tempokey::client
