#!/bin/bash
# session 23: is the zoo's Sim(3) failure (lookat, few, wide, narrow: Sim(3) dR above do-nothing at 64x48)
# a matter of the tiny images? The same scenes at 128x96 (make_zoo.sh's default size), the default plan,
# the same 10,000 steps of 256 rays at 1 thread (a step costs the same: rays, not pixels).
cd /work/runs/s23
while pgrep -f "q53.sh" > /dev/null; do sleep 10; done
export HASHCC=/work/runs/s23/hashcc OMP_NUM_THREADS=1
bash /work/main/tools/make_zoo.sh zoo128 128 96
bash /work/main/tools/bench_scenes.sh --out zoo128_10k --steps 10000 --threads 1 --jobs 2 -- \
  zoo128/lookat zoo128/few zoo128/wide zoo128/narrow -- --rays 256
