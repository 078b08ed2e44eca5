#!/usr/bin/env bash
# chain NAME FROM MINUTES_LEFT: fern60's stages 2-5 by hand from the cameras of FROM (a stage 1),
# as an interrupted --restarts prints them; the last stage with 64 samples. Then the 1000-epoch eval.
set -u
N=$1; FROM=$2; LEFT=$3
B=/work/exp/s10/hashcc_new
R=/work/exp/s10/$N
C="--data /work/shared/data/llff/fern --images images_8 --model sh --field grid --grid-density-init 2 --lr-pose 3e-3 --lr-net 2e-2 --lr-net-end 1e-3 --threads 1 --c2f 0"
T0=$(date +%s)
mkdir -p $R
$B train $C --steps 1200 --cameras-from $FROM --out $R/stage2 > $R.stage2.log 2>&1
$B train $C --steps 1200 --cameras-from $R/stage2 --out $R/stage3 > $R.stage3.log 2>&1
$B train $C --steps 1200 --cameras-from $R/stage3 --fx-only --focal-delay 0.1 --out $R/stage4 > $R.stage4.log 2>&1
M=$(python3 -c "import time; print(round($LEFT - (time.time() - $T0)/60, 3))")
echo "last stage minutes $M" > $R.minutes
$B train $C --minutes $M --cameras-from $R/stage4 --fx-only --focal-delay 0.1 --grid-log2-table 17 --samples 64 --out $R/last > $R.train.log 2>&1
$B eval --run $R/last --test-init sim3 --refine-epochs 1000 --threads 1 > $R.eval1000.log 2>&1
cp $R/last/eval/metrics.json $R/last/metrics_sim3_1000.json
echo done $N
