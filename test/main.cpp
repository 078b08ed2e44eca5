// The Catch2 runner for hashcc_tests. Tests are tagged by kernel/area ([fourier], [camera], …)
// and by kind ([grad] finite-difference gradient checks and nothing else, [exact] against a
// closed form or a naive reference implementation, [hard] numerically hard cases, [float] float-vs-double,
// [e2e] end-to-end); run a subset with e.g. `hashcc_tests "[grad]"`.
//
// Every test process gets its own temporary folder (TMPDIR=/tmp/hashcc_tests_<pid>), so two
// runs on one machine (CTest's 1- and 2-thread passes, a developer's run beside CI) never
// share scene or run folders; it is removed at exit.
//
// Tests that need data the repository does not ship ([shared], test/shared_data.h) and found
// none, or that this build cannot run ([isa]), are listed at exit, with summary lines naming the
// folder looked in or the reason; the run then exits with kSkipExitCode (77) instead of 0, so
// CTest reports the entry as skipped, not passed.
#define CATCH_CONFIG_RUNNER
// Messages wrap at 160 columns, not 80: a path in a failure message (a missing data folder)
// then stays on one line, whole, for the reader and for tools/check_fresh_clone.sh's grep.
#define CATCH_CONFIG_CONSOLE_WIDTH 160
#include <catch2/catch.hpp>

#include "test/shared_data.h"

#include <cstdio>
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
  int rc = Catch::Session().run(argc, argv);
  std::error_code ec;
  fs::remove_all(dir, ec);
  const auto& skipped = hashcc::test::skipped_tests();
  if (!skipped.empty()) {
    // One line per skipped test, then the summary lines tools/test.sh repeats after CTest's
    // summary (it greps "hashcc_tests: SKIPPED"): for data tests, which ones, the folder looked
    // in and what to do; for tests this build cannot run, which and why.
    const std::string data = hashcc::test::shared_data_dir();
    std::string which;
    int n_data = 0;
    for (const auto& s : skipped) {
      std::printf("SKIPPED (%s): %s: %s\n", s.data ? "no data" : "this build", s.test.c_str(),
                  s.what.c_str());
      if (!s.data) {
        std::printf("hashcc_tests: SKIPPED \"%s\": %s\n", s.test.c_str(), s.what.c_str());
        continue;
      }
      ++n_data;
      const std::string rel = fs::path(s.what).lexically_relative(data).string();
      which += (which.empty() ? "" : ", ") + ("\"" + s.test + "\" (" +
               (rel.empty() || rel.starts_with("..") ? s.what : rel) + ")");
    }
    if (n_data > 0)
      std::printf("hashcc_tests: SKIPPED %d data test%s, no data in %s: %s. To run %s, put the "
                  "data there as data/README.md says, or point HASHCC_DATA at it.\n",
                  n_data, n_data == 1 ? "" : "s", data.c_str(), which.c_str(),
                  n_data == 1 ? "it" : "them");
    std::fflush(stdout);
    if (rc == 0) rc = hashcc::test::kSkipExitCode;
  }
  return rc;
}
