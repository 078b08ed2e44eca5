#!/bin/bash
# session 23, issue 53: horns' evaluation time at 2 threads on a quiet machine. No 60-minute horns run is
# on this machine, so a short one with the same last-stage field (the default plan: 2^17 table, 64 samples)
# and the same 8 test views; the evaluation's cost is its refinement steps and renders, not the training's
# length (its PSNR is a short run's, not the table's).
cd /work/runs/s23
H=/work/runs/s23/hashcc; export OMP_NUM_THREADS=2
echo "load before: $(cat /proc/loadavg)"
$H train --data /work/shared/data/llff/horns --out q53/horns_8k --steps 8000 --threads 2 --seed 1 --no-progress > q53/horns_8k.train.out 2>&1
echo "trained $(date +%T), load $(cat /proc/loadavg)"
/usr/bin/time -v $H eval --run q53/horns_8k --test-init sim3 --refine-epochs 1000 --refine-mode fast --threads 2 --no-progress > q53/horns_eval_fast.out 2> q53/horns_eval_fast.time
cp q53/horns_8k/eval/metrics.json q53/horns_eval_fast_metrics.json
echo "eval fast done $(date +%T), load $(cat /proc/loadavg)"
/usr/bin/time -v $H eval --run q53/horns_8k --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > q53/horns_eval_adam.out 2> q53/horns_eval_adam.time
cp q53/horns_8k/eval/metrics.json q53/horns_eval_adam_metrics.json
echo "eval adam done $(date +%T), load $(cat /proc/loadavg)"
