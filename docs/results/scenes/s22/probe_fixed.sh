#!/bin/bash
# session 22 probe: as probe_last.sh's A (the recipe's last stage from fern_s1's stage-4 cameras, 6,000 steps,
# 1 thread), the focal held where stage 4 left it: does the training views' fit prefer the climbed focal?
cd /work/runs/s22
H=/work/runs/s22/hashcc; export OMP_NUM_THREADS=1
$H train --data /work/shared/data/llff/fern --out pF_focal_held --plan last_stage.json \
  --cameras-from /work/runs/s22/fern_s1/stage4 --threads 1 --seed 1 --no-progress --set 1.fixed_focal=true > pF_focal_held.train.out 2>&1
echo "pF_focal_held done $(date +%T)"
