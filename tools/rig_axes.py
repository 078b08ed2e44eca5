#!/usr/bin/env python3
"""Where a learned rig is wrong: its rotations, or its centres along one axis (issue 49).

    rig_axes.py RUN [SCENE_DIR]     (SCENE_DIR defaults to the run's config.json "data")

`hashcc eval`'s Sim(3) ΔR aligns the learned camera centres onto the reference ones (Umeyama)
and then compares rotations: when the centres are warped along one axis, the alignment tilts
and every rotation looks wrong by tens of degrees, even when the rotations themselves are right.
This script separates the two:
  - rotation-only alignment: the one rotation A that best maps the learned rotations onto the
    reference (chordal mean of R_learned R_refᵀ); the mean angle left is the rotations' own error;
  - then, in that frame, the centres axis by axis (x right, y up, z back of the world): the
    correlation of learned and reference centre coordinates, and the ratio of their spreads at
    the best common scale. A correct rig has correlations near 1 and ratios near 1 on every axis;
  - the depth error's shape: in the mean reference camera's frame, the learned centres' depth
    error (at the sideways scale) fitted as a·x + b·y + c·x² + d·y² + e·xy + f. When the plane
    explains most of it, the learned rig is the true one tilted in depth by atan a, atan b
    (LLFF horns: ~10° about both axes, 95% explained; docs/results/scenes/README.md).
Reads RUN/cameras.json (written by train at every checkpoint) and SCENE_DIR/poses_bounds.npy
with the images folder of the run (images_8 if present). Needs numpy.
"""
import json, os, sys

import numpy as np


def main():
    run = sys.argv[1]
    cfg = json.load(open(os.path.join(run, "config.json")))
    scene = sys.argv[2] if len(sys.argv) > 2 else cfg["data"]
    cams = json.load(open(os.path.join(run, "cameras.json")))
    learned = {os.path.basename(f["file_path"]): np.array(f["transform_matrix"])[:3] for f in cams["frames"]}
    folder = cfg.get("images_folder") or next((d for d in ("images_8", "images_4", "images")
                                               if os.path.isdir(os.path.join(scene, d))), "images")
    names = sorted(n for n in os.listdir(os.path.join(scene, folder)) if not n.startswith("."))
    P = np.load(os.path.join(scene, "poses_bounds.npy"))[:, :15].reshape(-1, 3, 5)
    R = np.stack([P[:, :, 1], -P[:, :, 0], P[:, :, 2]], -1)  # LLFF [down right back] -> [right up back]
    t = P[:, :, 3]
    keys = [n for n in names if n in learned]
    idx = [names.index(n) for n in keys]
    Rl = np.stack([learned[k][:, :3] for k in keys]); tl = np.stack([learned[k][:, 3] for k in keys])
    Rr, tr = R[idx], t[idx]
    U, _, Vt = np.linalg.svd(sum(Rl[i] @ Rr[i].T for i in range(len(keys))))
    A = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    ang = [np.degrees(np.arccos(np.clip((np.trace(A.T @ Rl[i] @ Rr[i].T) - 1) / 2, -1, 1)))
           for i in range(len(keys))]
    print(f"{run}: {len(keys)} training cameras")
    print(f"  rotation-only alignment: mean ΔR {np.mean(ang):.2f}° (max {np.max(ang):.2f}°)")
    la = (A.T @ (tl - tl.mean(0)).T).T
    rc = tr - tr.mean(0)
    s = np.sum(la * rc) / np.sum(la * la)
    for ax, name in enumerate("xyz"):
        c = np.corrcoef(la[:, ax], rc[:, ax])[0, 1]
        print(f"  centres along {name}: correlation {c:.3f}, spread learned/reference {la[:, ax].std() * s / rc[:, ax].std():.3f}")
    # The depth error's shape, in the mean reference camera's frame (its z: the viewing axis).
    U, _, Vt = np.linalg.svd(Rr.sum(0))
    Rm = U @ Vt
    lm, rm = (Rm.T @ la.T).T, (Rm.T @ rc.T).T
    k = np.sum(lm[:, :2] * rm[:, :2]) / np.sum(lm[:, :2] ** 2)  # the sideways scale
    ez = k * lm[:, 2] - rm[:, 2]
    x, y = rm[:, 0], rm[:, 1]
    X = np.stack([x, y, x * x, y * y, x * y, np.ones_like(x)], 1)
    coef = np.linalg.lstsq(X, ez, rcond=None)[0]
    explained = 1 - np.var(ez - X @ coef) / max(np.var(ez), 1e-300)
    print(f"  depth error (viewing axis) {ez.std():.3g} rms against the reference's depth spread "
          f"{rm[:, 2].std():.3g}: a plane explains {100 * explained:.0f}%, tilted "
          f"{np.degrees(np.arctan(coef[0])):.1f}° (x) and {np.degrees(np.arctan(coef[1])):.1f}° (y)")


if __name__ == "__main__":
    main()
