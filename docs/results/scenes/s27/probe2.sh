#!/usr/bin/env bash
# Session 27 probe 2: the held-focal fit late in training on the real scenes. From a quiet hour's
# final cameras (fern_s1 of session 22: focal +5.0%; horns_s0 of session 24: -0.7%), one
# restart-like stage (probe1.json: fresh field, all levels, poses learning) with the focal HELD;
# compare the train PSNR (mean of steps 1000-2000) across held focals.
set -u
S=/work/runs/s27
cd $S
run() { # name runsrc data focal
  local out=$S/p2/$1_f$4
  [[ -f $out/cameras.json ]] && return 0
  ./hashcc train --data $3 --out $out --plan probe1.json --init-poses $2/cameras.json \
    --init-focal none --focal $4 --fixed-focal --steps 2000 --threads 1 --seed 0 --no-progress > $out.out 2>&1
}
mkdir -p p2
while pgrep -f ev.sh > /dev/null; do sleep 20; done
F=/work/runs/s22/fern_s1; H=/work/runs/s24/horns_s0
run fern $F /work/shared/data/llff/fern 428.1
run fern $F /work/shared/data/llff/fern 372.5
run fern $F /work/shared/data/llff/fern 492.3
run horns $H /work/shared/data/llff/horns 418.3
run horns $H /work/shared/data/llff/horns 363.9
run horns $H /work/shared/data/llff/horns 481.0
run fern $F /work/shared/data/llff/fern 407.6
run horns $H /work/shared/data/llff/horns 421.1
