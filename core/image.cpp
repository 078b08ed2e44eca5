#include "core/image.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>

#include "core/error.h"
#include "core/fileio.h"

#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#define STBI_NO_STDIO_BUFFER_HACK
#include <stb_image.h>
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

namespace hashcc {

namespace {
std::string read_image_bytes(const std::string& path) {
  std::string bytes = read_file_bytes(path, int64_t(2) << 30);
  HCC_REQUIRE(!bytes.empty(), path, "", "empty file (0 bytes)", "an image");
  return bytes;
}
void check_header(const std::string& path, const std::string& bytes, int* w, int* h, int* c) {
  auto* p = reinterpret_cast<const stbi_uc*>(bytes.data());
  HCC_REQUIRE(stbi_info_from_memory(p, int(bytes.size()), w, h, c), path, "",
              "not a readable image ({})", stbi_failure_reason() ? stbi_failure_reason() : "?",
              "PNG, JPG, BMP or TGA");
  HCC_REQUIRE(*w > 0 && *h > 0 && int64_t(*w) * *h <= kMaxImagePixels, path, "header",
              "image size {}x{} is out of range", *w, *h,
              fmt::format("at most {} pixels", kMaxImagePixels));
}
}  // namespace

bool is_image_filename(const std::string& name) {
  std::string ext = std::filesystem::path(name).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".tga";
}

void image_size(const std::string& path, int* width, int* height) {
  std::string bytes = read_image_bytes(path);
  int c;
  check_header(path, bytes, width, height, &c);
}

ImageU8 read_image(const std::string& path) {
  return read_image_from_memory(read_image_bytes(path), path);
}

ImageU8 read_image_from_memory(const std::string& bytes, const std::string& path) {
  HCC_REQUIRE(!bytes.empty(), path, "", "empty file (0 bytes)", "an image");
  HCC_REQUIRE(bytes.size() < (size_t(1) << 31), path, "", "file too large ({} bytes)", bytes.size());
  int w, h, c;
  check_header(path, bytes, &w, &h, &c);
  auto* p = reinterpret_cast<const stbi_uc*>(bytes.data());
  ImageU8 img;
  img.width = w;
  img.height = h;
  img.rgb.resize(size_t(w) * h * 3);
  int ww = 0, hh = 0, cc = 0;
  if (stbi_is_16_bit_from_memory(p, int(bytes.size()))) {
    stbi_us* d = stbi_load_16_from_memory(p, int(bytes.size()), &ww, &hh, &cc, 3);
    HCC_REQUIRE(d, path, "", "corrupt or truncated image ({})",
                stbi_failure_reason() ? stbi_failure_reason() : "?");
    // The decoder may disagree with the header parser: never copy more than it returned.
    if (ww != w || hh != h) {
      stbi_image_free(d);
      throw Error(path, "", fmt::format("corrupt image: header says {}x{}, data decode to {}x{}",
                                        w, h, ww, hh));
    }
    for (size_t i = 0; i < img.rgb.size(); ++i) img.rgb[i] = uint8_t((d[i] * 255u + 32767u) / 65535u);
    stbi_image_free(d);
  } else {
    stbi_uc* d = stbi_load_from_memory(p, int(bytes.size()), &ww, &hh, &cc, 3);
    HCC_REQUIRE(d, path, "", "corrupt or truncated image ({})",
                stbi_failure_reason() ? stbi_failure_reason() : "?");
    if (ww != w || hh != h) {
      stbi_image_free(d);
      throw Error(path, "", fmt::format("corrupt image: header says {}x{}, data decode to {}x{}",
                                        w, h, ww, hh));
    }
    std::copy(d, d + img.rgb.size(), img.rgb.begin());
    stbi_image_free(d);
  }
  return img;
}

void write_png(const std::string& path, const uint8_t* rgb, int width, int height) {
  int len = 0;
  unsigned char* png = stbi_write_png_to_mem(rgb, width * 3, width, height, 3, &len);
  HCC_REQUIRE(png, path, "", "PNG encoding failed");
  std::string bytes(reinterpret_cast<char*>(png), size_t(len));
  STBIW_FREE(png);
  write_file_atomic(path, bytes);
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
