#!/bin/bash
# The same as run.sh with the NDC box held at the reference focal 421.1 for every F
# (--ndc-fixed-focal --ndc-box-scale 421.1/F): only the rays' focal differs between the runs.
B=/work/runs/s18/hashcc_box
D=/work/shared/data/llff/${SCENE:-horns}
for F in $FOCALS; do
  S=$(/usr/bin/python3 -c "print(${BOX:-421.103}/$F)")
  OMP_NUM_THREADS=1 $B train --data $D --out ${SCENE:-horns}_box${BOX:-}_f$F --steps ${STEPS:-2000} --threads 1 --seed 1 \
    --field grid --grid-density-init 2 --lr-pose 3e-3 --lr-net 2e-2 --lr-net-end 1e-3 --pose-precondition 0.1 \
    --init-poses $D/poses_bounds.npy --init-focal none --focal $F --fixed-focal --no-progress \
    --ndc-fixed-focal --ndc-box-scale $S > ${SCENE:-horns}_box${BOX:-}_f$F.out 2>&1
done
