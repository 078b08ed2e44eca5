#!/usr/bin/env bash
# Same-run A/B of the training step's time on a noisy machine. A shared VM's step time moves by
# 10-20% from minute to minute (other tenants' memory traffic), more than most changes are worth,
# so one long run per configuration compares the minutes, not the code. This runs a short
# `hashcc bench` of each configuration in turn, ROUNDS times over (A B C, A B C, ...), and reports
# per configuration the median over rounds of each run's median ms/step, and the per-round ratio
# to the first configuration (paired: the same minutes of noise), median over rounds.
#
# Usage: tools/bench_ab.sh OUT "LABEL=BINARY [bench args]" "LABEL=BINARY [bench args]" ...
#   e.g. tools/bench_ab.sh docs/bench/ab.txt "before=/tmp/old/hashcc" "after=build/hashcc" \
#          "after-64=build/hashcc --chunk-rays 64"
# Environment (defaults): ROUNDS=6  STEPS=4 (timed steps a run)  VARIANT=hashcc  THREADS=2
# OUT gets every run's line and the summary (also printed).
set -euo pipefail
if [[ $# -lt 3 ]]; then
  sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
OUT=$1
shift
ROUNDS=${ROUNDS:-6} STEPS=${STEPS:-4} VARIANT=${VARIANT:-hashcc} THREADS=${THREADS:-2}
for cfg in "$@"; do
  bin=${cfg#*=}
  bin=${bin%% *}
  [[ $cfg == *=* && -x $bin ]] || { echo "bench_ab: '$cfg' is not LABEL=BINARY [args] with an executable BINARY" >&2; exit 2; }
done
{
  echo "# tools/bench_ab.sh: ROUNDS=$ROUNDS STEPS=$STEPS VARIANT=$VARIANT THREADS=$THREADS, $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo "# CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), family $(grep -m1 'cpu family' /proc/cpuinfo | cut -d: -f2 | xargs) model $(grep -m1 '^model[[:space:]]' /proc/cpuinfo | cut -d: -f2 | xargs), $(grep -c ^processor /proc/cpuinfo) cores, avx512f: $(grep -q avx512f /proc/cpuinfo && echo yes || echo no)"
  for cfg in "$@"; do echo "# config ${cfg%%=*}: ${cfg#*=}"; done
} | tee "$OUT"
for round in $(seq "$ROUNDS"); do
  for cfg in "$@"; do
    label=${cfg%%=*}
    read -r -a cmd <<<"${cfg#*=}"
    line=$("${cmd[0]}" bench "${cmd[@]:1}" --variant "$VARIANT" --threads "$THREADS" --steps "$STEPS" 2>&1 |
      awk -v v="$VARIANT" '$1 == v { print; exit }' || true)
    # columns of the bench's step table: variant gemm thr smp steps median min..max cpu ...
    read -r -a f <<<"$line"
    [[ ${#f[@]} -ge 7 ]] || { echo "bench_ab: no step line from '$cfg'" >&2; exit 1; }
    echo "round $round $label median ${f[5]} min..max ${f[6]} load $(cut -d' ' -f1 /proc/loadavg)" | tee -a "$OUT"
  done
done
awk -v first="${1%%=*}" '
  $1 == "round" { m[$3, $2] = $5; rounds[$2] = 1; if (!($3 in order)) { order[$3] = ++n; name[n] = $3 } }
  function median(a, k,   i, j, t) {  # sorts a[1..k] in place
    for (i = 2; i <= k; ++i) { t = a[i]; for (j = i - 1; j >= 1 && a[j] > t; --j) a[j + 1] = a[j]; a[j + 1] = t }
    return k % 2 ? a[(k + 1) / 2] : (a[k / 2] + a[k / 2 + 1]) / 2
  }
  END {
    print "summary: median over rounds of each run'"'"'s median ms/step; ratio = paired by round to " first
    for (i = 1; i <= n; ++i) {
      l = name[i]; k = 0; r = 0
      for (rd in rounds) { a[++k] = m[l, rd]; b[++r] = m[l, rd] / m[first, rd] }
      printf "  %-24s %8.1f ms   ratio to %s %.3f (rounds %d)\n", l, median(a, k), first, median(b, r), k
    }
  }' "$OUT" | tee -a "$OUT"
