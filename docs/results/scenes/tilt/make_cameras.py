#!/usr/bin/env python3
"""make_cameras.py RUN OUT: the camera files of the tilt experiment (run.sh): RUN's learned cameras,
and the same rotations with the reference centres mapped into the learned frame by the best
similarity (rotation from the rotations, scale from the centres). Needs numpy."""

import json, os, sys
import numpy as np
run, outdir = sys.argv[1], sys.argv[2]
os.makedirs(outdir, exist_ok=True)
cfg = json.load(open(os.path.join(run, "config.json"))); scene = cfg["data"]
cams = json.load(open(os.path.join(run, "cameras.json")))
learned = {os.path.basename(f["file_path"]): np.array(f["transform_matrix"]) for f in cams["frames"]}
folder = "images_8"
names = sorted(n for n in os.listdir(os.path.join(scene, folder)) if not n.startswith("."))
P = np.load(os.path.join(scene, "poses_bounds.npy"))[:, :15].reshape(-1, 3, 5)
R = np.stack([P[:, :, 1], -P[:, :, 0], P[:, :, 2]], -1); t = P[:, :, 3]
keys = [n for n in names if n in learned]; idx = [names.index(n) for n in keys]
Rl = np.stack([learned[k][:3, :3] for k in keys]); tl = np.stack([learned[k][:3, 3] for k in keys])
Rr, tr = R[idx], t[idx]
U, _, Vt = np.linalg.svd(sum(Rl[i] @ Rr[i].T for i in range(len(keys))))
A = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt     # ref world -> learned world (A Rr ≈ Rl)
rc = (A @ (tr - tr.mean(0)).T).T                        # reference centres, turned into the learned frame
lc = tl - tl.mean(0)
s = np.sum(lc * rc) / np.sum(rc * rc)
new_t = tl.mean(0) + s * rc
out = json.loads(json.dumps(cams))
for f in out["frames"]:
    k = os.path.basename(f["file_path"])
    if k in keys:
        i = keys.index(k); m = np.array(f["transform_matrix"]); m[:3, 3] = new_t[i]
        f["transform_matrix"] = m.tolist()
json.dump(out, open(os.path.join(outdir, "cameras_b_learned_rotations_reference_centres.json"), "w"), indent=1)
json.dump(cams, open(os.path.join(outdir, "cameras_a_learned.json"), "w"), indent=1)
print("scale", s, "centre move rms", np.sqrt(((new_t - tl)**2).sum(1).mean()), "centre spread", np.sqrt((lc**2).sum(1).mean()))
