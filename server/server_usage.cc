#include "server/server_usage.h"

#include <algorithm>
#include <string_view>
#include <vector>

#include "absl/flags/commandlineflag.h"
#include "absl/flags/reflection.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace tempokey::server {
namespace {

// The flags of the server binary are the ones its main.cc defines; gRPC and Abseil register
// their own, which are not the server's interface.
bool IsServerFlag(const absl::CommandLineFlag& flag) {
  return absl::EndsWith(flag.Filename(), "server/main.cc");
}

std::string DefaultText(const absl::CommandLineFlag& flag) {
  const std::string value = flag.DefaultValue();
  return value.empty() ? "none" : value;
}

}  // namespace

bool WantsUsage(std::span<char* const> args) {
  for (std::size_t i = 1; i < args.size(); ++i) {
    const std::string_view arg = args[i];
    if (arg == "--") break;
    if (arg == "-h" || arg == "--help" || arg == "-help" || arg == "--helpfull" ||
        arg == "--helpshort") {
      return true;
    }
  }
  return false;
}

std::string ServerUsage() {
  std::vector<const absl::CommandLineFlag*> flags;
  for (const auto& [name, flag] : absl::GetAllFlags()) {
    if (IsServerFlag(*flag)) flags.push_back(flag);
  }
  std::sort(flags.begin(), flags.end(),
            [](const absl::CommandLineFlag* a, const absl::CommandLineFlag* b) {
              return a->Name() < b->Name();
            });
  std::string out =
      "usage: tempokey-server [flags]\n\n"
      "Serves tempokey.v1.MotionService (gRPC) until SIGTERM or SIGINT, then drains.\n\n"
      "flags (--name=value or --name value):\n";
  for (const absl::CommandLineFlag* flag : flags) {
    absl::StrAppendFormat(&out, "  --%-30s %s (default: %s)\n", flag->Name(), flag->Help(),
                          DefaultText(*flag));
  }
  out += "  -h, --help                       show this help and exit\n";
  return out;
}

}  // namespace tempokey::server
