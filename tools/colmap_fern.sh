#!/usr/bin/env bash
# tools/colmap_fern.sh — approximate cameras for `hashcc train --init-poses`, from Debian's colmap.
#
# Runs COLMAP's sparse pipeline (feature_extractor → exhaustive_matcher → mapper →
# model_converter to TXT) on a folder of images, CPU only, and leaves a COLMAP *text* model
# (cameras.txt, images.txt, points3D.txt) in OUT/sparse_txt, which hashcc reads directly:
#
#   bash tools/colmap_fern.sh [IMAGES] [OUT]
#   ./build/hashcc train --data ../shared/data/llff/fern --images images_8 --out runs/fern_colmap \
#       --init-poses OUT/sparse_txt --pose-lr 5e-4 --minutes 5
#
# Defaults: IMAGES = $HASHCC_DATA (else ../shared/data)/llff/fern/images_8 (the LLFF fern scene at 504×378),
# OUT = /tmp/hashcc_colmap_fern. The output lives outside the repository; never commit it.
#
# Install: `apt-get install colmap` (Debian 12: colmap 3.8-1; checked with `apt-cache policy
# colmap`). On the project machine the install took 18 s. The script took 102 s on fern
# images_8 with the 2 cores shared by other jobs (about 30 s unloaded); all 20 images registered.
# Camera model: SIMPLE_RADIAL (COLMAP's default; hashcc reads it and reports the radial term as
# ignored) with one camera shared by all images, since LLFF photos come from one phone.
# GPU SIFT is off (no display, no CUDA here).
# Measured (this model vs fern's poses_bounds.npy, 20 images, Sim(3)-aligned): ΔR 0.36°,
# ΔT 0.0025, relative rotation error 0.09°, focal 417.4 px vs 407.6 px (+2.4%).
# HASHCC_COLMAP_MODEL=SIMPLE_PINHOLE (or RADIAL, PINHOLE) picks another camera model: whether
# fern's focal depends on the lens distortion (docs/results/grid, the restarts section).
set -euo pipefail

here="$(cd "$(dirname "$0")/.." && pwd)"
IMAGES="${1:-${HASHCC_DATA:-$here/../shared/data}/llff/fern/images_8}"
OUT="${2:-/tmp/hashcc_colmap_fern}"

if ! command -v colmap >/dev/null; then
  echo "colmap not found; installing it with apt-get (Debian package 'colmap')" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y --no-install-recommends colmap
fi
[ -d "$IMAGES" ] || { echo "$IMAGES: no such image folder" >&2; exit 2; }

case "$(cd "$OUT" 2>/dev/null && pwd || echo "$OUT")" in
  "$here"|"$here"/*) echo "$OUT is inside the repository; choose a folder outside it" >&2; exit 2;;
esac

mkdir -p "$OUT/sparse" "$OUT/sparse_txt"
rm -f "$OUT/database.db"
export QT_QPA_PLATFORM=offscreen  # colmap links Qt; no display here
start=$(date +%s)

colmap feature_extractor --database_path "$OUT/database.db" --image_path "$IMAGES" \
  --ImageReader.camera_model "${HASHCC_COLMAP_MODEL:-SIMPLE_RADIAL}" --ImageReader.single_camera 1 \
  --SiftExtraction.use_gpu 0
colmap exhaustive_matcher --database_path "$OUT/database.db" --SiftMatching.use_gpu 0
colmap mapper --database_path "$OUT/database.db" --image_path "$IMAGES" \
  --output_path "$OUT/sparse"
# The mapper may produce several models (sparse/0, sparse/1, …); the first is the largest.
colmap model_converter --input_path "$OUT/sparse/0" --output_path "$OUT/sparse_txt" \
  --output_type TXT

n=$(grep -v '^#' "$OUT/sparse_txt/images.txt" | awk 'NR % 2 == 1' | wc -l)  # two lines per image
echo "COLMAP text model: $OUT/sparse_txt ($n of $(ls "$IMAGES" | wc -l) images registered, $(( $(date +%s) - start )) s)"
