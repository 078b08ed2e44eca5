#!/usr/bin/env python3
"""The pinhole focal that best matches a COLMAP camera with radial distortion.

LLFF's poses_bounds.npy takes its focal from COLMAP's first camera parameter and drops the
rest. When COLMAP fitted SIMPLE_RADIAL (f, cx, cy, k) or RADIAL (f, cx, cy, k1, k2), the images
keep that distortion, and a pinhole model (hashcc's) that best explains them has another
focal. This prints both for an image size: the least-squares pinhole focal f' of
    pixel - c  ≈  f' · x,   x the undistorted normalised point of each pixel centre,
over every pixel of the frame (the distortion inverted by fixed-point iteration).

Usage: tools/colmap_pinhole.py SPARSE_DIR [--width W]
  SPARSE_DIR: a COLMAP model folder with cameras.bin (e.g. ../shared/data/llff/fern/sparse/0)
  --width W:  the image width the focal is quoted at (default: COLMAP's; LLFF images_8: W/8)
"""
import argparse
import struct
import sys

import numpy as np

MODELS = {0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5)}


def read_cameras(path):
    with open(path, "rb") as fh:
        b = fh.read()
    (n,) = struct.unpack_from("<Q", b, 0)
    off, cams = 8, []
    for _ in range(n):
        cid, model, w, h = struct.unpack_from("<iiQQ", b, off)
        off += 24
        if model not in MODELS:
            sys.exit(f"{path}: camera {cid}: model id {model} not handled (expected one of {sorted(MODELS)})")
        name, npar = MODELS[model]
        params = struct.unpack_from(f"<{npar}d", b, off)
        off += 8 * npar
        cams.append((cid, name, w, h, params))
    return cams


def pinhole_equivalent(name, w, h, params, width):
    s = width / w
    W, H = int(round(w * s)), int(round(h * s))
    if name in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        f, cx, cy = params[0] * s, params[1] * s, params[2] * s
    else:
        f, cx, cy = params[0] * s, params[2] * s, params[3] * s
    k1 = params[3] if name in ("SIMPLE_RADIAL", "RADIAL") else 0.0
    k2 = params[4] if name == "RADIAL" else 0.0
    u, v = np.meshgrid(np.arange(W) + 0.5 - cx, np.arange(H) + 0.5 - cy)
    xd, yd = u / f, v / f
    x, y = xd.copy(), yd.copy()
    for _ in range(50):  # xd = x (1 + k1 r² + k2 r⁴): fixed point for x
        r2 = x * x + y * y
        g = 1 + k1 * r2 + k2 * r2 * r2
        x, y = xd / g, yd / g
    fp = float((u * x + v * y).sum() / (x * x + y * y).sum())
    return W, H, f, k1, k2, fp


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sparse")
    ap.add_argument("--width", type=float, default=0)
    a = ap.parse_args()
    for cid, name, w, h, params in read_cameras(f"{a.sparse}/cameras.bin"):
        W, H, f, k1, k2, fp = pinhole_equivalent(name, w, h, params, a.width or w)
        print(f"camera {cid}: {name} {w}x{h}, params {', '.join(f'{p:.6g}' for p in params)}")
        print(f"  at {W}x{H}: COLMAP focal {f:.2f} px (k1 {k1:.5g}, k2 {k2:.5g}); "
              f"least-squares pinhole focal over the frame {fp:.2f} px ({100 * (fp / f - 1):+.2f}%)")


if __name__ == "__main__":
    main()
