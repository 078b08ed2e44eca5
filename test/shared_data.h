// test/shared_data.h — the one rule for test data the repository does not ship (issue 54).
//
// Such tests are tagged [shared] and find their data only through shared_data_dir():
// $HASHCC_DATA if set, else ../shared/data beside the repository (where the project's machines
// and CI keep LLFF fern/horns and the LPIPS heads; data/README.md says how to get them).
// HASHCC_NEED_DATA(path) starts such a test:
//   - data present: the test runs;
//   - data absent, HASHCC_REQUIRE_DATA=1 (.ci/run sets it): the test FAILS, naming the path,
//     so CI proves the real-data checks ran;
//   - data absent, not required (a fresh clone): the test stops, is recorded as skipped, and
//     test/main.cpp prints what was skipped and where it looked, then exits with kSkipExitCode
//     if nothing failed. CTest runs the [shared] tests as their own entry, shared_data, with that
//     SKIP_RETURN_CODE (CMakeLists.txt), so its summary lists them as "Skipped", never "Passed"
//     (Catch2 v2 has no skip of its own).
//
// HASHCC_SKIP(reason) is the same skip for a test that cannot run in this BUILD (e.g. the AVX2
// micro-kernel's test in a build without AVX2, tagged [isa], CTest entry isa_kernel): recorded,
// listed at exit with its reason, exit 77.
//
// The repository the tests read their committed files from (test/data/…) is repo_root(): the
// folder built from, or $HASHCC_SOURCE_DIR. tools/check_fresh_clone.sh sets it to a fresh clone
// with nothing beside it, which is what makes that check about a clone and not about this tree.
#pragma once
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace hashcc::test {

// The exit status of a test run that skipped data tests and had no failure (77: the automake
// convention for "skipped"); CMakeLists.txt gives it to CTest as SKIP_RETURN_CODE.
inline constexpr int kSkipExitCode = 77;

inline std::string env_or(const char* name, const std::string& fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::string(v) : fallback;
}

// The repository holding the committed test files: $HASHCC_SOURCE_DIR, else the one built from.
inline std::string repo_root() { return env_or("HASHCC_SOURCE_DIR", HASHCC_SOURCE_DIR); }

// The Python with NumPy that runs the repository script `script` (test::python_with_numpy,
// test/fixtures.h); none found, the test FAILS naming the script, never passes silently.
#define HASHCC_REQUIRE_PYTHON(py_, script_)                                                        \
  const std::string py_ = ::hashcc::test::python_with_numpy();                                    \
  if (py_.empty())                                                                                 \
  FAIL("no Python with NumPy (tried $HASHCC_PYTHON, python3, /usr/bin/python3): " << script_      \
       << " was NOT checked. Install python3-numpy (tools/install_deps.sh does).")

// The folder of data the repository does not ship: $HASHCC_DATA, else <repo>/../shared/data.
inline std::string shared_data_dir() {
  const char* v = std::getenv("HASHCC_DATA");
  if (v && *v) return std::string(v);
  return (std::filesystem::path(repo_root()) / ".." / "shared" / "data").lexically_normal().string();
}

// HASHCC_REQUIRE_DATA set to anything but "" or "0": missing data is a failure.
inline bool data_required() {
  const char* v = std::getenv("HASHCC_REQUIRE_DATA");
  return v && *v && std::string(v) != "0";
}

struct SkippedTest {
  std::string test, what;  // what: the missing data path, or the reason
  bool data;               // a data test (counted in the "no data" summary line)
};
// The data tests this process skipped, in order (read by test/main.cpp at exit).
inline std::vector<SkippedTest>& skipped_tests() {
  static std::vector<SkippedTest> s;
  return s;
}

}  // namespace hashcc::test

// First statement of a [shared] test: `path` (under shared_data_dir()) must exist. Absent and
// not required, it records the skip and returns from the test case (a `return` in TEST_CASE's
// body); absent and required, it FAILs with the path and the rule.
#define HASHCC_NEED_DATA(path_)                                                                   \
  do {                                                                                            \
    const std::string hcc_need_ = (path_);                                                        \
    if (!std::filesystem::exists(hcc_need_)) {                                                    \
      if (::hashcc::test::data_required())                                                        \
        FAIL("shared data missing: " << hcc_need_ << " (HASHCC_REQUIRE_DATA is set, so a "        \
             "missing data folder is a failure; the data folder is $HASHCC_DATA or ../shared/data " \
             "beside the repository, see data/README.md)");                                       \
      ::hashcc::test::skipped_tests().push_back(                                                  \
          {Catch::getResultCapture().getCurrentTestName(), hcc_need_, true});                     \
      WARN("SKIPPED, no data at " << hcc_need_ << " (see data/README.md)");                       \
      return;                                                                                     \
    }                                                                                             \
  } while (0)

// Stops the current test as SKIPPED for a reason of this build (not data): recorded for
// test/main.cpp, which lists it and exits with kSkipExitCode if nothing failed.
#define HASHCC_SKIP(reason_)                                                                      \
  do {                                                                                            \
    ::hashcc::test::skipped_tests().push_back(                                                    \
        {Catch::getResultCapture().getCurrentTestName(), std::string(reason_), false});           \
    WARN("SKIPPED: " << (reason_));                                                               \
    return;                                                                                       \
  } while (0)

namespace hashcc::test {
// HASHCC_REQUIRE_TOOLS set to anything but "" or "0" (.ci/run sets it, as CI installs them):
// an optional program a test needs (chromium, ffmpeg) that is missing is a failure, not a skip.
inline bool tools_required() {
  const char* v = std::getenv("HASHCC_REQUIRE_TOOLS");
  return v && *v && std::string(v) != "0";
}
}  // namespace hashcc::test

// First statement of a test tagged [external] that runs a program hashcc does not depend on:
// `path_` is where it was found ("" = not on the PATH). Absent: FAIL under HASHCC_REQUIRE_TOOLS,
// else a recorded skip naming the program and its Debian package (tools/install_deps.sh
// installs it). CTest runs the [external] tests as their own entry, external_tools.
#define HASHCC_NEED_PROGRAM(path_, program_, package_)                                            \
  do {                                                                                            \
    if (std::string(path_).empty()) {                                                             \
      const std::string hcc_why_ = std::string(program_) + " is not on the PATH (Debian: apt-get " \
                                   "install " + (package_) + "; tools/install_deps.sh installs it)"; \
      if (::hashcc::test::tools_required())                                                      \
        FAIL(hcc_why_ << "; HASHCC_REQUIRE_TOOLS is set, so a missing program is a failure");     \
      HASHCC_SKIP(hcc_why_);                                                                      \
    }                                                                                             \
  } while (0)
