// The text of `tempokey-server --help`: the server's own flags, one line each.
#ifndef TEMPOKEY_SERVER_SERVER_USAGE_H_
#define TEMPOKEY_SERVER_SERVER_USAGE_H_

#include <span>
#include <string>

namespace tempokey::server {

// True when the command line asks for help (-h, --help, -help, --helpfull, --helpshort), which
// the server answers with ServerUsage() instead of Abseil's per-file listing (that one lists the
// flags of a file named after the program, and the server's flags live in server/main.cc).
bool WantsUsage(std::span<char* const> args);

// "usage: tempokey-server [flags]", then one line per flag defined in server/main.cc, sorted by
// name: "  --name  help (default: value)". Thread-safe once flags are registered (after main).
std::string ServerUsage();

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_SERVER_USAGE_H_
