#!/bin/bash
# The tilt experiment (issue 49, session 16): does the photos' fit see horns' depth tilt?
# A fresh grid field, 1,500 steps at 1 thread, on FIXED cameras:
#   (a) candidate 1's learned horns cameras (seed 0: ../cand1/horns_s0/cameras.json),
#   (b) the same rotations with the reference centres mapped into their frame
#       (make_cameras.py ../cand1/horns_s0 . writes both camera files),
#   (c) the reference cameras (poses_bounds.npy).
# Run as it was (binary of c75188a): HASHCC=build/hashcc DATA=../shared/data/llff/horns bash run.sh
H=${HASHCC:-hashcc}
D=${DATA:-../shared/data/llff/horns}
common="--data $D --field grid --model sh --grid-density-init 2 --lr-net 2e-2 --lr-net-end 1e-3 --c2f 0 --refine-poses off --steps 1500 --threads 1 --seed 0 --no-progress"
for v in a:cameras_a_learned.json b:cameras_b_learned_rotations_reference_centres.json c:$D/poses_bounds.npy; do
  n=${v%%:*}; f=${v#*:}
  $H train --out $n --init-poses $f $common > $n.log 2>&1
done
