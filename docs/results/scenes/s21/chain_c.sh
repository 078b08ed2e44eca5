#!/bin/bash
# session 21: when the gate file appears (build window over, horns_s1's eval done), a 20-second
# speed probe of the machine (the grid step at 2 threads, same binary), then fern_s0's quiet hour.
cd /work/runs/s21
until [ -e go_fern_s0 ]; do sleep 5; done
echo "probe $(date +%T)"
./hashcc bench --variant sh+grid --threads 2 --seconds 20 --json probe_before_fern_s0.json > probe_before_fern_s0.txt 2>&1
./hour.sh fern_s0 fern 0
