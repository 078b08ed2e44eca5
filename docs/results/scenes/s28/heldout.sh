#!/usr/bin/env bash
# Session 28: held-out test views' PSNR (eval, default fast refinement, Sim(3) start) of session 27's
# held-focal probes (p2): does the held-out fit peak at the reference lens where the train fit does not?
set -u
cd /work/runs/s28
# Run order below; stopped after horns_f481.0 and fern_f372.5 (the horns probes sit at Sim(3) 16-17 deg:
# their test views start 10+ deg off, so their test PSNR says nothing about the lens); fern_f428.1 was
# then evaluated alone with the same command.
for r in fern_f407.6 horns_f421.1 fern_f492.3 horns_f481.0 fern_f372.5 horns_f363.9 fern_f428.1 horns_f418.3; do
  d=/work/shared/data/llff/${r%%_*}
  [[ -f /work/runs/s27/p2/$r/eval/metrics.json ]] && continue
  /usr/bin/time -v ./hashcc eval --run /work/runs/s27/p2/$r --data $d --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > ev_$r.out 2> ev_$r.time
done
