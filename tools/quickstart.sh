#!/usr/bin/env bash
# Quick-start command 1: install dependencies, build, simulate the built-in scene and run the
# main job on it. Output goes to runs/quickstart/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/install_deps.sh
bash tools/build.sh
mkdir -p runs
./build/hashcc simulate --out runs/sim
if ./build/hashcc --help | grep -q '^  train'; then
  ./build/hashcc train --data runs/sim --out runs/quickstart --minutes "${MINUTES:-3}"
fi
