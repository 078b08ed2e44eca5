#!/usr/bin/env bash
# One table over every scene (issue 49): the same train command on each scene folder given, then
# `hashcc eval`, then one row per run in OUT/table.md and OUT/table.csv.
#
#   tools/bench_scenes.sh --out OUT [--minutes M | --steps N] [--threads T] [--seeds 0,1]
#                         [--refine-epochs K] [--jobs J] [--] SCENE_DIR [SCENE_DIR ...] [-- TRAIN_ARGS...]
#
# Every scene gets exactly the same command (nothing here names a scene): `hashcc train --data
# SCENE --out OUT/<scene>_s<seed> --seed S --threads T --minutes M TRAIN_ARGS`, then `hashcc eval
# --run RUN --test-init sim3 --refine-epochs K`. --jobs J runs J trainings side by side (their
# threads add up: J × T should not exceed the cores). A run folder that already has
# eval/metrics.json is not run again, so an interrupted table resumes where it stopped.
#
# Columns: scene, seed, minutes, steps, threads, relative rotation error (and its do-nothing
# value), Sim(3) ΔR (and the do-nothing ΔR: the error of cameras that never turn, aligned the same
# way), ΔT, the focal's error against the reference, test PSNR / SSIM, and the HashCC paper's
# PSNR / ΔR for the LLFF scenes (docs/results/scenes/paper_table1.csv, the paper's Table 1).
set -euo pipefail
HERE="$(cd "$(dirname "$0")/.." && pwd)"
HASHCC=${HASHCC:-$HERE/build/hashcc}
OUT="" MINUTES="" STEPS="" THREADS=1 SEEDS=0 REFINE=1000 JOBS=1
SCENES=() TRAIN_ARGS=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --out) OUT=$2; shift 2 ;;
    --minutes) MINUTES=$2; shift 2 ;;
    --steps) STEPS=$2; shift 2 ;;
    --threads) THREADS=$2; shift 2 ;;
    --seeds) SEEDS=$2; shift 2 ;;
    --refine-epochs) REFINE=$2; shift 2 ;;
    --jobs) JOBS=$2; shift 2 ;;
    --) shift; if [[ ${#SCENES[@]} -eq 0 ]]; then while [[ $# -gt 0 && $1 != -- ]]; do SCENES+=("$1"); shift; done
        [[ $# -gt 0 ]] && shift; fi; TRAIN_ARGS=("$@"); break ;;
    -h|--help) sed -n 2,18p "$0"; exit 0 ;;
    -*) echo "bench_scenes.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    *) SCENES+=("$1"); shift ;;
  esac
done
[[ -n $OUT ]] || { echo "bench_scenes.sh: --out OUT is required" >&2; exit 2; }
[[ ${#SCENES[@]} -gt 0 ]] || { echo "bench_scenes.sh: give at least one scene folder" >&2; exit 2; }
[[ -n $MINUTES || -n $STEPS ]] || { echo "bench_scenes.sh: give --minutes M or --steps N" >&2; exit 2; }
[[ -x $HASHCC ]] || { echo "bench_scenes.sh: $HASHCC not built (bash tools/build.sh)" >&2; exit 2; }
for s in "${SCENES[@]}"; do [[ -d $s ]] || { echo "bench_scenes.sh: $s: not a folder" >&2; exit 2; }; done
mkdir -p "$OUT"
BUDGET=(); [[ -n $MINUTES ]] && BUDGET=(--minutes "$MINUTES"); [[ -n $STEPS ]] && BUDGET=(--steps "$STEPS")
CMD_FILE="$OUT/commands.txt"
: > "$CMD_FILE"

one_run() {  # scene_dir seed
  local scene=$1 seed=$2 name run
  name=$(basename "$scene")
  run="$OUT/${name}_s${seed}"
  if [[ -f $run/eval/metrics.json ]]; then echo "[$name seed $seed] done before: $run"; return 0; fi
  local train=("$HASHCC" train --data "$scene" --out "$run" --seed "$seed" --threads "$THREADS"
               "${BUDGET[@]}" --no-progress "${TRAIN_ARGS[@]}")
  local ev=("$HASHCC" eval --run "$run" --test-init sim3 --refine-epochs "$REFINE"
            --threads "$THREADS" --no-progress)
  echo "${train[*]}" >> "$CMD_FILE"; echo "${ev[*]}" >> "$CMD_FILE"
  mkdir -p "$run"
  if [[ -f $run/checkpoint.bin || -f $run/plan.json ]]; then
    "$HASHCC" train --resume "$run" --no-progress > "$run/train.out" 2>&1 || true
  else
    "${train[@]}" > "$run/train.out" 2>&1
  fi
  "${ev[@]}" > "$run/eval.out" 2>&1
  echo "[$name seed $seed] $(tail -n 1 "$run/eval.out")"
}

pids=()
for scene in "${SCENES[@]}"; do
  for seed in ${SEEDS//,/ }; do
    one_run "$scene" "$seed" &
    pids+=($!)
    while [[ $(jobs -rp | wc -l) -ge $JOBS ]]; do wait -n || true; done
  done
done
for p in "${pids[@]}"; do wait "$p" || true; done

/usr/bin/python3 "$HERE/tools/scene_table.py" "$OUT" --paper "$HERE/docs/results/scenes/paper_table1.csv"
