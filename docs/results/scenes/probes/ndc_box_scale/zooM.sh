#!/bin/bash
# PROBE (scratch patch ndc_box_scale_probe.patch, not in the code): the NDC box drawn with 0.8x the
# stage's starting focal (a box 25% wider than the start's frustum), --ndc-fixed-focal otherwise.
cd /work/runs/s17
run() { HASHCC_NDC_BOX_SCALE=0.8 ./hashcc_boxprobe train --data /work/runs/zoo64/$1 --out zooM/$1 --steps 2500 --rays 256 --threads 1 --seed 0 --ndc-fixed-focal --no-progress > zooM/$1.log 2>&1; }
run lookat & run plain & wait
run sweep & run few & wait
run shiny & run deep & wait
