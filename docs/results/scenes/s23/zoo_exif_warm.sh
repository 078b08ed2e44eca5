#!/bin/bash
# session 23: the far lenses from their true focal (as zoo_exif.sh), with each restart's and the last
# stage's camera learning rate ramped over its first 100 steps (camera_warmup; session 20's probe used 600
# on horns' 60-minute restarts): does removing a restart's kick mend the narrow lens's cameras?
cd /work/runs/s23
H=/work/runs/s23/hashcc; export OMP_NUM_THREADS=1
one() { $H train --data zoo/$1 --out zooexifwarm10k/$1_s0 --seed 0 --threads 1 --steps 10000 --no-progress --rays 256 --focal $2 --set 2-5.camera_warmup=100 > zooexifwarm10k/$1_s0.train.out 2>&1 &&
        $H eval --run zooexifwarm10k/$1_s0 --test-init sim3 --refine-epochs 1000 --threads 1 --no-progress > zooexifwarm10k/$1_s0.eval.out 2>&1; echo "$1 done $(date +%T)"; }
mkdir -p zooexifwarm10k
one narrow 87.919 & one wide 32.0 & wait
