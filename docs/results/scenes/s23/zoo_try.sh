#!/bin/bash
# session 23: the zoo at 10,000 steps with the focal_try plan (stage 1 tries 40/55/70/90 deg, focal held,
# keeps the best training fit), against session 22's zoo10k (the default plan, same size and budget)
cd /work/runs/s23
export HASHCC=/work/runs/s23/hashcc OMP_NUM_THREADS=1
bash /work/main/tools/bench_scenes.sh --out zootry10k --steps 10000 --threads 1 --jobs 2 -- \
  zoo/wide zoo/narrow zoo/plain zoo/sweep zoo/lookat zoo/deep zoo/few zoo/shiny -- --rays 256 --plan /work/runs/s23/focal_try.json
