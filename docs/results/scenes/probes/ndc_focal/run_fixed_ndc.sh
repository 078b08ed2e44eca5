#!/bin/bash
# EXPERIMENT: the NDC box's focal fixed at the stage's starting focal (HASHCC_NDC_FIXED=1), so the
# focal's gradient comes from the ray directions alone (binary built from a scratch patch, not committed)
H=/work/runs/fbias/hashcc_ndcfix
D=/work/runs/zoo64/plain
HASHCC_NDC_FIXED=1 $H train --data $D --out ndcfix_truth --focal 51.2 --steps 2500 --rays 256 --threads 1 --seed 0 --no-progress > ndcfix_truth.log 2>&1
HASHCC_NDC_FIXED=1 $H train --data $D --out ndcfix_prior --steps 2500 --rays 256 --threads 1 --seed 0 --no-progress > ndcfix_prior.log 2>&1
HASHCC_NDC_FIXED=1 $H train --data /work/runs/zoo64/wide --out ndcfix_wide --steps 2500 --rays 256 --threads 1 --seed 0 --no-progress > ndcfix_wide.log 2>&1
