#include "core/image.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <cmath>
#include <filesystem>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>

#include "core/error.h"
#include "core/fileio.h"

// stb's implementation is compiled in core/stb_impl.cpp (with its own sanitizer settings).
#include <stb_image.h>
#include <stb_image_resize.h>
#include <stb_image_write.h>

namespace hashcc {

namespace {
std::string read_image_bytes(const std::string& path) {
  std::string bytes = read_file_bytes(path, int64_t(2) << 30);
  HCC_REQUIRE(!bytes.empty(), path, "", "empty file (0 bytes)", "an image");
  return bytes;
}
bool ends_with_ci(const std::string& s, const std::string& suffix) {
  if (s.size() < suffix.size()) return false;
  for (size_t i = 0; i < suffix.size(); ++i)
    if (std::tolower((unsigned char)s[s.size() - suffix.size() + i]) != suffix[i]) return false;
  return true;
}

uint32_t be16(const std::string& b, size_t i) { return (uint8_t(b[i]) << 8) | uint8_t(b[i + 1]); }

// JPEG checks stb 2.27 (Debian) does not make. Walks every marker segment (and the entropy-
// coded data between them, where a marker is FF followed by neither 00 nor RST0–7):
//  - a DHT table whose 16 code counts sum to more than 256 symbols overflows stb's Huffman
//    arrays (fuzz finding image/crash-3a2568c7: UBSan index 257 out of bounds in
//    stbi__build_huffman; fixed upstream in 2.28) — rejected here, before stb sees it;
//  - a file that stops before its end-of-image marker is truncated. stb decodes such a file
//    "successfully" with the missing part grey, which would train on a broken photo.
void check_jpeg(const std::string& path, const std::string& b) {
  const size_t n = b.size();
  bool eoi = false;
  size_t i = 2;  // after SOI (FF D8)
  while (i + 1 < n) {
    if (uint8_t(b[i]) != 0xFF) { ++i; continue; }
    size_t m = i + 1;
    while (m < n && uint8_t(b[m]) == 0xFF) ++m;  // fill bytes
    if (m >= n) break;
    const uint8_t marker = uint8_t(b[m]);
    i = m + 1;
    if (marker == 0x00 || (marker >= 0xD0 && marker <= 0xD7) || marker == 0x01) continue;
    if (marker == 0xD9) { eoi = true; break; }
    if (i + 2 > n) break;
    const size_t len = be16(b, i);
    HCC_REQUIRE(len >= 2 && i + len <= n, path, fmt::format("JPEG marker FF{:02X}", marker),
                "segment length {} runs past the end of the file (truncated or corrupt)", len,
                "a complete JPEG file");
    if (marker == 0xC4) {  // DHT: one or more tables of (class/id, 16 counts, symbols)
      size_t t = i + 2, end = i + len;
      while (t < end) {
        HCC_REQUIRE(t + 17 <= end, path, "JPEG Huffman table", "truncated table");
        int total = 0;
        for (int k = 0; k < 16; ++k) total += uint8_t(b[t + 1 + k]);
        HCC_REQUIRE(total <= 256, path, "JPEG Huffman table",
                    "{} codes, at most 256 are possible (corrupt file)", total);
        t += 17 + size_t(total);
      }
      HCC_REQUIRE(t == end, path, "JPEG Huffman table", "tables overrun their segment");
    }
    i += len;
  }
  HCC_REQUIRE(eoi, path, "", "truncated JPEG (no end-of-image marker)", "a complete JPEG file");
}

// The file's signature decides its format, never its name: PNG, JPEG and BMP have magic
// numbers; TGA has none, so it is accepted only from a file named *.tga.
// Returns 'p' (PNG), 'j' (JPEG), 'b' (BMP) or 't' (TGA).
char check_signature(const std::string& path, const std::string& b) {
  if (b.size() >= 8 && b.compare(0, 8, "\x89PNG\r\n\x1a\n", 8) == 0) {
    // stb refuses > 2^30-byte PNGs itself but says only "unknown image type": read IHDR's
    // size here so a huge header is reported as one, before anything is allocated.
    if (b.size() >= 24 && b.compare(12, 4, "IHDR") == 0) {
      const int64_t w = (int64_t(be16(b, 16)) << 16) | be16(b, 18);
      const int64_t h = (int64_t(be16(b, 20)) << 16) | be16(b, 22);
      // fuzz finding image/crash-…: w * h overflowed int64 for a 2^32-wide header (UBSan).
      HCC_REQUIRE(w > 0 && h > 0 && w <= kMaxImagePixels / h, path, "header",
                  "image size {}x{} is out of range (at most {} pixels)", w, h, kMaxImagePixels);
    }
    return 'p';
  }
  if (b.size() >= 3 && b.compare(0, 3, "\xFF\xD8\xFF", 3) == 0) {
    check_jpeg(path, b);
    return 'j';
  }
  if (b.size() >= 2 && b.compare(0, 2, "BM") == 0) return 'b';
  if (ends_with_ci(path, ".tga")) return 't';
  throw Error(path, "", "not an image (unrecognised file signature)", "PNG, JPG, BMP or TGA");
}

void check_header(const std::string& path, const std::string& bytes, int* w, int* h, int* c) {
  const char format = check_signature(path, bytes);
  auto* p = reinterpret_cast<const stbi_uc*>(bytes.data());
  HCC_REQUIRE(stbi_info_from_memory(p, int(bytes.size()), w, h, c), path, "",
              "corrupt or unreadable image header ({})",
              stbi_failure_reason() ? stbi_failure_reason() : "?", "PNG, JPG, BMP or TGA");
  HCC_REQUIRE(*w > 0 && *h > 0 && int64_t(*w) * *h <= kMaxImagePixels, path, "header",
              "image size {}x{} is out of range", *w, *h,
              fmt::format("at most {} pixels", kMaxImagePixels));
  // Decompression bombs and truncated files: no format packs more pixels into a byte than
  // deflate's 1032:1 at 1 bit a pixel (PNG, ≈ 8256 pixels a byte); RLE TGA/BMP and JPEG stay
  // far below 1100. stb reads zeros past the end of a TGA, so an 83-byte file claiming
  // 39203×1024 pixels decoded for 20 s under ASan (fuzz finding image/timeout-6d8bb7ca).
  const int64_t max_ratio = format == 'p' ? 8800 : 1100;
  HCC_REQUIRE(int64_t(*w) * *h <= int64_t(bytes.size()) * max_ratio, path, "header",
              "{} bytes cannot hold a {}x{} image (truncated or corrupt)", bytes.size(), *w, *h);
}
}  // namespace

bool is_image_filename(const std::string& name) {
  std::string ext = std::filesystem::path(name).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".tga";
}

void image_size(const std::string& path, int* width, int* height, ExifInfo* exif) {
  std::string bytes = read_image_bytes(path);
  int c;
  check_header(path, bytes, width, height, &c);
  const ExifInfo e = read_exif_from_jpeg(bytes);
  if (orientation_swaps_axes(e.orientation)) std::swap(*width, *height);
  if (exif) *exif = e;
}

ImageU8 read_image(const std::string& path, int max_side, ExifInfo* exif) {
  return read_image_from_memory(read_image_bytes(path), path, max_side, exif);
}

void working_size(int w, int h, int max_side, int* out_w, int* out_h) {
  *out_w = w;
  *out_h = h;
  const int longest = std::max(w, h);
  if (max_side <= 0 || longest <= max_side) return;
  const double s = double(max_side) / longest;
  *out_w = std::max(1, int(std::lround(w * s)));
  *out_h = std::max(1, int(std::lround(h * s)));
}

ImageU8 apply_orientation(const ImageU8& in, int orientation) {
  if (orientation < 2 || orientation > 8) return in;
  const int W = in.width, H = in.height;
  ImageU8 out;
  const bool swap = orientation_swaps_axes(orientation);
  out.width = swap ? H : W;
  out.height = swap ? W : H;
  out.rgb.resize(in.rgb.size());
  // For each displayed pixel (r, c), the stored pixel (sr, sc) it shows. EXIF 2.3 §4.6.4 A
  // names where the stored row 0 / column 0 go: 6 "row 0 on the right" = turn 90° clockwise
  // to view, so displayed (0, 0) is stored (H−1, 0), its bottom-left; 8 the other way round.
  for (int r = 0; r < out.height; ++r)
    for (int c = 0; c < out.width; ++c) {
      int sr = r, sc = c;
      switch (orientation) {
        case 2: sc = W - 1 - c; break;                     // mirrored left-right
        case 3: sr = H - 1 - r; sc = W - 1 - c; break;     // upside down (180°)
        case 4: sr = H - 1 - r; break;                     // mirrored top-bottom
        case 5: sr = c; sc = r; break;                     // transposed
        case 6: sr = H - 1 - c; sc = r; break;             // turn 90° clockwise to view
        case 7: sr = H - 1 - c; sc = W - 1 - r; break;     // transverse
        case 8: sr = c; sc = W - 1 - r; break;             // turn 90° anticlockwise to view
      }
      const uint8_t* src = &in.rgb[(size_t(sr) * W + sc) * 3];
      uint8_t* dst = &out.rgb[(size_t(r) * out.width + c) * 3];
      dst[0] = src[0]; dst[1] = src[1]; dst[2] = src[2];
    }
  return out;
}

ImageU8 resize_area(const uint8_t* rgb, int w, int h, int out_w, int out_h) {
  ImageU8 out;
  out.width = out_w;
  out.height = out_h;
  if (out_w == w && out_h == h) {
    out.rgb.assign(rgb, rgb + size_t(w) * h * 3);
    return out;
  }
  out.rgb.resize(size_t(out_w) * out_h * 3);
  // The box filter averages the 8-bit values over each output pixel's footprint (exactly for an
  // integer ratio such as 4032 → 504; stb ramps one source pixel at fractional edges). No sRGB
  // linearisation: LLFF's images_N were made the same way (ImageMagick on the encoded values),
  // so a phone photo at max-side 504 looks like LLFF's images_8.
  HCC_REQUIRE(stbir_resize_uint8_generic(rgb, w, h, w * 3, out.rgb.data(), out_w, out_h,
                                         out_w * 3, 3, STBIR_ALPHA_CHANNEL_NONE, 0,
                                         STBIR_EDGE_CLAMP, STBIR_FILTER_BOX,
                                         STBIR_COLORSPACE_LINEAR, nullptr),
              "resize", "", "out of memory downscaling {}x{} to {}x{}", w, h, out_w, out_h);
  return out;
}

// A zero-length IDAT chunk is legal PNG but makes stb 2.27 memcpy 0 bytes to a null buffer
// (UB; fuzz finding image/crash-…: stb_image.h:1663 "null pointer passed as argument 1").
// Such chunks carry no data: drop them (each chunk has its own CRC, so the rest stays valid).
static bool drop_empty_idat(const std::string& b, std::string* out_) {
  if (b.size() < 8 || b.compare(0, 8, "\x89PNG\r\n\x1a\n", 8) != 0) return false;
  std::string& out = *out_;
  size_t i = 8, copied = 0;
  while (i + 8 <= b.size()) {  // chunk: u32 length, type, data, u32 CRC
    const uint64_t len = (uint64_t(be16(b, i)) << 16) | be16(b, i + 2);
    if (len == 0 && b.compare(i + 4, 4, "IDAT") == 0) {  // even with its CRC cut off
      out.append(b, copied, i - copied);
      copied = std::min(i + 12, b.size());
    }
    if (len + 12 > b.size() - i) break;
    i += 12 + len;
  }
  if (copied == 0) return false;
  out.append(b, copied, std::string::npos);
  return true;
}

// What a file that fails to decode should have been (the "expected …" of its error).
constexpr const char* kWholeImage = "a complete PNG, JPG, BMP or TGA file";

ImageU8 read_image_from_memory(const std::string& raw, const std::string& path, int max_side,
                               ExifInfo* exif) {
  HCC_REQUIRE(!raw.empty(), path, "", "empty file (0 bytes)", "an image");
  std::string fixed;
  const std::string& bytes = drop_empty_idat(raw, &fixed) ? fixed : raw;
  HCC_REQUIRE(bytes.size() < (size_t(1) << 31), path, "", "file too large ({} bytes)", bytes.size());
  int w, h, c;
  check_header(path, bytes, &w, &h, &c);
  auto* p = reinterpret_cast<const stbi_uc*>(bytes.data());
  const ExifInfo e = read_exif_from_jpeg(bytes);
  if (exif) *exif = e;
  // Downscale first, then turn upright: the same pixels, and turning the small image is cheap.
  // max_side bounds the longer side, which turning does not change.
  int out_w, out_h;
  working_size(w, h, max_side, &out_w, &out_h);
  ImageU8 img;
  int ww = 0, hh = 0, cc = 0;
  // The decoder may disagree with the header parser: never copy more than it returned.
  auto check_decoded = [&](void* d) {
    HCC_REQUIRE(d, path, "", "corrupt or truncated image ({})",
                stbi_failure_reason() ? stbi_failure_reason() : "?", kWholeImage);
    if (ww != w || hh != h) {
      stbi_image_free(d);
      throw Error(path, "", fmt::format("corrupt image: header says {}x{}, data decode to {}x{}",
                                        w, h, ww, hh), kWholeImage);
    }
  };
  if (stbi_is_16_bit_from_memory(p, int(bytes.size()))) {
    stbi_us* d = stbi_load_16_from_memory(p, int(bytes.size()), &ww, &hh, &cc, 3);
    check_decoded(d);
    std::vector<uint8_t> rgb8(size_t(w) * h * 3);
    for (size_t i = 0; i < rgb8.size(); ++i) rgb8[i] = uint8_t((d[i] * 255u + 32767u) / 65535u);
    stbi_image_free(d);
    if (out_w == w && out_h == h) {
      img.width = w;
      img.height = h;
      img.rgb = std::move(rgb8);
    } else {
      img = resize_area(rgb8.data(), w, h, out_w, out_h);
    }
  } else {
    stbi_uc* d = stbi_load_from_memory(p, int(bytes.size()), &ww, &hh, &cc, 3);
    check_decoded(d);
    // The full-size decode lives only until its working-size copy exists (--max-side).
    try {
      img = resize_area(d, w, h, out_w, out_h);
    } catch (...) {
      stbi_image_free(d);
      throw;
    }
    stbi_image_free(d);
  }
  return e.orientation == 1 ? img : apply_orientation(img, e.orientation);
}

std::string encode_png(const uint8_t* rgb, int width, int height) {
  std::string bytes;
  int ok = stbi_write_png_to_func(
      [](void* ctx, void* data, int size) {
        static_cast<std::string*>(ctx)->append(static_cast<const char*>(data), size_t(size));
      },
      &bytes, width, height, 3, rgb, width * 3);
  HCC_REQUIRE(ok && !bytes.empty(), "png", "", "PNG encoding of a {}x{} image failed", width,
              height);
  return bytes;
}

void write_png(const std::string& path, const uint8_t* rgb, int width, int height) {
  std::string bytes;
  try {
    bytes = encode_png(rgb, width, height);
  } catch (const Error& e) {
    throw Error(path, "", e.problem);
  }
  write_file_atomic(path, bytes);
}

std::string encode_jpeg(const uint8_t* rgb, int width, int height, int quality) {
  std::string bytes;
  int ok = stbi_write_jpg_to_func(
      [](void* ctx, void* data, int size) {
        static_cast<std::string*>(ctx)->append(static_cast<const char*>(data), size_t(size));
      },
      &bytes, width, height, 3, rgb, quality);
  HCC_REQUIRE(ok && !bytes.empty(), "jpeg", "", "JPEG encoding of a {}x{} image failed", width,
              height);
  return bytes;
}

void write_png_float(const std::string& path, const float* rgb, int width, int height) {
  std::vector<uint8_t> b(size_t(width) * height * 3);
  for (size_t i = 0; i < b.size(); ++i) {
    float v = rgb[i];
    if (!(v >= 0)) v = 0;  // NaN → 0
    b[i] = uint8_t(std::lround(std::min(v, 1.0f) * 255.0f));
  }
  write_png(path, b.data(), width, height);
}

void write_exr(const std::string& path, const float* data, int width, int height, int channels) {
  HCC_ASSERT(channels == 1 || channels == 3);
  try {
    Imf::Header header(width, height);
    const char* names3[] = {"R", "G", "B"};
    for (int c = 0; c < channels; ++c)
      header.channels().insert(channels == 1 ? "Y" : names3[c], Imf::Channel(Imf::FLOAT));
    std::string tmp = path + ".tmp.exr";
    {
      Imf::OutputFile file(tmp.c_str(), header);
      Imf::FrameBuffer fb;
      for (int c = 0; c < channels; ++c)
        fb.insert(channels == 1 ? "Y" : names3[c],
                  Imf::Slice(Imf::FLOAT, (char*)(data + c), sizeof(float) * channels,
                             sizeof(float) * channels * width));
      file.setFrameBuffer(fb);
      file.writePixels(height);
    }
    std::filesystem::rename(tmp, path);
  } catch (const std::exception& e) {
    throw Error(path, "", fmt::format("EXR write failed: {}", e.what()));
  }
}

}  // namespace hashcc
