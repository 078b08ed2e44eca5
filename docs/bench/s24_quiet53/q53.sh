#!/bin/bash
# session 24, issue 53 after the hash-grid kernel change (5459cd3): every quiet timing again, nothing
# else running. 1) tools/bench_grid_quiet.sh (torch peer + roofline), 2) one 504x378 frame of fern
# seed 1's 60-minute run, 3) the fast evaluation of fern_s1 and of horns_8k (session 23's runs, copied).
cd /work/runs/s24
H=/work/runs/s24/hashcc
while awk '{exit !($1 >= 0.25)}' /proc/loadavg; do sleep 10; done
echo "start $(date +%T), load $(cat /proc/loadavg)"
(cd /work/main && tools/bench_grid_quiet.sh $H docs/bench/grid_quiet_s24) > q53/grid_quiet.log 2>&1
echo "grid quiet done $(date +%T), load $(cat /proc/loadavg)"
sleep 20
$H bench --render --run q53/fern_s1 --threads 1 --threads 2 --frames 1 > q53/render.txt 2>&1
echo "render done $(date +%T), load $(cat /proc/loadavg)"
/usr/bin/time -v $H eval --run q53/horns_8k --test-init sim3 --refine-epochs 1000 --refine-mode fast --threads 2 --no-progress > q53/horns_eval_fast.out 2> q53/horns_eval_fast.time
cp q53/horns_8k/eval/metrics.json q53/horns_eval_fast_metrics.json
echo "horns eval fast done $(date +%T), load $(cat /proc/loadavg)"
/usr/bin/time -v $H eval --run q53/fern_s1 --test-init sim3 --refine-epochs 1000 --refine-mode fast --threads 2 --no-progress > q53/eval_fast.out 2> q53/eval_fast.time
cp q53/fern_s1/eval/metrics.json q53/eval_fast_metrics.json
echo "fern eval fast done $(date +%T), load $(cat /proc/loadavg)"
