#!/usr/bin/env bash
# The test suite under AddressSanitizer + UBSan: a Debug build in build-asan/ with
# -DHASHCC_SANITIZE=ON, which also turns on HCC_DEBUG_FINITE (abort on a NaN/Inf output after
# every kernel of model/model.cpp and model/step.cpp). Runs the fast tests, "~[e2e]~[slow]~[.]~[external]",
# at 2 threads: [e2e] runs once in the Release build (tools/test.sh); [slow] would mark a test
# too slow at -O1 + ASan (none is tagged today; see docs/reliability.md "Tests"); [external]
# (a browser, ffmpeg: programs outside hashcc, driving a whole train/eval/render) runs in the
# Release build only.
# Any sanitizer report fails the run (halt_on_error). Tests needing data the repository does not
# ship ([shared], test/shared_data.h) run here too; without the data they are skipped (exit 77,
# with a line saying which) unless HASHCC_REQUIRE_DATA=1 (.ci/run), which makes that a failure.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=build-asan BUILD_TYPE=Debug bash tools/build.sh -DHASHCC_SANITIZE=ON
export ASAN_OPTIONS=${ASAN_OPTIONS:-halt_on_error=1:detect_leaks=1:abort_on_error=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2} OMP_WAIT_POLICY=passive
start=$(date +%s)
status=0
./build-asan/hashcc_tests "~[e2e]~[slow]~[.]~[external]" --order decl || status=$?
# 77: everything that ran passed, and data tests were skipped (the binary printed which).
if [ "$status" -ne 0 ] && [ "$status" -ne 77 ]; then exit "$status"; fi
echo "asan tests: $(( $(date +%s) - start )) s"
