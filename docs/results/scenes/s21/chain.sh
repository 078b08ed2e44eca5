#!/bin/bash
# session 21: the remaining quiet 2-thread hours of issue 49 (default command), one after another.
# hour.sh is ../s20/hour.sh with its `cd` made /work/runs/s21 (the one line that differs).
# This chain was stopped after horns_s1 started (its hour.sh ran on); fern_s0 ran from chain_c.sh.
cd /work/runs/s21
./hour.sh horns_s1 horns 1
./hour.sh fern_s0 fern 0
./hour.sh fern_s1 fern 1
