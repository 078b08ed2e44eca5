#!/usr/bin/env bash
# Session 26 (issue 49): the focal gauge of every scene of the table, and at the focal errors the
# runs ended with. ZOO = tools/make_zoo.sh ZOO 128 96 (the zoo10k runs trained its scenes at 64×48:
# --image-width 64 states their pixels). Each command is one row of docs/results/scenes/README.md.
set -e
G="python3 tools/focal_gauge.py"
L=../shared/data/llff
ZOO=${ZOO:-/tmp/zoo}
export OPENBLAS_NUM_THREADS=1
OUT=docs/results/scenes/s26/gauge
$G --eps=-10,-3,1,3,5,10,20 --iters 100 $L/fern $L/horns $ZOO/{plain,lookat,sweep,wide,narrow,deep,few} > $OUT/all.md
$G --eps=3,10 --iters 40 --points-per-view 24 --seed 1 $L/fern $L/horns $ZOO/narrow $ZOO/wide > $OUT/seed1_24.md
$G --eps=-33,-20,17.5,20 --iters 60 $ZOO/narrow $ZOO/wide > $OUT/far.md
$G --k1 0.0198 --eps=-20,-15,-10,-7,-5,-3,-2,0,1,2,3,4,5,6,8,10 --iters 40 $L/fern > $OUT/fern_k1.md
# At the runs' own focal errors (the quiet hours at 504 px; zoo10k at 64 px):
$G --eps=5.0,5.2 --iters 60 $L/fern > $OUT/runs_fern.md
$G --eps=-0.3,-0.7,-3.5 --iters 60 $L/horns > $OUT/runs_horns.md
for s in plain:-1.2 lookat:-3.7 deep:-0.9 few:-0.9 sweep:-5.7 wide:17.5 narrow:-33.4; do
  $G --image-width 64 --eps=${s#*:} --iters 60 $ZOO/${s%:*}
done > $OUT/runs_zoo64.md
