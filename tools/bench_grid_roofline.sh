#!/usr/bin/env bash
# The grid step's roofline (issue 53; docs/performance.md, "The grid step's roofline"). Builds
# nothing. Given a hashcc binary: the memory hierarchy (`hashcc bench --memory`: pointer-chase
# latency, random 8-byte gather and scatter-add throughput, streaming bandwidth, per working set
# and thread count), the grid step and the FMA peak (`hashcc bench --variant sh+grid`, 1 and 2
# threads), then tools/grid_roofline.py, which counts the step's gathers, scatters, bytes and
# FLOPs and divides: OUT_memory.json, OUT_bench.json, OUT.json and OUT.txt (everything printed).
#
# Usage: tools/bench_grid_roofline.sh BUILD/hashcc [OUT]     (OUT default docs/bench/grid_roofline)
# Environment: THREADS="1 2"  SECONDS_STEP=60 (hashcc bench --seconds)  PYTHON=/usr/bin/python3
# On a quiet machine: every figure is a time.
set -euo pipefail
cd "$(dirname "$0")/.."
HASHCC=${1:?usage: tools/bench_grid_roofline.sh BUILD/hashcc [OUT]}
OUT=${2:-docs/bench/grid_roofline}
THREADS=${THREADS:-1 2}
SECONDS_STEP=${SECONDS_STEP:-60}
PYTHON=${PYTHON:-/usr/bin/python3}
[[ -x $HASHCC ]] || { echo "bench_grid_roofline: $HASHCC is not an executable hashcc binary" >&2; exit 2; }
mkdir -p "$(dirname "$OUT")"
targs=()
for t in $THREADS; do targs+=(--threads "$t"); done
{
  echo "bench_grid_roofline: $(date -u +%FT%TZ), $HASHCC; cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2-)," \
       "family $(grep -m1 'cpu family' /proc/cpuinfo | cut -d: -f2 | tr -d ' '), model" \
       "$(grep -m1 '^model\s' /proc/cpuinfo | cut -d: -f2 | tr -d ' '), $(nproc) cores," \
       "$(grep -qw avx512f /proc/cpuinfo && echo AVX-512 || echo no AVX-512); uptime: $(uptime)"
  "$HASHCC" bench --memory "${targs[@]}" --json "${OUT}_memory.json"
  "$HASHCC" bench --variant sh+grid "${targs[@]}" --seconds "$SECONDS_STEP" --json "${OUT}_bench.json"
  "$PYTHON" tools/grid_roofline.py --memory "${OUT}_memory.json" --bench "${OUT}_bench.json" --json "$OUT.json"
  echo "uptime after: $(uptime)"
} 2>&1 | tee "$OUT.txt"
