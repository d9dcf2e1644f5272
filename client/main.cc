// The `tempokey` command-line client; everything is in cli.cc.
#include "client/cli.h"

int main(int argc, char** argv) { return tempokey::client::Main(argc, argv); }
