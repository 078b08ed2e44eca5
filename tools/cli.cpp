#include "tools/cli.h"
#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include "core/error.h"

namespace hashcc {
int run_cli(int argc, char** argv) {
  CLI::App app{"hashcc: NeRF-- + HashCC on a CPU, cameras learned from photos"};
  app.require_subcommand(1);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const Error& e) {
    fmt::print(stderr, "hashcc: {}\n", e.what());
    return 2;
  }
  return 0;
}
}  // namespace hashcc
