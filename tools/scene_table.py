#!/usr/bin/env python3
"""One table over every scene (tools/bench_scenes.sh writes the runs; this reads them).

    scene_table.py OUT [MORE ...] [--write DIR] [--paper docs/results/scenes/paper_table1.csv]

Each of OUT, MORE is a run folder (it has config.json) or a folder of them (bench_scenes.sh's
OUT/<scene>_s<seed>/). Reads every run folder that has eval/metrics.json (or camera_error.csv):
config.json (scene folder, threads), log.csv or log.csv.gz (steps and seconds trained: the last
row; over every stage of a staged run), eval/metrics.json (pose and image metrics). Writes
table.csv and table.md to --write (default: the first OUT), and prints the markdown.

The do-nothing Sim(3) ΔR is computed here from the scene's poses_bounds.npy: the error of a rig
whose cameras never turn (all rotations equal), given the best common rotation, i.e. the mean
angle between each reference rotation and their chordal L2 mean. A learned rig whose Sim(3) ΔR
is above it has settled on the wrong member of the rotation/focal/depth family, however good its
relative rotations are (issue 49). Only the training cameras count, as in `hashcc eval`
(every 8th image is a test view, LLFF's hold-out).
"""
import argparse, csv, gzip, json, math, os, sys

import numpy as np


def rot_angle_deg(R):
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(R) - 1) / 2))))


def do_nothing_sim3_dR(scene_dir, holdout=8):
    path = os.path.join(scene_dir, "poses_bounds.npy")
    if not os.path.isfile(path):
        return None
    pb = np.load(path)
    R = pb[:, :15].reshape(-1, 3, 5)[:, :, :3]
    train = [i for i in range(len(R)) if i % holdout != 0] if len(R) > holdout else list(range(len(R)))
    Rt = R[train]
    # Chordal L2 mean: the rotation nearest to the mean matrix (SVD projection).
    U, _, Vt = np.linalg.svd(Rt.mean(axis=0))
    M = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    return float(np.mean([rot_angle_deg(M.T @ r) for r in Rt]))


def last_log_row(run):
    path = os.path.join(run, "log.csv")
    if not os.path.isfile(path) and os.path.isfile(path + ".gz"):
        path += ".gz"  # the thinned copy committed under docs/results: its last row is kept
    if not os.path.isfile(path):
        return None
    last = None
    with (gzip.open(path, "rt") if path.endswith(".gz") else open(path)) as f:
        for row in csv.DictReader(f):
            last = row
    return last


def trained_folders(stage):
    """The folders a stage trained in: the stage's own, or for a stage that tries alternatives
    (a plan's "try") each alternative's, STAGE/try1 … (they all ran: their steps all count)."""
    tries = sorted((d for d in os.listdir(stage) if d.startswith("try") and d[3:].isdigit()),
                   key=lambda d: int(d[3:])) if os.path.isdir(stage) else []
    return [os.path.join(stage, d) for d in tries] if tries else [stage]


def run_totals(run):
    """(steps, seconds) of a run, over its stages: a staged run (a plan) trains RUN/stage1 … and
    RUN itself, each with its own log; the stages' steps and seconds add up, and a stage that
    tries alternatives counts every alternative's."""
    steps, seconds = 0, 0.0
    stages = sorted((d for d in os.listdir(run) if d.startswith("stage") and d[5:].isdigit()),
                    key=lambda d: int(d[5:]))
    for folder in [f for d in stages for f in trained_folders(os.path.join(run, d))] + [run]:
        last = last_log_row(folder)
        if last:
            steps += int(last["step"])
            seconds += float(last["seconds"])
    return steps, seconds


def metrics_from_camera_error(run):
    """A run without `hashcc eval`: its camera figures from the last row of RUN/camera_error.csv
    (written during training), the do-nothing relative rotation from the first row of its first
    stage (identity cameras), and no image metrics."""
    def rows(folder):
        with open(os.path.join(folder, "camera_error.csv")) as f:
            return list(csv.DictReader(f))
    last = rows(run)[-1]
    first_dir = trained_folders(os.path.join(run, "stage1"))[0] if os.path.isdir(os.path.join(run, "stage1")) else run
    first = rows(first_dir)[0]
    num = lambda v: float(v) if v not in (None, "") else None
    return {"rel_rot_err_deg": num(last["rel_rot_deg"]), "rel_rot_do_nothing_deg": num(first["rel_rot_deg"]),
            "rot_err_deg": num(last["sim3_dR_deg"]), "trans_err": num(last["sim3_dT"]),
            "focal": {"fx": num(last["fx"]), "fy": num(last["fy"]), "reference": num(last["ref_focal"])}}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out", nargs="+", help="run folders, or folders of run folders")
    ap.add_argument("--write", default=None, help="where table.csv and table.md go (default: the first OUT)")
    ap.add_argument("--paper", default=None)
    a = ap.parse_args()
    runs = []
    for path in a.out:
        if os.path.isfile(os.path.join(path, "config.json")):
            runs.append((os.path.basename(os.path.normpath(path)), path))
        elif os.path.isdir(path):
            runs += [(name, os.path.join(path, name)) for name in sorted(os.listdir(path))]
        else:
            sys.exit(f"scene_table.py: {path}: neither a run folder (config.json) nor a folder of them")
    write = a.write or a.out[0]
    os.makedirs(write, exist_ok=True)
    paper = {}
    if a.paper and os.path.isfile(a.paper):
        with open(a.paper) as f:
            paper = {r["scene"]: r for r in csv.DictReader(f)}
    rows = []
    for name, run in runs:
        mpath = os.path.join(run, "eval", "metrics.json")
        if os.path.isfile(mpath):
            m = json.load(open(mpath))
        elif os.path.isfile(os.path.join(run, "camera_error.csv")):
            m = metrics_from_camera_error(run)  # not evaluated: the cameras only, no PSNR
        else:
            continue
        cfg = json.load(open(os.path.join(run, "config.json")))
        scene_dir = cfg.get("data", "")
        scene = os.path.basename(os.path.normpath(scene_dir))
        steps, seconds = run_totals(run)
        f = m.get("focal") or {}
        ref = f.get("reference")
        fx, fy = f.get("fx"), f.get("fy")
        p = paper.get(scene, {})
        rows.append({
            "scene": scene, "run": name, "seed": cfg.get("seed"),
            "minutes": round(seconds / 60, 1), "steps": steps, "threads": cfg.get("threads"),
            "rel_rot_deg": m.get("rel_rot_err_deg"), "rel_rot_do_nothing_deg": m.get("rel_rot_do_nothing_deg"),
            "sim3_dR_deg": m.get("rot_err_deg"), "sim3_dR_do_nothing_deg": do_nothing_sim3_dR(scene_dir),
            "sim3_dT": m.get("trans_err"), "rig_dR_deg": m.get("rot_err_deg_rig"),
            "fx_err_pct": 100 * (fx / ref - 1) if fx and ref else None,
            "fy_err_pct": 100 * (fy / ref - 1) if fy and ref else None,
            "psnr": m.get("psnr"), "ssim": m.get("ssim"),
            "paper_psnr": p.get("hashcc_psnr", ""), "paper_dR_deg": p.get("hashcc_dR_deg", ""),
        })
    if not rows:
        sys.exit(f"scene_table.py: no run folder with eval/metrics.json under {' '.join(a.out)}")
    keys = list(rows[0].keys())
    with open(os.path.join(write, "table.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        w.writerows(rows)

    def fmt(v, d=2):
        if v is None or v == "":
            return "–"
        return f"{v:.{d}f}" if isinstance(v, float) else str(v)

    md = ["| scene | seed | min | steps | thr | rel. rot. ° (do-nothing) | Sim(3) ΔR ° (do-nothing) | ΔT | rotation-aligned ΔR ° | fx / fy err % | PSNR / SSIM | HashCC paper PSNR / ΔR° |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        paper_cell = f"{r['paper_psnr']} / {r['paper_dR_deg']}" if r["paper_psnr"] else "–"
        md.append(f"| {r['scene']} | {r['seed']} | {r['minutes']} | {r['steps']} | {r['threads']} | "
                  f"{fmt(r['rel_rot_deg'])} ({fmt(r['rel_rot_do_nothing_deg'])}) | "
                  f"{fmt(r['sim3_dR_deg'])} ({fmt(r['sim3_dR_do_nothing_deg'])}) | {fmt(r['sim3_dT'], 3)} | "
                  f"{fmt(r['rig_dR_deg'])} | "
                  f"{fmt(r['fx_err_pct'], 1)} / {fmt(r['fy_err_pct'], 1)} | "
                  f"{fmt(r['psnr'])} / {fmt(r['ssim'])} | {paper_cell} |")
    text = "\n".join(md) + "\n"
    open(os.path.join(write, "table.md"), "w").write(text)
    print(text)


if __name__ == "__main__":
    main()
