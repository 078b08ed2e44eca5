#!/usr/bin/env bash
# tools/slurm_array.sh — one run of a `hashcc study --emit-commands FILE` as one task of a Slurm
# job array (docs/study.md#fan-out-on-a-scheduler). Task i runs line i of FILE:
#
#   hashcc study --data DIR --out STUDY --budgets 1,2 --threads 4 --emit-commands runs.sh
#   sbatch --array=1-$(wc -l < runs.sh) --cpus-per-task=4 tools/slurm_array.sh runs.sh
#   hashcc study --collect STUDY        # once the array has finished
#
# Each line is self-contained (absolute paths; train && eval; its logs in STUDY/runs/<id>/), so
# tasks share nothing but the file system; add `%K` to --array (e.g. 1-40%8) to cap how many
# run at once. A failed task is reported by --collect with its log line; rerun just it with
# `sbatch --array=<i> tools/slurm_array.sh runs.sh`.
#SBATCH --job-name=hashcc-study
#SBATCH --output=slurm-%A_%a.out
set -euo pipefail
file=${1:?usage: sbatch --array=1-N tools/slurm_array.sh FILE}
task=${SLURM_ARRAY_TASK_ID:?not a Slurm array task (submit with sbatch --array=1-N)}
line=$(sed -n "${task}p" "$file")
if [ -z "$line" ]; then
  echo "slurm_array: $file has no line $task" >&2
  exit 1
fi
# OpenMP uses the CPUs Slurm gave the task (train/eval take --threads from the line when set).
if [ -n "${SLURM_CPUS_PER_TASK:-}" ]; then export OMP_NUM_THREADS=$SLURM_CPUS_PER_TASK; fi
echo "slurm_array: task $task: $line"
exec bash -c "$line"
