#!/usr/bin/env python3
"""tools/eval_floor.py — `hashcc eval` of a grid-field run against the machine's floors.

    eval_floor.py RUN --memory MEM.json --bench BENCH.json [--threads 2]

RUN is a run folder that `hashcc eval` has evaluated (RUN/config.json, RUN/eval/metrics.json,
RUN/eval/renders/*.png). MEM.json is what `hashcc bench --memory --json MEM.json` writes (per
working-set size and thread count: random 8-byte gather ns a row, streaming GB/s); BENCH.json what
`hashcc bench --json BENCH.json` writes (it holds the measured FMA peaks, `peaks`);
tools/bench_grid_roofline.sh writes both. Nothing is timed here: it counts what the evaluation did and
divides by what the machine measured, as tools/grid_roofline.py does for the training step.

Counted, from the run's configuration and the engine's kernels:

  * the refinement (docs/evaluation.md §3; fast mode: `refine_full_epochs` epochs of the run's
    ray grid a view, then `refine_rays` a view; adam mode: the run's grid every epoch), each
    sample a forward of the grid field and the CC branch and a backward of the grid field's two
    MLPs with input gradients only (no weight GEMM, no table scatter: eval's frozen networks),
    the grid's position gradient from the forward's Jacobian (kernels/hash_grid.h);
  * the renders: every pixel of every test view, the run's samples a ray, a forward (no
    shortcut counted: the shortcuts of docs/render.md only drop samples);
  * FLOPs = 2 × the dense layers' multiply-adds; rows = 8 table rows a sample a level
    (trilinear corners), the grid's and the CC branch's; the Jacobian's bytes (3 × L·F floats a
    sample, written by the forward, read by the backward).

Floors (seconds, at --threads T):

  FLOP floor      = FLOPs / the measured FMA peak at T threads
  gather floor    = rows × the gather rate, per thread, of a working set:
                    "interleaved": the whole table (a 256-point block visits every level in
                    turn, so the table's levels share the caches: the engine's order), at the
                    probe above the table's size and ("interleaved-") the probe below it;
                    "level": each level's own table bytes (a kernel that kept one level in
                    cache at a time);
                    "L1": every row from L1 (the smallest working set measured): the floor
                    of any order, reached only where rows are re-read while still in L1
                    (the renders' neighbouring pixels, not the refinement's random ones)
  stream floor    = the Jacobian's bytes / the measured read + write bandwidth

It prints each floor, their sum and the measured refinement and render seconds of metrics.json
over that sum.
"""
import argparse
import json
import math
import pathlib
import struct
import sys


def level_res(base, finest, levels, l):
    # tiny-cuda-nn's level geometry (formulas.md §5): b = exp((ln N_max − ln N_min)/(L − 1)),
    # scale_l = N_min·b^l − 1, res_l = ceil(scale_l) + 1 vertices an axis.
    b = math.exp((math.log(finest) - math.log(base)) / (levels - 1)) if levels > 1 else 1.0
    return math.ceil(base * b ** l - 1.0) + 1


def table_levels(base, finest, levels, log2_table, features):
    """Per level: (res, dense, table bytes in use)."""
    out = []
    for l in range(levels):
        res = level_res(base, finest, levels, l)
        dense = res ** 3 <= 2 ** log2_table
        rows = res ** 3 if dense else 2 ** log2_table
        out.append((res, dense, rows * features * 4))
    return out


def gather_ns(mem, threads, nbytes, below=False):
    """The gather rate (ns a row, per thread) of the smallest measured working set ≥ nbytes
    (below: of the largest ≤ nbytes; the probes are powers of two, so the two bracket it)."""
    rows = sorted((r for r in mem["rows"] if r["threads"] == threads), key=lambda r: r["bytes"])
    if not rows:
        sys.exit(f"eval_floor: no {threads}-thread rows in the memory JSON")
    if below:
        le = [r for r in rows if r["bytes"] <= nbytes]
        r = le[-1] if le else rows[0]
        return r["gather_ns"], r["bytes"]
    for r in rows:
        if r["bytes"] >= nbytes:
            return r["gather_ns"], r["bytes"]
    return rows[-1]["gather_ns"], rows[-1]["bytes"]


def stream_gbs(mem, threads):
    """Read and write GB/s (all threads) at the largest measured working set."""
    rows = [r for r in mem["rows"] if r["threads"] == threads]
    big = max(rows, key=lambda r: r["bytes"])
    return big["read_gbs"], big["write_gbs"]


def png_size(path):
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit(f"eval_floor: {path}: not a PNG")
    return struct.unpack(">II", head[16:24])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    ap.add_argument("--memory", required=True, help="hashcc bench --memory JSON")
    ap.add_argument("--bench", required=True, help="hashcc bench JSON with the measured peaks")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    run = pathlib.Path(a.run)

    def load(path, what):
        try:
            return json.loads(pathlib.Path(path).read_text())
        except FileNotFoundError:
            sys.exit(f"eval_floor: {path}: no such file ({what})")
        except json.JSONDecodeError as e:
            sys.exit(f"eval_floor: {path}: line {e.lineno}: not JSON ({e.msg})")

    cfg = load(run / "config.json", "the run's configuration: is RUN a run folder?")
    met = load(run / "eval" / "metrics.json", "run `hashcc eval --run RUN` first")
    mem = load(a.memory, "hashcc bench --memory --json FILE")
    bench = load(a.bench, "hashcc bench --json FILE: it holds the measured peaks")
    if "rows" not in mem or "peaks" not in bench:
        sys.exit("eval_floor: --memory needs the `rows` of hashcc bench --memory, --bench the `peaks` of hashcc bench")
    T = a.threads
    if cfg.get("field") != "grid":
        sys.exit("eval_floor: a grid-field run is needed (config.json field)")
    peak = next((p["gflops_cpu"] * T / p["threads"] if p["threads"] != T else p["gflops_cpu"]
                 for p in bench["peaks"] if p["threads"] == T), None)
    if peak is None:
        sys.exit(f"eval_floor: no {T}-thread peak in {a.bench}")

    # The networks (docs/math/grid_field.md; model/model.cpp's layout).
    L, F = cfg["grid_levels"], cfg["grid_features"]
    LF, H, G, RH = L * F, cfg["grid_hidden"], cfg["grid_geo"], cfg["grid_rgb_hidden"]
    E = (cfg["sh_degree"] + 1) ** 2 if cfg.get("sh_degree", 0) > 0 else 3
    cc = cfg.get("model", "hashcc") == "hashcc"
    CL, CF, CH = cfg["cc_levels"], cfg["cc_features"], cfg["cc_hidden"]
    grid_mac = LF * H + H * (1 + G) + (G + E) * RH + RH * 3
    cc_mac = (CL * CF * CH + CH * 3) if cc else 0
    S = cfg["samples"]

    # What the evaluation ran.
    n = len(met["per_image"])
    E_ep = met["refine_epochs"]
    full_rays = cfg["rays"]
    if met.get("refine_mode") == "fast":
        full = min(met.get("refine_full_epochs", 0), E_ep)
        rays = full * n * full_rays + (E_ep - full) * n * met["refine_rays"]
    else:
        rays = E_ep * n * full_rays
    ref_samples = rays * S
    pngs = sorted((run / "eval" / "renders").glob("*.png"))
    if len(pngs) < n:
        sys.exit(f"eval_floor: {run}/eval/renders has {len(pngs)} PNGs for {n} test views")
    W, Hh = png_size(pngs[0])
    ren_samples = n * W * Hh * S

    grid = table_levels(cfg["grid_base_res"], cfg["grid_max_res"], L, cfg["grid_log2_table"], F)
    ccl = table_levels(cfg["cc_base_res"], cfg["cc_max_res"], CL, cfg["cc_log2_table"], CF) if cc else []
    grid_bytes = sum(b for _, _, b in grid)
    cc_bytes = sum(b for _, _, b in ccl)

    def rows_time(levels, total_bytes, samples, ws):
        t = 0.0
        for _, _, b in levels:
            ns, _ = gather_ns(mem, T, {"interleaved": total_bytes, "interleaved-": total_bytes,
                                       "level": b, "L1": 0}[ws], below=ws == "interleaved-")
            t += samples * 8 * ns * 1e-9
        return t / T  # per-thread rates, the samples split over T threads

    rd, wr = stream_gbs(mem, T)
    jac_bytes = ref_samples * 3 * LF * 4
    out = {}
    print(f"eval_floor: {run} — {cfg.get('preset', '?')} preset, grid 16 x {F} x 2^{cfg['grid_log2_table']}"
          f" ({grid_bytes / 2**20:.1f} MiB; {sum(d for _, d, _ in grid)} dense levels), CC 2^{cfg['cc_log2_table']}"
          f" ({cc_bytes / 2**10:.0f} KiB), {S} samples; {n} test views of {W}x{Hh}")
    print(f"machine: {mem.get('cpu_model', '?')}, {mem.get('isa_compiled', '?')}; {T} threads: peak {peak:.1f} GFLOP/s,"
          f" stream read {rd:.1f} / write {wr:.1f} GB/s; gather ns a row (per thread): whole grid table"
          f" {gather_ns(mem, T, grid_bytes)[0]:.2f} (probe above) / {gather_ns(mem, T, grid_bytes, True)[0]:.2f}"
          f" (below), CC table {gather_ns(mem, T, cc_bytes)[0]:.2f}")
    for name, samples, flops_mac, jac in (
            ("refinement", ref_samples, 2 * grid_mac + cc_mac, jac_bytes),
            ("renders", ren_samples, grid_mac + cc_mac, 0)):
        fl = 2.0 * flops_mac * samples / (peak * 1e9)
        g = {ws: rows_time(grid, grid_bytes, samples, ws) + rows_time(ccl, cc_bytes, samples, ws)
             for ws in ("interleaved", "interleaved-", "level", "L1")}
        st = jac / (wr * 1e9) + jac / (rd * 1e9)
        meas = met["refine_seconds" if name == "refinement" else "render_seconds"]
        sums = {ws: fl + g[ws] + st for ws in g}
        print(f"{name}: {samples / 1e6:.1f} M samples, {2.0 * flops_mac * samples / 1e12:.2f} TFLOP;"
              f" FLOP floor {fl:.1f} s; gather floor {g['interleaved']:.1f} s interleaved"
              f" ({g['interleaved-']:.1f} s at the probe below),"
              f" {g['level']:.1f} s level, {g['L1']:.1f} s L1; stream {st:.1f} s")
        print(f"  floors' sum {sums['interleaved']:.1f} / {sums['interleaved-']:.1f} / {sums['level']:.1f} /"
              f" {sums['L1']:.1f} s (interleaved / interleaved- / level / L1); measured {meas:.1f} s ="
              f" {meas / sums['interleaved']:.2f}x / {meas / sums['interleaved-']:.2f}x /"
              f" {meas / sums['level']:.2f}x / {meas / sums['L1']:.2f}x")
        out[name] = dict(samples=samples, flop_floor_s=fl, stream_floor_s=st, measured_s=meas,
                         **{f"gather_floor_{ws}_s": g[ws] for ws in g})
    tot = met["refine_seconds"] + met["render_seconds"]
    lo = out["refinement"]["flop_floor_s"] + out["renders"]["flop_floor_s"]
    print(f"whole evaluation: measured {tot:.1f} s (refinement + renders); the FLOP floors alone {lo:.1f} s")


if __name__ == "__main__":
    main()
