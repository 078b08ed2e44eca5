#!/usr/bin/env python3
"""Session 23: the real scenes' fit against a fixed lens (stage 1 alone, 5,000 steps, 1 thread).
One row a run: the train PSNR averaged over the last 500 steps, and the cameras at step 5,000."""
import csv, glob, gzip, math, os, sys
root = sys.argv[1] if len(sys.argv) > 1 else "lens"
print("| scene | FOV ° (focal px) | reference focal px | train PSNR, last 500 steps | rel. rot. ° | Sim(3) ΔR ° |")
print("|---|---|---|---|---|---|")
for d in sorted([g for g in glob.glob(os.path.join(root, "*_f*")) if os.path.isdir(g)], key=lambda d: (d.split("/")[-1].split("_f")[0], int(d.split("_f")[-1]))):
    if not os.path.isdir(d): continue
    lp = os.path.join(d, "log.csv")
    opener = open
    if not os.path.isfile(lp): lp += ".gz"; opener = lambda p: gzip.open(p, "rt")
    if not os.path.isfile(lp): continue
    rows = list(csv.DictReader(opener(lp)))
    if int(rows[-1]["step"]) < 5000: continue
    ps = [float(r["psnr"]) for r in rows if int(r["step"]) > 4500]
    cam = list(csv.DictReader(open(os.path.join(d, "camera_error.csv"))))[-1]
    scene, fov = os.path.basename(d).split("_f")
    print(f"| {scene} | {fov} ({float(cam['fx']):.1f}) | {float(cam['ref_focal']):.1f} | {sum(ps)/len(ps):.3f} | "
          f"{float(cam['rel_rot_deg']):.2f} | {float(cam['sim3_dR_deg']):.2f} |")
