#!/usr/bin/env python3
"""Moves a run's cameras along the NDC rotation/depth family (docs/results/log/grid.md, "Why
fern's cameras stop at ~6°"), to start another run from them with --init-poses.

    python3 tools/gauge_move.py RUN/cameras.json KAPPA SCALE OUT.json

For every camera with centre c (world frame = the identity start's frame) and rotation R:
    R' = Exp(kappa * (c_y, -c_x, 0)) R      (turn by kappa per unit of sideways offset: c x z)
    c' = SCALE * c                          (the translations' scale about the start point)
kappa = 0, SCALE = 1 writes the cameras unchanged. tools/pose_compare.py fits kappa against a
reference; the SCALE of the reference is the Sim(3) scale `hashcc eval` reports.
Pure Python; the cameras.json layout (transforms.json convention) is kept as read.
"""
import json
import math
import sys


def exp_so3(w):
    """Rodrigues: the rotation matrix of the axis-angle vector w."""
    th = math.sqrt(sum(x * x for x in w))
    eye = [[1.0 if i == j else 0.0 for j in range(3)] for i in range(3)]
    if th < 1e-12:
        return eye
    K = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
    K2 = [[sum(K[i][k] * K[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    a, b = math.sin(th) / th, (1 - math.cos(th)) / (th * th)
    return [[eye[i][j] + a * K[i][j] + b * K2[i][j] for j in range(3)] for i in range(3)]


def move(cams, kappa, scale):
    for f in cams['frames']:
        M = f['transform_matrix']
        R = [row[:3] for row in M[:3]]
        c = [M[i][3] for i in range(3)]
        E = exp_so3([kappa * c[1], -kappa * c[0], 0.0])
        R2 = [[sum(E[i][k] * R[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
        f['transform_matrix'] = [R2[i] + [scale * c[i]] for i in range(3)] + [[0, 0, 0, 1]]
    return cams


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    src, dst = sys.argv[1], sys.argv[4]
    try:
        kappa, scale = float(sys.argv[2]), float(sys.argv[3])
    except ValueError:
        sys.exit(f"gauge_move: KAPPA and SCALE must be numbers (got {sys.argv[2]!r}, {sys.argv[3]!r})")
    try:
        cams = json.load(open(src))
    except (OSError, ValueError) as e:
        sys.exit(f"{src}: {e}")
    if 'frames' not in cams:
        sys.exit(f"{src}: no 'frames' (expected a cameras.json written by hashcc train)")
    json.dump(move(cams, kappa, scale), open(dst, 'w'), indent=1)


if __name__ == '__main__':
    main()
