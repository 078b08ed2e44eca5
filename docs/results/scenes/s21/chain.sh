#!/bin/bash
# session 21: the remaining quiet 2-thread hours of issue 49 (default command), one after another
cd /work/runs/s21
./hour.sh horns_s1 horns 1
./hour.sh fern_s0 fern 0
./hour.sh fern_s1 fern 1
