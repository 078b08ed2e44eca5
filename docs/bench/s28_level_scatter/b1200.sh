#!/usr/bin/env bash
# Session 28: the 1,200-step built-in-scene run, old binary (d4803d4) against new (level scatter
# + vectorised guard), 1 thread (expect bitwise) and 2 threads (expect within noise).
cd /work/runs/s28/b1200
for b in old new; do bin=/work/runs/s28/hashcc; [[ $b == new ]] && bin=/work/main/build/hashcc
  $bin train --data /work/runs/s28/sim --field grid --steps 1200 --threads 1 --out t1_$b --no-progress > t1_$b.out 2>&1 &
done; wait
for b in old new; do bin=/work/runs/s28/hashcc; [[ $b == new ]] && bin=/work/main/build/hashcc
  $bin train --data /work/runs/s28/sim --field grid --steps 1200 --threads 2 --out t2_$b --no-progress > t2_$b.out 2>&1
done
