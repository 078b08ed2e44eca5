#!/bin/bash
# usage: hour.sh NAME SCENE SEED [extra train args] — the condition: 60 minutes, 2 threads, then
# the fast eval (timed, issue 53) and the spec eval (the scene table's). Session 24: the build of main
# after the hash kernels' vectorisation (training bitwise the same a step, ~15-20% faster steps).
name=$1; scene=$2; seed=$3; shift 3
cd /work/runs/s24
H=/work/runs/s24/hashcc_h
export OMP_NUM_THREADS=2
echo "$name start $(date +%T), load $(cat /proc/loadavg)"
$H train --data /work/shared/data/llff/$scene --out $name --minutes 60 --threads 2 --seed $seed --no-progress "$@" > $name.train.out 2>&1
echo "$name trained $(date +%T), load $(cat /proc/loadavg)"
/usr/bin/time -v $H eval --run $name --test-init sim3 --refine-epochs 1000 --refine-mode fast --threads 2 --no-progress > $name.eval_fast.out 2> $name.eval_fast.time
cp $name/eval/metrics.json $name.eval_fast_metrics.json
echo "$name fast eval done $(date +%T), load $(cat /proc/loadavg)"
$H eval --run $name --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > $name.eval.out 2>&1
echo "$name done $(date +%T)"
