// The `tempokey` command line (SPEC 6). main.cc only calls Main(); tests call RunCli() with their
// own streams, or run the built binary.
//
//   tempokey [global options] COMMAND [ARGS] [options]
//
// Commands: info, upload, run, retime, reduce, health, server-info, jobs list|get|cancel|delete|
// watch|result. `tempokey --help` and `tempokey COMMAND --help` print usage on stdout (exit 0).
// Results go to stdout; errors are one line on stderr (cli_errors.h); exit codes 0 ok, 1 failed,
// 2 usage.
#ifndef TEMPOKEY_CLIENT_CLI_H_
#define TEMPOKEY_CLIENT_CLI_H_

#include <ostream>
#include <span>
#include <string>

namespace tempokey::client {

// Where a command writes. `show_progress` enables the live progress line on `err` (the CLI sets
// it when stderr is a terminal, so logs and tests never see carriage returns).
struct CliIo {
  std::ostream& out;
  std::ostream& err;
  bool show_progress = false;
};

// Runs one command line (`args` excludes the program name) and returns its exit code.
// Not thread-safe with respect to `io`'s streams; otherwise keeps no global state.
int RunCli(std::span<const std::string> args, const CliIo& io);

// RunCli() on the process's argv, std::cout and std::cerr.
int Main(int argc, char** argv);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_CLI_H_
