#!/bin/bash
# Session 31: paired render bench and horns eval, the build before (s30, 55e2f65) and after (s31).
cd /work/runs/s31
OLD=/work/runs/s30/hashcc NEW=/work/runs/s31/hashcc2
for i in 1 2; do
  for v in old new; do B=$OLD; [ $v = new ] && B=$NEW
    echo "== render bench $v round $i $(date -u +%H:%M:%S) load $(cut -d' ' -f1-3 /proc/loadavg)"
    $B bench --render --run horns_$v --threads 2 --frames 3 2>&1 | tail -n 12
  done
done
for v in old new; do B=$OLD; [ $v = new ] && B=$NEW
  echo "== eval $v $(date -u +%H:%M:%S) load $(cut -d' ' -f1-3 /proc/loadavg)"
  /usr/bin/time -v $B eval --run horns_$v --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > eval_$v.out 2> eval_$v.time
  head -3 eval_$v.out; grep -E "Elapsed|User time" eval_$v.time
done
echo "== done $(date -u +%H:%M:%S)"
