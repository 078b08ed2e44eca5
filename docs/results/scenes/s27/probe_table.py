#!/usr/bin/env python3
"""Session 27 probes (usage: probe_table.py p1 | p2; reads log.csv or log.csv.gz): per run folder, the held focal, the reference, the mean train PSNR of the
last half of the steps, and the final camera errors (camera_error.csv's last row)."""
import csv, glob, gzip, os, sys
rows = []
for d in sorted(glob.glob(sys.argv[1] + '/*/')):
    f = d + 'log.csv'
    log = list(csv.DictReader(open(f) if os.path.exists(f) else gzip.open(f + '.gz', 'rt')))
    last = int(log[-1]['step'])
    half = [float(r['psnr']) for r in log if int(r['step']) > last // 2]
    ce = list(csv.DictReader(open(d + 'camera_error.csv')))[-1]
    f, ref = float(ce['fx']), float(ce['ref_focal'])
    rows.append((os.path.basename(d.rstrip('/')), f, ref, 100 * (f / ref - 1), sum(half) / len(half), len(half),
                 float(ce['rel_rot_deg']), float(ce['sim3_dR_deg'])))
print('| run | held focal | reference | focal err. % | train PSNR, mean of the last half of the steps | rel. rot. ° | Sim(3) ΔR ° |')
print('|---|---|---|---|---|---|---|')
for r in rows:
    print(f'| {r[0]} | {r[1]:.1f} | {r[2]:.1f} | {r[3]:+.1f} | {r[4]:.3f} ({r[5]} steps) | {r[6]:.2f} | {r[7]:.2f} |')
