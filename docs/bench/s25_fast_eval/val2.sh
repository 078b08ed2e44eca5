#!/bin/sh
# fast mode validation, part 2 (session 25): more runs, after val.sh
cd /work/runs/s25
while [ ! -f val.done ]; do sleep 5; done
B=./hashcc_avg
for run in pA_recipe zrun/plain zrun/sweep zrun/wide zrun/lookat; do
  tag=$(echo $run | tr / _)
  data=""
  case $run in zrun/*) data="--data /work/runs/s22/zoo/${run#zrun/}";; esac
  for mode in spec fast128 fast64; do
    case $mode in
      spec) args="";;
      fast128) args="--refine-mode fast";;
      fast64) args="--refine-mode fast --refine-rays 64";;
    esac
    /usr/bin/time -v $B eval --run $run $data --test-init sim3 --refine-epochs 1000 $args --threads 2 --no-progress > val_${tag}_$mode.out 2> val_${tag}_$mode.time
    cp $run/eval/metrics.json val_${tag}_${mode}_metrics.json
    cp $run/eval/refine.csv val_${tag}_${mode}_refine.csv
  done
done
echo done > val2.done
