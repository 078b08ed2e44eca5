#!/usr/bin/env bash
# Session 27 probe: is the late-training fit a lens search? From a 10k-step zoo run's final
# cameras, one restart-like stage (probe1.json) with the focal HELD at a value, poses learning;
# compare train PSNR (mean of the last 1000 steps) and camera errors across held focals.
set -u
S=/work/runs/s27
cd /work/runs/s22
run() { # scene focal
  local out=$S/p1/$1_f$2
  [[ -f $out/cameras.json ]] && return 0
  $S/hashcc train --data zoo/$1 --out $out --plan $S/probe1.json --init-poses zoo10k/$1_s0/cameras.json \
    --init-focal none --focal $2 --fixed-focal --steps 3000 --threads 1 --rays 256 --seed 0 --no-progress > $out.out 2>&1
}
mkdir -p $S/p1
run narrow 58.5; run narrow 88; run narrow 72
run wide 37.6; run wide 32; run wide 34.5
run plain 49.6; run plain 44.6; run plain 54.6
