#!/bin/sh
# fast mode (mean or trend over epochs 600-999) on every validation run (session 25)
cd /work/runs/s25
B=./hashcc_hyb
for run in /work/runs/s24/horns_s0 fern_s1 pA_recipe zrun/plain zrun/sweep zrun/wide zrun/lookat horns_8k; do
  tag=$(basename $run); case $run in zrun/*) tag=zrun_$tag;; esac
  data=""
  case $run in zrun/*) data="--data /work/runs/s22/zoo/${run#zrun/}";; esac
  /usr/bin/time -v $B eval --run $run $data --test-init sim3 --refine-epochs 1000 --refine-mode fast --threads 2 --no-progress > val3_${tag}.out 2> val3_${tag}.time
  cp $run/eval/metrics.json val3_${tag}_metrics.json
  cp $run/eval/refine.csv val3_${tag}_refine.csv
done
echo done > val3.done
