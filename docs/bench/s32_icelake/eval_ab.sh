#!/bin/bash
# Session 32: horns seed 0's eval, main before (s31 hashcc3 = 9b6016b's code) and after keep_mlp in the refinement, alternated.
cd /work/runs/s32
OLD=/work/runs/s31/hashcc3 NEW=/work/runs/s32/hashcc_keep
for i in 1 2; do
  for v in old new; do B=$OLD; [ $v = new ] && B=$NEW
    rm -rf horns_$v/eval
    echo "== eval $v round $i $(date -u +%H:%M:%S) load $(cut -d' ' -f1-3 /proc/loadavg)"
    /usr/bin/time -v $B eval --run horns_$v --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > eval_${v}_$i.out 2> eval_${v}_$i.time
    head -3 eval_${v}_$i.out | tail -2; grep -E "Elapsed|User time" eval_${v}_$i.time
    cp horns_$v/eval/metrics.json metrics_${v}_$i.json
  done
done
echo "== done $(date -u +%H:%M:%S)"
