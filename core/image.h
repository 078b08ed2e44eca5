// core/image.h — images in and out: PNG/JPG via stb (8- and 16-bit), float images via OpenEXR.
//
// Training images are held as 8-bit RGB until a pixel is sampled (memory: 3 bytes a pixel);
// 16-bit PNGs are reduced to 8 bits on load, RGBA drops alpha, grey is replicated to RGB.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "core/exif.h"

namespace hashcc {

struct ImageU8 {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // (H, W, 3)
  float at(int row, int col, int c) const {
    return rgb[(size_t(row) * width + col) * 3 + c] * (1.0f / 255.0f);
  }
};

// Largest image accepted: checked from the header BEFORE any pixel memory is allocated.
constexpr int64_t kMaxImagePixels = int64_t(1) << 28;  // 268 M pixels (e.g. 16384²)

// Reads the size from the header only, as the image displays: a JPEG whose EXIF orientation
// is 5-8 (stored on its side) reports its height as width. *exif (optional) gets the JPEG's
// EXIF tags (core/exif.h; absent for other formats). Throws hashcc::Error for unreadable or
// corrupt files.
void image_size(const std::string& path, int* width, int* height, ExifInfo* exif = nullptr);
// Reads a PNG/JPG/BMP/TGA as 8-bit RGB, upright (a JPEG's EXIF orientation applied) and, when
// max_side > 0 and the image is larger, downscaled with an area filter so that its longer side
// is max_side (working_size). Only the result is kept: the full-size decode is freed before
// returning. Throws hashcc::Error naming the file on any problem (missing, zero bytes,
// truncated, corrupt, too large).
ImageU8 read_image(const std::string& path, int max_side = 0, ExifInfo* exif = nullptr);
// The same from bytes already in memory; `name` is used in error messages (fuzzers, tests).
ImageU8 read_image_from_memory(const std::string& bytes, const std::string& name,
                               int max_side = 0, ExifInfo* exif = nullptr);

// The size a w×h image is loaded at under max_side: unchanged when max_side is 0 or the longer
// side already fits, else scaled by max_side / max(w, h) with each side rounded (at least 1):
// 4032×3024 → 504×378, 2000×1500 at 500 → 500×375.
void working_size(int w, int h, int max_side, int* out_w, int* out_h);
// The stored pixels turned upright for EXIF orientation 1-8 (5-8 swap width and height).
ImageU8 apply_orientation(const ImageU8& stored, int orientation);
// Area-filtered downscale (stb_image_resize's box filter on the 8-bit values, as LLFF's
// images_N were made) to out_w × out_h; the pixels unchanged when the size is the same.
ImageU8 resize_area(const uint8_t* rgb, int w, int h, int out_w, int out_h);

// A PNG file's bytes of 8-bit RGB (stb): for files (write_png) and for pages that carry their
// images inline (tools/run_report.h: base64 data URIs). rgb (H, W, 3).
std::string encode_png(const uint8_t* rgb, int width, int height);
// Writes 8-bit RGB PNG (crash-safe). rgb (H, W, 3).
void write_png(const std::string& path, const uint8_t* rgb, int width, int height);
// A JPEG file's bytes (stb, baseline, quality 1-100) of 8-bit RGB; no EXIF (jpeg_with_exif).
std::string encode_jpeg(const uint8_t* rgb, int width, int height, int quality);
// Writes float RGB in [0,1] as PNG (clamped, rounded).
void write_png_float(const std::string& path, const float* rgb, int width, int height);
// Writes a float image with `channels` (1 = "Y", 3 = "R,G,B") channels as OpenEXR (half-free
// float32). data (H, W, channels).
void write_exr(const std::string& path, const float* data, int width, int height, int channels);

// True for file names stb can read (by extension, case-insensitive).
bool is_image_filename(const std::string& name);

}  // namespace hashcc
