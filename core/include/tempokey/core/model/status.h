// Status helpers missing from Debian 12's Abseil (20220623 has no status macros).
#ifndef TEMPOKEY_CORE_MODEL_STATUS_H_
#define TEMPOKEY_CORE_MODEL_STATUS_H_

#include <string_view>
#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

#define TEMPOKEY_STATUS_CONCAT_INNER_(a, b) a##b
#define TEMPOKEY_STATUS_CONCAT_(a, b) TEMPOKEY_STATUS_CONCAT_INNER_(a, b)

// Returns the status of `expr` from the enclosing function if it is not OK.
#define TEMPOKEY_RETURN_IF_ERROR(expr)                 \
  do {                                                 \
    ::absl::Status tempokey_status_ = (expr);          \
    if (!tempokey_status_.ok()) return tempokey_status_; \
  } while (false)

// `lhs = value of expr`, or returns its status from the enclosing function.
#define TEMPOKEY_ASSIGN_OR_RETURN(lhs, expr) \
  TEMPOKEY_ASSIGN_OR_RETURN_IMPL_(TEMPOKEY_STATUS_CONCAT_(tempokey_statusor_, __LINE__), lhs, expr)

#define TEMPOKEY_ASSIGN_OR_RETURN_IMPL_(statusor, lhs, expr) \
  auto statusor = (expr);                                   \
  if (!statusor.ok()) return std::move(statusor).status();  \
  lhs = std::move(statusor).value()

namespace tempokey::core {

// Debian's Abseil is built with its own absl::string_view (ABSL_OPTION_USE_STD_STRING_VIEW 0), so
// a std::string_view does not convert to StrCat's arguments or a Status message on its own.
inline absl::string_view AsAbsl(std::string_view s) { return absl::string_view(s.data(), s.size()); }
inline std::string_view AsStd(absl::string_view s) { return std::string_view(s.data(), s.size()); }

// A value over a size limit (frames, channels, samples, joints, keys, operations): code
// kResourceExhausted, as gRPC answers a message over its size limit, so callers can tell "too
// big for this server" from "malformed" (kInvalidArgument).
inline absl::Status OverLimitError(std::string_view message) {
  return absl::ResourceExhaustedError(AsAbsl(message));
}

// Prefixes the message of a non-OK status with `context` ("context: message"), keeping the code
// and the payloads.
absl::Status Annotate(const absl::Status& status, std::string_view context);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_STATUS_H_
