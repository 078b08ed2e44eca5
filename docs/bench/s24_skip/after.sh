#!/bin/bash
# session 24: after the horns hour (hour.sh) ends, on the quiet machine: the empty-space skip's
# measurement (hashcc bench --render --skip-sigma) on fern_s1 (session 22's hour) and on the new
# horns_s0 hour, 2 threads, 3 frames.
cd /work/runs/s24
while pgrep -f "hour.sh" > /dev/null; do sleep 15; done
sleep 20
H=/work/runs/s24/hashcc_skip
echo "start $(date +%T), load $(cat /proc/loadavg)"
$H bench --render --run q53/fern_s1 --threads 2 --frames 3 --skip-sigma 0.1 --skip-sigma 1 --skip-sigma 4 > skip_fern_s1.txt 2>&1
echo "fern done $(date +%T), load $(cat /proc/loadavg)"
$H bench --render --run horns_s0 --threads 2 --frames 3 --skip-sigma 0.1 --skip-sigma 1 --skip-sigma 4 > skip_horns_s0.txt 2>&1
echo "horns done $(date +%T), load $(cat /proc/loadavg)"
