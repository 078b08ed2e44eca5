// eval/metrics.cpp — PSNR, SSIM, error heatmap (see metrics.h).
#include "eval/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/parallel.h"

namespace hashcc {
namespace {

void require_same_size(const ImageF& a, const ImageF& b, const char* what) {
  HCC_REQUIRE(a.H > 0 && a.W > 0, "", what, "empty image ({}x{})", a.H, a.W);
  HCC_REQUIRE(a.H == b.H && a.W == b.W, "", what, "image sizes differ: {}x{} vs {}x{}", a.H,
              a.W, b.H, b.W);
  HCC_REQUIRE(a.rgb.size() == size_t(a.H) * a.W * 3 && b.rgb.size() == a.rgb.size(), "", what,
              "pixel buffer size does not match H*W*3 = {}", size_t(a.H) * a.W * 3);
}

constexpr int kRadius = 5;  // 11×11 window
constexpr double kC1 = 0.01 * 0.01, kC2 = 0.03 * 0.03;

// Zero-padded separable blur of an interleaved (H, W, 3) plane: out = g ⊗ g * in.
// Rows first into tmp, then columns; each pass is parallel over the output rows it writes.
void blur(std::vector<double>& out, std::vector<double>& tmp, const std::vector<double>& in,
          int H, int W, const std::vector<double>& g) {
  const int C = 3;
  parallel_for(H, [&](int64_t y) {
    const double* row = &in[size_t(y) * W * C];
    double* dst = &tmp[size_t(y) * W * C];
    for (int x = 0; x < W; ++x) {
      double s[3] = {0, 0, 0};
      int k0 = std::max(0, kRadius - x), k1 = std::min(2 * kRadius, W - 1 - x + kRadius);
      for (int k = k0; k <= k1; ++k) {
        const double* p = row + size_t(x + k - kRadius) * C;
        s[0] += g[k] * p[0]; s[1] += g[k] * p[1]; s[2] += g[k] * p[2];
      }
      dst[x * C + 0] = s[0]; dst[x * C + 1] = s[1]; dst[x * C + 2] = s[2];
    }
  });
  parallel_for(H, [&](int64_t y) {
    double* dst = &out[size_t(y) * W * C];
    std::fill(dst, dst + size_t(W) * C, 0.0);
    int k0 = std::max<int>(0, kRadius - int(y)), k1 = std::min<int>(2 * kRadius, H - 1 - int(y) + kRadius);
    for (int k = k0; k <= k1; ++k) {
      const double* src = &tmp[size_t(y + k - kRadius) * W * C];
      for (int i = 0; i < W * C; ++i) dst[i] += g[k] * src[i];
    }
  });
}

}  // namespace

double mse(const ImageF& a, const ImageF& b) {
  require_same_size(a, b, "mse");
  double s = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    double d = double(a.rgb[i]) - double(b.rgb[i]);
    s += d * d;
  }
  return s / double(a.rgb.size());
}

double psnr(const ImageF& a, const ImageF& b) {
  double m = mse(a, b);
  if (m == 0.0) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(m);  // formulas.md §7
}

std::vector<double> ssim_gaussian_1d() {
  std::vector<double> g(2 * kRadius + 1);
  double sum = 0;
  for (int i = 0; i <= 2 * kRadius; ++i) {
    double d = i - kRadius;
    g[i] = std::exp(-d * d / (2.0 * 1.5 * 1.5));
    sum += g[i];
  }
  for (double& v : g) v /= sum;
  return g;
}

std::vector<float> ssim_map(const ImageF& a, const ImageF& b) {
  require_same_size(a, b, "ssim");
  const int H = a.H, W = a.W;
  const size_t n = size_t(H) * W * 3;
  const std::vector<double> g = ssim_gaussian_1d();
  std::vector<double> in(n), tmp(n), mu_a(n), mu_b(n), e_aa(n), e_bb(n), e_ab(n);
  auto blur_of = [&](std::vector<double>& out, auto f) {
    parallel_for(int64_t(n), [&](int64_t i) { in[i] = f(double(a.rgb[i]), double(b.rgb[i])); }, 4096);
    blur(out, tmp, in, H, W, g);
  };
  blur_of(mu_a, [](double x, double) { return x; });
  blur_of(mu_b, [](double, double y) { return y; });
  blur_of(e_aa, [](double x, double) { return x * x; });
  blur_of(e_bb, [](double, double y) { return y * y; });
  blur_of(e_ab, [](double x, double y) { return x * y; });
  std::vector<float> map(n);
  parallel_for(int64_t(n), [&](int64_t i) {
    double ma = mu_a[i], mb = mu_b[i];
    double va = e_aa[i] - ma * ma, vb = e_bb[i] - mb * mb, cov = e_ab[i] - ma * mb;
    map[i] = float(((2 * ma * mb + kC1) * (2 * cov + kC2)) /
                   ((ma * ma + mb * mb + kC1) * (va + vb + kC2)));
  }, 4096);
  return map;
}

double ssim(const ImageF& a, const ImageF& b) {
  std::vector<float> m = ssim_map(a, b);
  double s = 0;
  for (float v : m) s += v;
  return s / double(m.size());
}

void turbo_colormap(float t, float rgb[3]) {
  // Turbo, polynomial fit by Ruofei Du (Google, 2019, Apache-2.0 snippet), max error ~1%.
  double x = std::clamp(double(t), 0.0, 1.0);
  double x2 = x * x, x3 = x2 * x, x4 = x2 * x2, x5 = x4 * x;
  double r = 0.13572138 + 4.61539260 * x - 42.66032258 * x2 + 132.13108234 * x3 -
             152.94239396 * x4 + 59.28637943 * x5;
  double gg = 0.09140261 + 2.19418839 * x + 4.84296658 * x2 - 14.18503333 * x3 +
              4.27729857 * x4 + 2.82956604 * x5;
  double b = 0.10667330 + 12.64194608 * x - 60.58204836 * x2 + 110.36276771 * x3 -
             89.90310912 * x4 + 27.34824973 * x5;
  rgb[0] = float(std::clamp(r, 0.0, 1.0));
  rgb[1] = float(std::clamp(gg, 0.0, 1.0));
  rgb[2] = float(std::clamp(b, 0.0, 1.0));
}

ImageRGB8 error_heatmap(const ImageF& a, const ImageF& b, float max_error) {
  require_same_size(a, b, "error_heatmap");
  HCC_REQUIRE(max_error > 0 && std::isfinite(max_error), "", "error_heatmap",
              "max_error = {} (expected a positive finite value)", max_error);
  ImageRGB8 out;
  out.H = a.H; out.W = a.W;
  out.rgb.resize(size_t(a.H) * a.W * 3);
  parallel_for(int64_t(a.H) * a.W, [&](int64_t p) {
    float e = 0;
    for (int c = 0; c < 3; ++c) e += std::fabs(a.rgb[p * 3 + c] - b.rgb[p * 3 + c]);
    e /= 3.f;
    float col[3];
    turbo_colormap(e / max_error, col);
    for (int c = 0; c < 3; ++c) out.rgb[p * 3 + c] = uint8_t(std::lround(col[c] * 255.f));
  }, 4096);
  return out;
}

}  // namespace hashcc
