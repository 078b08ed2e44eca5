#!/bin/bash
# session 22: fern seed 1's quiet hour (the machine restarted, session 21's run was lost), after a 20-s speed probe
cd /work/runs/s22
OMP_NUM_THREADS=2 ./hashcc bench --variant sh+grid --threads 2 --seconds 20 --json probe_before_fern_s1.json > probe_before_fern_s1.txt 2>&1
./hour.sh fern_s1 fern 1
