#!/usr/bin/env bash
# Builds hashcc for each instruction set this CPU can run and benches each build in turn:
# `hashcc bench --dense` (the paper's dense layers alone, Eigen's GEMM against the build's path,
# then the training step), one JSON and one text file per ISA:
#   docs/bench/isa_<isa>_<tag>.json / .txt        (tag: first argument, default "run")
# Usage: tools/bench_isa.sh [tag] [extra hashcc bench arguments]
#   e.g. tools/bench_isa.sh after --variant hashcc --threads 1 --threads 2
# ISAs: avx2 (-DHASHCC_ISA=avx2, x86-64-v3) when the CPU has AVX2 + FMA; avx512 (x86-64-v4) when
# it has AVX-512 F/BW/DQ/VL. An ISA the CPU lacks is compiled only with COMPILE_ALL=1 (to check
# that it builds; its binary refuses to start here) and never benched. Build folders:
# build-isa-<isa> (ccache is used when installed). ISAS="native avx2 avx512" adds the default
# -march=native build. The machine's load is in each JSON.
set -euo pipefail
cd "$(dirname "$0")/.."
TAG=${1:-run}
shift || true
flags=$(grep -m1 '^flags' /proc/cpuinfo || true)
has() { for f in "$@"; do [[ " $flags " == *" $f "* ]] || return 1; done; }
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
mkdir -p docs/bench
for isa in ${ISAS:-avx2 avx512}; do
  case $isa in
    native) runnable=1 ;;
    avx2) runnable=$(has avx2 fma && echo 1 || echo 0) ;;
    avx512) runnable=$(has avx512f avx512bw avx512dq avx512vl && echo 1 || echo 0) ;;
    *) echo "bench_isa: unknown ISA '$isa' (native, avx2, avx512)" >&2; exit 2 ;;
  esac
  if [[ $runnable == 0 && ${COMPILE_ALL:-0} != 1 ]]; then
    echo "bench_isa: skipping $isa: this CPU cannot run it (COMPILE_ALL=1 to compile it anyway)"
    continue
  fi
  echo "bench_isa: building $isa into build-isa-$isa"
  BUILD_DIR=build-isa-$isa bash tools/build.sh -DHASHCC_ISA=$isa "${launcher[@]}"
  if [[ $runnable == 0 ]]; then
    echo "bench_isa: $isa compiled; not benched (this CPU lacks it)"
    continue
  fi
  out=docs/bench/isa_${isa}_${TAG}
  ./build-isa-$isa/hashcc bench --dense --json "$out.json" "$@" | tee "$out.txt"
done
