// core/image.h — images in and out: PNG/JPG via stb (8- and 16-bit), float images via OpenEXR.
//
// Training images are held as 8-bit RGB until a pixel is sampled (memory: 3 bytes a pixel);
// 16-bit PNGs are reduced to 8 bits on load, RGBA drops alpha, grey is replicated to RGB.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

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

// Reads the size from the header only; throws hashcc::Error for unreadable/corrupt files.
void image_size(const std::string& path, int* width, int* height);
// Reads a PNG/JPG/BMP/TGA as 8-bit RGB. Throws hashcc::Error naming the file on any problem
// (missing, zero bytes, truncated, corrupt, too large).
ImageU8 read_image(const std::string& path);
// The same from bytes already in memory; `name` is used in error messages (fuzzers, tests).
ImageU8 read_image_from_memory(const std::string& bytes, const std::string& name);

// Writes 8-bit RGB PNG (crash-safe). rgb (H, W, 3).
void write_png(const std::string& path, const uint8_t* rgb, int width, int height);
// Writes float RGB in [0,1] as PNG (clamped, rounded).
void write_png_float(const std::string& path, const float* rgb, int width, int height);
// Writes a float image with `channels` (1 = "Y", 3 = "R,G,B") channels as OpenEXR (half-free
// float32). data (H, W, channels).
void write_exr(const std::string& path, const float* data, int width, int height, int channels);

// True for file names stb can read (by extension, case-insensitive).
bool is_image_filename(const std::string& name);

}  // namespace hashcc
