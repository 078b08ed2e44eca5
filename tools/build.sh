#!/usr/bin/env bash
# Configures and builds hashcc (Release) into build/. Usage: tools/build.sh [extra cmake args]
# For the sanitizer build: BUILD_DIR=build-asan tools/build.sh -DHASHCC_SANITIZE=ON
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=${BUILD_TYPE:-Release} "$@" >/dev/null
cmake --build "$BUILD_DIR" -j"$(nproc)"
