#!/usr/bin/env bash
# run60 NAME [extra flags]: the 60-minute fern recipe (--preset fern60 --model sh), 1 thread, then the spec's eval
set -u
N=$1; shift
F=/work/shared/data/llff/fern
B=${B:-/work/exp/s11/hashcc}
R=/work/exp/s11/$N
$B train --data $F --images images_8 --out $R --preset fern60 --model sh --threads 1 --minutes 60 "$@" > $R.train.log 2>&1
$B eval --run $R --test-init sim3 --refine-epochs 1000 --threads 1 > $R.eval1000.log 2>&1
cp $R/eval/metrics.json $R/metrics_sim3_1000.json
echo done $N
