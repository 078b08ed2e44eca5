// tools/cli.h — the hashcc command line (one binary, subcommands).
#pragma once
namespace hashcc {
// Parses argv and runs a subcommand. Returns the process exit status: 0 ok, 2 bad input
// (one-line message naming the file/flag and the problem), 1 internal failure.
int run_cli(int argc, char** argv);
}  // namespace hashcc
