#!/usr/bin/env python3
"""tools/reference_step.py — an independent NumPy (float64) reference of ONE training step.

Written from docs/formulas.md, docs/golden-step.md ("What the step computes"),
docs/math/hash_grid.md and docs/math/grid_field.md — NOT from the C++ — so that a mistake in
how hashcc assembles its model (a concat order, the loss normalisation, Δc before compositing,
the NDC map, the hash indexing, the level curriculum) shows up as a disagreement with
`hashcc step --double`. Nothing here calls or imports hashcc.

    reference_step.py --in IN --out OUT          # forward outputs, loss, camera gradient (.npy)
    reference_step.py --in IN --compare HCCOUT   # ... and print the difference to hashcc's files
    reference_step.py --in IN --check-init       # IN's tensors follow formulas.md §4's init

IN is an input folder of `hashcc step` (docs/golden-step.md). OUT receives rgb_main, rgb_cc
(hashcc), depth, loss, rays_o, rays_d, x, grad.pose_r, grad.pose_t, grad.focal_ab and, for
every network tensor X, fd.X.idx.npy (int64 flat indices) with fd.X.npy (dL/dX there). Every
gradient is this script's own finite differences of its own loss (5-point central, a finer
step or one-sided where a kink lies within the stencil): the camera's 8 numbers all, with the
CC branch's input held at the unperturbed samples (the detach rule, formulas.md §5) and, with
grid_smooth, through the grid's straight-through surrogate (docs/math/grid_field.md); the
network tensors on a random subset (PARAM_SUBSET entries a tensor, seed PARAM_SEED: the output
says both). Only NumPy is needed.
"""
import argparse
import json
import math
import pathlib
import sys

import numpy as np

# ---------------------------------------------------------------- inputs


def load_inputs(d):
    d = pathlib.Path(d)
    cfg = json.loads((d / "config.json").read_text())
    arrays = {f.stem: np.load(f).astype(np.float64) for f in d.glob("*.npy")}
    for k in ("rows", "cols"):
        arrays[k] = np.load(d / f"{k}.npy").astype(np.int64)
    return cfg, arrays


# ---------------------------------------------------------------- camera (formulas.md §1, §2)


def skew(r):
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def rodrigues(r):
    """R = I + (sin θ/θ)[r]× + ((1 − cos θ)/θ²)[r]×², θ = |r| (Taylor series near 0)."""
    th2 = float(r @ r)
    th = math.sqrt(th2)
    if th < 1e-4:
        a, b = 1 - th2 / 6 + th2 * th2 / 120, 0.5 - th2 / 24 + th2 * th2 / 720
    else:
        a, b = math.sin(th) / th, (1 - math.cos(th)) / th2
    K = skew(r)
    return np.eye(3) + a * K + b * (K @ K)


def make_rays(cfg, A, pose_r, pose_t, focal_ab):
    """Ray k = pixel (u, v) = (cols[k % C], rows[k // C]); returns o', d' (NDC when cfg.ndc).
    fx_only: fy = fx = a²W (b unused). With a P0 (test-pose camera, formulas.md §1):
    c2w = [Exp(r) | t]·P0, i.e. rotation Exp(r)·R0 and centre Exp(r)·t0 + t."""
    H, W = cfg["H"], cfg["W"]
    rows, cols = A["rows"], A["cols"]
    v = np.repeat(rows, len(cols)).astype(np.float64)   # row-major over the R × C grid
    u = np.tile(cols, len(rows)).astype(np.float64)
    fx = focal_ab[0] ** 2 * W
    fy = fx if cfg.get("fx_only", False) else focal_ab[1] ** 2 * H
    dc = np.stack([(u - W / 2) / fx, -(v - H / 2) / fy, -np.ones_like(u)], axis=1)
    Rd = rodrigues(pose_r)
    if "P0" in A:
        R, centre = Rd @ A["P0"][:, :3], Rd @ A["P0"][:, 3] + pose_t
    else:
        R, centre = Rd, pose_t
    d = dc @ R.T                                          # d = R·d_c, not normalised
    o = np.broadcast_to(centre, d.shape).copy()
    if not cfg["ndc"]:
        return o, d
    tn = -(1 + o[:, 2]) / d[:, 2]                          # onto the near plane z = −1
    o = o + tn[:, None] * d
    ox, oy, oz = o[:, 0], o[:, 1], o[:, 2]
    dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
    kx, ky = 2 * fx / W, 2 * fy / H
    o2 = np.stack([-kx * ox / oz, -ky * oy / oz, 1 + 2 / oz], axis=1)
    d2 = np.stack([-kx * (dx / dz - ox / oz), -ky * (dy / dz - oy / oz), -2 / oz], axis=1)
    return o2, d2


# ---------------------------------------------------------------- encodings (§4, §8, §5)


def c2f_weights(n, alpha):
    """BARF weights (1 − cos(π·clamp(α − k, 0, 1)))/2 for k < n; all 1 when α < 0."""
    if alpha < 0:
        return np.ones(n)
    a = np.clip(alpha - np.arange(n), 0.0, 1.0)
    return (1 - np.cos(np.pi * a)) / 2


def fourier(x, bands, alpha=-1.0):
    """[x, sin(2⁰x), cos(2⁰x), …, sin(2^{L−1}x), cos(2^{L−1}x)], blocks of the 3 coordinates,
    no π; with α ≥ 0 band k's sin and cos are weighted (the raw x never is)."""
    w = c2f_weights(bands, alpha)
    out = [x]
    for k in range(bands):
        out += [w[k] * np.sin(2.0 ** k * x), w[k] * np.cos(2.0 ** k * x)]
    return np.concatenate(out, axis=1)


def sh4(u):
    """The 16 real SH of degree 4 of unit directions (formulas.md §8)."""
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    return np.stack([
        0.28209479177387814 * np.ones_like(x),
        -0.48860251190291987 * y, 0.48860251190291987 * z, -0.48860251190291987 * x,
        1.0925484305920792 * x * y, -1.0925484305920792 * y * z,
        0.94617469575755997 * z * z - 0.31539156525251999,
        -1.0925484305920792 * x * z, 0.54627421529603959 * (x * x - y * y),
        0.59004358992664352 * y * (-3 * x * x + y * y), 2.8906114426405538 * x * y * z,
        0.45704579946446572 * y * (1 - 5 * z * z), 0.3731763325901154 * z * (5 * z * z - 3),
        0.45704579946446572 * x * (1 - 5 * z * z), 1.4453057213202769 * z * (x * x - y * y),
        0.59004358992664352 * x * (-x * x + 3 * y * y)], axis=1)


def dir_encoding(model, u):
    return fourier(u, 4) if model == "nerfmm" else sh4(u)


def hash_levels(levels, base, finest, log2_table):
    """(scale, res, dense) per level, docs/math/hash_grid.md."""
    b = 1.0 if levels == 1 else math.exp((math.log(finest) - math.log(base)) / (levels - 1))
    out = []
    for l in range(levels):
        scale = base * b ** l - 1
        if abs(scale - round(scale)) < 1e-9:
            scale = float(round(scale))   # rounding in b^l must not move ceil
        res = math.ceil(scale) + 1
        out.append((scale, res, res ** 3 <= 2 ** log2_table))
    return out


def lerp_encode(x01, table, base, finest, sig, blend):
    """The lookup both encodings share: per level, the cell c = floor(p) of p = scale·x + 0.5 on
    the clamped input, the 8 corners' entries (dense index or spatial hash), each weighted by
    Π_d (k_d ? blend(f_d) : 1 − blend(f_d)) with f = p − c; output (N, L·F) level-major. Appends
    the clamp mask and each level's cell indices to sig (the kinks)."""
    L, S, F = table.shape
    log2_table = int(round(math.log2(S)))
    xc = np.clip(np.nan_to_num(x01, nan=0.0), 0.0, 1.0)
    sig.append(((x01 >= 0) & (x01 <= 1)).ravel())
    cols = []
    for l, (scale, res, dense) in enumerate(hash_levels(L, base, finest, log2_table)):
        p = scale * xc + 0.5
        c = np.floor(p)
        t = blend(p - c)
        c = c.astype(np.uint64)
        sig.append(c.ravel())
        y = np.zeros((len(x01), F))
        for k in range(8):
            bit = [(k >> dd) & 1 for dd in range(3)]              # bit 0 = x, 1 = y, 2 = z
            v = c + np.array(bit, dtype=np.uint64)
            if dense:
                r = np.uint64(res)
                e = (v[:, 0] + v[:, 1] * r + v[:, 2] * r * r) % np.uint64(S)
            else:
                m = np.uint64(0xFFFFFFFF)
                e = ((v[:, 0] * np.uint64(1)) & m) ^ ((v[:, 1] * np.uint64(2654435761)) & m) \
                    ^ ((v[:, 2] * np.uint64(805459861)) & m)
                e = (e & m) % np.uint64(S)
            w = np.ones(len(x01))
            for dd in range(3):
                w = w * (t[:, dd] if bit[dd] else 1 - t[:, dd])
            y += w[:, None] * table[l][e.astype(np.int64)]
        cols.append(y)
    return np.concatenate(cols, axis=1)


def hash_encode(x01, table, base, finest, sig):
    """Multiresolution hash encoding of points x01 (N, 3), table (L, 2^T, F): trilinear corner
    weights (lerp_encode with blend(f) = f)."""
    return lerp_encode(x01, table, base, finest, sig, lambda f: f)


def smooth_encode(x01, table, base, finest, sig):
    """h̃(u) of docs/math/grid_field.md: the trilinear lookup with the smooth corner weights
    w̃_k = Π_d (k_d ? δ(f_d) : 1 − δ(f_d)), δ(f) = (1 − cos πf)/2, on the clamped input. Its
    derivative in u is the grid's smooth straight-through position gradient. It is C¹ across
    cell faces but not C²: a 5-point stencil across a face is off by O(h·jump of h̃''), so the
    cell indices and the clamp mask go into the kink signature as hash_encode's do."""
    return lerp_encode(x01, table, base, finest, sig, lambda f: (1 - np.cos(np.pi * f)) / 2)


# ---------------------------------------------------------------- networks (§4, §5, grid_field.md)


def linear(P, name, x):
    """PyTorch nn.Linear: y = x·Wᵀ + b, W of shape (out, in)."""
    return x @ P[name + ".weight"].T + P[name + ".bias"]


def relu(x, sig):
    sig.append((x > 0).ravel())
    return np.maximum(x, 0.0)


def sigmoid(x):
    return 1 / (1 + np.exp(-x))


def mlp_field(cfg, P, x, enc_dir, sig):
    """The paper's field: γ(x) → 8-layer trunk (skip [h3, γ] into layer 4) → σ_raw, and
    [feature, direction] → colour."""
    g = fourier(x, 10, cfg.get("c2f_alpha", -1.0))
    h = g
    for k in range(8):
        if k == 4:
            h = np.concatenate([h, g], axis=1)                  # concat order [h, γ(x)]
        h = relu(linear(P, f"trunk.{k}", h), sig)
    sigma_raw = linear(P, "density", h)[:, 0]
    feat = linear(P, "feature", h)                              # no activation
    hid = relu(linear(P, "rgb_hidden", np.concatenate([feat, enc_dir], axis=1)), sig)
    return sigma_raw, sigmoid(linear(P, "rgb", hid))


def grid_field(cfg, P, x, enc_dir, sig, x_held=None):
    """docs/math/grid_field.md: u = (x+1)/2 → hash grid × w_l(α) → density MLP → [z, g];
    σ_raw = exp(min(z, 15)); colour MLP on [g, e(dir)].

    x_held (grid_smooth only): the straight-through surrogate H(u₀) + h̃(u) − h̃(u₀), u₀ from
    x_held — the same value at x = x_held, and its derivative in x is the smooth position
    gradient (what the engine's backward returns with grid_smooth: true)."""
    tab, base, finest = P["grid.table"], cfg["grid_base_res"], cfg["grid_max_res"]
    if x_held is None:
        y = hash_encode((x + 1) / 2, tab, base, finest, sig)
    else:
        u0 = (x_held + 1) / 2
        y = hash_encode(u0, tab, base, finest, sig) + smooth_encode((x + 1) / 2, tab, base, finest, sig) \
            - smooth_encode(u0, tab, base, finest, sig)
    L, F = cfg["grid_levels"], cfg["grid_features"]
    y = y * np.repeat(c2f_weights(L, cfg.get("c2f_alpha", -1.0)), F)
    h = relu(linear(P, "grid.density.0", y), sig)
    zg = linear(P, "grid.density.1", h)
    z, g = zg[:, 0], zg[:, 1:]
    sig.append((z < 15).ravel())
    sigma_raw = np.exp(np.minimum(z, 15.0))
    hid = relu(linear(P, "grid.rgb.0", np.concatenate([g, enc_dir], axis=1)), sig)
    return sigma_raw, sigmoid(linear(P, "grid.rgb.1", hid))


def cc_branch(cfg, P, cc_x, sig):
    """Δc = cc.1 · relu(cc.0 · hash(clamp((x+1)/2, 0, 1))), no output activation."""
    p = np.clip((cc_x + 1) / 2, 0.0, 1.0)
    enc = hash_encode(p, P["cc.table"], cfg["cc_base_res"], cfg["cc_max_res"], sig)
    return linear(P, "cc.1", relu(linear(P, "cc.0", enc), sig))


# ---------------------------------------------------------------- compositor, loss (§3, §6)


def composite(sigma, color, s):
    """δ_i = s_{i+1} − s_i (last 1e10), α = 1 − exp(−σδ), T_i = Π_{j<i}(1 − α_j + 1e-10)."""
    delta = np.concatenate([s[:, 1:] - s[:, :-1], np.full((len(s), 1), 1e10)], axis=1)
    alpha = 1 - np.exp(-sigma * delta)
    T = np.cumprod(np.concatenate([np.ones((len(s), 1)), 1 - alpha[:, :-1] + 1e-10], axis=1), axis=1)
    w = T * alpha
    return (w[:, :, None] * color).sum(axis=1), (w * s).sum(axis=1), w


def step(cfg, A, cam, cc_x=None):
    """One forward pass. cam = (pose_r, pose_t, focal_ab). cc_x: the CC input (default: this
    pass's own samples); when given and the grid field has grid_smooth, also the u₀ of the
    grid's straight-through surrogate (see grid_field). Returns a dict of outputs and the kink
    signature."""
    sig = []
    o, d = make_rays(cfg, A, *cam)
    s = A["s"]
    Rn, S = s.shape
    x = (o[:, None, :] + s[:, :, None] * d[:, None, :]).reshape(-1, 3)   # ray-major samples
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    enc_dir = np.repeat(dir_encoding(cfg["model"], u), S, axis=0)       # per ray → its samples
    field = grid_field if cfg.get("field", "mlp") == "grid" else mlp_field
    if field is grid_field and cfg.get("grid_smooth", False) and cc_x is not None:
        sigma_raw, c = grid_field(cfg, A, x, enc_dir, sig, x_held=cc_x)
    else:
        sigma_raw, c = field(cfg, A, x, enc_dir, sig)
    if field is mlp_field:
        sig.append((sigma_raw > 0).ravel())
    sigma = np.maximum(sigma_raw, 0.0).reshape(Rn, S)
    rgb, depth, w = composite(sigma, c.reshape(Rn, S, 3), s)
    v, cidx = np.repeat(A["rows"], len(A["cols"])), np.tile(A["cols"], len(A["rows"]))
    target = A["image"][v, cidx, :]
    out = {"rgb_main": rgb, "depth": depth, "rays_o": o, "rays_d": d, "x": x}
    loss = np.mean((rgb - target) ** 2)                                  # mean over R·C·3
    if cfg["model"] == "hashcc":
        dc = cc_branch(cfg, A, x if cc_x is None else cc_x, sig)
        cc = c + dc                                                       # Δc before compositing
        out["rgb_cc"] = (w[:, :, None] * cc.reshape(Rn, S, 3)).sum(axis=1)
        loss += np.mean((out["rgb_cc"] - target) ** 2)
    out["loss"] = np.array(loss)
    return out, sig


def same(sig_a, sig_b):
    return all(np.array_equal(a, b) for a, b in zip(sig_a, sig_b))


def camera_gradient(cfg, A, steps=(1e-5, 3e-6, 1e-6)):
    """dL/d(pose_r, pose_t, focal_ab) by finite differences of step()'s loss, the CC input held
    at the unperturbed samples (formulas.md §5).

    Per entry: the 5-point central difference (8(L₊₁ − L₋₁) − (L₊₂ − L₋₂))/12h (truncation
    O(h⁴)) at h = 1e-5, where the loss's rounding (~1e-17) costs ~2e-12 absolute and the Fourier
    bands' curvature ~1e-8 relative. If ±h or ±2h changes the kink signature (a ReLU, the
    density clamp, a hash cell: the loss is only C⁰ there), the same at h = 3e-6, then 1e-6
    (rounding ~2e-11), and if that crosses one too, the 4-point one-sided formula
    ±(−11L₀ + 18L±₁ − 9L±₂ + 2L±₃)/6h (truncation O(h³)) at 1e-6 on the side that keeps the
    signature. With grid_smooth the grid's straight-through surrogate is differenced (step(),
    grid_field): its derivative is the smooth position gradient the engine returns.
    Returns the gradients and counts of the fallbacks."""
    cam0 = [A["pose_r"].copy(), A["pose_t"].copy(), A["focal_ab"].copy()]
    base, _ = step(cfg, A, cam0)
    x0 = base["x"]
    L0 = float(base["loss"])
    _, sig0 = step(cfg, A, cam0, cc_x=x0)   # the signature of what ev() evaluates (surrogate)
    grads, notes = [], {"fine": 0, "one_sided": 0, "skipped": 0}

    def ev(which, i, step_h):
        cam = [c.copy() for c in cam0]
        cam[which][i] += step_h
        out, sig = step(cfg, A, cam, cc_x=x0)
        return float(out["loss"]), same(sig, sig0)

    for which, c0 in enumerate(cam0):
        grads.append(np.array([fd_entry(lambda dh: ev(which, i, dh), L0, steps, notes)
                               for i in range(len(c0))]))
    return base, grads, notes


# The inputs that are not parameters (P0 is a fixed camera input, cc_x the test hook).
NOT_PARAMETERS = {"image", "rows", "cols", "s", "P0", "cc_x", "pose_r", "pose_t", "focal_ab"}
PARAM_SUBSET = 8       # entries a network tensor (all of a smaller one)
PARAM_SEED = 52        # numpy.random.default_rng(PARAM_SEED) draws them, tensors in name order


def fd_entry(loss_at, L0, steps, notes):
    """One derivative by finite differences of loss_at(Δ) → (loss, same kink signature as at
    Δ = 0): the 5-point central formula at steps[0], then at each finer step where the stencil
    crosses a kink, then the 4-point one-sided formula at the finest step on a side that keeps
    the signature; NaN (counted as skipped) when both sides cross one."""
    for h in steps:
        e = {m: loss_at(m * h) for m in (-2, -1, 1, 2)}
        if all(ok for _, ok in e.values()):
            if h != steps[0]:
                notes["fine"] += 1
            return (8 * (e[1][0] - e[-1][0]) - (e[2][0] - e[-2][0])) / (12 * h)
    for side in (1, -1):
        l3, ok3 = loss_at(3 * side * h)
        if e[side][1] and e[2 * side][1] and ok3:
            notes["one_sided"] += 1
            return side * (-11 * L0 + 18 * e[side][0] - 9 * e[2 * side][0] + 2 * l3) / (6 * h)
    notes["skipped"] += 1
    return np.nan


def param_gradient(cfg, A, per_tensor=PARAM_SUBSET, seed=PARAM_SEED, steps=(1e-4, 3e-5, 1e-5)):
    """dL/dθ of every network tensor by finite differences of step()'s loss, on a random subset:
    all entries of a tensor of ≤ per_tensor entries, else per_tensor distinct ones drawn by
    numpy.random.default_rng(seed) (tensors in name order). Full differences would take
    ~4 × (4,600 entries) forward passes a folder (a minute or more). The camera is not moved, so
    the CC input is the step's own samples (no detach question) and, with grid_smooth, the
    plain trilinear forward is differenced (the smooth surrogate equals it at fixed samples).
    h = 1e-4: the loss (~0.1–0.5) rounds at ~1e-17, i.e. ~1e-13 absolute noise; the network
    is smooth in its weights between ReLU kinks (truncation O(h⁴)). Returns
    {name: (flat indices, derivatives)} and counts of the fallbacks."""
    cam = [A["pose_r"], A["pose_t"], A["focal_ab"]]
    base, sig0 = step(cfg, A, cam)
    L0 = float(base["loss"])
    rng = np.random.default_rng(seed)
    notes = {"fine": 0, "one_sided": 0, "skipped": 0, "entries": 0, "tensors": 0}
    out = {}
    for name in sorted(k for k in A if k not in NOT_PARAMETERS):
        t = A[name]
        n = t.size
        idx = np.arange(n) if n <= per_tensor else np.sort(rng.choice(n, per_tensor, replace=False))
        flat = t.reshape(-1)                      # a view: perturbs A[name] in place

        def loss_at(dh, i):
            keep = flat[i]
            flat[i] = keep + dh
            o, sig = step(cfg, A, cam)
            flat[i] = keep
            return float(o["loss"]), same(sig, sig0)

        g = np.array([fd_entry(lambda dh: loss_at(dh, i), L0, steps, notes) for i in idx])
        keep = ~np.isnan(g)
        out[name] = (idx[keep].astype(np.int64), g[keep])
        notes["entries"] += int(keep.sum())
        notes["tensors"] += 1
    return out, notes


# ---------------------------------------------------------------- initialisation (§4)


def check_init(cfg, A):
    """formulas.md §4: every Linear weight and bias uniform in ±1/√fan_in, except the density
    bias (0.1) and the rgb bias (0.02) of the paper's field. Returns a list of problems."""
    bad = []
    for name, w in sorted(A.items()):
        if not name.endswith(".weight"):
            continue
        layer = name[: -len(".weight")]
        bound = 1 / math.sqrt(w.shape[1])
        for t in (name, layer + ".bias"):
            if t in ("density.bias", "rgb.bias"):
                continue
            v = A[t].ravel()
            if np.abs(v).max() > bound:
                bad.append(f"{t}: |entry| {np.abs(v).max():.4g} > 1/sqrt(fan_in) = {bound:.4g}")
            # Uniform ±bound has standard deviation bound/√3; a wrong fan_in (e.g. fan_out)
            # or a zero init moves it by far more than the sampling error at ≥ 100 entries
            # (relative standard error √(0.8/4n) ≤ 0.045: the band 0.7–1.3 is ±6.7 of it).
            if len(v) >= 100 and not 0.7 < v.std() / (bound / math.sqrt(3)) < 1.3:
                bad.append(f"{t}: std {v.std():.4g}, expected about {bound / math.sqrt(3):.4g}")
    if cfg.get("field", "mlp") != "grid":
        if not np.all(A["density.bias"] == 0.1):
            bad.append(f"density.bias = {A['density.bias']}, expected 0.1")
        if not np.all(A["rgb.bias"] == 0.02):
            bad.append(f"rgb.bias = {A['rgb.bias']}, expected 0.02")
    return bad


# ---------------------------------------------------------------- command line


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--in", dest="inp", required=True, help="input folder of `hashcc step`")
    ap.add_argument("--out", help="write the reference's .npy files here")
    ap.add_argument("--compare", help="a `hashcc step --double` output folder to diff against")
    ap.add_argument("--check-init", action="store_true", help="check the tensors' initialisation")
    ap.add_argument("--param-subset", type=int, default=PARAM_SUBSET,
                    help="network-tensor entries differenced a tensor (all of a smaller one)")
    ap.add_argument("--param-seed", type=int, default=PARAM_SEED, help="seed of that subset")
    ap.add_argument("--no-params", action="store_true", help="skip the parameter gradients")
    a = ap.parse_args()
    cfg, A = load_inputs(a.inp)
    if a.check_init:
        bad = check_init(cfg, A)
        for b in bad:
            print("init:", b)
        print(f"init: {'FAILED' if bad else 'ok'} ({a.inp})")
        if bad:
            return 1
    if not (a.out or a.compare):
        return 0
    base, grads, notes = camera_gradient(cfg, A)
    files = dict(base)
    for name, g in zip(("pose_r", "pose_t", "focal_ab"), grads):
        files["grad." + name] = g
    pgrad, pnotes = ({}, None) if a.no_params else param_gradient(cfg, A, a.param_subset, a.param_seed)
    for name, (idx, g) in pgrad.items():
        files["fd." + name + ".idx"] = idx        # flat (C-order) indices into the tensor
        files["fd." + name] = g                   # dL/dθ at those indices
    if a.out:
        out = pathlib.Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        for name, v in files.items():
            v = np.asarray(v)
            np.save(out / f"{name}.npy", v if v.dtype == np.int64 else v.astype(np.float64))
    print(f"reference step: {cfg['model']} {cfg.get('field', 'mlp')} loss {float(base['loss']):.17g}"
          f" | camera differences: {notes['fine']} at a finer h, {notes['one_sided']} one-sided,"
          f" {notes['skipped']} skipped | NumPy {np.__version__}")
    if pnotes:
        print(f"parameter differences: {pnotes['entries']} entries of {pnotes['tensors']} tensors"
              f" (up to {a.param_subset} a tensor, numpy default_rng seed {a.param_seed}):"
              f" {pnotes['fine']} at a finer h, {pnotes['one_sided']} one-sided,"
              f" {pnotes['skipped']} skipped")
    if a.compare:
        for name, v in sorted(files.items()):
            if name.startswith("fd.") and not name.endswith(".idx"):
                tensor = name[3:]
                theirs = np.load(pathlib.Path(a.compare) / f"grad.{tensor}.npy").reshape(-1)
                idx = files[name + ".idx"]
                err = np.abs(theirs[idx] - v) / np.maximum(np.abs(theirs[idx]) + np.abs(v), 1e-6)
                print(f"{'grad.' + tensor + ' (fd)':28s} {err.max() if len(v) else 0:.2e}")
            elif not name.startswith("fd."):
                theirs = np.load(pathlib.Path(a.compare) / f"{name}.npy")
                scale = max(np.abs(v).max(), 1e-300)
                print(f"{name:28s} {np.abs(theirs - v).max() / scale:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
