#!/usr/bin/env bash
# The simulated zoo (issue 49): one `hashcc simulate` per capture effect that makes real
# forward-facing scenes differ, each scene switching on only what it is named for.
#
#   tools/make_zoo.sh OUT [WIDTH HEIGHT]      (default 128 96)
#
# Writes OUT/<name>/ for every scene below (an LLFF folder each: images/, poses_bounds.npy,
# scene.json). Which LLFF scene each one mimics, and by which measured numbers
# (tools/scene_stats.py), is in docs/results/scenes/README.md.
set -euo pipefail
HERE="$(cd "$(dirname "$0")/.." && pwd)"
HASHCC=${HASHCC:-$HERE/build/hashcc}
OUT=${1:?usage: tools/make_zoo.sh OUT [WIDTH HEIGHT]}
W=${2:-128} H=${3:-96}
sim() {  # name, flags...
  local name=$1; shift
  [[ -f $OUT/$name/poses_bounds.npy ]] && return 0
  # The progress bar goes to stderr: kept out of sight unless the simulator fails.
  "$HASHCC" simulate --out "$OUT/$name" --width "$W" --height "$H" "$@" > /dev/null 2> "$OUT/.$name.err" ||
    { cat "$OUT/.$name.err" >&2; exit 2; }
  rm -f "$OUT/.$name.err"
  echo "zoo: $OUT/$name ($*)"
}
mkdir -p "$OUT"
sim plain                                                     # the built-in scene, nothing switched on
sim lookat  --rig lookat --baseline 0.5 --rot-jitter 2        # fern-like: walks round a near object, turning to it
sim sweep   --rig sweep --sweep 22 --views 62 --baseline 0.5 --rot-jitter 1.5 --backdrop-depth 24  # horns-like
sim wide    --fov 90                                          # a wide lens
sim narrow  --fov 40 --rot-jitter 1.5                         # a narrow lens, a steadier hand
sim deep    --backdrop-depth 40                               # a near subject before a far wall
sim few     --views 8                                         # few photos
sim shiny   --specular                                        # view-dependent highlights
