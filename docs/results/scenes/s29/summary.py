#!/usr/bin/env python3
"""summary.py RUN: one row a stage (steps, Sim(3) dR, relative rotation, focal at the stage's end,
from each stage's camera_error.csv and log) and the eval's metrics, as a markdown table."""
import csv, gzip, json, os, sys
run = sys.argv[1]
ref = None
rows = []
stages = sorted(d for d in os.listdir(run) if d.startswith("stage")) + ["."]
for i, st in enumerate(stages, 1):
    ce = os.path.join(run, st, "camera_error.csv")
    if not os.path.exists(ce):
        continue
    r = list(csv.DictReader(open(ce)))[-1]
    ref = r["ref_focal"]
    rows.append(f"| {i} | {r['step']} | {float(r['sim3_dR_deg']):.2f} | {float(r['rel_rot_deg']):.2f} | "
                f"{float(r['fx']):.1f} ({100 * (float(r['fx']) / float(r['ref_focal']) - 1):+.1f}%) |")
print("| stage end | steps | Sim(3) ΔR ° | rel. rot. ° | focal (reference " + f"{float(ref):.1f}) |")
print("|---|---|---|---|---|")
print("\n".join(rows))
m = os.path.join(run, "eval", "metrics.json")
if os.path.exists(m):
    d = json.load(open(m))
    print(f"\neval ({d.get('refine_mode')} refinement, {d.get('refine_epochs')} epochs, test init "
          f"{d.get('test_init')}): test PSNR {d['psnr']:.2f} dB, SSIM {d['ssim']:.3f}, Sim(3) ΔR "
          f"{d['rot_err_deg']:.2f}°, relative rotation {d['rel_rot_err_deg']:.2f}° (do-nothing "
          f"{d['rel_rot_do_nothing_deg']:.2f}°), eval {d.get('seconds', 0):.0f} s")
