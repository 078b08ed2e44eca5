#!/usr/bin/env python3
"""The focal profile's table: for each run folder given, the focal of the rays (fx), the focal the
NDC box is drawn with, the train PSNR averaged over steps 1,501-2,000 of log.csv(.gz), and the
cameras' error at the end (camera_error.csv). usage: table.py RUN...
"""
import csv, gzip, io, json, os, sys
for run in sys.argv[1:]:
    cfg = json.load(open(os.path.join(run, 'config.json')))
    p = os.path.join(run, 'log.csv')
    text = open(p).read() if os.path.exists(p) else gzip.open(p + '.gz', 'rt').read()
    rows = list(csv.DictReader(io.StringIO(text)))
    tail = [float(r['psnr']) for r in rows if 1500 < int(r['step']) <= 2000]
    err = list(csv.DictReader(open(os.path.join(run, 'camera_error.csv'))))[-1]
    fx = float(err['fx'])
    box = fx * cfg.get('ndc_box_scale', 1) if cfg.get('ndc_fixed_focal') else fx
    print(f"| {os.path.basename(run.rstrip('/'))} | {fx:.0f} | {box:.0f} | {sum(tail)/len(tail):.3f} "
          f"| {float(err['rel_rot_deg']):.2f} | {float(err['sim3_dR_deg']):.2f} |")
