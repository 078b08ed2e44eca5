#!/bin/sh
# session 25: the final fast mode's wall time on horns_s0, twice more, quiet, 2 threads
cd /work/runs/s25
for r in 1 2; do
  /usr/bin/time -v ./hashcc_final eval --run /work/runs/s24/horns_s0 --test-init sim3 --refine-epochs 1000 --refine-mode fast --threads 2 --no-progress > tf_horns_s0_$r.out 2> tf_horns_s0_$r.time
  cp /work/runs/s24/horns_s0/eval/metrics.json tf_horns_s0_${r}_metrics.json
done
echo done > tf.done
