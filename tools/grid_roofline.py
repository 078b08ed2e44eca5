#!/usr/bin/env python3
"""tools/grid_roofline.py — the grid field's training step against the machine's floors.

    grid_roofline.py                                   # the counts alone (no timing, no binary)
    grid_roofline.py --memory MEM.json --bench BENCH.json [--json OUT.json]

The step is `hashcc bench --variant sh+grid`'s (tools/bench.cpp): 1,024 rays × 32 samples
(N = 32,768 points) of the grid field (docs/math/grid_field.md: a hash grid of 16 levels ×
2 features × 2^15 entries, base 16, finest 512; the density MLP 32 → 64 → 16 and the colour
MLP 31 → 64 → 3), SH-4 directions, volume rendering, MSE, Adam over the networks and the
cameras. Counted here, from the configuration and the engine's kernels (kernels/hash_grid.cpp,
model/grid_field.cpp, model/step.cpp, train/trainer.cpp):

  * per level: resolution, dense or hashed, the table rows and bytes in use, the rows and 64-byte
    lines one kernel block (256 points, kBlock) touches, measured on the bench's own first-step points
    (identity cameras, the 128 × 96 scene, 32 × 32 distinct rows and columns, jittered samples,
    NDC: reference_step.make_rays), and the cache level those bytes fit, against this machine's
    /sys/devices/system/cpu/cpu0/cache sizes;
  * the hash gathers of the forward (8 rows a point a level) and of the backward (the same 8
    rows again, for the position gradient's corner sums s_k) and the backward's scatter-adds into
    the gradient table (8 rows a point a level), with their bytes;
  * the dense FLOPs of the two MLPs (forward 2·in·out a point a layer, backward 2× forward: the
    bench's own count, tools/bench.cpp dense_flops_per_step);
  * the streaming bytes a step: zeroing the parameter gradient, each thread's gradient arena and
    its reduction (2 threads), the Adam update (param, grad, m, v read; param, m, v written).

With --memory (the JSON of `hashcc bench --memory`: per working-set size and thread count the
pointer-chase latency, the random 8-byte gather and scatter-add throughput, streaming read and
write bandwidth) and --bench (the JSON of `hashcc bench --variant sh+grid --threads 1 --threads
2`: the measured step and the measured FMA peak), it turns the counts into times — the floors —
and prints measured step / floor per thread count:

  FLOP floor    = dense FLOPs / the measured peak at that thread count
  gather floor  = Σ_levels N·8·(2·t_gather + t_scatter) / threads, each level's t from the
                  --memory row of the smallest working set ≥ that level's touched bytes (the
                  table rows a chunk reads, with the gradient rows for the scatter), plus the
                  L3 → L2 refills (each chunk re-reads every level's lines: 3 × Σ lines a chunk
                  × chunks, forward table, backward table and gradient) at the gather rate of
                  an 8 MiB working set
  stream floor  = the streaming bytes / the measured read and write bandwidth at their size
  latency bound = the same gathers × the pointer-chase latency (no overlap at all: not a floor,
                  the time a kernel that waited for every row in turn would take)

Only NumPy is needed (tools/reference_step.py is imported from beside this file).
"""
import argparse
import importlib.util
import json
import math
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
spec = importlib.util.spec_from_file_location("reference_step", HERE / "reference_step.py")
ref = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ref)

# The bench's grid step (tools/bench.cpp: BenchOptions, TrainConfig defaults, model_of("sh+grid")).
CFG = {"H": 96, "W": 128, "ndc": True, "rays_side": 32, "samples": 32, "levels": 16, "features": 2,
       "log2_table": 15, "base": 16, "finest": 512, "hidden": 64, "geo": 15, "rgb_hidden": 64,
       "dir_dim": 16, "kernel_chunk": 256}
LINE = 64
PRIMES = (1, 2654435761, 805459861)


def caches():
    """(level, type, bytes, shared_cpu_list) of cpu0's caches, from sysfs."""
    out = []
    base = pathlib.Path("/sys/devices/system/cpu/cpu0/cache")
    for d in sorted(base.glob("index*")):
        try:
            size = (d / "size").read_text().strip()
            n = int(size[:-1]) * (1024 if size[-1] == "K" else 1 << 20 if size[-1] == "M" else 1)
            out.append({"level": int((d / "level").read_text()), "type": (d / "type").read_text().strip(),
                        "bytes": n, "shared_cpu_list": (d / "shared_cpu_list").read_text().strip()})
        except (OSError, ValueError):
            continue
    return out


def data_caches(cs):
    """[(name, bytes)] of the data/unified levels, smallest first."""
    return [(f"L{c['level']}{'d' if c['type'] == 'Data' else ''}", c["bytes"])
            for c in sorted(cs, key=lambda c: c["level"]) if c["type"] in ("Data", "Unified")]


def fits(nbytes, dcs):
    for name, b in dcs:
        if nbytes <= b:
            return name
    return "DRAM"


def bench_points(seed=0):
    """The bench's first step's N points: identity cameras (every pose starts at 0, focal a = b =
    1: fx = W, fy = H), a 32 × 32 grid of distinct random rows and columns, 32 jittered samples a
    ray, NDC. Returns u = clamp((x + 1)/2) (N, 3), ray-major as the step orders them."""
    rng = np.random.default_rng(seed)
    c = {"H": CFG["H"], "W": CFG["W"], "ndc": True}
    A = {"rows": rng.permutation(CFG["H"])[: CFG["rays_side"]], "cols": rng.permutation(CFG["W"])[: CFG["rays_side"]]}
    o, d = ref.make_rays(c, A, np.zeros(3), np.zeros(3), np.ones(2))
    S = CFG["samples"]
    s = (np.arange(S) + rng.random((len(o), S))) / S
    x = (o[:, None, :] + s[:, :, None] * d[:, None, :]).reshape(-1, 3)
    return np.clip((x + 1) / 2, 0, 1)


def corner_rows(u, scale, res, dense, size):
    """The 8 corner rows (N, 8) of points u at one level (docs/math/hash_grid.md)."""
    p = u * scale + 0.5
    cell = np.floor(p).astype(np.uint64)
    rows = []
    for k in range(8):
        v = cell + np.array([(k >> d) & 1 for d in range(3)], dtype=np.uint64)
        if dense:
            e = v[:, 0] + v[:, 1] * np.uint64(res) + v[:, 2] * np.uint64(res * res)
        else:
            m = np.uint64(0xFFFFFFFF)
            e = ((v[:, 0] * np.uint64(PRIMES[0])) & m) ^ ((v[:, 1] * np.uint64(PRIMES[1])) & m) \
                ^ ((v[:, 2] * np.uint64(PRIMES[2])) & m)
        rows.append((e & np.uint64(size - 1)).astype(np.int64))
    return np.stack(rows, axis=1)


def count(dcs):
    """Every count of the module docstring, as a dict."""
    L, F, T = CFG["levels"], CFG["features"], CFG["log2_table"]
    size, row_bytes = 2 ** T, F * 4
    N = CFG["rays_side"] ** 2 * CFG["samples"]
    u = bench_points()
    ch = CFG["kernel_chunk"]
    levels = []
    for l, (scale, res, dense) in enumerate(ref.hash_levels(L, CFG["base"], CFG["finest"], T)):
        rows = corner_rows(u, scale, res, dense, size)
        used = min(res ** 3, size) if dense else size
        lines_pt = np.mean([len(set((r * row_bytes) // LINE)) for r in rows[:ch]])
        per_chunk_rows, per_chunk_lines = [], []
        for c0 in range(0, N, ch):
            r = rows[c0:c0 + ch].ravel()
            per_chunk_rows.append(len(np.unique(r)))
            per_chunk_lines.append(len(np.unique((r * row_bytes) // LINE)))
        touched = float(np.mean(per_chunk_lines)) * LINE        # bytes of table a chunk reads
        levels.append({
            "level": l, "scale": scale, "res": res, "dense": bool(dense), "rows_used": used,
            "table_bytes": used * row_bytes, "table_fits": fits(used * row_bytes, dcs),
            "chunk_rows": float(np.mean(per_chunk_rows)), "chunk_lines": float(np.mean(per_chunk_lines)),
            "chunk_bytes": touched, "chunk_fits": fits(touched, dcs),
            "chunk_bytes_bwd": 2 * touched, "chunk_bwd_fits": fits(2 * touched, dcs),
            "lines_per_point": float(lines_pt),
            "step_rows": int(len(np.unique(rows))), "step_lines": int(len(np.unique((rows * row_bytes) // LINE))),
            "chunks": len(per_chunk_lines)})
    gathers_fwd = N * L * 8
    E, G, Hd, Hr = CFG["dir_dim"], CFG["geo"], CFG["hidden"], CFG["rgb_hidden"]
    layers = [(L * F, Hd), (Hd, 1 + G), (G + E, Hr), (Hr, 3)]
    macs = sum(i * o for i, o in layers)
    flops_fwd = 2 * macs * N
    mlp_params = sum(i * o + o for i, o in layers)
    P = L * size * F + mlp_params                                # the network group (floats)
    # The camera group (3 training images × 6) and the focal (2) are negligible.
    stream = {
        "grad_zero": 4 * P,                                       # trainer: d_net_ = 0 (write)
        "adam_read": 4 * 4 * P, "adam_write": 3 * 4 * P,          # param, grad, m, v → param, m, v
        # 2 threads (model/step.cpp): each thread's arena zeroed (serially, before the region),
        # then d_params += arena_0 + arena_1 (read 3, write 1).
        "arena_zero_2thr": 2 * 4 * P, "arena_reduce_read_2thr": 3 * 4 * P, "arena_reduce_write_2thr": 4 * P}
    # The kernels run level after level over a chunk (kernels/hash_grid.cpp), so a level's rows
    # are re-read from L3 for every chunk once the other levels have pushed them out of L2 (the
    # 16 levels' chunk rows, ~2.3 MiB, are more than a 1 MiB L2): lines a step brought into L2,
    # forward (table) and backward (table, and the gradient rows read and written back).
    refill_fwd = sum(lv["chunk_lines"] * lv["chunks"] for lv in levels)
    return {"config": dict(CFG, N=N), "caches": dcs, "levels": levels,
            "refill_lines_fwd": refill_fwd, "refill_lines_bwd": 2 * refill_fwd,
            "chunk_bytes_all_levels": sum(lv["chunk_bytes"] for lv in levels),
            "gathers_fwd": gathers_fwd, "gathers_bwd": gathers_fwd, "scatters_bwd": gathers_fwd,
            "gather_bytes_fwd": gathers_fwd * row_bytes, "gather_bytes_bwd": gathers_fwd * row_bytes,
            "scatter_bytes_bwd": 2 * gathers_fwd * row_bytes,        # read-modify-write
            "mlp_macs_per_point": macs, "mlp_flops_fwd": flops_fwd, "mlp_flops_step": 3 * flops_fwd,
            "params_net": P, "table_params": L * size * F, "mlp_params": mlp_params, "stream_bytes": stream}


def row_at(mem, threads, nbytes):
    """The --memory row at this thread count of the smallest working set ≥ nbytes (the largest
    when none is)."""
    rows = sorted((r for r in mem["rows"] if r["threads"] == threads), key=lambda r: r["bytes"])
    if not rows:
        raise SystemExit(f"grid_roofline: the --memory file has no rows at {threads} thread(s)")
    for r in rows:
        if r["bytes"] >= nbytes:
            return r
    return rows[-1]


def floors(c, mem, bench):
    """Per thread count of the bench: the floors and measured / floor."""
    out = []
    N = c["config"]["N"]
    # A dependent load takes >= 3 cycles on any CPU; a chase row below 0.1 ns comes from a
    # bench --memory whose chase loop the compiler folded (builds before the fix): no latency bound.
    chase_ok = all(r["chase_ns"] > 0.1 for r in mem["rows"])
    if not chase_ok:
        print("grid_roofline: the --memory file's pointer-chase rows are below 0.1 ns (a bench --memory "
              "from before the chase fix): the latency bound is left out; measure again", file=sys.stderr)
    for run in bench["runs"]:
        if run["variant"] != "sh+grid" or run.get("distortion", 0) or run.get("gemm", "kernel") != "kernel":
            continue
        T = run["threads"]
        peak = next((p["gflops_cpu"] for p in bench["peaks"] if p["threads"] == T), None)
        t_flop = run["mlp_flops"] / (peak * 1e9) if peak else float("nan")
        t_gather = t_lat = 0.0
        per_level = []
        for lv in c["levels"]:
            rf = row_at(mem, T, lv["chunk_bytes"])
            rb = row_at(mem, T, lv["chunk_bytes_bwd"])
            n = N * 8
            tg = n * (rf["gather_ns"] + rb["gather_ns"] + rb["scatter_ns"]) * 1e-9 / T
            tl = n * (rf["chase_ns"] + 2 * rb["chase_ns"]) * 1e-9 / T if chase_ok else float("nan")
            t_gather += tg
            t_lat += tl
            per_level.append({"level": lv["level"], "fwd_row_bytes": rf["bytes"], "bwd_row_bytes": rb["bytes"],
                              "gather_ms": tg * 1e3, "latency_ms": tl * 1e3})
        # The L3 → L2 refills: one random line each, at the gather rate of an L3-sized working set.
        r3 = row_at(mem, T, 8 << 20)
        t_refill = (c["refill_lines_fwd"] + c["refill_lines_bwd"]) * r3["gather_ns"] * 1e-9 / T
        t_gather += t_refill
        sb = c["stream_bytes"]
        rd = sb["adam_read"] + (sb["arena_reduce_read_2thr"] if T > 1 else 0)
        wr = sb["grad_zero"] + sb["adam_write"] + (sb["arena_zero_2thr"] + sb["arena_reduce_write_2thr"] if T > 1 else 0)
        ws = 4 * c["params_net"] * (4 if T == 1 else 6)          # the arrays these passes cycle through
        r = row_at(mem, T, ws)
        t_stream = rd / (r["read_gbs"] * 1e9) + wr / (r["write_gbs"] * 1e9)
        meas = run["ms_per_step"] * 1e-3
        fl = {"flop": t_flop, "gather": t_gather, "stream": t_stream}
        out.append({"threads": T, "measured_ms": run["ms_per_step"], "cpu_ms": run["cpu_ms_per_step"],
                    "peak_gflops": peak, "floors_ms": {k: v * 1e3 for k, v in fl.items()},
                    "latency_bound_ms": t_lat * 1e3, "refill_ms": t_refill * 1e3, "stream_working_set_row": r["bytes"],
                    "max_floor": max(fl, key=fl.get), "ratio": {k: meas / v for k, v in fl.items()},
                    "ratio_max_floor": meas / max(fl.values()), "ratio_sum_floors": meas / sum(fl.values()),
                    "ratio_latency_bound": meas / t_lat if chase_ok else float("nan"),
                    "stages_ms": run.get("stages", {}), "per_level": per_level})
        st = run.get("stages", {})
        if st:  # each floor against the stage it bounds (wall-equivalent ms, mean over threads)
            mlp = (st.get("mlp_fwd", 0) + st.get("mlp_bwd", 0)) * 1e-3
            out[-1]["stage_ratio"] = {"mlp_over_flop_floor": mlp / t_flop,
                                      "encodings_over_gather_floor": st.get("encodings", 0) * 1e-3 / t_gather,
                                      "adam_over_stream_floor": st.get("adam", 0) * 1e-3 / t_stream}
    return out


def fmt_bytes(b):
    return f"{b / 2**20:.2f} MiB" if b >= 2**20 else f"{b / 1024:.1f} KiB"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--memory", help="JSON of `hashcc bench --memory --json FILE`")
    ap.add_argument("--bench", help="JSON of `hashcc bench --variant sh+grid --json FILE`")
    ap.add_argument("--json", help="write everything here")
    a = ap.parse_args()
    cs = caches()
    dcs = data_caches(cs)
    c = count(dcs)
    N, L = c["config"]["N"], c["config"]["levels"]
    print(f"grid step of `hashcc bench --variant sh+grid`: N = {N:,} points "
          f"({c['config']['rays_side'] ** 2:,} rays × {c['config']['samples']} samples); caches (cpu0, sysfs): "
          + ", ".join(f"{n} {fmt_bytes(b)}" for n, b in dcs))
    print(f"{'lvl':>3} {'res':>4} {'kind':>6} {'rows used':>9} {'table':>10} {'fits':>4} "
          f"{'rows/chunk':>10} {'lines/chunk':>11} {'chunk fwd':>10} {'fits':>4} {'fwd+grad':>10} {'fits':>4} {'lines/pt':>8}")
    for lv in c["levels"]:
        print(f"{lv['level']:>3} {lv['res']:>4} {'dense' if lv['dense'] else 'hashed':>6} {lv['rows_used']:>9,} "
              f"{fmt_bytes(lv['table_bytes']):>10} {lv['table_fits']:>4} {lv['chunk_rows']:>10,.0f} "
              f"{lv['chunk_lines']:>11,.0f} {fmt_bytes(lv['chunk_bytes']):>10} {lv['chunk_fits']:>4} "
              f"{fmt_bytes(lv['chunk_bytes_bwd']):>10} {lv['chunk_bwd_fits']:>4} {lv['lines_per_point']:>8.2f}")
    print(f"  rows/chunk, lines/chunk: distinct table rows (8 B: F = 2 floats) and 64-byte lines one "
          f"kernel chunk of {c['config']['kernel_chunk']:,} points reads at that level (mean over the "
          f"step's {N // c['config']['kernel_chunk']} chunks); fwd+grad: with the gradient rows the "
          f"backward scatters into; lines/pt: distinct lines of a point's 8 corners")
    print(f"hash gathers a step: forward {c['gathers_fwd']:,} ({N:,} points × {L} levels × 8 corners; "
          f"{c['gather_bytes_fwd'] / 2**20:.0f} MiB of rows), backward {c['gathers_bwd']:,} gathers "
          f"(the corner sums s_k, {c['gather_bytes_bwd'] / 2**20:.0f} MiB) + {c['scatters_bwd']:,} "
          f"scatter-adds ({c['scatter_bytes_bwd'] / 2**20:.0f} MiB read + written); per point per level "
          f"8 + 8 + 8 rows")
    print(f"one chunk's rows over all 16 levels: {fmt_bytes(c['chunk_bytes_all_levels'])} (forward), "
          f"so each chunk refills every level from L3: {c['refill_lines_fwd']:,.0f} lines forward, "
          f"{c['refill_lines_bwd']:,.0f} backward (table + gradient) a step")
    print(f"MLP: {c['mlp_macs_per_point']:,} multiply-adds a point; {c['mlp_flops_fwd'] / 1e9:.3f} GFLOP "
          f"forward, {c['mlp_flops_step'] / 1e9:.3f} GFLOP a step (forward + backward = 3 × forward)")
    sb = c["stream_bytes"]
    print(f"parameters (network group): {c['params_net']:,} floats ({c['table_params']:,} the table, "
          f"{c['mlp_params']:,} the MLPs) = {fmt_bytes(4 * c['params_net'])}; streaming a step: gradient "
          f"zero {fmt_bytes(sb['grad_zero'])} written, Adam {fmt_bytes(sb['adam_read'])} read + "
          f"{fmt_bytes(sb['adam_write'])} written; at 2 threads also the arenas "
          f"{fmt_bytes(sb['arena_zero_2thr'])} zeroed (serially) and reduced "
          f"({fmt_bytes(sb['arena_reduce_read_2thr'])} read, {fmt_bytes(sb['arena_reduce_write_2thr'])} written)")
    res = {"counts": c}
    if a.memory and a.bench:
        mem, bench = json.loads(pathlib.Path(a.memory).read_text()), json.loads(pathlib.Path(a.bench).read_text())
        fl = floors(c, mem, bench)
        res.update({"floors": fl, "memory_cpu": mem.get("cpu_model"), "memory_load": mem.get("load_average"),
                    "bench_load": bench.get("load_average")})
        print(f"\nfloors ({mem.get('cpu_model')}, compiled {bench.get('isa_compiled')}; load "
              f"{mem.get('load_average')} (memory probes), {bench.get('load_average')} (bench)):")
        for f in fl:
            fm = f["floors_ms"]
            print(f"  {f['threads']} thread(s): measured {f['measured_ms']:.1f} ms/step (CPU {f['cpu_ms']:.1f}); "
                  f"floors: FLOP {fm['flop']:.2f} ms (peak {f['peak_gflops']:.1f} GFLOP/s), gather "
                  f"{fm['gather']:.2f} ms (of it L3 refills {f['refill_ms']:.2f}), stream {fm['stream']:.2f} ms; latency bound {f['latency_bound_ms']:.2f} ms")
            print(f"    measured / floor: FLOP {f['ratio']['flop']:.1f}×, gather {f['ratio']['gather']:.1f}×, "
                  f"stream {f['ratio']['stream']:.1f}×; / the highest floor ({f['max_floor']}) "
                  f"{f['ratio_max_floor']:.1f}×, / their sum {f['ratio_sum_floors']:.1f}×, / the latency "
                  f"bound {f['ratio_latency_bound']:.2f}×")
            st = f["stages_ms"]
            if st:
                print("    hashcc's stages (wall ms): " + ", ".join(f"{k} {v:.1f}" for k, v in st.items()))
                sr = f["stage_ratio"]
                print(f"    stage / its floor: MLPs (mlp_fwd + mlp_bwd) / FLOP floor {sr['mlp_over_flop_floor']:.1f}×, "
                      f"encodings (hash grid fwd + bwd, SH) / gather floor {sr['encodings_over_gather_floor']:.1f}×, "
                      f"adam / stream floor {sr['adam_over_stream_floor']:.1f}× (the stream floor also holds the "
                      f"gradient zero and, at 2 threads, the arenas)")
    elif a.memory or a.bench:
        ap.error("--memory and --bench go together")
    if a.json:
        pathlib.Path(a.json).write_text(json.dumps(res, indent=1) + "\n")
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
