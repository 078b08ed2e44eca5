#!/usr/bin/env bash
# Installs hashcc's build and test dependencies from Debian packages, only those missing (idempotent).
#
# Two lists. REQUIRED: building and the test suite need them; the script fails without them.
# OPTIONAL: programs hashcc runs when present and never links: chromium (the [external] test
# that loads a run's report.html in a headless browser) and ffmpeg (`hashcc render --video`
# and its test) and parallel (GNU parallel: the [study] test that runs `hashcc study
# --emit-commands` lines with `parallel -j 2`; without it that test runs them with bash). Missing, they are installed when the script can (root or sudo); when it
# cannot, or the install fails, it says so and goes on: their tests are then reported skipped
# (CTest entry external_tools). HASHCC_NO_OPTIONAL_DEPS=1 does not try them at all.
# OPTIONAL_BENCH: the PyTorch peer of the benchmarks (tools/bench_torch.py, tools/bench_vs_torch.sh:
# python3-torch, the OpenMP OpenBLAS it should call, tcmalloc). No test and no build needs them,
# and python3-torch is large, so they are opt-in: HASHCC_TORCH=1 bash tools/install_deps.sh. They
# go in their own apt-get call, so that a failure there never keeps the optional test tools out.
set -euo pipefail
# python3-numpy: the tests' independent reference of a training step (tools/reference_step.py).
REQUIRED=(build-essential cmake pkg-config libeigen3-dev libomp-dev libstb-dev libopenexr-dev
          catch2 libfmt-dev libcli11-dev nlohmann-json3-dev python3-numpy)
OPTIONAL=(chromium ffmpeg parallel)
OPTIONAL_BENCH=(python3-torch libopenblas0-openmp libtcmalloc-minimal4)
installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
missing=() optional=() bench=()
for p in "${REQUIRED[@]}"; do installed "$p" || missing+=("$p"); done
if [ "${HASHCC_NO_OPTIONAL_DEPS:-0}" = "0" ]; then
  for p in "${OPTIONAL[@]}"; do installed "$p" || optional+=("$p"); done
  if [ "${HASHCC_TORCH:-0}" = "1" ]; then
    for p in "${OPTIONAL_BENCH[@]}"; do installed "$p" || bench+=("$p"); done
  fi
fi
if [ ${#missing[@]} -eq 0 ] && [ ${#optional[@]} -eq 0 ] && [ ${#bench[@]} -eq 0 ]; then
  echo "install_deps: all ${#REQUIRED[@]} packages present (optional: ${OPTIONAL[*]} present or not asked for; the PyTorch peer: HASHCC_TORCH=1)"
  exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    if [ ${#missing[@]} -gt 0 ]; then
      echo "install_deps: not root and no sudo; please run as root: apt-get install ${missing[*]} ${optional[*]}" >&2
      exit 1
    fi
    echo "install_deps: optional ${optional[*]} ${bench[*]} not installed (not root, no sudo): their tests will be skipped"
    exit 0
  fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
if [ ${#missing[@]} -gt 0 ]; then
  echo "install_deps: installing ${missing[*]}"
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
if [ ${#optional[@]} -gt 0 ]; then
  echo "install_deps: installing the optional ${optional[*]}"
  $SUDO apt-get install -y -qq --no-install-recommends "${optional[@]}" ||
    echo "install_deps: optional ${optional[*]} could not be installed: their tests will be skipped"
fi
if [ ${#bench[@]} -gt 0 ]; then
  echo "install_deps: installing the optional ${bench[*]} (the PyTorch peer of tools/bench_vs_torch.sh)"
  $SUDO apt-get install -y -qq --no-install-recommends "${bench[@]}" ||
    echo "install_deps: optional ${bench[*]} could not be installed: tools/bench_vs_torch.sh will not run (nothing else needs them)"
fi
