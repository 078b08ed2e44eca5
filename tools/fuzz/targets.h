// tools/fuzz/targets.h — one fuzz input → one parser call, shared by the libFuzzer targets
// (tools/fuzz/fuzz_*.cpp, built by tools/fuzz.sh) and the regression test that replays every
// kept input (test/test_reliability.cpp, test/data/fuzz/<target>/). The contract under test:
// any bytes either parse or throw hashcc::Error; every other outcome is a bug.
#pragma once
#include <cstdint>
#include <cmath>
#include <cstdlib>
#include <string>

#include "core/error.h"
#include "core/exif.h"
#include "core/image.h"
#include "core/npy.h"
#include "train/checkpoint.h"
#include "train/trainer.h"

namespace hashcc::fuzz {

// Returns true when the input parsed, false when it was rejected with hashcc::Error.
inline bool npy(const std::string& bytes) {
  try {
    NpyArray a = parse_npy(bytes, "fuzz.npy");
    if (int64_t(a.data.size()) != a.size()) std::abort();
    return true;
  } catch (const Error&) {
    return false;
  }
}

// Byte 0 picks the mode: odd = wrap the rest as a payload with a valid header and checksum
// (otherwise the checksum stops nearly every mutation before the section parser).
inline bool checkpoint(const std::string& input) {
  if (input.empty()) return false;
  std::string bytes = input.substr(1);
  if (input[0] & 1) {
    std::string out = "HASHCCKP";
    uint32_t v = kCheckpointVersion;
    uint64_t n = bytes.size(), sum = fnv1a64(bytes.data(), bytes.size());
    out.append(reinterpret_cast<const char*>(&v), 4);
    out.append(reinterpret_cast<const char*>(&n), 8);
    out += bytes;
    out.append(reinterpret_cast<const char*>(&sum), 8);
    bytes.swap(out);
  }
  try {
    Checkpoint c = Checkpoint::parse(bytes, "fuzz.bin");
    for (auto& [name, b] : c.sections) {
      try {
        (void)c.floats(name, "fuzz.bin", int64_t(b.size() / 4));
      } catch (const Error&) {
      }
    }
    if (Checkpoint::parse(c.serialize(), "again").sections != c.sections) std::abort();
    return true;
  } catch (const Error&) {
    return false;
  }
}

inline bool config(const std::string& text) {
  try {
    TrainConfig c = train_config_from_json(text, "config.json");
    // What we write we must read back.
    TrainConfig d = train_config_from_json(train_config_json(c), "again");
    if (train_config_json(d) != train_config_json(c)) std::abort();
    return true;
  } catch (const Error&) {
    return false;
  }
}

inline bool image(const std::string& bytes) {
  try {
    // TGA has no signature and is read only from *.tga files: a leading 0 byte (a TGA's usual
    // id length) names the input .tga so that decoder is fuzzed too.
    const char* name = !bytes.empty() && bytes[0] == 0 ? "fuzz.tga" : "fuzz.png";
    ImageU8 im = read_image_from_memory(bytes, name);
    if (im.width <= 0 || im.height <= 0 || im.rgb.size() != size_t(im.width) * im.height * 3)
      std::abort();
    return true;
  } catch (const Error&) {
    return false;
  }
}

// The EXIF reader's contract is stronger: it never throws (a bad block is ignored with a note),
// and what it returns is in range. The bytes are read three ways: as a TIFF block, as a whole
// file, and wrapped into a JPEG's APP1 segment. True when the TIFF block's IFD0 was read.
inline bool exif(const std::string& bytes) {
  auto check = [](const ExifInfo& e) {
    const bool ok = e.orientation >= 1 && e.orientation <= 8 && e.focal35_mm >= 0 &&
                    e.focal_mm >= 0 && e.plane_xres >= 0 && e.plane_unit_mm >= 0 &&
                    e.pixel_x >= 0 && e.pixel_y >= 0;
    const double f = exif_focal_px(e, 4032);
    if (!ok || !(f >= 0) || !std::isfinite(f)) std::abort();
  };
  const ExifInfo a = parse_exif_tiff(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  check(a);
  check(read_exif_from_jpeg(bytes));
  check(read_exif_from_jpeg(jpeg_with_exif(std::string("\xFF\xD8\xFF\xD9", 4), bytes)));
  return a.present;
}

}  // namespace hashcc::fuzz
