#!/usr/bin/env bash
# libFuzzer targets for hashcc's input parsers, built straight with clang++ (no CMake):
#   npy         core/npy.cpp            parse_npy                (poses_bounds.npy, any .npy)
#   checkpoint  train/checkpoint.cpp    Checkpoint::parse        (RUN/checkpoint.bin)
#   config      train/train_config.cpp  train_config_from_json   (RUN/config.json)
#   image       core/image.cpp          read_image_from_memory   (stb: PNG/JPG/BMP/TGA)
#   exif        core/exif.cpp           parse_exif_tiff, read_exif_from_jpeg (a JPEG's EXIF block)
# Each is built with -fsanitize=fuzzer,address,undefined and run for FUZZ_SECONDS (default 60).
# A finding (crash, sanitizer report, leak, timeout, OOM, or any exception other than
# hashcc::Error) stops that target and leaves the input in build-fuzz/findings/<target>/;
# copy it to test/data/fuzz/<target>/ so test_reliability.cpp replays it forever after.
#
#   tools/fuzz.sh                  # all targets, 60 s each
#   FUZZ_SECONDS=10 tools/fuzz.sh npy image
# Needs clang (Debian: apt-get install clang). Exit status: 0 clean, 1 a target found something.
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH=${FUZZ_SECONDS:-60}
OUT=${FUZZ_DIR:-build-fuzz}
CXX=${FUZZ_CXX:-clang++}
command -v "$CXX" >/dev/null || { echo "fuzz.sh: $CXX not found (apt-get install clang)"; exit 2; }
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(npy checkpoint config image exif)

FLAGS=(-std=c++20 -g -O1 -fno-omit-frame-pointer -fsanitize=fuzzer,address,undefined
       -fno-sanitize-recover=undefined -I. -I/usr/include/stb -I/usr/include/eigen3
       -DHASHCC_VERSION=\"fuzz\" -DEIGEN_NO_DEBUG)
declare -A SRC=(
  [npy]="core/npy.cpp core/fileio.cpp"
  [checkpoint]="train/checkpoint.cpp core/fileio.cpp"
  [config]="train/train_config.cpp train/recipes.cpp $OUT/recipes_none.cpp model/model.cpp model/grid_field.cpp kernels/dense.cpp kernels/fourier.cpp kernels/sh.cpp kernels/hash_grid.cpp"
  [image]="core/image.cpp core/exif.cpp core/fileio.cpp $OUT/stb_impl.o"
  [exif]="core/exif.cpp"
)
declare -A LIBS=(
  [npy]="-lfmt" [checkpoint]="-lfmt" [config]="-lfmt -fopenmp"
  [image]="-lfmt $(pkg-config --libs OpenEXR 2>/dev/null)"
  [exif]="-lfmt"
)
declare -A EXTRA=([config]="-fopenmp" [image]="$(pkg-config --cflags OpenEXR 2>/dev/null)")

mkdir -p "$OUT"
# The config reader checks "preset" against the built-in recipes, which CMake embeds: here none
# (every preset but "paper" is then an Error, a path the fuzzer explores like any other).
cat > "$OUT/recipes_none.cpp" <<'CPP'
#include "train/recipes.h"
namespace hashcc {
const std::vector<std::pair<std::string, std::string>>& embedded_recipes() {
  static const std::vector<std::pair<std::string, std::string>> none;
  return none;
}
}  // namespace hashcc
CPP
status=0
if [[ " ${targets[*]} " == *" image "* ]]; then
  # stb on its own: signed-overflow/shift checks off there only (see core/stb_impl.cpp).
  "$CXX" "${FLAGS[@]}" -fno-sanitize=signed-integer-overflow,shift -c core/stb_impl.cpp -o "$OUT/stb_impl.o"
fi
for t in "${targets[@]}"; do
  [ -n "${SRC[$t]:-}" ] || { echo "fuzz.sh: unknown target '$t' (npy checkpoint config image exif)"; exit 2; }
  bin="$OUT/fuzz_$t"
  echo "== $t: building $bin"
  # shellcheck disable=SC2086
  "$CXX" "${FLAGS[@]}" ${EXTRA[$t]:-} "tools/fuzz/fuzz_$t.cpp" ${SRC[$t]} ${LIBS[$t]} -o "$bin"
  corpus="$OUT/corpus/$t"; findings="$OUT/findings/$t"
  mkdir -p "$corpus" "$findings"
  # Seeds: the hand-made ones and every regression input kept so far.
  for d in "test/data/fuzz/seeds/$t" "test/data/fuzz/$t"; do
    [ -d "$d" ] && cp -n "$d"/* "$corpus"/ 2>/dev/null || true
  done
  echo "== $t: fuzzing for ${SECONDS_EACH}s"
  if ! "$bin" "$corpus" -max_total_time="$SECONDS_EACH" -rss_limit_mb=3072 -malloc_limit_mb=2048 \
       -timeout=20 -max_len=8192 -artifact_prefix="$findings/" -print_final_stats=1 \
       > "$OUT/$t.log" 2>&1; then
    echo "!! $t: FINDING (see $OUT/$t.log, input in $findings/)"
    grep -E "ERROR|SUMMARY|runtime error|terminate" "$OUT/$t.log" | head -5 || true
    status=1
  else
    grep -E "stat::number_of_executed_runs|cov:" "$OUT/$t.log" | tail -2 || true
    echo "== $t: clean"
  fi
done
exit $status
