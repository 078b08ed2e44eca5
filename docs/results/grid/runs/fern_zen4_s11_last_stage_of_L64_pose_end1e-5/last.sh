#!/usr/bin/env bash
# last NAME [extra flags]: the last stage of session 9's L64 run (fern60 --model sh --last-samples 64)
# again from its stage 4's cameras, 40.99 minutes as there, 1 thread; then the spec's eval.
set -u
N=$1; shift
B=/work/exp/s11/hashcc
R=/work/exp/s11/$N
C="--data /work/shared/data/llff/fern --images images_8 --model sh --field grid --grid-density-init 2 --lr-pose 3e-3 --lr-net 2e-2 --lr-net-end 1e-3 --threads 1 --c2f 0"
$B train $C --minutes 40.99 --cameras-from /work/exp/s9/L64/stage4 --fx-only --focal-delay 0.1 --grid-log2-table 17 --samples 64 --out $R "$@" > $R.train.log 2>&1
$B eval --run $R --test-init sim3 --refine-epochs 1000 --threads 1 > $R.eval1000.log 2>&1
cp $R/eval/metrics.json $R/metrics_sim3_1000.json
echo done $N
