#!/bin/bash
# session 23, issue 53 on a quiet machine (nothing else running): one 504x378 frame of fern seed 1's
# 60-minute grid-field run (2^17 table) at 32 and 64 samples, 1 and 2 threads, exact and with the
# shortcuts; then the evaluation in its fast mode and in the spec's, at 2 threads, each timed.
cd /work/runs/s23
H=/work/runs/s23/hashcc
while pgrep -f "lens_real.sh|zoo_exif.sh" > /dev/null; do sleep 10; done
sleep 30; echo "load before: $(cat /proc/loadavg)"
$H bench --render --run q53/fern_s1 --threads 1 --threads 2 --frames 1 > q53/render.txt 2>&1
echo "render done $(date +%T), load $(cat /proc/loadavg)"
/usr/bin/time -v $H eval --run q53/fern_s1 --test-init sim3 --refine-epochs 1000 --refine-mode fast --threads 2 --no-progress > q53/eval_fast.out 2> q53/eval_fast.time
cp q53/fern_s1/eval/metrics.json q53/eval_fast_metrics.json
echo "eval fast done $(date +%T), load $(cat /proc/loadavg)"
/usr/bin/time -v $H eval --run q53/fern_s1 --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > q53/eval_adam.out 2> q53/eval_adam.time
cp q53/fern_s1/eval/metrics.json q53/eval_adam_metrics.json
echo "eval adam done $(date +%T), load $(cat /proc/loadavg)"
