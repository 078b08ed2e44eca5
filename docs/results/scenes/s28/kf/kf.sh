#!/usr/bin/env bash
# Session 28: what a known focal (EXIF-like) does to the forward recipe on fern: the default
# command against the same with the focal held at the reference (COLMAP's 407.57 px), 40 minutes,
# seed 1, 1 thread each, side by side; then the default eval of each at 2 threads.
set -u
cd /work/runs/s28/kf
F=/work/shared/data/llff/fern
./hashcc train --data $F --out learned --minutes 40 --seed 1 --threads 1 --no-progress > learned.train.out 2>&1 &
./hashcc train --data $F --out held --minutes 40 --seed 1 --threads 1 --focal 407.57 --fixed-focal --no-progress > held.train.out 2>&1 &
wait
for r in learned held; do
  ./hashcc eval --run $r --data $F --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > $r.eval.out 2>&1
done
