#!/bin/bash
# session 23: the far lenses with the default plan started from their true focal (as EXIF would give it):
# does a known lens alone mend them? 10,000 steps, 256 rays, 1 thread (as zoo10k)
cd /work/runs/s23
H=/work/runs/s23/hashcc; export OMP_NUM_THREADS=1
one() { $H train --data zoo/$1 --out zooexif10k/$1_s0 --seed 0 --threads 1 --steps 10000 --no-progress --rays 256 --focal $2 > zooexif10k/$1_s0.train.out 2>&1 &&
        $H eval --run zooexif10k/$1_s0 --test-init sim3 --refine-epochs 1000 --threads 1 --no-progress > zooexif10k/$1_s0.eval.out 2>&1; echo "$1 done $(date +%T)"; }
mkdir -p zooexif10k
one narrow 87.919 & one wide 32.0 & wait
