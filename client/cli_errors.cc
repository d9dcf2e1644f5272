#include "client/cli_errors.h"

#include "absl/strings/cord.h"
#include "absl/strings/str_cat.h"
#include "tempokey/core/io/json.h"
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
  return absl::Status(status.code(), absl::StrCat("server: ", absl::StatusCodeToString(status.code()),
                                                  ": ", status.message()));
}

std::string PrintableText(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '\n' || c == '\r') {
      out += ' ';
    } else if (c < 0x20 || c == 0x7f) {
      // A control byte (from a file name, a file or a server) would act on the terminal.
      absl::StrAppend(&out, "\\x", absl::Hex(c, absl::kZeroPad2));
    } else if (c < 0x80) {
      out += static_cast<char>(c);
    } else if (const std::size_t length = core::Utf8CharLength(text.substr(i)); length == 0) {
      // Not UTF-8 (a Latin-1 file name; a lone 0x9b is a terminal sequence on 8-bit terminals).
      absl::StrAppend(&out, "\\x", absl::Hex(c, absl::kZeroPad2));
    } else if (c == 0xc2 && static_cast<unsigned char>(text[i + 1]) <= 0x9f) {
      // A C1 control character in UTF-8 (U+0080 to U+009F; U+009B starts a terminal sequence).
      absl::StrAppend(&out, "\\u00",
                      absl::Hex(static_cast<unsigned char>(text[i + 1]), absl::kZeroPad2));
      ++i;
    } else {
      out.append(text.substr(i, length));
      i += length - 1;
    }
  }
  return out;
}

std::string ErrorLine(const absl::Status& status) {
  std::string_view message = core::AsStd(status.message());
  const std::string code = absl::StatusCodeToString(status.code());
  if (message.empty()) message = code;
  return absl::StrCat("error: ", PrintableText(message));
}

}  // namespace tempokey::client
