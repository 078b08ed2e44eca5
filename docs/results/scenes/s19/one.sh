#!/bin/bash
# usage: one.sh NAME SCENE SEED STEPS [extra train args...] — train then eval (fast refinement), 1 thread
name=$1; scene=$2; seed=$3; steps=$4; shift 4
cd /work/runs/s19/t12k
H=${H:-/work/runs/s19/hashcc}   # the build of the commit named in jobs.txt
export OMP_NUM_THREADS=1
if [ ! -f $name/eval/metrics.json ]; then
  $H train --data /work/shared/data/llff/$scene --out $name --steps $steps --threads 1 --seed $seed --no-progress "$@" > $name.train.out 2>&1
  $H eval --run $name --test-init sim3 --refine-mode fast --threads 1 --no-progress > $name.eval.out 2>&1
fi
echo "$name done $(date +%T)"
