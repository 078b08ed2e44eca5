#!/bin/bash
# session 22: the zoo with the default command at a larger step budget than session 16's 2,500:
# 64x48, 10,000 steps of 256 rays, 1 thread, seed 0 (a step budget at 1 thread: the same run whatever the load)
cd /work/runs/s22
export HASHCC=/work/runs/s22/hashcc OMP_NUM_THREADS=1
bash /work/main/tools/make_zoo.sh zoo 64 48
bash /work/main/tools/bench_scenes.sh --out zoo10k --steps 10000 --threads 1 --jobs 2 -- \
  zoo/plain zoo/lookat zoo/sweep zoo/wide zoo/narrow zoo/deep zoo/few zoo/shiny -- --rays 256
