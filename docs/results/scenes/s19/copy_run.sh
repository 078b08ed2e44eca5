#!/bin/bash
# copy_run.sh RUN DEST: what a reader needs of a run folder (plan, configs, camera_error.csv,
# cameras, eval metrics and log (RUN.train.out or RUN/train.out: bench_scenes.sh's), the logs thinned
# by tools/thin_log.py: every 10th step plus the last 500 rows, gzipped; docs/results/README.md).
set -euo pipefail
run=$1; dest=$2
mkdir -p "$dest"
ROOT="$(cd "$(dirname "$0")/../../../.." && pwd)"
thin() {  # LOG DEST.gz: the project's thinning, on a copy (thin_log.py writes beside its input)
  local t; t=$(mktemp -d); cp "$1" "$t/log.csv"
  python3 "$ROOT/tools/thin_log.py" "$t/log.csv" > /dev/null; mv "$t/log.csv.gz" "$2"; rm -rf "$t"; }
for f in plan.json config.json camera_error.csv cameras.json; do [ -f "$run/$f" ] && cp "$run/$f" "$dest/"; done
[ -f "$run/log.csv" ] && thin "$run/log.csv" "$dest/log.csv.gz"
for s in "$run"/stage* "$run"/stage*/try*; do  # a stage that tries alternatives: each one's folder
  [ -d "$s" ] || continue; d="$dest/${s#"$run"/}"; mkdir -p "$d"
  for f in config.json camera_error.csv; do [ -f "$s/$f" ] && cp "$s/$f" "$d/"; done
  [ -f "$s/log.csv" ] && thin "$s/log.csv" "$d/log.csv.gz"
done
if [ -f "$run/eval/metrics.json" ]; then mkdir -p "$dest/eval"; cp "$run/eval/metrics.json" "$dest/eval/"; fi
for f in "$run".train.out "$run".eval.out "$run"/train.out "$run"/eval.out; do
  [ -f "$f" ] || continue; case $f in "$run"/*) name=$(basename "$f") ;; *) name=$(basename "$f" | sed 's/^[^.]*\.//') ;; esac
  grep -v '^\s*$' "$f" | tail -n 40 > "$dest/$name"
done
true
