#!/usr/bin/env bash
# Every timing of issue 53's grid items in one command, for a QUIET machine (nothing else
# running): the paper's and the grid field's step against PyTorch at 1 and 2 threads with each
# side's 1 → 2 thread scaling (tools/bench_vs_torch.sh → OUT_torch.json/.txt), then the grid
# step's roofline (tools/bench_grid_roofline.sh → OUT_roofline*.json/.txt). 8 minutes on
# the 2-core Zen 4 (session 23).
#
# Usage: tools/bench_grid_quiet.sh BUILD/hashcc [OUT]    (OUT default docs/bench/grid_quiet)
# It refuses to start when the 1-minute load average is 0.3 or more (FORCE=1 starts anyway: the
# figures then measure the contention too, and the docs must say so).
set -euo pipefail
cd "$(dirname "$0")/.."
HASHCC=${1:?usage: tools/bench_grid_quiet.sh BUILD/hashcc [OUT]}
OUT=${2:-docs/bench/grid_quiet}
load=$(cut -d' ' -f1 /proc/loadavg)
if [[ ${FORCE:-0} != 1 ]] && awk -v l="$load" 'BEGIN { exit !(l >= 0.3) }'; then
  echo "bench_grid_quiet: load average $load ≥ 0.3: not a quiet machine (FORCE=1 to run anyway)" >&2
  exit 1
fi
tools/bench_vs_torch.sh "$HASHCC" "${OUT}_torch"
tools/bench_grid_roofline.sh "$HASHCC" "${OUT}_roofline"
