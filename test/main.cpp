// The Catch2 runner for hashcc_tests. Tests are tagged by kernel/area ([fourier], [camera], …)
// and by kind ([grad] finite-difference gradient checks and nothing else, [exact] against a
// closed form or a naive reference implementation, [hard] numerically hard cases, [float] float-vs-double,
// [e2e] end-to-end); run a subset with e.g. `hashcc_tests "[grad]"`.
//
// Every test process gets its own temporary folder (TMPDIR=/tmp/hashcc_tests_<pid>), so two
// runs on one machine (CTest's 1- and 2-thread passes, a developer's run beside CI) never
// share scene or run folders; it is removed at exit.
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <unistd.h>

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  const fs::path base = std::getenv("TMPDIR") ? fs::path(std::getenv("TMPDIR")) : fs::path("/tmp");
  const fs::path dir = base / ("hashcc_tests_" + std::to_string(getpid()));
  fs::create_directories(dir);
  setenv("TMPDIR", dir.c_str(), 1);
  const int rc = Catch::Session().run(argc, argv);
  std::error_code ec;
  fs::remove_all(dir, ec);
  return rc;
}
