#!/bin/bash
# usage: hour.sh NAME SCENE SEED [extra train args] — issue 49's condition: 60 minutes, 2 threads, then the default eval
name=$1; scene=$2; seed=$3; shift 3
cd /work/runs/s29
H=/work/runs/s29/hashcc   # build of main 38e3285 (training code = b18e40b's)
export OMP_NUM_THREADS=2
echo "$name start $(date +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
$H train --data /work/shared/data/llff/$scene --out $name --minutes 60 --threads 2 --seed $seed --no-progress "$@" > $name.train.out 2>&1
echo "$name trained $(date +%T)"
$H eval --run $name --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > $name.eval.out 2>&1
echo "$name done $(date +%T)"
