#!/bin/bash
# session 23: two lenses that fall between focal_try's alternatives (48 and 78 deg), focal_try plan, 10,000 steps
cd /work/runs/s23
export HASHCC=/work/runs/s23/hashcc OMP_NUM_THREADS=1
bash /work/main/tools/bench_scenes.sh --out zootry10k --steps 10000 --threads 1 --jobs 2 -- \
  zoo2/tele48 zoo2/wide78 -- --rays 256 --plan /work/runs/s23/focal_try.json
