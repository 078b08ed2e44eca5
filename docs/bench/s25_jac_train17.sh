#!/bin/bash
# A/B of the training step on the default plan's last-stage field (2^17 table, 64 samples), horns, 1 and 2 threads
for T in 1 2; do
for r in 1 2 3; do
for b in before s25; do
  rm -rf /tmp/ab17_$b
  s=$( { /usr/bin/time -f "%e %U" /work/runs/s25/hashcc_$b train --data /work/shared/data/llff/horns --field grid --grid-log2-table 17 --samples 64 --steps 80 --threads $T --out /tmp/ab17_$b --no-progress > /tmp/ab17_$b.out; } 2>&1 | tail -1)
  fin=$(grep -o "in [0-9.]* s" /tmp/ab17_$b.out | head -1)
  echo "T=$T round $r $b wall/user $s train $fin"
done; done; done
