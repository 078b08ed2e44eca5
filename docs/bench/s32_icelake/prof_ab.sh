#!/bin/bash
# Session 32: eval's refinement step profile (HASHCC_REFINE_PROFILE=1, 20 epochs of horns seed 0's hour, 2 threads), before / after, alternated.
cd /tmp/s32
for r in 1 2 3; do for b in /work/runs/s31/hashcc3 /work/runs/s32/hashcc_final; do
  rm -rf hp/eval
  HASHCC_REFINE_PROFILE=1 $b eval --run hp --test-init sim3 --refine-epochs 20 --threads 2 --no-progress > pa.out 2> pa.err
  echo "$(basename $b) round $r: $(grep -o 'refine profile.*' pa.err) | $(grep -o 'PSNR [0-9.]*  SSIM [0-9.]*' pa.out | head -1)"
done; done
