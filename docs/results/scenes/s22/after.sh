#!/bin/bash
# session 22: once fern_s1 has trained (its eval runs on), the step-budgeted probes and the zoo (load-independent)
cd /work/runs/s22
until grep -q "fern_s1 trained" chain.log; do sleep 10; done
./probe_last.sh > probe_last.log 2>&1 &
./probe_fixed.sh > probe_fixed.log 2>&1 &
./zoo.sh > zoo.log 2>&1 &
wait
