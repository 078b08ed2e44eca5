#!/usr/bin/env bash
# Issue 49, session 26: does the focal come nearer with more pixels? fern seed 1, the default
# command, 60 minutes, 1 thread each, side by side: images_8 (504 px) against images_4 (1008 px).
H=./hashcc
D=/work/shared/data/llff/fern
$H train --data $D --out f8_s1 --minutes 60 --threads 1 --seed 1 --no-progress > f8_s1.out 2>&1 &
$H train --data $D --images images_4 --max-side 1008 --out f4_s1 --minutes 60 --threads 1 --seed 1 --no-progress > f4_s1.out 2>&1 &
wait
