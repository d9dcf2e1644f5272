#include "client/cli.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/cord.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "client/cli_errors.h"
#include "client/command.h"
#include "client/tls_diagnosis.h"
#include "grpc/support/log.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;
using core::AsStd;

constexpr FlagSpec kHelpFlag{"--help", "-h", "", "show this help and exit"};
constexpr FlagSpec kVersionFlag{"--version", "", "", "print the version and exit"};

// Column where flag and command descriptions start in help text.
constexpr std::size_t kHelpColumn = 30;

std::string PadTo(std::string text, std::size_t width) {
  if (text.size() + 2 > width) return absl::StrCat(text, "\n", std::string(width, ' '));
  text.resize(width, ' ');
  return text;
}

std::string FlagLine(const FlagSpec& flag) {
  std::string left = "  ";
  if (!flag.short_name.empty()) absl::StrAppend(&left, AsAbsl(flag.short_name), ", ");
  absl::StrAppend(&left, AsAbsl(flag.name));
  if (!flag.value_name.empty()) absl::StrAppend(&left, " ", AsAbsl(flag.value_name));
  return absl::StrCat(PadTo(std::move(left), kHelpColumn), AsAbsl(flag.help),
                      flag.repeatable ? " (repeatable)" : "", "\n");
}

std::string ToolHelp() {
  std::string text =
      "usage: tempokey [global options] COMMAND [ARGS] [options]\n"
      "\n"
      "Retimes motion-capture clips and reduces them to key-frame curves on a tempokey server.\n"
      "\n"
      "commands:\n";
  for (const Command* command : AllCommands()) {
    absl::StrAppend(&text, PadTo(absl::StrCat("  ", AsAbsl(command->name)), kHelpColumn),
                    AsAbsl(command->summary), "\n");
  }
  absl::StrAppend(&text, "\nglobal options (accepted by every command):\n");
  for (const FlagSpec& flag : GlobalFlags()) absl::StrAppend(&text, FlagLine(flag));
  absl::StrAppend(&text, FlagLine(kHelpFlag), FlagLine(kVersionFlag));
  absl::StrAppend(&text,
                  "\n"
                  "Results go to stdout. An error is one line on stderr, \"error: <message>\";\n"
                  "refusals by the server read \"error: server: <gRPC CODE>: <message>\".\n"
                  "Exit codes: 0 ok, 1 failed, 2 usage.\n"
                  "Run 'tempokey COMMAND --help' for the options of a command.\n");
  return text;
}

std::string CommandHelp(const Command& command) {
  std::string text = absl::StrCat("usage: tempokey ", AsAbsl(command.name), " ",
                                  AsAbsl(command.synopsis), "\n\n", AsAbsl(command.description));
  if (!command.flags.empty()) {
    absl::StrAppend(&text, "\noptions:\n");
    for (const FlagSpec& flag : command.flags) absl::StrAppend(&text, FlagLine(flag));
  }
  absl::StrAppend(&text, "\nglobal options: --server TARGET, --timeout SECONDS, TLS and token "
                         "flags (see tempokey --help)\n");
  return text;
}

std::string JobsHelp() {
  std::string text =
      "usage: tempokey jobs SUBCOMMAND [ARGS] [options]\n"
      "\n"
      "Manages the jobs of a server.\n"
      "\n"
      "subcommands:\n";
  for (const Command* command : AllCommands()) {
    if (!command->name.starts_with("jobs ")) continue;
    absl::StrAppend(&text,
                    PadTo(absl::StrCat("  ", AsAbsl(command->name.substr(5)), " ",
                                       AsAbsl(command->synopsis)),
                          kHelpColumn),
                    AsAbsl(command->summary), "\n");
  }
  absl::StrAppend(&text, "\nRun 'tempokey jobs SUBCOMMAND --help' for its options.\n");
  return text;
}

const Command* FindCommand(std::string_view name) {
  for (const Command* command : AllCommands()) {
    if (command->name == name) return command;
  }
  return nullptr;
}

const FlagSpec* FindSpec(std::span<const FlagSpec> flags, std::string_view arg) {
  const std::string_view name = arg.substr(0, arg.find('='));
  for (const FlagSpec& flag : flags) {
    if (flag.name == name || (!flag.short_name.empty() && flag.short_name == arg)) return &flag;
  }
  return nullptr;
}

// The command line split into the command's words and everything else.
struct Invocation {
  std::vector<std::string> words;  // "retime" or "jobs", "list"
  std::vector<std::string> rest;   // flags (global ones included) and positionals, in order
  bool tool_help = false;          // --help before any command
  bool version = false;
};

// Finds the command: global flags (and their values) may precede it; any other flag there is a
// usage error. "jobs" takes its subcommand as the next word.
absl::StatusOr<Invocation> SplitInvocation(std::span<const std::string> args) {
  Invocation invocation;
  std::size_t i = 0;
  for (; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (arg.size() < 2 || arg[0] != '-') break;
    if (arg == "--help" || arg == "-h") {
      invocation.tool_help = true;
      continue;
    }
    if (arg == "--version") {
      invocation.version = true;
      continue;
    }
    const FlagSpec* spec = FindSpec(GlobalFlags(), arg);
    if (spec == nullptr) {
      return UsageError(absl::StrCat("unknown flag ", arg.substr(0, arg.find('=')),
                                     " (see tempokey --help)"));
    }
    invocation.rest.push_back(arg);
    if (!spec->value_name.empty() && arg.find('=') == std::string::npos && i + 1 < args.size()) {
      invocation.rest.push_back(args[++i]);
    }
  }
  if (i < args.size()) {
    invocation.words.push_back(args[i++]);
    if (invocation.words[0] == "jobs" && i < args.size() && args[i].rfind('-', 0) != 0) {
      invocation.words.push_back(args[i++]);
    }
  }
  invocation.rest.insert(invocation.rest.end(), args.begin() + static_cast<std::ptrdiff_t>(i),
                         args.end());
  return invocation;
}

bool WantsHelp(const std::vector<std::string>& rest) {
  for (const std::string& arg : rest) {
    if (arg == "--") return false;
    if (arg == "--help" || arg == "-h") return true;
  }
  return false;
}

// A command that failed UNAVAILABLE after making its client, with gRPC's text alone ("Socket
// closed", "certificate verify failed"), gets the reason a probe of the server finds
// (tls_diagnosis.h) appended to the same message: still one error line, same code.
absl::Status WithConnectionDiagnosis(const CommandContext& context, absl::Status status) {
  // Only a server call's own failure (ServerError()'s words): a local file's UNAVAILABLE is not
  // the connection's.
  if (status.code() != absl::StatusCode::kUnavailable || context.client() == nullptr ||
      !absl::StartsWith(status.message(), "server: UNAVAILABLE: ")) {
    return status;
  }
  const TlsFlagFiles files{.ca = context.args().Value("--ca").value_or(""),
                           .cert = context.args().Value("--cert").value_or("")};
  const std::string explanation =
      DiagnoseConnectionFailure(context.client()->options(), files, AsStd(status.message()));
  if (explanation.empty()) return status;
  absl::Status explained(status.code(), absl::StrCat(status.message(), "; ", explanation));
  status.ForEachPayload([&](absl::string_view url, const absl::Cord& payload) {
    explained.SetPayload(url, payload);
  });
  return explained;
}

absl::Status Dispatch(std::span<const std::string> args, const CliIo& io) {
  TEMPOKEY_ASSIGN_OR_RETURN(Invocation invocation, SplitInvocation(args));
  if (invocation.version) {
    io.out << "tempokey " << TEMPOKEY_VERSION << "\n";
    return absl::OkStatus();
  }
  if (invocation.words.empty()) {
    if (invocation.tool_help) {
      io.out << ToolHelp();
      return absl::OkStatus();
    }
    return UsageError("missing command (see tempokey --help)");
  }
  if (invocation.words[0] == "help") {
    // `tempokey help` and `tempokey help retime`.
    std::vector<std::string> topic(invocation.rest.begin(), invocation.rest.end());
    if (topic.empty()) {
      io.out << ToolHelp();
      return absl::OkStatus();
    }
    std::vector<std::string> again = topic;
    again.push_back("--help");
    return Dispatch(again, io);
  }
  if (invocation.words[0] == "jobs" && invocation.words.size() == 1) {
    if (invocation.tool_help || WantsHelp(invocation.rest)) {
      io.out << JobsHelp();
      return absl::OkStatus();
    }
    return UsageError(
        "jobs: missing subcommand: list, get, cancel, delete, watch or result (see tempokey jobs "
        "--help)");
  }
  std::string name = invocation.words[0];
  if (invocation.words.size() == 2) absl::StrAppend(&name, " ", invocation.words[1]);
  const Command* command = FindCommand(name);
  if (command == nullptr) {
    if (invocation.words[0] == "jobs") {
      return UsageError(absl::StrCat("jobs: unknown subcommand '", invocation.words[1],
                                     "' (see tempokey jobs --help)"));
    }
    return UsageError(absl::StrCat("unknown command '", name, "' (see tempokey --help)"));
  }
  if (invocation.tool_help || WantsHelp(invocation.rest)) {
    io.out << CommandHelp(*command);
    return absl::OkStatus();
  }

  std::vector<FlagSpec> flags(command->flags.begin(), command->flags.end());
  flags.insert(flags.end(), GlobalFlags().begin(), GlobalFlags().end());
  TEMPOKEY_ASSIGN_OR_RETURN(ParsedArgs parsed, ParseArgs(invocation.rest, flags, command->name));
  CommandContext context(io, *command, std::move(parsed));
  return WithConnectionDiagnosis(context, command->run(context));
}

}  // namespace

int RunCli(std::span<const std::string> args, const CliIo& io) {
  absl::Status status = Dispatch(args, io);
  errno = 0;
  io.out.flush();
  // A result nobody got is a failure: with stdout on a full disk (or /dev/full) every command
  // exited 0, a batch leaving an empty summary and an upload its id nowhere.
  if (!io.out && status.ok()) {
    std::string reason = errno != 0 ? std::strerror(errno) : "";
    if (!reason.empty()) reason[0] = absl::ascii_tolower(static_cast<unsigned char>(reason[0]));
    status = absl::DataLossError(absl::StrCat("cannot write the result to standard output",
                                              reason.empty() ? "" : ": ", reason));
  }
  if (!status.ok()) io.err << ErrorLine(status) << "\n";
  io.err.flush();
  return ExitCodeFor(status);
}

namespace {

// SIGINT, SIGTERM, SIGHUP: remove the temporary file of any output being written, then die of
// the signal as if unhandled (the shell sees 130 for Ctrl-C). Only async-signal-safe calls:
// RemovePendingTempFiles() (unlink), sigaction(), raise().
void RemoveTempFilesAndDie(int signal_number) {
  core::RemovePendingTempFiles();
  struct sigaction default_action {};
  default_action.sa_handler = SIG_DFL;
  sigemptyset(&default_action.sa_mask);
  sigaction(signal_number, &default_action, nullptr);
  raise(signal_number);
}

void InstallSignalHandlers() {
  struct sigaction action {};
  action.sa_handler = RemoveTempFilesAndDie;
  sigemptyset(&action.sa_mask);
  for (int signal_number : {SIGINT, SIGTERM, SIGHUP}) sigaction(signal_number, &action, nullptr);
  // Test hook (tests/client): stop the process right after an output's temporary file exists,
  // so a test can signal it in the middle of the write without racing it.
  if (std::getenv("TEMPOKEY_TEST_STOP_IN_WRITE") != nullptr) {
    core::SetTempFileCreatedHookForTesting([] { raise(SIGSTOP); });
  }
}

}  // namespace

int Main(int argc, char** argv) {
  InstallSignalHandlers();
  // gRPC logs connection failures to stderr on its own ("Handshake failed ..."); the CLI reports
  // every failure as one line of its own, so the runtime's log stays off unless asked for.
  if (std::getenv("GRPC_VERBOSITY") == nullptr && std::getenv("GRPC_TRACE") == nullptr) {
    gpr_set_log_function([](gpr_log_func_args*) {});
  }
  std::vector<std::string> args(argv + std::min(argc, 1), argv + argc);
  const CliIo io{.out = std::cout, .err = std::cerr, .show_progress = isatty(STDERR_FILENO) == 1};
  return RunCli(args, io);
}

}  // namespace tempokey::client
