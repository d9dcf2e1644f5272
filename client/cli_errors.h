// How the CLI classifies and prints failures (the README's "exit codes" and "errors" sections).
//
// Every failure is printed as exactly one line on stderr:
//
//   error: <message>
//
// where <message> is, by origin:
//   usage     "unknown flag --fsp for 'retime' (see tempokey retime --help)"      exit 2
//   a file    "walk.bvh:12:7: expected '{' after joint name, got \"OFFSET\""      exit 1
//   a flag    "--speed: speed knot 3 '2x:0.5': time needs a unit, s or f"         exit 2 for bad
//             syntax, 1 when the feature itself fails (e.g. not implemented)
//   a step    "operation 1 (retime): speed knot 2 (1s:1000): speed 1000 is ..."   exit 1
//             (refused before anything is sent: core's check of the steps against the clip)
//   server    "server: INVALID_ARGUMENT: operation 1 (retime): ..."               exit 1
//             (gRPC code name, then the server's message; also for UNAVAILABLE /
//             DEADLINE_EXCEEDED when the server cannot be reached in time)
//   a job     "job 42 FAILED: INVALID_ARGUMENT: ..."                              exit 1
// Exit codes: 0 ok, 1 failed, 2 usage.
#ifndef TEMPOKEY_CLIENT_CLI_ERRORS_H_
#define TEMPOKEY_CLIENT_CLI_ERRORS_H_

#include <string>
#include <string_view>

#include "absl/status/status.h"

namespace tempokey::client {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailed = 1;
inline constexpr int kExitUsage = 2;

// A kInvalidArgument status marked as a usage error (exit 2).
absl::Status UsageError(std::string_view message);
bool IsUsageError(const absl::Status& status);

// The same status marked as a usage error, message unchanged; OK stays OK.
absl::Status AsUsageError(const absl::Status& status);

// 0 for OK, 2 for usage errors, 1 for everything else.
int ExitCodeFor(const absl::Status& status);

// A status from a server call, its message prefixed "server: <CODE>: " (code kept), so the
// user can tell the server's refusals from local ones. gRPC's own text for the client's deadline
// ("Deadline Exceeded") becomes one that names --timeout.
absl::Status ServerError(const absl::Status& status);

// "error: <message>", the message made core::PrintableText() (line breaks as spaces): an error
// is always exactly one line.
// No trailing newline.
std::string ErrorLine(const absl::Status& status);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_CLI_ERRORS_H_
