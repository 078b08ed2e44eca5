#!/bin/bash
# usage: run_screen.sh NAME SCENE SEED STEPS [extra args...]
name=$1; scene=$2; seed=$3; steps=$4; shift 4
cd /work/runs/s18
OMP_NUM_THREADS=1 /work/runs/s18/hashcc train --data /work/shared/data/llff/$scene --out $name --steps $steps --threads 1 --seed $seed "$@" > $name.out 2>&1
