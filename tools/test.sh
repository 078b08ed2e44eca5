#!/usr/bin/env bash
# Quick-start command 2: install dependencies, build, run the whole test suite (CTest runs the
# Catch2 binary at 1 and 2 threads, then the end-to-end tests).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/install_deps.sh
bash tools/build.sh
cd build
ctest --output-on-failure --timeout 1500
