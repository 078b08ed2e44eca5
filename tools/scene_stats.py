#!/usr/bin/env python3
"""What kind of capture a scene folder is, from its poses_bounds.npy alone (issue 49's zoo).

    scene_stats.py SCENE_DIR [SCENE_DIR ...]

One markdown row a scene: views, horizontal field of view, the mean and largest pairwise
rotation between cameras (the rotation spread; the mean over the training views is close to
`hashcc eval`'s do-nothing relative rotation error), far/near (the depth range), and the extent of
the camera centres along each world axis in units of the nearest depth (the baseline). This is
how the simulator's zoo scenes were matched to LLFF's (docs/results/scenes/README.md).
"""
import sys

import numpy as np


def stats(path):
    pb = np.load(path + "/poses_bounds.npy")
    P = pb[:, :15].reshape(-1, 3, 5)
    H, W, f = P[0, :, 4]
    R, t, b = P[:, :, :3], P[:, :, 3], pb[:, 15:]
    ang = [np.degrees(np.arccos(np.clip((np.trace(R[i].T @ R[j]) - 1) / 2, -1, 1)))
           for i in range(len(R)) for j in range(i + 1, len(R))]
    near, far = b[:, 0].min(), b[:, 1].max()
    ext = np.ptp(t, axis=0) / near
    return (f"| {path.rstrip('/').split('/')[-1]} | {len(R)} | {2 * np.degrees(np.arctan(W / 2 / f)):.1f} | "
            f"{np.mean(ang):.2f} / {np.max(ang):.1f} | {far / near:.1f} | "
            f"{ext[0]:.2f}, {ext[1]:.2f}, {ext[2]:.2f} |")


print("| scene | views | horizontal FOV ° | pairwise rotation ° mean / max | far/near | centre extent / near (x, y, z) |")
print("|---|---|---|---|---|---|")
for p in sys.argv[1:]:
    print(stats(p))
