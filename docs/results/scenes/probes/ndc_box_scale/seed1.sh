#!/bin/bash
# Seed 1 of the zoo for the three boxes: A the default (learned box), B --ndc-fixed-focal,
# M the scratch probe (box 0.8x the start focal). 64x48, 2,500 steps, 256 rays, 1 thread.
cd /work/runs/s17
r() { v=$1; s=$2; case $v in
  A) ./hashcc_bc59211 train --data /work/runs/zoo64/$s --out seed1/${v}_$s --steps 2500 --rays 256 --threads 1 --seed 1 --no-progress > seed1/${v}_$s.log 2>&1;;
  B) ./hashcc_bc59211 train --data /work/runs/zoo64/$s --out seed1/${v}_$s --steps 2500 --rays 256 --threads 1 --seed 1 --ndc-fixed-focal --no-progress > seed1/${v}_$s.log 2>&1;;
  M) HASHCC_NDC_BOX_SCALE=0.8 ./hashcc_boxprobe train --data /work/runs/zoo64/$s --out seed1/${v}_$s --steps 2500 --rays 256 --threads 1 --seed 1 --ndc-fixed-focal --no-progress > seed1/${v}_$s.log 2>&1;;
  esac; }
for s in lookat plain few deep sweep shiny; do
  r A $s & r B $s & r M $s & wait
done
