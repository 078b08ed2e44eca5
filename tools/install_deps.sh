#!/usr/bin/env bash
# Installs hashcc's build and test dependencies from Debian packages, only those missing (idempotent).
set -euo pipefail
# python3-numpy: the tests' independent reference of a training step (tools/reference_step.py).
PKGS=(build-essential cmake pkg-config libeigen3-dev libomp-dev libstb-dev libopenexr-dev
      catch2 libfmt-dev libcli11-dev nlohmann-json3-dev python3-numpy)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all ${#PKGS[@]} packages present"
  exit 0
fi
echo "install_deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "install_deps: not root and no sudo; please run as root: apt-get install ${missing[*]}" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
