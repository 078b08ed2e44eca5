#!/bin/bash
# After horns_s0's hour: pause its eval (SIGSTOP) so the variant runs on a quiet machine (2 threads),
# the variant = the recipe's stages 2-5 from horns_s0's own stage 1, each restart's camera lr ramped
# over its first 600 steps (restarts_warmup.json); same budgets as the control's stages 2-5 (5/5/5/30 min).
cd /work/runs/s20
until grep -q "horns_s0 trained" horns_s0.q.log; do sleep 5; done
sleep 3
E=$(pgrep -f "eval --run horns_s0"); [ -n "$E" ] && kill -STOP $E
echo "paused horns_s0 eval ($E) $(date +%T)"
H=/work/runs/s20/hashcc; export OMP_NUM_THREADS=2
echo "hW_s0 start $(date +%T)"
$H train --data /work/shared/data/llff/horns --out hW_s0 --plan restarts_warmup.json \
  --cameras-from /work/runs/s20/horns_s0/stage1 --minutes 45 --threads 2 --seed 0 --no-progress > hW_s0.train.out 2>&1
echo "hW_s0 trained $(date +%T)"
[ -n "$E" ] && kill -CONT $E && echo "resumed horns_s0 eval $(date +%T)"
$H eval --run hW_s0 --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > hW_s0.eval.out 2>&1
echo "hW_s0 done $(date +%T)"
