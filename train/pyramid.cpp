// train/pyramid.cpp — box-filtered lattice levels and the level schedule (train/pyramid.h).
#include "train/pyramid.h"

#include <algorithm>

#include "core/error.h"

namespace hashcc {

std::vector<int> box_filter_taps(int s) {
  HCC_REQUIRE(s >= 2 && s <= 8 && s % 2 == 0, "--pyramid", "level", "{}", s, "2, 4, 6 or 8");
  std::vector<int> c(size_t(s) + 1, 2);
  c.front() = c.back() = 1;  // the half-covered end pixels: weight 1/(2s)
  return c;
}

PyramidLevel make_pyramid_level(const ImageU8& img, int s) {
  const std::vector<int> c = box_filter_taps(s);
  const int W = img.width, H = img.height, half = s / 2;
  PyramidLevel L;
  L.s = s;
  L.width = (W + s - 1) / s;
  L.height = (H + s - 1) / s;
  L.num.assign(size_t(L.width) * L.height * 3, 0);
  for (int y = 0; y < L.height; ++y)
    for (int x = 0; x < L.width; ++x) {
      // Centred on the full-resolution pixel (s·x, s·y); borders clamp (edge pixels repeat).
      int sum[3] = {0, 0, 0};
      for (int i = 0; i <= s; ++i) {
        const int row = std::clamp(s * y - half + i, 0, H - 1);
        for (int j = 0; j <= s; ++j) {
          const int col = std::clamp(s * x - half + j, 0, W - 1);
          const uint8_t* p = &img.rgb[(size_t(row) * W + col) * 3];
          for (int k = 0; k < 3; ++k) sum[k] += c[i] * c[j] * p[k];
        }
      }
      // Σ c_i c_j p ≤ (2s)²·255 ≤ 65,280 for s ≤ 8: exact in a uint16.
      for (int k = 0; k < 3; ++k) L.num[(size_t(y) * L.width + x) * 3 + k] = uint16_t(sum[k]);
    }
  return L;
}

int pyramid_level(int64_t step, int64_t total, double fraction) {
  if (fraction <= 0) return 1;
  // Boundaries truncated like --camera-delay's start (train/trainer.cpp, camera_lr).
  if (step < int64_t(0.5 * fraction * double(total))) return 4;
  if (step < int64_t(fraction * double(total))) return 2;
  return 1;
}

}  // namespace hashcc
