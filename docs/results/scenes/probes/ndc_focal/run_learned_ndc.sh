#!/bin/bash
# Is the learned focal biased low? zoo plain (64x48), the default plan, focal started at the truth
H=/work/runs/zoo_default/hashcc_new
D=/work/runs/zoo64/plain
$H train --data $D --out truth --focal 51.2 --steps 2500 --rays 256 --threads 1 --seed 0 --no-progress > truth.log 2>&1
