#include "client/args.h"

#include <charconv>
#include <cmath>
#include <numeric>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "client/cli_errors.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;

const FlagSpec* FindFlag(std::span<const FlagSpec> flags, std::string_view name) {
  for (const FlagSpec& flag : flags) {
    if (flag.name == name || (!flag.short_name.empty() && flag.short_name == name)) return &flag;
  }
  return nullptr;
}

absl::Status BadValue(std::string_view flag, std::string_view expected, std::string_view text) {
  return UsageError(absl::StrCat(AsAbsl(flag), ": expected ", AsAbsl(expected), ", got '",
                                 AsAbsl(text), "'"));
}

// NTSC rates as video tools spell them, and the exact rates they stand for.
struct NtscSpelling {
  std::string_view text;
  std::int64_t numerator;
};
constexpr NtscSpelling kNtscSpellings[] = {
    {"23.976", 24000}, {"23.98", 24000},  {"29.97", 30000},
    {"47.952", 48000}, {"59.94", 60000}, {"119.88", 120000},
};

// "12.5" -> 25/2 exactly; nullopt for anything but digits with at most one '.'.
std::optional<core::FrameRate> ParseDecimalFraction(std::string_view text) {
  std::int64_t numerator = 0;
  std::int64_t denominator = 1;
  bool seen_point = false;
  int digits = 0;
  for (char c : text) {
    if (c == '.' && !seen_point) {
      seen_point = true;
      continue;
    }
    if (c < '0' || c > '9') return std::nullopt;
    if (++digits > 15) return std::nullopt;  // keeps the fraction exact in 64 bits
    numerator = numerator * 10 + (c - '0');
    if (seen_point) denominator *= 10;
  }
  if (digits == 0) return std::nullopt;
  const std::int64_t divisor = std::gcd(numerator, denominator);
  if (divisor > 1) {
    numerator /= divisor;
    denominator /= divisor;
  }
  return core::FrameRate{.numerator = numerator, .denominator = denominator};
}

}  // namespace

bool ParsedArgs::Has(std::string_view flag) const { return values_.find(flag) != values_.end(); }

std::optional<std::string> ParsedArgs::Value(std::string_view flag) const {
  auto it = values_.find(flag);
  if (it == values_.end() || it->second.empty()) return std::nullopt;
  return it->second.back();
}

std::vector<std::string> ParsedArgs::Values(std::string_view flag) const {
  auto it = values_.find(flag);
  if (it == values_.end()) return {};
  return it->second;
}

absl::StatusOr<ParsedArgs> ParseArgs(std::span<const std::string> args,
                                     std::span<const FlagSpec> flags, std::string_view command) {
  ParsedArgs parsed;
  const std::string help_hint =
      command.empty() ? "see tempokey --help" : absl::StrCat("see tempokey ", AsAbsl(command), " --help");
  bool flags_ended = false;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (flags_ended || arg.size() < 2 || arg[0] != '-') {
      parsed.positionals_.push_back(arg);
      continue;
    }
    if (arg == "--") {
      flags_ended = true;
      continue;
    }
    std::string_view name = arg;
    std::optional<std::string> inline_value;
    if (const std::size_t eq = name.find('='); eq != std::string_view::npos && name.starts_with("--")) {
      inline_value = std::string(name.substr(eq + 1));
      name = name.substr(0, eq);
    }
    const FlagSpec* spec = FindFlag(flags, name);
    if (spec == nullptr) {
      if (command.empty()) {
        return UsageError(absl::StrCat("unknown flag ", AsAbsl(name), " (", help_hint, ")"));
      }
      return UsageError(absl::StrCat("unknown flag ", AsAbsl(name), " for '", AsAbsl(command),
                                     "' (", help_hint, ")"));
    }
    std::vector<std::string>& values = parsed.values_[std::string(spec->name)];
    if (!values.empty() && !spec->repeatable) {
      return UsageError(absl::StrCat(AsAbsl(spec->name), " given twice"));
    }
    if (spec->value_name.empty()) {
      if (inline_value) {
        return UsageError(absl::StrCat(AsAbsl(spec->name), " takes no value"));
      }
      values.emplace_back();
      continue;
    }
    if (inline_value) {
      values.push_back(*std::move(inline_value));
    } else if (i + 1 < args.size()) {
      values.push_back(args[++i]);
    } else {
      return UsageError(absl::StrCat(AsAbsl(spec->name), " needs a value (",
                                     AsAbsl(spec->value_name), ")"));
    }
  }
  return parsed;
}

absl::StatusOr<double> ParseDouble(std::string_view flag, std::string_view text) {
  double value = 0.0;
  if (core::ParseDoubleToken(text, value) != core::NumberError::kNone) {
    return BadValue(flag, "a number", text);
  }
  return value;
}

absl::StatusOr<double> ParsePositiveDouble(std::string_view flag, std::string_view text) {
  absl::StatusOr<double> value = ParseDouble(flag, text);
  if (!value.ok() || *value <= 0) return BadValue(flag, "a number > 0", text);
  return value;
}

absl::StatusOr<std::int64_t> ParseInt64(std::string_view flag, std::string_view text) {
  std::int64_t value = 0;
  const char* end = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(text.data(), end, value);
  if (text.empty() || ec != std::errc() || ptr != end) return BadValue(flag, "an integer", text);
  return value;
}

absl::StatusOr<core::FrameRate> ParseFrameRate(std::string_view flag, std::string_view text) {
  constexpr std::string_view kExpected = "a frame rate such as 30, 29.97 or 30000/1001";
  for (const NtscSpelling& ntsc : kNtscSpellings) {
    if (text == ntsc.text) return core::FrameRate{.numerator = ntsc.numerator, .denominator = 1001};
  }
  core::FrameRate rate;
  if (const std::size_t slash = text.find('/'); slash != std::string_view::npos) {
    const std::string_view num = text.substr(0, slash);
    const std::string_view den = text.substr(slash + 1);
    auto [p1, e1] = std::from_chars(num.data(), num.data() + num.size(), rate.numerator);
    auto [p2, e2] = std::from_chars(den.data(), den.data() + den.size(), rate.denominator);
    if (num.empty() || den.empty() || e1 != std::errc() || e2 != std::errc() ||
        p1 != num.data() + num.size() || p2 != den.data() + den.size()) {
      return BadValue(flag, kExpected, text);
    }
  } else {
    std::optional<core::FrameRate> decimal = ParseDecimalFraction(text);
    if (!decimal) return BadValue(flag, kExpected, text);
    rate = *decimal;
  }
  if (rate.numerator <= 0 || rate.denominator <= 0) {
    return BadValue(flag, "a frame rate > 0", text);
  }
  return rate;
}

absl::StatusOr<core::TimePoint> ParseTimePoint(std::string_view flag, std::string_view text) {
  constexpr std::string_view kExpected = "a time with a unit, such as 2.5s or 75f";
  if (text.size() < 2 || (text.back() != 's' && text.back() != 'f')) {
    return BadValue(flag, kExpected, text);
  }
  absl::StatusOr<double> value = ParseDouble(flag, text.substr(0, text.size() - 1));
  if (!value.ok()) return BadValue(flag, kExpected, text);
  return core::TimePoint{.value = *value, .in_frames = text.back() == 'f'};
}

absl::StatusOr<double> ParseSeconds(std::string_view flag, std::string_view text) {
  std::string_view number = text;
  if (!number.empty() && number.back() == 's') number.remove_suffix(1);
  absl::StatusOr<double> value = ParseDouble(flag, number);
  if (!value.ok()) return BadValue(flag, "seconds, such as 0.5s", text);
  return value;
}

absl::StatusOr<std::pair<std::string, std::string>> SplitPair(std::string_view flag,
                                                              std::string_view text,
                                                              std::string_view expected) {
  const std::size_t colon = text.find(':');
  if (colon == std::string_view::npos || text.find(':', colon + 1) != std::string_view::npos) {
    return BadValue(flag, expected, text);
  }
  return std::make_pair(std::string(text.substr(0, colon)), std::string(text.substr(colon + 1)));
}

absl::StatusOr<std::pair<std::string, std::string>> ParseLabel(std::string_view flag,
                                                               std::string_view text) {
  const std::size_t eq = text.find('=');
  if (eq == std::string_view::npos || eq == 0) return BadValue(flag, "KEY=VALUE", text);
  return std::make_pair(std::string(text.substr(0, eq)), std::string(text.substr(eq + 1)));
}

absl::StatusOr<std::string_view> ParseChoice(std::string_view flag, std::string_view text,
                                             std::span<const std::string_view> choices) {
  for (std::string_view choice : choices) {
    if (text == choice) return choice;
  }
  std::vector<std::string> names(choices.begin(), choices.end());
  return BadValue(flag, absl::StrCat("one of ", absl::StrJoin(names, ", ")), text);
}

}  // namespace tempokey::client
