#!/usr/bin/env python3
"""The floor of one grid-field frame on this machine (docs/render.md, "The render's floor").

    render_floor.py [--width 504] [--height 378] [--samples 32] [--density-share 0.966]
                    [--colour-share 0.926] [--no-cc] [--peak 232.8] [--threads 2]
                    [--gather-field-ns 0.941] [--gather-cc-ns 0.370]

Counts the work a frame must do whatever the kernels — the dense layers' FLOPs and the hash
rows gathered — from the model's sizes (model/model.h: the grid field's density MLP
32 → 64 → 16, its colour MLP (15 geometry + 16 SH) → 64 → 3, HashCC's CC branch of
16 levels × 2 features → 64 → 3; every hash grid 16 levels, 8 corner rows a point a level) and
the shares of samples whose density and colour the render computes (`hashcc bench --render`
prints them), and divides by rates `hashcc bench` measured: the FMA peak (GFLOP/s at --threads)
and one random row gather (ns, one thread: the field's 2^17 tables from an 8 MiB working set,
the CC branch's 2^9 tables from L1; `hashcc bench --memory`, docs/performance.md). The gathers
are spread over the threads as the render spreads its rays. NumPy-free, no timing.
"""
import argparse


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--width", type=int, default=504)
    ap.add_argument("--height", type=int, default=378)
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--density-share", type=float, default=0.966)
    ap.add_argument("--colour-share", type=float, default=0.926)
    ap.add_argument("--no-cc", action="store_true", help="the sh model: no CC branch")
    ap.add_argument("--peak", type=float, default=232.8, help="FMA peak, GFLOP/s at --threads")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--gather-field-ns", type=float, default=0.941)
    ap.add_argument("--gather-cc-ns", type=float, default=0.370)
    a = ap.parse_args()

    S = a.width * a.height * a.samples
    nd, nc = S * a.density_share, S * a.colour_share
    flop_d = nd * 2 * (32 * 64 + 64 * 16)
    flop_c = nc * 2 * (31 * 64 + 64 * 3)
    flop_cc = 0 if a.no_cc else nc * 2 * (32 * 64 + 64 * 3)
    dense = flop_d + flop_c + flop_cc
    rows_f = 16 * 8 * nd
    rows_cc = 0 if a.no_cc else 16 * 8 * nc
    t_dense = dense / (a.peak * 1e9)
    t_gf = rows_f * a.gather_field_ns * 1e-9 / a.threads
    t_gc = rows_cc * a.gather_cc_ns * 1e-9 / a.threads
    t_g = t_gf + t_gc
    print(f"frame {a.width}x{a.height}, {a.samples} samples = {S / 1e6:.2f} M samples; "
          f"{'sh (no CC)' if a.no_cc else 'hashcc'}; {a.threads} thread(s)")
    print(f"  dense: density {flop_d / 1e9:.1f} + colour {flop_c / 1e9:.1f} + CC {flop_cc / 1e9:.1f}"
          f" = {dense / 1e9:.1f} GFLOP -> {t_dense:.3f} s at {a.peak} GFLOP/s")
    print(f"  gathers: field {rows_f / 1e6:.0f} M rows -> {t_gf:.3f} s, CC {rows_cc / 1e6:.0f} M rows"
          f" -> {t_gc:.3f} s; together {t_g:.3f} s")
    print(f"  highest floor {max(t_dense, t_g):.3f} s, sum {t_dense + t_g:.3f} s")


if __name__ == "__main__":
    main()
