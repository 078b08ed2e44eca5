#!/usr/bin/env python3
"""How well a scene's camera geometry can pin its focal at all (issue 49): the focal gauge.

    focal_gauge.py [--points-per-view K] [--eps 1,3,5,10] [--seed S] SCENE_DIR [SCENE_DIR ...]

Any method that learns the cameras and the scene together (NeRF--, BARF, hashcc, COLMAP) can
only find the focal to the extent that a wrong focal cannot be hidden by moving the cameras and
the scene. This measures that, from a scene's reference cameras alone (poses_bounds.npy), with
no photos and no training:

1. Scene points: K pixels a view drawn at random, each at a depth drawn uniformly in inverse
   depth between the view's near and far bound, lifted to the world. A point is observed by
   every view in whose image it falls (in front of the camera, inside the frame).
2. Their exact projections with the reference focal f are the observations.
3. For each ε, the focal is held at f·(1 + ε) and every camera (rotation and centre) and every
   point is moved to fit the observations as well as possible: bundle adjustment
   (Levenberg–Marquardt, the points eliminated by the Schur complement, analytic Jacobians),
   starting from the reference. The scene's points are free, as a radiance field's content is.
4. Reported: the RMS reprojection error in pixels before (the reference cameras and points seen
   through the wrong focal) and after the cameras and points have absorbed what they can, and
   the relative rotation error (formulas.md §7) of the cameras that absorbed it: how far a run
   that settled on that focal would have had to turn its cameras from the reference.

--k1 K observes the points through COLMAP's SIMPLE_RADIAL lens (the model LLFF's COLMAP run
fits; LLFF keeps its f and drops k1) and fits pinhole cameras: the ε with the smallest "after"
is the focal a distortion-free model (hashcc's) would prefer on those photos.

"After" is what a photometric fit could at best see of a focal ε off: if it is a small fraction
of a pixel, the photos cannot tell f from f·(1 + ε), whatever the optimiser. The pixel is the
scene's own (poses_bounds.npy's H, W, f: LLFF's images_8 size for the LLFF scenes here after
scaling by --image-width, default the file's width divided by 8 when it is > 1,000 px).
Pure geometry: no lens distortion, no noise; NumPy only.
"""
import argparse
import sys

import numpy as np


def load_cameras(path, image_width):
    pb = np.load(path + "/poses_bounds.npy")
    P = pb[:, :15].reshape(-1, 3, 5)
    H, W, f = P[0, :, 4]
    scale = 1.0
    if image_width > 0:
        scale = image_width / W
    elif W > 1000:  # a full-size LLFF file: its images_8 pixels
        scale = 1.0 / 8
    H, W, f = H * scale, W * scale, f * scale
    # LLFF's camera-to-world columns are [down, right, back]; ours are [right, up, back]
    # (the camera looks along −back, image v grows downward).
    D, Rt, B = P[:, :, 0], P[:, :, 1], P[:, :, 2]
    R = np.stack([Rt, -D, B], axis=2)  # (N, 3, 3), columns = camera axes in the world
    C = P[:, :, 3].copy()
    bounds = pb[:, 15:17]
    return R, C, bounds, H, W, f


def project(R, C, X, f, W, H):
    """Pixels (u, v) of world points X (M, 3) in cameras (R, C) (M each), and the camera-frame point."""
    Xc = np.einsum("mji,mj->mi", R, X - C)  # R^T (X − C)
    z = -Xc[:, 2]
    u = f * Xc[:, 0] / z + W / 2
    v = -f * Xc[:, 1] / z + H / 2
    return u, v, Xc, z


def make_points(R, C, bounds, H, W, f, k, rng):
    pts = []
    for i in range(len(R)):
        px = rng.uniform(0, W, k)
        py = rng.uniform(0, H, k)
        near, far = bounds[i]
        inv = rng.uniform(1 / far, 1 / near, k)
        z = 1 / inv
        Xc = np.stack([(px - W / 2) / f * z, -(py - H / 2) / f * z, -z], axis=1)
        pts.append(C[i] + Xc @ R[i].T)
    X = np.concatenate(pts)
    cam, pt = [], []
    for i in range(len(R)):
        u, v, _, z = project(np.repeat(R[i:i + 1], len(X), 0), np.repeat(C[i:i + 1], len(X), 0),
                             X, f, W, H)
        ok = (z > 1e-6) & (u >= 0) & (u <= W) & (v >= 0) & (v <= H)
        cam.append(np.full(ok.sum(), i))
        pt.append(np.nonzero(ok)[0])
    return X, np.concatenate(cam), np.concatenate(pt)


def skew(a):
    Z = np.zeros(a.shape[:-1] + (3, 3))
    Z[..., 0, 1], Z[..., 0, 2] = -a[..., 2], a[..., 1]
    Z[..., 1, 0], Z[..., 1, 2] = a[..., 2], -a[..., 0]
    Z[..., 2, 0], Z[..., 2, 1] = -a[..., 1], a[..., 0]
    return Z


def rodrigues(w):
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w)
    th_safe = np.where(th < 1e-12, 1.0, th)
    A = np.where(th < 1e-12, 1.0, np.sin(th_safe) / th_safe)
    B = np.where(th < 1e-12, 0.5, (1 - np.cos(th_safe)) / th_safe ** 2)
    return np.eye(3) + A * K + B * (K @ K)


def residuals(R, C, X, cam, pt, obs, f, W, H):
    u, v, Xc, z = project(R[cam], C[cam], X[pt], f, W, H)
    return np.stack([u - obs[:, 0], v - obs[:, 1]], axis=1), Xc, z


def bundle_adjust(R, C, X, cam, pt, obs, f, W, H, iters=60):
    """LM over every camera (δω in the camera frame, δC) and every point, focal held."""
    N, M = len(R), len(X)
    lam = 1e-3
    r, Xc, z = residuals(R, C, X, cam, pt, obs, f, W, H)
    cost = float(np.sum(r * r))
    for _ in range(iters):
        # d(u, v)/dXc (2×3 per observation)
        Jp = np.zeros((len(cam), 2, 3))
        Jp[:, 0, 0] = f / z
        Jp[:, 0, 2] = f * Xc[:, 0] / z ** 2
        Jp[:, 1, 1] = -f / z
        Jp[:, 1, 2] = -f * Xc[:, 1] / z ** 2
        Rt = np.transpose(R[cam], (0, 2, 1))
        Jw = Jp @ skew(Xc)          # R ← R·exp(δω): Xc ← Xc + Xc × δω
        JC = -Jp @ Rt               # Xc = Rᵀ(X − C)
        JX = Jp @ Rt
        Jc = np.concatenate([Jw, JC], axis=2)  # (O, 2, 6)
        # Normal equations, points eliminated (Schur complement).
        Hcc = np.zeros((N, 6, 6))
        np.add.at(Hcc, cam, np.einsum("oai,oaj->oij", Jc, Jc))
        Hpp = np.zeros((M, 3, 3))
        np.add.at(Hpp, pt, np.einsum("oai,oaj->oij", JX, JX))
        Hcp = np.einsum("oai,oaj->oij", Jc, JX)  # per observation (6×3)
        gc = np.zeros((N, 6))
        np.add.at(gc, cam, np.einsum("oai,oa->oi", Jc, r))
        gp = np.zeros((M, 3))
        np.add.at(gp, pt, np.einsum("oai,oa->oi", JX, r))
        while True:
            Hpp_d = Hpp + lam * (np.eye(3) * (np.einsum("mii->mi", Hpp)[:, :, None] + 1e-9))
            Hpp_inv = np.linalg.inv(Hpp_d)
            S = np.zeros((6 * N, 6 * N))
            for i in range(N):
                d = Hcc[i] + lam * np.diag(np.diag(Hcc[i]) + 1e-9)
                S[6 * i:6 * i + 6, 6 * i:6 * i + 6] += d
            b = -gc.reshape(-1).copy()
            # S −= Hcp Hpp⁻¹ Hcpᵀ and b += Hcp Hpp⁻¹ gp, with Hcp (6N × 3M) dense: each
            # (camera, point) pair is observed at most once.
            Hcp_nm = np.zeros((N, M, 6, 3))
            Hcp_nm[cam, pt] = Hcp
            Hcp_full = Hcp_nm.transpose(0, 2, 1, 3).reshape(6 * N, 3 * M)
            T = np.einsum("cmj,mjk->cmk", Hcp_full.reshape(6 * N, M, 3), Hpp_inv).reshape(6 * N, 3 * M)
            S -= T @ Hcp_full.T
            b += T @ gp.reshape(-1)
            try:
                dc = np.linalg.solve(S, b).reshape(N, 6)
            except np.linalg.LinAlgError:
                dc = np.linalg.lstsq(S, b, rcond=None)[0].reshape(N, 6)
            # δX_p = Hpp⁻¹ (−gp − Σ Hcpᵀ δc)
            rhs = -gp.copy()
            np.add.at(rhs, pt, -np.einsum("oij,oi->oj", Hcp, dc[cam]))
            dX = np.einsum("mij,mj->mi", Hpp_inv, rhs)
            R2 = R @ rodrigues(dc[:, :3])
            C2 = C + dc[:, 3:]
            X2 = X + dX
            r2, Xc2, z2 = residuals(R2, C2, X2, cam, pt, obs, f, W, H)
            if np.all(z2 > 0):
                cost2 = float(np.sum(r2 * r2))
                if cost2 < cost:
                    R, C, X, r, Xc, z, cost = R2, C2, X2, r2, Xc2, z2, cost2
                    lam = max(lam / 3, 1e-9)
                    break
            lam *= 4
            if lam > 1e8:
                return R, C, X, cost
        if cost < 1e-20:
            break
    return R, C, X, cost


def relative_rotation_deg(R, Rref):
    """formulas.md §7: the mean over pairs i < j of the angle of (R_iᵀR_j)·(R_iᵀR_j)_refᵀ."""
    ang = []
    for i in range(len(R)):
        for j in range(i + 1, len(R)):
            E = (R[i].T @ R[j]) @ (Rref[i].T @ Rref[j]).T
            ang.append(np.degrees(np.arccos(np.clip((np.trace(E) - 1) / 2, -1, 1))))
    return float(np.mean(ang))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--points-per-view", type=int, default=12)
    ap.add_argument("--eps", default="1,3,5,10", help="focal errors in %%, comma-separated")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--image-width", type=float, default=0,
                    help="pixels of the image width the errors are stated in (default: the file's, /8 if > 1,000)")
    ap.add_argument("--iters", type=int, default=60)
    ap.add_argument("--json", help="also write every cell as JSON to this file (test/test_focal_gauge.cpp)")
    ap.add_argument("--k1", type=float, default=0,
                    help="observe through COLMAP's SIMPLE_RADIAL lens with this k1 (focal f, the file's); "
                         "the pinhole fits then show which focal a distortion-free model would prefer")
    a = ap.parse_args()
    eps = [float(e) for e in a.eps.split(",")]
    head = " | ".join(f"{e:+g}%: px before → after (rel. rot.)" for e in eps)
    print(f"| scene | views | points (observations) | W × H, f px | {head} |")
    print("|---|---|---|---|" + "---|" * len(eps))
    cells_json = []
    for path in a.scenes:
        rng = np.random.default_rng(a.seed)
        R, C, bounds, H, W, f = load_cameras(path, a.image_width)
        X, cam, pt = make_points(R, C, bounds, H, W, f, a.points_per_view, rng)
        u, v, _, _ = project(R[cam], C[cam], X[pt], f, W, H)
        if a.k1 != 0:  # COLMAP's SIMPLE_RADIAL: x_d = x·(1 + k1·r²) in normalised coordinates
            x, y = (u - W / 2) / f, (v - H / 2) / f
            d = 1 + a.k1 * (x * x + y * y)
            u, v = W / 2 + f * x * d, H / 2 + f * y * d
        obs = np.stack([u, v], axis=1)
        cells = []
        for e in eps:
            f2 = f * (1 + e / 100)
            r0, _, _ = residuals(R, C, X, cam, pt, obs, f2, W, H)
            before = np.sqrt(np.mean(np.sum(r0 * r0, axis=1)))
            R2, _, _, cost = bundle_adjust(R.copy(), C.copy(), X.copy(), cam, pt, obs, f2, W, H,
                                           a.iters)
            after = np.sqrt(cost / len(cam))
            rel = relative_rotation_deg(R2, R)
            cells.append(f"{before:.2f} → **{after:.3f}** ({rel:.2f}°)")
            cells_json.append({"scene": path, "eps_pct": e, "before_px": float(before),
                               "after_px": float(after), "rel_rot_deg": rel,
                               "observations": int(len(cam))})
            sys.stdout.flush()
        name = path.rstrip("/").split("/")[-1]
        print(f"| {name} | {len(R)} | {len(X)} ({len(cam)}) | {W:.0f} × {H:.0f}, {f:.1f} | "
              + " | ".join(cells) + " |", flush=True)
    if a.json:
        import json
        with open(a.json, "w") as fo:
            json.dump(cells_json, fo, indent=1)


if __name__ == "__main__":
    main()
