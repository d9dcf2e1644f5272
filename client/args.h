// The CLI's small explicit argument parser and the parsers of flag values.
//
// Syntax: flags are `--name VALUE`, `--name=VALUE`, a short alias `-o VALUE`, or a switch
// `--name`; `--` ends flags; everything else is a positional argument, in order. Flags may come
// before or after positionals. Every mistake is a usage error (cli_errors.h, exit 2) naming the
// flag: "unknown flag --fsp", "--fps needs a value", "--speed given twice".
#ifndef TEMPOKEY_CLIENT_ARGS_H_
#define TEMPOKEY_CLIENT_ARGS_H_

#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::client {

// One flag a command accepts.
struct FlagSpec {
  std::string_view name;        // "--speed"
  std::string_view short_name;  // "-o", or empty
  std::string_view value_name;  // "KNOTS"; empty for a switch that takes no value
  std::string_view help;        // one line for --help
  bool repeatable = false;      // may be given several times (values kept in order)
};

class ParsedArgs {
 public:
  const std::vector<std::string>& positionals() const { return positionals_; }
  // Whether `flag` (its long name) was given.
  bool Has(std::string_view flag) const;
  // The value of a non-repeatable flag, if given.
  std::optional<std::string> Value(std::string_view flag) const;
  // Every value of a (repeatable) flag, in order; empty when not given.
  std::vector<std::string> Values(std::string_view flag) const;

 private:
  friend absl::StatusOr<ParsedArgs> ParseArgs(std::span<const std::string> args,
                                              std::span<const FlagSpec> flags,
                                              std::string_view command);
  std::vector<std::string> positionals_;
  std::map<std::string, std::vector<std::string>, std::less<>> values_;
};

// Parses `args` against `flags`. `command` names the command in messages ("retime").
// Errors: usage errors for unknown flags, a missing value, a value given to a switch and a
// non-repeatable flag given twice.
absl::StatusOr<ParsedArgs> ParseArgs(std::span<const std::string> args,
                                     std::span<const FlagSpec> flags, std::string_view command);

// ---- values -------------------------------------------------------------------------------------
// Each takes the flag name for its message and returns a usage error for bad syntax:
// "--tolerance: expected a number, got 'abc'".

// A finite decimal number (core::ParseDoubleToken(): exponents and a leading + allowed).
absl::StatusOr<double> ParseDouble(std::string_view flag, std::string_view text);
// A finite number > 0.
absl::StatusOr<double> ParsePositiveDouble(std::string_view flag, std::string_view text);
// A decimal integer.
absl::StatusOr<std::int64_t> ParseInt64(std::string_view flag, std::string_view text);

// A frame rate: "30", "29.97", "12.5" or a fraction "30000/1001". Decimals are exact fractions
// (12.5 = 25/2), except the NTSC spellings 23.976, 23.98, 29.97, 47.952, 59.94 and 119.88, which
// mean N*1000/1001 as every video tool does. Must be > 0.
absl::StatusOr<core::FrameRate> ParseFrameRate(std::string_view flag, std::string_view text);

// A time with its unit: "2.5s" (seconds) or "75f" (frames of the timeline).
absl::StatusOr<core::TimePoint> ParseTimePoint(std::string_view flag, std::string_view text);

// A duration in seconds, "0.5s" or "0.5".
absl::StatusOr<double> ParseSeconds(std::string_view flag, std::string_view text);

// "a:b" split at its single colon. Errors: a usage error naming `expected` ("T:DURATION").
absl::StatusOr<std::pair<std::string, std::string>> SplitPair(std::string_view flag,
                                                              std::string_view text,
                                                              std::string_view expected);

// "key=value". Errors: a usage error for a missing '=' or an empty key.
absl::StatusOr<std::pair<std::string, std::string>> ParseLabel(std::string_view flag,
                                                               std::string_view text);

// The entry of `choices` equal to `text` (a view of that entry: `choices` must outlive it).
// Errors: "--filter: expected one of tent, linear, ..., got 'x'".
absl::StatusOr<std::string_view> ParseChoice(std::string_view flag, std::string_view text,
                                             std::span<const std::string_view> choices);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_ARGS_H_
