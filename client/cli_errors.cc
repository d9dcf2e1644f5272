#include "client/cli_errors.h"

#include "absl/strings/cord.h"
#include "absl/strings/str_cat.h"
#include "tempokey/core/io/printable_text.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

// The payload that marks usage errors; the value is irrelevant.
constexpr char kUsagePayload[] = "tempokey.cli/usage";

}  // namespace

absl::Status UsageError(std::string_view message) {
  return AsUsageError(absl::InvalidArgumentError(core::AsAbsl(message)));
}

absl::Status AsUsageError(const absl::Status& status) {
  if (status.ok()) return status;
  absl::Status marked = status;
  marked.SetPayload(kUsagePayload, absl::Cord("1"));
  return marked;
}

bool IsUsageError(const absl::Status& status) {
  return !status.ok() && status.GetPayload(kUsagePayload).has_value();
}

int ExitCodeFor(const absl::Status& status) {
  if (status.ok()) return kExitOk;
  return IsUsageError(status) ? kExitUsage : kExitFailed;
}

absl::Status ServerError(const absl::Status& status) {
  if (status.ok()) return status;
  // gRPC's text when the call's own deadline (--timeout) passed on this side; the server's
  // deadline errors (an idle stream, a queued job) carry messages of their own.
  constexpr std::string_view kClientDeadline = "Deadline Exceeded";
  const std::string_view message =
      status.code() == absl::StatusCode::kDeadlineExceeded &&
              core::AsStd(status.message()) == kClientDeadline
          ? "no answer within --timeout (default 60 s, retries included); give a longer "
            "--timeout, or 0 for none"
          : core::AsStd(status.message());
  return absl::Status(status.code(), absl::StrCat("server: ", absl::StatusCodeToString(status.code()),
                                                  ": ", core::AsAbsl(message)));
}

std::string ErrorLine(const absl::Status& status) {
  std::string_view message = core::AsStd(status.message());
  const std::string code = absl::StatusCodeToString(status.code());
  if (message.empty()) message = code;
  return absl::StrCat("error: ", core::PrintableText(message));
}

}  // namespace tempokey::client
