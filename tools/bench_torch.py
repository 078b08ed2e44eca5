#!/usr/bin/env python3
"""tools/bench_torch.py — hashcc's training steps written in PyTorch (CPU): the paper's and the grid field's.

Issue 25 asks for hashcc's step to be ≥ 2× faster than "a PyTorch CPU implementation of the same
step on the same machine". This is that implementation: what a competent PyTorch user would write
from docs/formulas.md and docs/golden-step.md ("What the step computes") — nn.Linear layers,
batched tensors, autograd for every gradient (the camera's included), the hash grid as an integer
index gather (advanced indexing) with trilinear weights, torch.optim.Adam with three parameter groups.
Nothing here calls or imports hashcc; it was written from the docs, with tools/reference_step.py
(the NumPy float64 reference) as a guide to the conventions.

    bench_torch.py [--variant hashcc|sh+grid|hashcc+grid] [--threads N] [--steps K] [--warmup W]
                   [--chunk-rays C] [--json FILE]
    bench_torch.py --check-golden DIR [--check-golden DIR2 ...] [--hashcc BUILD/hashcc]
    bench_torch.py --check-grid [--hashcc BUILD/hashcc]

The timed step is `hashcc bench --variant hashcc`'s (tools/bench.h BenchOptions, Trainer::
step_once): 1,024 rays (32 distinct random rows × 32 distinct random columns of one of 3 training
images, 128 × 96 pixels, like the bench's simulated scene) × 128 jittered samples, width 128,
colour width 64, SH-4 directions, CC hash grid 16 levels × 2 features × 2^9 entries, base 16,
finest 512, CC MLP 32 → 64 → 3, NDC, axis-angle poses + squared focal factors, the loss
MSE(main) + MSE(CC), the CC input detached from the camera, Adam (β 0.9/0.999, ε 1e-8) over the
networks, the poses and the focal with exponentially decaying learning rates, a finite-loss
guard. Forward and backward run per chunk of --chunk-rays rays (default 64, as the bench): the
rays are computed once, each chunk's backward accumulates into the rays' gradient, then one
backward through the camera. --chunk-rays 0 runs the whole step as one batch (131,072 points,
64 MB a width-128 activation, as NeRF-- implementations do); tools/bench_vs_torch.sh times both
and compares the faster.

--variant sh+grid is `hashcc bench --variant sh+grid`'s step instead (docs/math/grid_field.md):
the grid field — a hash grid of 16 levels × 2 features × 2^15 entries (base 16, finest 512; the
levels whose res³ fits the table, 0–3, indexed densely, the rest by the spatial hash), written as
nerfstudio's torch HashEncoding writes it (the corners' indices by integer arithmetic, the rows
gathered by advanced indexing, whose backward is autograd's scatter-add into the table), the
level curriculum when c2f_alpha ≥ 0, the density MLP 32 → 64 → 1 + 15 with σ_raw = exp(min(z,
15)), the colour MLP [15 geometry features, SH-4] → 64 → 3 with a sigmoid — and the smooth
straight-through position gradient of Heo et al. (the training default, grid_smooth): the forward
is trilinear, the position gradient that of the smooth-weight interpolant, written as
y + (h̃ − h̃.detach()) with the table detached in h̃. 1,024 rays × 32 samples, the same camera,
NDC, compositor, loss and Adam as the paper's step; chunks of 256 rays (the bench's automatic
chunk for this field) or the whole batch. hashcc+grid adds the CC branch on top.

--check-grid checks that function at the benched size: the encoding of 4,096 random points (an
eighth on faces and corners) with the 16-level 2^15 grid, the trilinear one against
reference_step.hash_encode and the smooth surrogate against reference_step.smooth_encode, and a
seeded whole step (sh and hashcc on the benched grid field, a 4 × 4 grid of rays × 32 samples,
smooth gradient on): forward and loss against reference_step.py and, with --hashcc BIN, every
output and gradient against `BIN step --double` on the same folder (written to a temp folder).

--check-golden DIR runs the same code in float64 on a `hashcc step` input folder (DIR/in, or DIR
itself when it holds config.json) and compares the forward outputs, the loss and every gradient
with DIR/out (hashcc step --double's files; without DIR/out and with --hashcc BIN, the files of
`BIN step --double` run on the folder) and with tools/reference_step.py's forward; it exits 1 if
any file differs by more than its tolerance.

The BLAS and allocator the process loaded are reported. Debian's python3-torch calls whatever
libblas.so.3 the loader finds — the unoptimised reference BLAS unless OpenBLAS is selected: run
with LD_LIBRARY_PATH=/usr/lib/x86_64-linux-gnu/openblas-openmp (tools/bench_vs_torch.sh does).
"""
import argparse
import json
import math
import os
import pathlib
import statistics
import sys
import time


# --variant → (model, field), as hashcc bench's NAME or NAME+grid.
VARIANTS = {"hashcc": ("hashcc", "mlp"), "sh+grid": ("sh", "grid"), "hashcc+grid": ("hashcc", "grid")}


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--threads", type=int, default=1, help="torch.set_num_threads (default 1)")
    ap.add_argument("--steps", type=int, default=10, help="timed steps (default 10)")
    ap.add_argument("--warmup", type=int, default=2, help="untimed steps first (default 2)")
    ap.add_argument("--rays", type=int, default=1024, help="rays per step, a square grid (default 1024)")
    ap.add_argument("--variant", default="hashcc", choices=sorted(VARIANTS),
                    help="the step: hashcc (the paper's, default), sh+grid or hashcc+grid (the grid field's)")
    ap.add_argument("--samples", type=int, default=0,
                    help="samples per ray (default 128; the grid variants 32, as hashcc bench)")
    ap.add_argument("--width", type=int, default=128, help="main network width (default 128)")
    ap.add_argument("--chunk-rays", type=int, default=-1,
                    help="rays per forward/backward chunk; 0 = the whole step at once (default 64; "
                    "the grid variants 256)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the timings as JSON to this file")
    ap.add_argument("--check-golden", action="append", metavar="DIR",
                    help="check the step in float64 against a golden folder (repeatable)")
    ap.add_argument("--check-grid", action="store_true",
                    help="check the grid field's function at the benched size (see above)")
    ap.add_argument("--hashcc", metavar="BIN", help="with --check-golden: a folder without out/ is "
                    "compared with `BIN step --in IN --out TMP --double` (run here); with "
                    "--check-grid: the seeded step too")
    a = ap.parse_args()
    grid = VARIANTS[a.variant][1] == "grid"
    if a.samples == 0:
        a.samples = 32 if grid else 128
    if a.chunk_rays == -1:
        a.chunk_rays = 256 if grid else 64
    if a.threads < 1 or a.steps < 1 or a.warmup < 0 or a.chunk_rays < 0:
        ap.error("--threads and --steps must be ≥ 1, --warmup and --chunk-rays ≥ 0")
    side = math.isqrt(a.rays)
    if side * side != a.rays:
        ap.error(f"--rays {a.rays}: must be a square (rows × cols grid, e.g. 1024 = 32 × 32)")
    return a


ARGS = parse_args() if __name__ == "__main__" else None
# OpenMP (torch and OpenBLAS-openmp) reads this when it starts: set it before importing torch.
if ARGS is not None:
    os.environ.setdefault("OMP_NUM_THREADS", str(ARGS.threads))

import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.nn as nn  # noqa: E402
import torch.nn.functional as F  # noqa: E402

PRIMES = (1, 2654435761, 805459861)  # formulas.md §5 (tiny-cuda-nn's spatial hash)

# ---------------------------------------------------------------- configuration


def paper_config(width=128, samples=128, rays=1024):
    """The bench's step (BenchOptions defaults, ModelConfig defaults, the simulated scene)."""
    side = math.isqrt(rays)
    return {"model": "hashcc", "H": 96, "W": 128, "samples": samples, "ndc": True,
            "width": width, "rgb_width": 64, "cc_levels": 16, "cc_features": 2,
            "cc_log2_table": 9, "cc_base_res": 16, "cc_max_res": 512, "cc_hidden": 64,
            "rows": side, "cols": side, "c2f_alpha": -1.0}


def grid_config(model="sh", samples=32, rays=1024):
    """`hashcc bench --variant sh+grid` (or hashcc+grid): the grid field's ModelConfig defaults
    (GridFieldConfig: 16 levels × 2 features × 2^15, base 16, finest 512, smooth position
    gradient; density MLP hidden 64, 15 geometry features, colour MLP hidden 64), 32 samples (the
    bench's grid_samples), no level curriculum (the bench's c2f_end = 0), the paper's CC grid."""
    cfg = paper_config(samples=samples, rays=rays)
    cfg.update({"model": model, "field": "grid", "grid_levels": 16, "grid_features": 2,
                "grid_log2_table": 15, "grid_base_res": 16, "grid_max_res": 512,
                "grid_smooth": True, "grid_hidden": 64, "grid_geo": 15, "grid_rgb_hidden": 64})
    return cfg


def variant_config(variant, width=128, samples=128, rays=1024):
    model, field = VARIANTS[variant]
    if field == "grid":
        return grid_config(model, samples, rays)
    return paper_config(width, samples, rays)


# ---------------------------------------------------------------- encodings (formulas.md §4, §8)


def band_weights(n, alpha, like):
    """Coarse-to-fine weights (1 − cos(π·clamp(α − k, 0, 1)))/2 of Fourier band k; 1 when α < 0."""
    if alpha < 0:
        return None
    a = (alpha - torch.arange(n, dtype=like.dtype)).clamp(0.0, 1.0)
    return (1 - torch.cos(math.pi * a)) / 2


def fourier(x, bands, alpha=-1.0):
    """γ(x) = [x, sin(2⁰x), cos(2⁰x), …, sin(2^{L−1}x), cos(2^{L−1}x)], 3-coordinate blocks, no π."""
    freqs = 2.0 ** torch.arange(bands, dtype=x.dtype)
    xb = x[:, None, :] * freqs[:, None]                        # (N, L, 3)
    sc = torch.stack([torch.sin(xb), torch.cos(xb)], dim=2)     # (N, L, 2, 3): band-major
    w = band_weights(bands, alpha, x)
    if w is not None:
        sc = sc * w[:, None, None]
    return torch.cat([x, sc.reshape(len(x), 6 * bands)], dim=1)


SH_C = (0.28209479177387814, 0.48860251190291987, 1.0925484305920792, 0.94617469575755997,
        0.31539156525251999, 0.54627421529603959, 0.59004358992664352, 2.8906114426405538,
        0.45704579946446572, 0.3731763325901154, 1.4453057213202769)


def sh4(u):
    """The 16 real spherical harmonics of degree 4 of unit directions u (R, 3), formulas.md §8."""
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    c = SH_C
    xx, yy, zz = x * x, y * y, z * z
    return torch.stack([
        torch.full_like(x, c[0]), -c[1] * y, c[1] * z, -c[1] * x,
        c[2] * x * y, -c[2] * y * z, c[3] * zz - c[4], -c[2] * x * z, c[5] * (xx - yy),
        c[6] * y * (-3 * xx + yy), c[7] * x * y * z, c[8] * y * (1 - 5 * zz),
        c[9] * z * (5 * zz - 3), c[8] * x * (1 - 5 * zz), c[10] * z * (xx - yy),
        c[6] * x * (-xx + 3 * yy)], dim=1)


# ---------------------------------------------------------------- networks (§4, §5)


class HashGrid(nn.Module):
    """Multiresolution hash encoding (formulas.md §5, tiny-cuda-nn's), as nerfstudio's torch
    HashEncoding computes it: per level, the 8 corners' table rows gathered by integer index
    (advanced indexing: its backward is autograd's scatter-add into the table) and blended with
    trilinear weights. The table (levels, 2^log2_table, features) is its owner's parameter,
    passed in. Inputs x01 are in [0, 1]³ (the caller clamps); the CC branch's carry no gradient
    (the detach rule), the grid field's do: exact (autograd through the trilinear weights) or,
    with smooth=True, Heo et al.'s straight-through one (docs/math/grid_field.md)."""

    def __init__(self, levels, features, log2_table, base, finest):
        super().__init__()
        self.levels, self.features, self.size = levels, features, 2 ** log2_table
        b = 1.0 if levels == 1 else math.exp((math.log(finest) - math.log(base)) / (levels - 1))
        scale, res = [], []
        for lv in range(levels):
            s = base * b ** lv - 1
            if abs(s - round(s)) < 1e-9:
                s = float(round(s))           # rounding in b^l must not move ceil
            scale.append(s)
            res.append(math.ceil(s) + 1)
        self.register_buffer("scale", torch.tensor(scale, dtype=torch.float64), persistent=False)
        res = torch.tensor(res, dtype=torch.int64)
        self.register_buffer("res", res, persistent=False)
        self.register_buffer("dense", res ** 3 <= self.size, persistent=False)
        # res grows with the level, so the dense levels are the first n_dense: their indices and
        # the hashed levels' are computed on their own levels only, and concatenated.
        self.n_dense = int(self.dense.sum())
        self.prefix = bool(self.dense[: self.n_dense].all())
        self.register_buffer("offset", torch.arange(levels) * self.size, persistent=False)
        self.register_buffer("step", torch.tensor([0, 1]), persistent=False)  # a cell's 2 corners

    def forward(self, x01, table, smooth=False):
        """x01 (N, 3) → (N, levels·features), level-major."""
        n = len(x01)
        p = x01[:, None, :] * self.scale.to(x01.dtype)[:, None] + 0.5   # (N, L, 3)
        corner = torch.floor(p)
        frac = p - corner                                               # d frac/d p = 1
        c = corner.long()[..., None] + self.step                        # (N, L, 3, 2): per axis
        idx = (self.index(c) & (self.size - 1)) + self.offset[:, None]  # (N, L, 8) flat-table rows
        # Advanced indexing: its backward is index_put_(accumulate=True), which torch 1.13 runs
        # faster on CPU than the backward of F.embedding or index_select (timed on one chunk).
        rows = table.view(-1, self.features)[idx]                       # (N, L, 8, F)
        # Trilinear weights: the outer product of (1 − f, f) over the axes, laid out like idx.
        # Smooth: the forward's weights carry no position gradient ...
        f = frac.detach() if smooth else frac
        w = self.corners(torch.stack([1 - f, f], dim=-1), torch.mul)
        y = torch.einsum("nlk,nlkf->nlf", w, rows)
        if smooth and frac.requires_grad:
            # ... the smooth-weight interpolant h̃ (weights δ(f) = (1 − cos πf)/2, the table
            # detached) does: y + (h̃ − h̃.detach()) has y's value (the difference is exactly 0)
            # and h̃'s position gradient, Σ_k s_k ∂w̃_k/∂f · scale_l.
            t = (1 - torch.cos(math.pi * frac)) / 2
            ws = self.corners(torch.stack([1 - t, t], dim=-1), torch.mul)
            hs = torch.einsum("nlk,nlkf->nlf", ws, rows.detach())
            y = y + (hs - hs.detach())
        return y.reshape(n, self.levels * self.features)

    def smooth_interpolant(self, x01, table):
        """h̃(x01) itself, the smooth-weight interpolant whose gradient the straight-through
        forward returns (for --check-grid: compared with reference_step.smooth_encode)."""
        p = x01[:, None, :] * self.scale.to(x01.dtype)[:, None] + 0.5
        corner = torch.floor(p)
        t = (1 - torch.cos(math.pi * (p - corner))) / 2
        c = corner.long()[..., None] + self.step
        idx = (self.index(c) & (self.size - 1)) + self.offset[:, None]
        ws = self.corners(torch.stack([1 - t, t], dim=-1), torch.mul)
        rows = table.view(-1, self.features)[idx]
        return torch.einsum("nlk,nlkf->nlf", ws, rows).reshape(len(x01), self.levels * self.features)

    def corners(self, t, op):
        """Per-axis pairs t (N, L', 3, 2) → (N, L', 8) by op over the 8 corners; corner k =
        x + 2y + 4z (bit 0 = x), i.e. laid out (z, y, x) so that it flattens to k."""
        zy = op(t[:, :, 2, :, None], t[:, :, 1, None, :])               # (N, L', 2, 2)
        return op(zy[..., None], t[:, :, 0, None, None, :]).reshape(t.shape[0], t.shape[1], 8)

    def index(self, c):
        """Corner coordinates per axis c (N, L, 3, 2) → the 8 corners' table index before the
        modulo: dense (x + y·res + z·res²) where res³ fits the table, else the XOR hash in
        uint32. The products are taken per axis and combined by broadcasting, each kind on the
        levels that use it (the paper's CC grid: all 16 hashed; the grid field's: 4 dense, 12
        hashed)."""
        mult = torch.stack([torch.ones_like(self.res), self.res, self.res * self.res], 1)
        primes = torch.tensor(PRIMES, dtype=torch.int64)[:, None]
        dense = lambda cc, m: self.corners(cc * m[:, :, None], torch.add)
        hashed = lambda cc: self.corners(cc * primes, torch.bitwise_xor) & 0xFFFFFFFF  # uint32
        nd = self.n_dense
        if nd == 0:
            return hashed(c)
        if nd == self.levels:
            return dense(c, mult)
        if self.prefix:
            return torch.cat([dense(c[:, :nd], mult[:nd]), hashed(c[:, nd:])], dim=1)
        return torch.where(self.dense[:, None], dense(c, mult), hashed(c))


class ColourCorrection(nn.Module):
    """Δc = cc.1 · relu(cc.0 · hash(p)), no output activation (formulas.md §5). Submodules are
    named "0" and "1" so the state dict reads cc.table, cc.0.weight, … as the golden files do."""

    def __init__(self, cfg):
        super().__init__()
        self.grid = HashGrid(cfg["cc_levels"], cfg["cc_features"], cfg["cc_log2_table"],
                             cfg["cc_base_res"], cfg["cc_max_res"])
        self.table = nn.Parameter(torch.empty(self.grid.levels, self.grid.size, cfg["cc_features"])
                                  .uniform_(-1e-4, 1e-4))         # features start uniform ±1e-4
        self.add_module("0", nn.Linear(cfg["cc_levels"] * cfg["cc_features"], cfg["cc_hidden"]))
        self.add_module("1", nn.Linear(cfg["cc_hidden"], 3))

    def forward(self, p):
        return getattr(self, "1")(F.relu(getattr(self, "0")(self.grid(p, self.table)), inplace=True))


class NeRFmmHashCC(nn.Module):
    """The paper's field (formulas.md §4) and, for hashcc, the CC branch. nn.Linear's default
    init is the spec's (uniform ±1/√fan_in); density bias 0.1, colour bias 0.02."""

    def __init__(self, cfg):
        super().__init__()
        w, rw = cfg["width"], cfg["rgb_width"]
        self.model, self.c2f_alpha = cfg["model"], cfg.get("c2f_alpha", -1.0)
        self.trunk = nn.ModuleList([nn.Linear(63 if k == 0 else w + 63 if k == 4 else w, w)
                                    for k in range(8)])
        self.density = nn.Linear(w, 1)
        self.feature = nn.Linear(w, w)
        self.rgb_hidden = nn.Linear(w + (27 if self.model == "nerfmm" else 16), rw)
        self.rgb = nn.Linear(rw, 3)
        with torch.no_grad():
            self.density.bias.fill_(0.1)
            self.rgb.bias.fill_(0.02)
        self.cc = ColourCorrection(cfg) if self.model == "hashcc" else None

    def dir_encoding(self, u):
        return fourier(u, 4) if self.model == "nerfmm" else sh4(u)

    def forward(self, x, enc_dir):
        """x (N, 3) samples, enc_dir (N, E) → σ_raw (N,), c (N, 3)."""
        g = fourier(x, 10, self.c2f_alpha)
        h = g
        for k, layer in enumerate(self.trunk):
            if k == 4:
                h = torch.cat([h, g], dim=1)             # concat order [h, γ(x)]
            h = F.relu(layer(h), inplace=True)
        sigma_raw = self.density(h)[:, 0]
        feat = self.feature(h)                           # no activation
        hid = F.relu(self.rgb_hidden(torch.cat([feat, enc_dir], dim=1)), inplace=True)
        return sigma_raw, torch.sigmoid(self.rgb(hid))


class GridParams(nn.Module):
    """The grid field's tensors under the golden files' names (grid.table, grid.density.{0,1},
    grid.rgb.{0,1}); nn.Linear's default init is the spec's uniform ±1/√fan_in, the table
    uniform ±1e-4 (formulas.md §5)."""

    def __init__(self, cfg, dir_dim):
        super().__init__()
        L, F, T = cfg["grid_levels"], cfg["grid_features"], cfg["grid_log2_table"]
        G = cfg["grid_geo"]
        self.enc = HashGrid(L, F, T, cfg["grid_base_res"], cfg["grid_max_res"])
        self.table = nn.Parameter(torch.empty(L, 2 ** T, F).uniform_(-1e-4, 1e-4))
        self.density = nn.Sequential(nn.Linear(L * F, cfg["grid_hidden"]), nn.Linear(cfg["grid_hidden"], 1 + G))
        self.rgb = nn.Sequential(nn.Linear(G + dir_dim, cfg["grid_rgb_hidden"]),
                                 nn.Linear(cfg["grid_rgb_hidden"], 3))


class GridField(nn.Module):
    """docs/math/grid_field.md: u = clamp((x + 1)/2, 0, 1) → hash grid (× the level weights
    w_l(α) when α ≥ 0) → h = relu(density.0 ỹ) → [z, g] = density.1 h → σ_raw = exp(min(z, 15));
    c = sigmoid(rgb.1 relu(rgb.0 [g, e(dir)])). The position gradient: smooth straight-through
    with grid_smooth (the training default), else exact. With hashcc, the CC branch on top."""

    def __init__(self, cfg):
        super().__init__()
        self.model, self.c2f_alpha = cfg["model"], cfg.get("c2f_alpha", -1.0)
        self.smooth = bool(cfg.get("grid_smooth", False))
        self.grid = GridParams(cfg, 27 if self.model == "nerfmm" else 16)
        self.cc = ColourCorrection(cfg) if self.model == "hashcc" else None

    def dir_encoding(self, u):
        return fourier(u, 4) if self.model == "nerfmm" else sh4(u)

    def forward(self, x, enc_dir):
        g = self.grid
        y = g.enc(((x + 1) / 2).clamp(0, 1), g.table, self.smooth)
        w = band_weights(g.enc.levels, self.c2f_alpha, y)
        if w is not None:
            y = y * w.repeat_interleave(g.enc.features)
        zg = g.density[1](F.relu(g.density[0](y), inplace=True))
        sigma_raw = torch.exp(torch.clamp(zg[:, 0], max=15.0))
        hid = F.relu(g.rgb[0](torch.cat([zg[:, 1:], enc_dir], dim=1)), inplace=True)
        return sigma_raw, torch.sigmoid(g.rgb[1](hid))


def make_model(cfg):
    return GridField(cfg) if cfg.get("field", "mlp") == "grid" else NeRFmmHashCC(cfg)


class Cameras(nn.Module):
    """Per image an axis-angle r and a centre t (both 0 at the start); one focal pair a, b
    (fx = a²W, fy = b²H, both 1 at the start). formulas.md §1."""

    def __init__(self, n):
        super().__init__()
        self.pose_r = nn.Parameter(torch.zeros(n, 3))
        self.pose_t = nn.Parameter(torch.zeros(n, 3))
        self.focal_ab = nn.Parameter(torch.ones(2))
        self.P0 = None  # optional fixed (3, 4) [R0 | t0] of image 0 (golden_p0): c2w = [Exp(r) | t]·P0


# ---------------------------------------------------------------- camera, NDC (§1, §2)


def rodrigues(r):
    """R = I + (sin θ/θ)[r]× + ((1 − cos θ)/θ²)[r]×², Taylor series for θ < 1e-4 (the poses
    start at exactly 0, where sqrt's derivative is infinite: the unused branch sees θ² = 1)."""
    th2 = (r * r).sum()
    small = th2 < 1e-8
    safe = torch.where(small, torch.ones_like(th2), th2)
    th = torch.sqrt(safe)
    a = torch.where(small, 1 - th2 / 6 + th2 * th2 / 120, torch.sin(th) / th)
    b = torch.where(small, 0.5 - th2 / 24 + th2 * th2 / 720, (1 - torch.cos(th)) / safe)
    z = torch.zeros_like(r[0])
    K = torch.stack([torch.stack([z, -r[2], r[1]]), torch.stack([r[2], z, -r[0]]),
                     torch.stack([-r[1], r[0], z])])
    return torch.eye(3, dtype=r.dtype) + a * K + b * (K @ K)


def make_rays(cfg, cams, img, rows, cols):
    """Ray k = pixel (u, v) = (cols[k % C], rows[k // C]) of image img → (o', d') (NDC)."""
    H, W = cfg["H"], cfg["W"]
    dt = cams.focal_ab.dtype
    v = rows.repeat_interleave(len(cols)).to(dt)         # row-major over the R × C grid
    u = cols.repeat(len(rows)).to(dt)
    fx = cams.focal_ab[0] ** 2 * W
    fy = fx if cfg.get("fx_only", False) else cams.focal_ab[1] ** 2 * H
    dc = torch.stack([(u - W / 2) / fx, -(v - H / 2) / fy, -torch.ones_like(u)], dim=1)
    R = rodrigues(cams.pose_r[img])
    if cams.P0 is None:
        d = dc @ R.T                                     # d = R·d_c, not normalised
        o = cams.pose_t[img].expand_as(d)
    else:                                                # d = R·R0·d_c, o = R·t0 + t
        d = dc @ (R @ cams.P0[:, :3]).T
        o = (R @ cams.P0[:, 3] + cams.pose_t[img]).expand_as(d)
    if not cfg["ndc"]:
        return o, d
    o = o + (-(1 + o[:, 2]) / d[:, 2])[:, None] * d      # onto the near plane z = −1
    ox, oy, oz = o[:, 0], o[:, 1], o[:, 2]
    dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
    kx, ky = 2 * fx / W, 2 * fy / H
    o2 = torch.stack([-kx * ox / oz, -ky * oy / oz, 1 + 2 / oz], dim=1)
    d2 = torch.stack([-kx * (dx / dz - ox / oz), -ky * (dy / dz - oy / oz), -2 / oz], dim=1)
    return o2, d2


# ---------------------------------------------------------------- rays → loss (§3, §5, §6)


def composite_weights(sigma, s):
    """w_i = T_i α_i, α = 1 − exp(−σδ), δ_i = s_{i+1} − s_i (last 1e10), T_i = Π_{j<i}(1 − α_j + 1e-10)."""
    delta = torch.cat([s[:, 1:] - s[:, :-1], torch.full_like(s[:, :1], 1e10)], dim=1)
    alpha = 1 - torch.exp(-sigma * delta)
    trans = torch.cumprod(torch.cat([torch.ones_like(s[:, :1]), 1 - alpha[:, :-1] + 1e-10], dim=1), 1)
    return trans * alpha


def render_rays(model, o, d, s, target, n_total, cc_x=None):
    """Rays (r, 3) with samples s (r, S) → outputs and this chunk's share of the loss: each MSE is
    the mean over all n_total·3 numbers of the step (golden-step.md item 8)."""
    r, S = s.shape
    x = (o[:, None, :] + s[:, :, None] * d[:, None, :]).reshape(r * S, 3)   # ray-major
    u = d / d.norm(dim=1, keepdim=True)
    enc = model.dir_encoding(u)
    enc = enc[:, None, :].expand(r, S, enc.shape[1]).reshape(r * S, -1)    # per ray → samples
    sigma_raw, c = model(x, enc)
    w = composite_weights(F.relu(sigma_raw).view(r, S), s)
    rgb = (w[:, :, None] * c.view(r, S, 3)).sum(1)
    out = {"rgb_main": rgb, "depth": (w * s).sum(1), "x": x}
    loss = ((rgb - target) ** 2).sum() / (3 * n_total)
    if model.cc is not None:
        # The detach rule (formulas.md §5): the CC input sends no gradient to x, so none to the camera.
        p = (((x if cc_x is None else cc_x) + 1) / 2).clamp(0, 1).detach()
        cc = c + model.cc(p)                                              # Δc before compositing
        out["rgb_cc"] = (w[:, :, None] * cc.view(r, S, 3)).sum(1)
        loss = loss + ((out["rgb_cc"] - target) ** 2).sum() / (3 * n_total)
    out["loss"] = loss
    return out


def forward_backward(cfg, model, cams, batch, chunk_rays, keep=False):
    """One step's loss and every gradient (accumulated into .grad). chunk_rays > 0: the rays are
    computed once, each chunk's forward + backward runs alone (its activations freed before the
    next) and accumulates the rays' gradient, then one backward through the camera. keep:
    return the outputs too (the golden check)."""
    o, d = make_rays(cfg, cams, batch["img"], batch["rows"], batch["cols"])
    R = len(o)
    chunk = R if chunk_rays <= 0 else chunk_rays
    o_in, d_in = (o, d) if chunk >= R else (o.detach().requires_grad_(), d.detach().requires_grad_())
    loss, outs = 0.0, []
    for a in range(0, R, chunk):
        sl = slice(a, a + chunk)
        cc_x = None if batch.get("cc_x") is None else batch["cc_x"].view(R, -1, 3)[sl].reshape(-1, 3)
        out = render_rays(model, o_in[sl], d_in[sl], batch["s"][sl], batch["target"][sl], R, cc_x)
        out["loss"].backward()
        loss += float(out["loss"])
        if keep:
            outs.append({k: v.detach() for k, v in out.items() if k != "loss"})
    if chunk < R:
        torch.autograd.backward([o, d], [o_in.grad, d_in.grad])
    if not keep:
        return loss, None
    res = {k: torch.cat([q[k] for q in outs]) for k in outs[0]}
    res.update(rays_o=o.detach(), rays_d=d.detach())
    return loss, res


# ---------------------------------------------------------------- the golden check


def load_golden(d):
    """DIR/in (+ DIR/out when present) or an input folder itself → (cfg, arrays, in, out)."""
    d = pathlib.Path(d)
    inp = d / "in" if (d / "in" / "config.json").is_file() else d
    if not (inp / "config.json").is_file():
        raise SystemExit(f"bench_torch: {d}: no config.json in it or in {d / 'in'}")
    out = d / "out" if inp != d and (d / "out" / "loss.npy").is_file() else None
    cfg = {"width": 128, "rgb_width": 64, "cc_hidden": 64, "cc_levels": 16, "cc_features": 2,
           "cc_log2_table": 9, "cc_base_res": 16, "cc_max_res": 512, "c2f_alpha": -1.0}
    cfg.update(json.loads((inp / "config.json").read_text()))
    return cfg, {f.stem: np.load(f) for f in inp.glob("*.npy")}, inp, out


def golden_files(cfg, A, chunk):
    """Runs the step in float64 on the golden inputs → {file name: array} as `hashcc step` names
    its outputs (forward outputs, loss, grad.<every parameter>)."""
    model, cams = make_model(cfg).double(), Cameras(1).double()
    inputs = {"image", "rows", "cols", "s", "pose_r", "pose_t", "focal_ab", "cc_x", "P0"}
    params = dict(model.named_parameters())
    unknown = set(A) - inputs - set(params)
    missing = set(params) - set(A)
    if unknown or missing:
        raise SystemExit(f"bench_torch: golden folder: unexpected {sorted(unknown)}, missing {sorted(missing)}")
    with torch.no_grad():
        for name, p in params.items():
            p.copy_(torch.from_numpy(A[name].astype(np.float64)).view(p.shape))
        cams.pose_r[0] = torch.from_numpy(A["pose_r"].astype(np.float64))
        cams.pose_t[0] = torch.from_numpy(A["pose_t"].astype(np.float64))
        cams.focal_ab.copy_(torch.from_numpy(A["focal_ab"].astype(np.float64)))
    if "P0" in A:
        cams.P0 = torch.from_numpy(A["P0"].astype(np.float64))
    rows, cols = torch.from_numpy(A["rows"].astype(np.int64)), torch.from_numpy(A["cols"].astype(np.int64))
    image = torch.from_numpy(A["image"].astype(np.float64))
    batch = {"img": 0, "rows": rows, "cols": cols, "s": torch.from_numpy(A["s"].astype(np.float64)),
             "target": image[rows.repeat_interleave(len(cols)), cols.repeat(len(rows))],
             "cc_x": torch.from_numpy(A["cc_x"].astype(np.float64)) if "cc_x" in A else None}
    loss, res = forward_backward(cfg, model, cams, batch, chunk, keep=True)
    files = {k: v.numpy() for k, v in res.items()}
    files["loss"] = np.array(loss)
    for name, p in params.items():
        files["grad." + name] = p.grad.numpy()
    for name in ("pose_r", "pose_t"):
        files["grad." + name] = getattr(cams, name).grad[0].numpy()
    files["grad.focal_ab"] = cams.focal_ab.grad.numpy()
    return files


def reference_module():
    """tools/reference_step.py, loaded from beside this file (it is not a package)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "reference_step", pathlib.Path(__file__).with_name("reference_step.py"))
    ref = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ref)
    return ref


def check_paper_grid(n=4096, seed=7):
    """The golden folders' CC grids are tiny (finest 32); the benched one is the paper's (16
    levels, 2^9 entries, finest 512: every level hashed, corner coordinates up to 513). Its
    encoding of random points in float64 against reference_step.hash_encode, a random table
    of ±1 so that every level counts. Returns the largest difference over the largest entry."""
    cfg = paper_config()
    g = torch.Generator().manual_seed(seed)
    cc = ColourCorrection(cfg).double()
    x = torch.rand(n, 3, generator=g, dtype=torch.float64)
    x[: n // 8] = torch.randint(0, 2, (n // 8, 3), generator=g).double()  # faces and corners
    with torch.no_grad():
        cc.table.uniform_(-1, 1, generator=g)
        ours = cc.grid(x, cc.table).numpy()
    theirs = reference_module().hash_encode(x.numpy(), cc.table.detach().numpy(),
                                            cfg["cc_base_res"], cfg["cc_max_res"], [])
    return float(np.abs(ours - theirs).max() / np.abs(theirs).max())


def grid_points(n, g):
    """n random points of [0, 1]³, the first eighth on cell faces and the cube's corners."""
    x = torch.rand(n, 3, generator=g, dtype=torch.float64)
    x[: n // 8] = torch.randint(0, 2, (n // 8, 3), generator=g).double()
    return x


def check_bench_grid_encoding(n=4096, seed=11):
    """The benched grid field's hash grid (16 levels × 2 × 2^15, base 16, finest 512: levels 0–3
    dense, 4–15 hashed) on n random points, float64, a random table of ±1: the trilinear encoding
    against reference_step.hash_encode and the smooth interpolant h̃ (whose gradient is the
    straight-through one) against reference_step.smooth_encode. Returns both worst relative
    differences and the number of dense levels."""
    cfg = grid_config()
    g = torch.Generator().manual_seed(seed)
    enc = HashGrid(cfg["grid_levels"], cfg["grid_features"], cfg["grid_log2_table"],
                   cfg["grid_base_res"], cfg["grid_max_res"])
    table = torch.empty(enc.levels, enc.size, enc.features, dtype=torch.float64).uniform_(-1, 1, generator=g)
    x = grid_points(n, g)
    ref = reference_module()
    with torch.no_grad():
        ours, ours_s = enc(x, table).numpy(), enc.smooth_interpolant(x, table).numpy()
    args = (table.numpy(), cfg["grid_base_res"], cfg["grid_max_res"], [])
    theirs, theirs_s = ref.hash_encode(x.numpy(), *args), ref.smooth_encode(x.numpy(), *args)
    rel = lambda a, b: float(np.abs(a - b).max() / np.abs(b).max())
    return rel(ours, theirs), rel(ours_s, theirs_s), enc.n_dense


GOLDEN_KEYS = {"model", "H", "W", "samples", "ndc", "width", "rgb_width", "cc_hidden", "cc_levels",
               "cc_features", "cc_log2_table", "cc_base_res", "cc_max_res", "field", "grid_levels",
               "grid_features", "grid_log2_table", "grid_base_res", "grid_max_res", "grid_smooth",
               "grid_hidden", "grid_geo", "grid_rgb_hidden", "c2f_alpha", "fx_only"}


def write_bench_grid_inputs(d, model, seed, side=4):
    """A `hashcc step` input folder (docs/golden-step.md) at the benched grid field's size: the
    bench's 128 × 96 image (random colours), a side × side grid of distinct rows and columns, 32
    jittered samples a ray, a pose within ±0.05 of identity, focal factors 1 ± 0.05, the networks
    initialised as the engine does (uniform ±1/√fan_in) but the tables uniform ±0.5 (not ±1e-4,
    so that the grid and its position gradient decide the outputs), the smooth gradient on."""
    d = pathlib.Path(d)
    d.mkdir(parents=True, exist_ok=True)
    cfg = grid_config(model)
    torch.manual_seed(seed)
    g = torch.Generator().manual_seed(seed)
    net = make_model(cfg).double()
    with torch.no_grad():
        for name, p in net.named_parameters():
            if name.endswith("table"):
                p.uniform_(-0.5, 0.5, generator=g)
    H, W, S = cfg["H"], cfg["W"], cfg["samples"]
    arrays = {name: p.detach().numpy() for name, p in net.named_parameters()}
    arrays.update({
        "image": torch.rand(H, W, 3, generator=g, dtype=torch.float64).numpy(),
        "rows": torch.randperm(H, generator=g)[:side].numpy().astype(np.int64),
        "cols": torch.randperm(W, generator=g)[:side].numpy().astype(np.int64),
        "s": ((torch.arange(S, dtype=torch.float64) + torch.rand(side * side, S, generator=g,
                                                                   dtype=torch.float64)) / S).numpy(),
        "pose_r": (torch.rand(3, generator=g, dtype=torch.float64) * 0.1 - 0.05).numpy(),
        "pose_t": (torch.rand(3, generator=g, dtype=torch.float64) * 0.1 - 0.05).numpy(),
        "focal_ab": (1 + torch.rand(2, generator=g, dtype=torch.float64) * 0.1 - 0.05).numpy()})
    for name, a in arrays.items():
        np.save(d / f"{name}.npy", a)
    conf = {k: v for k, v in cfg.items() if k in GOLDEN_KEYS}
    (d / "config.json").write_text(json.dumps(conf, indent=1) + "\n")
    return d


def check_grid(binary=None):
    """--check-grid: the grid field's function at the benched size (module docstring). 0 / 1."""
    import tempfile
    failed = []
    tri, smooth, n_dense = check_bench_grid_encoding()
    print(f"benched grid field's hash grid (16 levels × 2 × 2^15, base 16, finest 512; {n_dense} "
          f"dense levels), 4,096 points, float64, against reference_step.py: trilinear {tri:.2e}, "
          f"smooth interpolant {smooth:.2e}")
    if not (tri <= TOL_FORWARD and smooth <= TOL_FORWARD):
        failed.append("the benched grid field's hash grid")
    tmp = tempfile.TemporaryDirectory(prefix="bench_torch_grid_")
    for i, model in enumerate(("sh", "hashcc")):
        inp = write_bench_grid_inputs(pathlib.Path(tmp.name) / f"in_{model}", model, seed=20 + i)
        cfg, A, _, _ = load_golden(inp)
        ref = reference_forward(inp)
        out = hashcc_step(binary, inp, pathlib.Path(tmp.name) / f"out_{model}") if binary else None
        theirs = {} if out is None else {f.stem: np.load(f) for f in out.glob("*.npy")}
        for chunk in (0, 2):
            ours = golden_files(cfg, A, chunk)
            print(f"seeded {model}+grid step at the benched size (4 × 4 rays × 32 samples, smooth "
                  f"gradient), chunk {chunk or 'whole batch'}, loss {float(ours['loss']):.17g}")
            w_ref, bad_ref = compare(ours, ref, "reference")
            w_out, bad_out = (0.0, []) if out is None else compare(ours, theirs, "hashcc")
            n_grad = sum(k.startswith("grad.") for k in theirs)
            print(f"  worst: {w_ref:.2e} against reference_step.py (forward, loss), "
                  f"{w_out:.2e} against {'hashcc step --double' if out else '(no --hashcc)'} "
                  f"({len(theirs)} files, {n_grad} gradients)")
            failed += [f"{model}+grid chunk {chunk}: {b}" for b in bad_ref + bad_out]
    for f in failed:
        print("FAILED:", f)
    print("grid check:", "FAILED" if failed else "ok")
    return 1 if failed else 0


def reference_forward(inp):
    """tools/reference_step.py's forward outputs and loss on the same folder (NumPy, float64)."""
    ref = reference_module()
    cfg, A = ref.load_inputs(inp)
    out, _ = ref.step(cfg, A, (A["pose_r"], A["pose_t"], A["focal_ab"]), cc_x=A.get("cc_x"))
    return out


# Tolerances, each file's largest difference over its largest entry (the loss: relative). Both
# sides are float64 evaluations of the same formulas in a different order (and hashcc's Fourier
# bands by a recurrence, ~1e-13 at band 9), so agreement is expected near 1e-13; 1e-9 is the
# bound tools/reference_step.py's test uses, and far below any convention error (a swapped
# concat order moves the loss by ≥ 1e-4, docs/golden-step.md).
TOL_FORWARD, TOL_GRAD = 1e-9, 1e-9


def compare(ours, theirs, label):
    """Prints and returns the worst relative difference per file; names the failures."""
    worst, bad = 0.0, []
    for name in sorted(theirs):
        if name not in ours:
            continue
        a, b = np.asarray(ours[name], np.float64), np.asarray(theirs[name], np.float64)
        if a.shape != b.shape:
            bad.append(f"{name}: shape {a.shape} vs {b.shape}")
            continue
        rel = float(np.abs(a - b).max()) / max(float(np.abs(b).max()), 1e-300)
        tol = TOL_GRAD if name.startswith("grad.") else TOL_FORWARD
        worst = max(worst, rel)
        print(f"  {label:9s} {name:24s} {rel:.2e}{'  > tolerance ' + format(tol, '.0e') if rel > tol else ''}")
        if rel > tol:
            bad.append(name)
    return worst, bad


def hashcc_step(binary, inp, tmp):
    """`hashcc step --in inp --out tmp --double`: the engine's float64 files for this folder."""
    import subprocess
    r = subprocess.run([binary, "step", "--in", str(inp), "--out", str(tmp), "--double"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"bench_torch: {binary} step failed ({r.returncode}): {r.stderr.strip()}")
    return pathlib.Path(tmp)


def check_golden(dirs, binary=None):
    """--check-golden: every folder, whole-batch and chunked (2 rays a chunk). Returns 0 / 1."""
    import tempfile
    failed = []
    tmp = tempfile.TemporaryDirectory(prefix="bench_torch_golden_")
    for i, d in enumerate(dirs):
        cfg, A, inp, out = load_golden(d)
        if out is None and binary:
            out = hashcc_step(binary, inp, pathlib.Path(tmp.name) / str(i))
        ref = reference_forward(inp)
        theirs = {} if out is None else {f.stem: np.load(f) for f in out.glob("*.npy")}
        for chunk in (0, 2):
            ours = golden_files(cfg, A, chunk)
            print(f"{d}: {cfg['model']}, chunk {chunk or 'whole batch'}, loss {float(ours['loss']):.17g}")
            w_ref, bad_ref = compare(ours, ref, "reference")
            w_out, bad_out = (0.0, []) if out is None else compare(ours, theirs, "hashcc")
            n_grad = sum(k.startswith("grad.") for k in theirs)
            print(f"  worst: {w_ref:.2e} against reference_step.py (forward, loss), "
                  f"{w_out:.2e} against {out or '(no out/ folder)'} ({len(theirs)} files, {n_grad} gradients)")
            failed += [f"{d} chunk {chunk}: {b}" for b in bad_ref + bad_out]
    grid = check_paper_grid()
    print(f"paper-config CC hash grid (16 levels, 2^9, finest 512) against reference_step.py: {grid:.2e}")
    if not grid <= TOL_FORWARD:
        failed.append("the paper-config hash grid")
    for f in failed:
        print("FAILED:", f)
    print("golden check:", "FAILED" if failed else "ok")
    return 1 if failed else 0


# ---------------------------------------------------------------- the timed training step


def exp_decay(lr0, lr_end, step, total):
    """formulas.md §6: lr0 · (lr_end / lr0)^(step / total)."""
    return lr0 * (lr_end / lr0) ** (min(step, total) / total)


class TrainStep:
    """The bench's trainer: the simulated scene's size (128 × 96, 4 views, every 8th held out:
    3 training images; random pixels — the step's cost does not depend on them), fresh networks
    and cameras, Adam with three groups, the planned run as long as the bench's (2^30 steps)."""

    LR = {"net": (1e-3, 1e-5), "poses": (1e-3, 1e-8), "focal": (1e-3, 1e-8)}
    TOTAL = 2 ** 30

    def __init__(self, cfg, chunk_rays, seed):
        torch.manual_seed(seed)
        self.cfg, self.chunk = cfg, chunk_rays
        self.gen = torch.Generator().manual_seed(seed + 1)
        views = 4
        self.train = [i for i in range(views) if i % 8 != 0]
        self.images = torch.randint(0, 256, (len(self.train), cfg["H"], cfg["W"], 3),
                                    dtype=torch.uint8, generator=self.gen)
        self.model, self.cams = make_model(cfg), Cameras(len(self.train))
        self.opt = torch.optim.Adam([
            {"params": self.model.parameters(), "name": "net"},
            {"params": [self.cams.pose_r, self.cams.pose_t], "name": "poses"},
            {"params": [self.cams.focal_ab], "name": "focal"}], lr=1e-3, betas=(0.9, 0.999), eps=1e-8)
        self.n_step, self.perm = 0, None

    def batch(self):
        """One image per step (a shuffled order per epoch), distinct random rows and columns,
        jittered samples s_i = (i + U[0, 1))/S (formulas.md §3, §6)."""
        cfg, n = self.cfg, len(self.train)
        if self.n_step % n == 0:
            self.perm = torch.randperm(n, generator=self.gen)
        img = int(self.perm[self.n_step % n])
        rows = torch.randperm(cfg["H"], generator=self.gen)[: cfg["rows"]]
        cols = torch.randperm(cfg["W"], generator=self.gen)[: cfg["cols"]]
        target = self.images[img][rows][:, cols].reshape(-1, 3).float() / 255
        R, S = len(rows) * len(cols), cfg["samples"]
        s = (torch.arange(S, dtype=torch.float32) + torch.rand(R, S, generator=self.gen)) / S
        return {"img": img, "rows": rows, "cols": cols, "s": s, "target": target}

    def step(self):
        for g in self.opt.param_groups:
            g["lr"] = exp_decay(*self.LR[g["name"]], self.n_step, self.TOTAL)
        batch = self.batch()
        self.opt.zero_grad(set_to_none=True)
        loss, _ = forward_backward(self.cfg, self.model, self.cams, batch, self.chunk)
        if math.isfinite(loss):       # the guard: a non-finite step is not applied
            self.opt.step()
        self.n_step += 1
        return loss


def machine_info():
    """CPU model and ISA, the BLAS and allocator this process loaded, the load average."""
    info, flags = {}, set()
    for line in open("/proc/cpuinfo"):
        key, _, val = line.partition(":")
        key = key.strip()
        if key in ("model name", "cpu family", "model") and key not in info:
            info[key] = val.strip()
        if key == "flags" and not flags:
            flags = set(val.split())
    cpu = (f"{info.get('model name', '?')} (family {info.get('cpu family', '?')}, "
           f"model {info.get('model', '?')})")
    isa = "avx512" if "avx512f" in flags else "avx2+fma" if {"avx2", "fma"} <= flags else "sse/other"
    libs = [ln.split()[-1] for ln in open("/proc/self/maps") if ln.rstrip().endswith(".so") or ".so." in ln]
    blas = sorted({p for p in libs if "blas" in p.lower()})
    alloc = sorted({p for p in libs if "tcmalloc" in p or "jemalloc" in p}) or ["glibc malloc"]
    cap = [ln.split(":", 1)[1].strip() for ln in torch.__config__.show().splitlines()
           if "CPU capability" in ln]
    return {"cpu_model": cpu, "cpu_isa": isa, "torch": torch.__version__,
            "torch_cpu_capability": cap[0] if cap else "?", "blas": blas, "allocator": alloc,
            "load_average": [float(v) for v in open("/proc/loadavg").read().split()[:3]]}


def run_bench(a):
    torch.set_num_threads(a.threads)
    cfg = variant_config(a.variant, a.width, a.samples, a.rays)
    tr = TrainStep(cfg, a.chunk_rays, a.seed)
    info = machine_info()
    if any("/blas/" in p for p in info["blas"]):  # Debian's reference BLAS, not OpenBLAS
        print("bench_torch: WARNING: the reference BLAS is loaded (slow); run with "
              "LD_LIBRARY_PATH=/usr/lib/x86_64-linux-gnu/openblas-openmp", file=sys.stderr)
    for _ in range(a.warmup):
        tr.step()
    ms, cpu0, losses = [], time.process_time(), []
    for _ in range(a.steps):
        t0 = time.perf_counter()
        losses.append(tr.step())
        ms.append((time.perf_counter() - t0) * 1e3)
    cpu_ms = (time.process_time() - cpu0) * 1e3 / a.steps
    info["load_after"] = [float(v) for v in open("/proc/loadavg").read().split()[:3]]
    r = {"implementation": "pytorch", "variant": a.variant, "threads": a.threads,
         "rays": a.rays, "samples": a.samples, "width": a.width, "chunk_rays": a.chunk_rays,
         "warmup": a.warmup, "steps": a.steps, "ms": ms, "ms_median": statistics.median(ms),
         "ms_min": min(ms), "ms_max": max(ms), "cpu_ms_per_step": cpu_ms,
         "loss_first": losses[0], "loss_last": losses[-1], **info}
    print(f"pytorch {torch.__version__} {a.variant} step, {a.threads} thread(s), {a.rays} rays × "
          f"{a.samples} samples{'' if cfg.get('field') == 'grid' else f', width {a.width}'}, chunk {a.chunk_rays or 'whole batch'}: median "
          f"{r['ms_median']:.1f} ms/step (min {r['ms_min']:.1f}, max {r['ms_max']:.1f}, "
          f"{a.steps} steps), CPU {cpu_ms:.1f} ms/step | {info['cpu_model']} ({info['cpu_isa']}), "
          f"BLAS {','.join(info['blas']) or '?'}, allocator {','.join(info['allocator'])}, "
          f"load {info['load_average'][0]:.2f} → {info['load_after'][0]:.2f}")
    if a.json:
        pathlib.Path(a.json).write_text(json.dumps(r, indent=1) + "\n")
        print(f"wrote {a.json}")
    return 0


def main(a):
    if a.check_golden or a.check_grid:
        rc = check_golden(a.check_golden, a.hashcc) if a.check_golden else 0
        return max(rc, check_grid(a.hashcc) if a.check_grid else 0)
    return run_bench(a)


if __name__ == "__main__":
    sys.exit(main(ARGS))
