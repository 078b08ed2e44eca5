#!/usr/bin/env python3
"""Session 23: the zoo at 10,000 steps, focal_try plan against the default plan (zoo10k).
Prints one markdown row a scene: true field of view, the alternatives' fits (train PSNR EMA at the
end of each), the kept one, then focal error, relative-rotation ratio and test PSNR for both plans.
usage: compare_try.py TRY_DIR DEFAULT_DIR (run folders <scene>_s0 with eval/metrics.json)"""
import json, math, os, sys
tdir, ddir = sys.argv[1], sys.argv[2]
def metrics(run):
    p = os.path.join(run, "eval", "metrics.json")
    return json.load(open(p)) if os.path.isfile(p) else None
def summary(m):
    if not m: return "–", "–", "–"
    f = m["focal"]; err = 100 * (f["fx"] / f["reference"] - 1)
    ratio = m["rel_rot_err_deg"] / m["rel_rot_do_nothing_deg"]
    return f"{err:+.1f}%", f"{ratio:.2f}", f"{m['psnr']:.2f}"
print("| scene | true FOV ° | fits at 40 / 55 / 70 / 90° (dB) | kept | focal err. try / default | rel. rot. ratio try / default | test PSNR try / default |")
print("|---|---|---|---|---|---|---|")
for name in sorted(os.listdir(tdir)):
    run = os.path.join(tdir, name)
    if not os.path.isfile(os.path.join(run, "plan.json")): continue
    plan = json.load(open(os.path.join(run, "plan.json")))
    st = plan["stages"][0]
    fits = [t.get("psnr_ema") for t in st["try"]]
    kept = st.get("kept")
    fovs = [t["set"]["focal_fov"] for t in st["try"]]
    ref = None
    m = metrics(run)
    cfg = json.load(open(os.path.join(run, "config.json")))
    W = None
    if m: ref = m["focal"]["reference"]
    fov = "–"
    if ref:
        # the zoo's images are 64 px wide
        fov = f"{2 * math.degrees(math.atan(32 / ref)):.0f}"
    fit_s = " / ".join("–" if v is None else (f"**{v:.2f}**" if i + 1 == kept else f"{v:.2f}") for i, v in enumerate(fits))
    t, d = summary(m), summary(metrics(os.path.join(ddir, name)))
    print(f"| {name[:-3]} | {fov} | {fit_s} | {fovs[kept-1] if kept else '–'}° | {t[0]} / {d[0]} | {t[1]} / {d[1]} | {t[2]} / {d[2]} |")
