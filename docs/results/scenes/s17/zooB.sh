#!/bin/bash
# The zoo (64x48, tools/make_zoo.sh) with the default command + --ndc-fixed-focal; the default's own
# runs are docs/results/scenes/zoo_default64 (same binary path bitwise for the learned box).
cd /work/runs/s17
for s in plain lookat deep sweep few shiny wide narrow; do
  ./hashcc_1053a09 train --data /work/runs/zoo64/$s --out zooB/$s --steps 2500 --rays 256 --threads 1 --seed 0 --ndc-fixed-focal --no-progress > zooB/$s.log 2>&1
done
