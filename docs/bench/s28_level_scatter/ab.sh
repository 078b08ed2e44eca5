#!/usr/bin/env bash
# Session 28 A/B #2: old = main d4803d4, new = 983d123 (level scatter, vectorised guard and Adam)
set -u
cd /work/main
OLD=/work/runs/s28/hashcc; NEW=/work/runs/s28/hashcc_983d123
ROUNDS=9 STEPS=60 VARIANT=sh+grid THREADS=2 tools/bench_ab.sh /work/runs/s28/ab/r2_t2.txt "before=$OLD" "after=$NEW" > /dev/null 2>&1
ROUNDS=7 STEPS=40 VARIANT=sh+grid THREADS=1 tools/bench_ab.sh /work/runs/s28/ab/r2_t1.txt "before=$OLD" "after=$NEW" > /dev/null 2>&1
