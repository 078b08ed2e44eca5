#!/usr/bin/env bash
# Session 27: eval's default fast mode with the spec fallback for still-moving views, on the runs
# of docs/bench/s25_fast_eval (copies in ev/). Binary: hashcc_fb (main 0655cad + the fallback).
set -u
cd /work/runs/s27
ev() { # name [data]
  local n=$1; shift
  /usr/bin/time -v ./hashcc_fb eval --run ev/$n "$@" --test-init sim3 --refine-epochs 1000 --threads 2 --no-progress > ev/$n.eval.out 2> ev/$n.eval.time
  cp ev/$n/eval/metrics.json ev/$n.metrics.json
}
ev wide_s0 --data /work/runs/s22/zoo/wide
ev lookat_s0 --data /work/runs/s22/zoo/lookat
ev plain_s0 --data /work/runs/s22/zoo/plain
ev sweep_s0 --data /work/runs/s22/zoo/sweep
ev fern_s1
ev horns_s0
ev horns_8k
