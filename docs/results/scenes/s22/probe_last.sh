#!/bin/bash
# session 22 probe: the forward recipe's last stage from fern_s1's stage-4 cameras, 6,000 steps, 1 thread,
# two variants side by side: A = the recipe (2^17 table, 64 samples), E = the restarts' field (2^15, 32 samples)
cd /work/runs/s22
H=/work/runs/s22/hashcc; export OMP_NUM_THREADS=1
run() { name=$1; shift; $H train --data /work/shared/data/llff/fern --out $name --plan last_stage.json \
  --cameras-from /work/runs/s22/fern_s1/stage4 --threads 1 --seed 1 --no-progress "$@" > $name.train.out 2>&1; echo "$name done $(date +%T)"; }
run pA_recipe &
run pE_t15_s32 --set 1.grid_log2_table=15 --set 1.samples=32 &
wait
