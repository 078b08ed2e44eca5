#!/usr/bin/env python3
"""Per-camera comparison of a run's learned cameras with the scene's reference (poses_bounds.npy),
and the fit of the NDC rotation/depth family (docs/results/log/grid.md, "Why fern fails").

    python3 tools/pose_compare.py RUN

Everything is expressed in the frame of the middle training camera (anchor a), so no alignment
is needed: for each camera i, the relative rotation R_a^T R_i as an axis-angle vector (degrees)
and the relative centre R_a^T (c_i - c_a), for the reference and for the run.

In NDC, from identity cameras, "rotate camera i by kappa (t_i x z) and move the field in NDC depth"
renders the same rays to first order. If a run's cameras sit in that family, the rotation
error is explained by one number: (ref - learned) rotation ~= kappa (t_y, -t_x, 0) with t the
learned relative centre. The script prints the least-squares kappa and how much of the
rotation error it explains, and the slope of learned against reference turns about x (pitch)
and y (yaw). Pure Python (no numpy): reads the .npy header itself.
"""
import json
import math
import os
import struct
import sys


def load_npy_f64(path):
    b = open(path, 'rb').read()
    if b[:6] != b'\x93NUMPY':
        sys.exit(f"{path}: not a .npy file")
    hl = struct.unpack('<H', b[8:10])[0]
    header = b[10:10 + hl].decode('latin1')
    if "'<f8'" not in header:
        sys.exit(f"{path}: expected float64 ('<f8'), header {header.strip()}")
    data = b[10 + hl:]
    return list(struct.unpack('<%dd' % (len(data) // 8), data))


def mm(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def tr(A):
    return [[A[j][i] for j in range(3)] for i in range(3)]


def log_deg(R):
    c = max(-1.0, min(1.0, (R[0][0] + R[1][1] + R[2][2] - 1) / 2))
    w = [R[2][1] - R[1][2], R[0][2] - R[2][0], R[1][0] - R[0][1]]
    s = math.sqrt(sum(x * x for x in w)) / 2
    ang = math.atan2(s, c)
    if s < 1e-12:
        return [0.0, 0.0, 0.0]
    return [math.degrees(ang) * x / (2 * s) for x in w]


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    run = sys.argv[1]
    cfg = json.load(open(os.path.join(run, 'config.json')))
    cams = json.load(open(os.path.join(run, 'cameras.json')))
    data = cfg['data']
    pb = os.path.join(data, 'poses_bounds.npy')
    if not os.path.exists(pb):
        sys.exit(f"{pb}: no reference cameras")
    v = load_npy_f64(pb)
    n = len(v) // 17
    folder = os.path.join(data, cfg.get('images_folder') or 'images')
    names = sorted(f for f in os.listdir(folder) if f.lower().endswith(('.png', '.jpg', '.jpeg')))
    if len(names) != n:
        sys.exit(f"{folder}: {len(names)} images but poses_bounds.npy has {n} cameras")
    ref_R, ref_c = {}, {}
    for i in range(n):
        M = [[v[17 * i + 5 * a + c] for c in range(5)] for a in range(3)]
        ref_R[names[i]] = [[M[a][1], -M[a][0], M[a][2]] for a in range(3)]  # LLFF -> OpenGL
        ref_c[names[i]] = [M[a][3] for a in range(3)]
    L_R, L_c = {}, {}
    for f in cams['frames']:
        M = f['transform_matrix']
        name = os.path.basename(f['file_path'])
        L_R[name] = [row[:3] for row in M[:3]]
        L_c[name] = [M[a][3] for a in range(3)]
    ids = [x for x in names if x in L_R]
    a = ids[len(ids) // 2]
    print(f"anchor camera: {a} (relative rotations in degrees, axis-angle x y z; centres in each"
          f" set's own units)")
    print(f"{'image':>14} | {'reference rotation':>22} | {'learned rotation':>22} | "
          f"{'learned centre':>24}")
    rows = []
    for i in ids:
        r = log_deg(mm(tr(ref_R[a]), ref_R[i]))
        l = log_deg(mm(tr(L_R[a]), L_R[i]))
        lc = [sum(L_R[a][k][j] * (L_c[i][k] - L_c[a][k]) for k in range(3)) for j in range(3)]
        rows.append((r, l, lc))
        print(f"{i:>14} | {r[0]:6.2f} {r[1]:6.2f} {r[2]:6.2f}   | {l[0]:6.2f} {l[1]:6.2f} "
              f"{l[2]:6.2f}   | {lc[0]:7.3f} {lc[1]:7.3f} {lc[2]:7.3f}")
    # Least squares: d = ref - learned (radians) ~ kappa * (t_y, -t_x).
    num = den = 0.0
    for r, l, t in rows:
        d = [math.radians(r[k] - l[k]) for k in range(2)]
        g = [t[1], -t[0]]
        num += d[0] * g[0] + d[1] * g[1]
        den += g[0] * g[0] + g[1] * g[1]
    kappa = num / den if den > 0 else 0.0
    before = sum(math.radians(r[k] - l[k]) ** 2 for r, l, _ in rows for k in range(2))
    after = sum((math.radians(r[k] - l[k]) - kappa * [t[1], -t[0]][k]) ** 2
                for r, l, t in rows for k in range(2))
    rms = lambda s: math.degrees(math.sqrt(s / max(1, 2 * len(rows))))
    print(f"rotation/depth family fit: kappa = {kappa:.4f} rad per learned unit; x/y rotation "
          f"error rms {rms(before):.3f} deg -> {rms(after):.3f} deg after the one-number family move")
    # How much larger (> 1) or smaller the learned relative turns are than the reference's, per
    # axis: the least-squares slope through 0 of learned against reference (x: pitch, y: yaw).
    # A focal that is off scales the turns it observes (docs/results/log/grid.md, "Short
    # restarts"); the rotation/depth family shrinks both.
    slope = []
    for k in range(2):
        rr = sum(r[k] * r[k] for r, _, _ in rows)
        slope.append(sum(r[k] * l[k] for r, l, _ in rows) / rr if rr > 0 else float('nan'))
    print(f"learned / reference turn (least-squares slope): pitch (x) {slope[0]:.3f}, "
          f"yaw (y) {slope[1]:.3f}")


if __name__ == '__main__':
    main()
