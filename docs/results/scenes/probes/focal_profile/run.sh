#!/bin/bash
# Does horns' photo fit see the focal when the cameras start right? The reference cameras
# (poses_bounds.npy) refined jointly with a grid field, the focal FIXED at F; train PSNR at the end.
B=/work/runs/s18/hashcc
D=/work/shared/data/llff/${SCENE:-horns}
for F in $FOCALS; do
  OMP_NUM_THREADS=1 $B train --data $D --out ${SCENE:-horns}_f$F --steps ${STEPS:-2000} --threads 1 --seed 1 \
    --field grid --grid-density-init 2 --lr-pose 3e-3 --lr-net 2e-2 --lr-net-end 1e-3 --pose-precondition 0.1 \
    --init-poses $D/poses_bounds.npy --init-focal none --focal $F --fixed-focal --no-progress > ${SCENE:-horns}_f$F.out 2>&1
done
