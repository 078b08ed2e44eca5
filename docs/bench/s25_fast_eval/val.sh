#!/bin/sh
# fast mode validation (session 25): spec (adam) vs fast with averaging at 128 and 64 rays, jac binary
cd /work/runs/s25
B=./hashcc_avg
for run in fern_s1 horns_8k; do
  for mode in spec fast128 fast64; do
    case $mode in
      spec) args="";;
      fast128) args="--refine-mode fast";;
      fast64) args="--refine-mode fast --refine-rays 64";;
    esac
    /usr/bin/time -v $B eval --run $run --test-init sim3 --refine-epochs 1000 $args --threads 2 --no-progress > val_${run}_$mode.out 2> val_${run}_$mode.time
    cp $run/eval/metrics.json val_${run}_${mode}_metrics.json
    cp $run/eval/refine.csv val_${run}_${mode}_refine.csv
  done
done
echo done > val.done
