#!/bin/bash
# session 23: the training views' fit against the lens on the real scenes: the forward recipe's stage 1
# alone (5,000 steps, 1 thread, seed 0) with the focal fixed at five fields of view
# (fern's reference 63.5 deg, horns' 61.8 deg). Two runs side by side.
cd /work/runs/s23
export OMP_NUM_THREADS=1
for scene in horns fern; do for f in 40 55 63 70 90; do
  echo "$scene $f"
done; done | xargs -P 2 -n 2 sh -c 'd=lens/$0_f$1; [ -f $d/camera_error.csv ] && grep -q "^5000," $d/camera_error.csv && exit 0;
  ./hashcc train --data /work/shared/data/llff/$0 --out $d --plan /work/runs/s23/s1_fixed.json --set focal_fov=$1 --steps 5000 --threads 1 --seed 0 --no-progress > $d.train.out 2>&1; echo "$d done $(date +%T)"'
