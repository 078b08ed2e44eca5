#!/usr/bin/env bash
# hashcc against PyTorch (issue 25: "≥ 2× a PyTorch CPU implementation of the same step, on the
# same machine, in one run"; issue 53: the grid field's step too). Builds nothing. Given a hashcc
# binary, runs, per thread count and step (VARIANTS: hashcc = the paper's step, sh+grid = the
# grid field's),
#   hashcc bench --variant V --threads T   and   tools/bench_torch.py --variant V --threads T
# alternately, ROUNDS times (hashcc, torch, hashcc, torch, …), so a change of load hits both
# alike, and writes OUT.json (every run, the CPU model and ISA, the load before and after, the
# BLAS and allocator torch used) and OUT.txt (the log and the summary: median ms/step of each,
# torch / hashcc per step and thread count, and each side's 1 → 2 thread scaling).
#
# Usage: tools/bench_vs_torch.sh BUILD/hashcc [OUT]      (OUT default docs/bench/torch_vs_hashcc)
# Environment (defaults): THREADS="1 2"  ROUNDS=2  VARIANTS="hashcc sh+grid"
#   STEPS=10 WARMUP=2 (the paper's step: timed / untimed steps per run, both sides)
#   GRID_STEPS=40 GRID_WARMUP=3 (the grid step, ~20× cheaper)
#   TORCH_CHUNKS="64 0" (bench_torch.py --chunk-rays for the paper's step: 64 = the chunk it was
#   first compared at, 0 = the whole step as one batch; the faster is the one compared)
#   GRID_TORCH_CHUNKS="256 0" (the grid step: 256 = hashcc's automatic chunk for it, 0 = whole)
#   PYTHON=/usr/bin/python3
#   TORCH_BLAS_DIR=/usr/lib/x86_64-linux-gnu/openblas-openmp (put first on LD_LIBRARY_PATH: Debian's
#   python3-torch calls whatever libblas.so.3 is found, the reference BLAS unless OpenBLAS is
#   installed and selected)  TORCH_MALLOC=libtcmalloc_minimal.so.4 (LD_PRELOADed into torch
#   when found; "none" for glibc malloc)
# Needs: apt-get install python3-torch libopenblas0-openmp libtcmalloc-minimal4 (optional:
# tools/install_deps.sh tries them, CI does not need them). Before timing, bench_torch.py checks
# that the torch steps are hashcc's: --check-golden on the committed golden folders (the paper's
# against its committed out/, the grid field's against `hashcc step --double` run here) and
# --check-grid (the benched grid field's size, against reference_step.py and hashcc step).
set -euo pipefail
cd "$(dirname "$0")/.."
HASHCC=${1:?usage: tools/bench_vs_torch.sh BUILD/hashcc [OUT]}
OUT=${2:-docs/bench/torch_vs_hashcc}
THREADS=${THREADS:-1 2}
ROUNDS=${ROUNDS:-2}
STEPS=${STEPS:-10}
WARMUP=${WARMUP:-2}
GRID_STEPS=${GRID_STEPS:-40}
GRID_WARMUP=${GRID_WARMUP:-3}
VARIANTS=${VARIANTS:-hashcc sh+grid}
TORCH_CHUNKS=${TORCH_CHUNKS:-64 0}
GRID_TORCH_CHUNKS=${GRID_TORCH_CHUNKS:-256 0}
PYTHON=${PYTHON:-/usr/bin/python3}
TORCH_BLAS_DIR=${TORCH_BLAS_DIR:-/usr/lib/x86_64-linux-gnu/openblas-openmp}
TORCH_MALLOC=${TORCH_MALLOC:-libtcmalloc_minimal.so.4}

[[ -x $HASHCC ]] || { echo "bench_vs_torch: $HASHCC is not an executable hashcc binary" >&2; exit 2; }
"$PYTHON" -c "import torch" 2>/dev/null || {
  echo "bench_vs_torch: $PYTHON cannot import torch; install it: apt-get install python3-torch" \
       "libopenblas0-openmp libtcmalloc-minimal4" >&2; exit 2; }
torch_env=(env)
if [[ -f $TORCH_BLAS_DIR/libblas.so.3 ]]; then
  torch_env+=("LD_LIBRARY_PATH=$TORCH_BLAS_DIR${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}")
else
  echo "bench_vs_torch: no OpenBLAS in $TORCH_BLAS_DIR: torch uses the system libblas.so.3" >&2
fi
if [[ $TORCH_MALLOC != none ]]; then
  malloc=$(ldconfig -p | awk -v n="$TORCH_MALLOC" '$1 == n && !p {print $NF; p = 1}')
  [[ -n $malloc ]] && torch_env+=("LD_PRELOAD=$malloc") ||
    echo "bench_vs_torch: $TORCH_MALLOC not found: torch uses glibc malloc" >&2
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
log=$tmp/log.txt
say() { echo "$@" | tee -a "$log"; }
mkdir -p "$(dirname "$OUT")"
say "bench_vs_torch: $(date -u +%FT%TZ), hashcc $HASHCC, torch via ${torch_env[*]:1} $PYTHON"
say "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2-), $(nproc) cores; uptime: $(uptime)"
uptime > "$tmp/uptime_before"
"${torch_env[@]}" "$PYTHON" tools/bench_torch.py --hashcc "$HASHCC" --check-grid \
  --check-golden test/data/golden_hashcc --check-golden test/data/golden_grid \
  --check-golden test/data/golden_p0 --check-golden test/data/golden_fxonly \
  --check-golden test/data/golden_grid_smooth > "$tmp/golden.txt" 2>&1 || { cat "$tmp/golden.txt" >&2;
  echo "bench_vs_torch: the torch steps do not reproduce hashcc's; not timing them" >&2; exit 1; }
grep -E 'worst|golden check|grid check|hash grid' "$tmp/golden.txt" | tee -a "$log"

for t in $THREADS; do
  for r in $(seq 1 "$ROUNDS"); do
    for v in $VARIANTS; do
      tag=${v//+/_}
      if [[ $v == *+grid ]]; then steps=$GRID_STEPS warm=$GRID_WARMUP chunks=$GRID_TORCH_CHUNKS
      else steps=$STEPS warm=$WARMUP chunks=$TORCH_CHUNKS; fi
      say "-- $v, threads $t, round $r: hashcc"
      "$HASHCC" bench --variant "$v" --threads "$t" --steps "$steps" --warmup "$warm" \
        --json "$tmp/hashcc_${tag}_t${t}_r${r}.json" >> "$log" 2>&1
      "$PYTHON" -c 'import json, sys; r = json.load(open(sys.argv[1]))["runs"][0]
print("hashcc bench {variant}: median {ms_per_step:.1f} ms/step (min {ms_min:.1f}, max {ms_max:.1f}, {steps} steps),"
      " CPU {cpu_ms_per_step:.1f} ms/step, chunk {chunk_rays} rays".format(**r))' \
        "$tmp/hashcc_${tag}_t${t}_r${r}.json" | tee -a "$log"
      for c in $chunks; do
        say "-- $v, threads $t, round $r: torch, chunk $c"
        "${torch_env[@]}" "$PYTHON" tools/bench_torch.py --variant "$v" --threads "$t" --steps "$steps" \
          --warmup "$warm" --chunk-rays "$c" --json "$tmp/torch_${tag}_t${t}_c${c}_r${r}.json" 2>&1 | tee -a "$log"
      done
    done
  done
done
uptime > "$tmp/uptime_after"
say "uptime after: $(cat "$tmp/uptime_after")"
cp "$log" "$OUT.txt"

"$PYTHON" - "$tmp" "$OUT" "$HASHCC" <<'EOF'
import glob, json, os, re, statistics, sys
tmp, out, binary = sys.argv[1:4]
load = lambda f: json.load(open(f))
runs = {"hashcc": [], "torch": []}
for f in sorted(glob.glob(f"{tmp}/hashcc_*.json")):
    j = load(f)
    for r in j["runs"]:
        runs["hashcc"].append({"variant": r["variant"], "threads": r["threads"],
                               "round": int(re.search(r"_r(\d+)", f)[1]),
                               "ms_median": r["ms_per_step"], "ms_min": r["ms_min"],
                               "ms_max": r["ms_max"], "cpu_ms_per_step": r["cpu_ms_per_step"],
                               "steps": r["steps"], "samples": r["samples"], "chunk_rays": r["chunk_rays"],
                               "mlp_gflops": r["mlp_gflops"], "peak_gflops": r["peak_gflops"],
                               "stages": r["stages"], "stages_cpu": r["stages_cpu"],
                               "isa_compiled": j.get("isa_compiled"), "isa_cpu": j.get("isa_cpu"),
                               "gemm": j.get("gemm")})
for f in sorted(glob.glob(f"{tmp}/torch_*.json")):
    j = load(f)
    j["round"] = int(re.search(r"_r(\d+)", f)[1])
    del j["ms"]
    runs["torch"].append(j)
med = lambda xs: statistics.median(xs) if xs else float("nan")
order = ["hashcc", "sh+grid", "hashcc+grid"]
variants = sorted({r["variant"] for r in runs["hashcc"]}, key=lambda v: order.index(v) if v in order else 9)
summary = []
for v in variants:
    for t in sorted({r["threads"] for r in runs["hashcc"] if r["variant"] == v}):
        h = [r for r in runs["hashcc"] if r["variant"] == v and r["threads"] == t]
        by_chunk = {}
        for r in runs["torch"]:
            if r["variant"] == v and r["threads"] == t:
                by_chunk.setdefault(r["chunk_rays"], []).append(r)
        if not by_chunk:
            continue
        chunks = {c: {"ms": med([r["ms_median"] for r in rs]), "cpu_ms": med([r["cpu_ms_per_step"] for r in rs])}
                  for c, rs in by_chunk.items()}
        best = min(chunks, key=lambda c: chunks[c]["ms"])
        hm, hc = med([r["ms_median"] for r in h]), med([r["cpu_ms_per_step"] for r in h])
        summary.append({"variant": v, "threads": t, "hashcc_ms": hm, "hashcc_cpu_ms": hc,
                        "torch_ms_by_chunk": {str(c): x["ms"] for c, x in chunks.items()},
                        "torch_best_chunk": best, "torch_ms": chunks[best]["ms"],
                        "torch_cpu_ms": chunks[best]["cpu_ms"],
                        "ratio_wall": chunks[best]["ms"] / hm, "ratio_cpu": chunks[best]["cpu_ms"] / hc})
# 1 → T thread scaling of each side (wall: ms at 1 thread / ms at T; torch: its faster chunking at each)
scaling = []
for v in variants:
    rows = {s["threads"]: s for s in summary if s["variant"] == v}
    if 1 not in rows:
        continue
    for t in sorted(rows):
        if t == 1:
            continue
        for side in ("hashcc", "torch"):
            scaling.append({"variant": v, "implementation": side, "from_threads": 1, "to_threads": t,
                            "speedup_wall": rows[1][side + "_ms"] / rows[t][side + "_ms"],
                            "cpu_ratio": rows[t][side + "_cpu_ms"] / rows[1][side + "_cpu_ms"]})
t0 = runs["torch"][0] if runs["torch"] else {}
res = {"what": "training steps, hashcc bench --variant V vs tools/bench_torch.py --variant V "
               "(hashcc: the paper's step; sh+grid: the grid field's)",
       "hashcc_binary": binary, "cpu_model": t0.get("cpu_model"), "cpu_isa": t0.get("cpu_isa"),
       "cores": os.cpu_count(), "torch": t0.get("torch"), "torch_blas": t0.get("blas"),
       "torch_allocator": t0.get("allocator"),
       "uptime_before": open(f"{tmp}/uptime_before").read().strip(),
       "uptime_after": open(f"{tmp}/uptime_after").read().strip(),
       "golden_check": [l.strip() for l in open(f"{tmp}/golden.txt")
                        if "worst" in l or "check:" in l or "hash grid" in l],
       "summary": summary, "scaling": scaling, "runs": runs}
open(out + ".json", "w").write(json.dumps(res, indent=1) + "\n")
isa = runs["hashcc"][0]["isa_compiled"] if runs["hashcc"] else "?"
lines = [f"{res['cpu_model']} ({res['cpu_isa']}, {res['cores']} cores); hashcc compiled for {isa};"
         f" torch {res['torch']}, BLAS {','.join(os.path.basename(b) for b in res['torch_blas'] or [])},"
         f" allocator {','.join(os.path.basename(a) for a in res['torch_allocator'] or [])}",
         f"load before: {res['uptime_before']}", f"load after:  {res['uptime_after']}",
         "median over rounds of each run's median wall ms/step (CPU ms/step in brackets)",
         f"{'step':>8} {'threads':>7} {'hashcc ms':>16} {'torch ms (chunk)':>24} {'torch/hashcc':>12} {'(CPU)':>7}"]
for s in summary:
    lines.append(f"{s['variant']:>8} {s['threads']:>7} {s['hashcc_ms']:>8.1f} ({s['hashcc_cpu_ms']:>6.0f}) "
                 f"{s['torch_ms']:>9.1f} ({s['torch_cpu_ms']:>6.0f}, {s['torch_best_chunk'] or 'whole'}) "
                 f"{s['ratio_wall']:>12.2f} {s['ratio_cpu']:>7.2f}")
    others = ", ".join(f"chunk {c}: {v:.1f}" for c, v in s["torch_ms_by_chunk"].items())
    lines.append(f"{'':>16} torch by chunk: {others}")
for sc in scaling:
    lines.append(f"scaling {sc['variant']:>8} {sc['implementation']:>6}: {sc['from_threads']} → "
                 f"{sc['to_threads']} threads {sc['speedup_wall']:.2f}× faster (wall), CPU ms ratio {sc['cpu_ratio']:.2f}")
open(out + ".txt", "a").write("\n".join(lines) + "\n")
print("\n".join(lines))
print(f"wrote {out}.json, {out}.txt")
EOF
