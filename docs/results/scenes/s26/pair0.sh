#!/usr/bin/env bash
# Issue 49, session 26: the resolution pair again with seed 0 (as pair.sh).
H=./hashcc
D=/work/shared/data/llff/fern
$H train --data $D --out f8_s0 --minutes 60 --threads 1 --seed 0 --no-progress > f8_s0.out 2>&1 &
$H train --data $D --images images_4 --max-side 1008 --out f4_s0 --minutes 60 --threads 1 --seed 0 --no-progress > f4_s0.out 2>&1 &
wait
