// hashcc — the one binary. Subcommands live in tools/cli.cpp so tests can call them in-process.
#include "tools/cli.h"
int main(int argc, char** argv) { return hashcc::run_cli(argc, argv); }
