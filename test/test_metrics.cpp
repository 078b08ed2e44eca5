// Tests of eval/metrics: PSNR, SSIM (against an independent direct 121-tap implementation and a
// closed form for constant images), error heatmap.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/parallel.h"
#include "eval/metrics.h"
#include "test/gradcheck.h"

using namespace hashcc;

namespace {

ImageF random_image(int H, int W, uint64_t seed) {
  Rng rng(seed);
  ImageF im(H, W);
  for (float& v : im.rgb) v = rng.uniformf();
  return im;
}

// A smooth-ish image (sum of sinusoids) so that shifts give SSIM well inside (0, 1).
ImageF smooth_image(int H, int W) {
  ImageF im(H, W);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < 3; ++c)
        im.at(y, x, c) = float(0.5 + 0.3 * std::sin(0.31 * x + 0.7 * c) * std::cos(0.23 * y - 0.4 * c) +
                               0.15 * std::sin(0.9 * (x + y)));
  return im;
}

// Direct SSIM map: the full 11×11 window, written independently of the library (2-D Gaussian
// from exp(−(i²+j²)/(2σ²)) normalised over its 121 taps, zero padding = skip outside taps).
std::vector<double> ssim_map_direct(const ImageF& a, const ImageF& b) {
  double w[11][11], sum = 0;
  for (int i = 0; i < 11; ++i)
    for (int j = 0; j < 11; ++j) sum += (w[i][j] = std::exp(-((i - 5) * (i - 5) + (j - 5) * (j - 5)) / 4.5));
  for (auto& r : w) for (double& v : r) v /= sum;
  const double C1 = 1e-4, C2 = 9e-4;
  std::vector<double> out(a.rgb.size());
  for (int y = 0; y < a.H; ++y)
    for (int x = 0; x < a.W; ++x)
      for (int c = 0; c < 3; ++c) {
        double ma = 0, mb = 0, aa = 0, bb = 0, ab = 0;
        for (int i = 0; i < 11; ++i)
          for (int j = 0; j < 11; ++j) {
            int yy = y + i - 5, xx = x + j - 5;
            if (yy < 0 || yy >= a.H || xx < 0 || xx >= a.W) continue;
            double va = a.at(yy, xx, c), vb = b.at(yy, xx, c);
            ma += w[i][j] * va; mb += w[i][j] * vb;
            aa += w[i][j] * va * va; bb += w[i][j] * vb * vb; ab += w[i][j] * va * vb;
          }
        double sa = aa - ma * ma, sb = bb - mb * mb, sab = ab - ma * mb;
        out[(size_t(y) * a.W + x) * 3 + c] =
            ((2 * ma * mb + C1) * (2 * sab + C2)) / ((ma * ma + mb * mb + C1) * (sa + sb + C2));
      }
  return out;
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return s / v.size();
}

void compare_with_direct(const ImageF& a, const ImageF& b, double* max_diff_out = nullptr) {
  std::vector<float> m = ssim_map(a, b);
  std::vector<double> d = ssim_map_direct(a, b);
  REQUIRE(m.size() == d.size());
  double max_diff = 0;
  for (size_t i = 0; i < m.size(); ++i) hashcc::test::keep_worst(max_diff, std::fabs(m[i] - d[i]));
  CHECK(max_diff < 2e-6);  // float map vs double reference
  CHECK(ssim(a, b) == Approx(mean(d)).margin(1e-6));
  if (max_diff_out) *max_diff_out = max_diff;
}

}  // namespace

TEST_CASE("psnr of a known MSE", "[metrics][eval]") {
  ImageF a(6, 8, 0.5f), b = a;
  // A quarter of the values differ by 0.25 (exact in float): MSE = 0.0625 / 4 = 1/64.
  for (size_t i = 0; i < b.rgb.size(); i += 4) b.rgb[i] = 0.75f;
  CHECK(mse(a, b) == Approx(1.0 / 64).epsilon(1e-15));
  CHECK(psnr(a, b) == Approx(18.061799739838872).epsilon(1e-12));  // 10·log10(64)
  CHECK(psnr(b, a) == psnr(a, b));
  CHECK(psnr(a, a) == std::numeric_limits<double>::infinity());
  ImageF c(6, 7, 0.5f);
  CHECK_THROWS_AS(psnr(a, c), hashcc::Error);
}

TEST_CASE("ssim window is the normalised 11-tap Gaussian with sigma 1.5", "[metrics][eval]") {
  std::vector<double> g = ssim_gaussian_1d();
  REQUIRE(g.size() == 11);
  double s = 0;
  for (double v : g) s += v;
  CHECK(s == Approx(1.0).epsilon(1e-15));
  // Ratio of neighbouring taps: exp(−(1² − 0²)/(2·1.5²)) = exp(−2/9).
  CHECK(g[6] / g[5] == Approx(std::exp(-2.0 / 9.0)).epsilon(1e-14));
  CHECK(g[0] == Approx(g[10]).epsilon(1e-15));
  CHECK(g[5] == Approx(0.26601172486179436).epsilon(1e-12));  // 1 / Σ_k exp(−k²/4.5), k = −5..5
}

TEST_CASE("ssim of identical images is 1", "[metrics][eval]") {
  ImageF a = random_image(23, 31, 1);
  CHECK(ssim(a, a) == Approx(1.0).margin(1e-7));
  for (float v : ssim_map(a, a)) REQUIRE(v == Approx(1.0f).margin(1e-6));
}

TEST_CASE("ssim of constant images matches the zero-padding closed form", "[metrics][eval]") {
  // For constant a, b and a window whose in-bounds weight is w(p) (w = wx·wy with zero
  // padding): μ_a = a·w, σ_a² = a²w − a²w² = a²w(1 − w), σ_ab = ab·w(1 − w). So
  // SSIM(p) = (2abw² + C1)(2ab·w(1−w) + C2) / (((a²+b²)w² + C1)((a²+b²)·w(1−w) + C2)),
  // which in the interior (w = 1) is (2ab + C1)/(a² + b² + C1).
  const int H = 14, W = 19;
  const double av = 0.25, bv = 0.75;  // exact in float
  ImageF a(H, W, float(av)), b(H, W, float(bv));
  const double C1 = 1e-4, C2 = 9e-4;
  double g[11], gs = 0;
  for (int k = 0; k < 11; ++k) gs += (g[k] = std::exp(-(k - 5) * (k - 5) / 4.5));
  for (double& v : g) v /= gs;
  auto inbounds = [&](int p, int n) {
    double s = 0;
    for (int k = 0; k < 11; ++k) if (p + k - 5 >= 0 && p + k - 5 < n) s += g[k];
    return s;
  };
  auto closed = [&](double w) {
    const double ab = av * bv, s2 = av * av + bv * bv, v = w * (1 - w);
    return (2 * ab * w * w + C1) * (2 * ab * v + C2) / ((s2 * w * w + C1) * (s2 * v + C2));
  };
  std::vector<float> m = ssim_map(a, b);
  double expect_mean = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const double e = closed(inbounds(y, H) * inbounds(x, W));
      expect_mean += e / (H * W);
      for (int c = 0; c < 3; ++c) REQUIRE(m[(size_t(y) * W + x) * 3 + c] == Approx(e).margin(2e-6));
    }
  const double interior = (2 * av * bv + C1) / (av * av + bv * bv + C1);  // = 0.3751 / 0.6251
  CHECK(m[(size_t(7) * W + 9) * 3] == Approx(0.6000639897616381).margin(1e-6));  // by hand
  // The corner differs a lot from the interior (zero padding darkens the means there).
  CHECK(std::fabs(m[0] - interior) > 0.05);
  CHECK(ssim(a, b) == Approx(expect_mean).margin(1e-6));
  compare_with_direct(a, b);
}

TEST_CASE("ssim of shifted and noisy copies matches the direct implementation", "[metrics][eval]") {
  ImageF a = smooth_image(27, 33);
  SECTION("shifted by 2 pixels") {
    ImageF b = a;
    for (int y = 0; y < a.H; ++y)
      for (int x = 0; x < a.W; ++x)
        for (int c = 0; c < 3; ++c) b.at(y, x, c) = a.at(y, std::min(a.W - 1, x + 2), c);
    const double s = ssim(a, b);
    CHECK(s < 0.95);
    CHECK(s > 0.1);
    compare_with_direct(a, b);
  }
  SECTION("gaussian noise 0.05") {
    Rng rng(7);
    ImageF b = a;
    for (float& v : b.rgb) v = std::clamp(float(v + 0.05 * rng.normal()), 0.f, 1.f);
    const double s = ssim(a, b);
    CHECK(s < 0.99);
    CHECK(s > 0.5);
    compare_with_direct(a, b);
  }
  SECTION("two unrelated random images") {
    ImageF b = random_image(27, 33, 99);
    CHECK(std::fabs(ssim(a, b)) < 0.3);
    compare_with_direct(a, b);
  }
}

TEST_CASE("ssim does not depend on the thread count", "[metrics][eval]") {
  ImageF a = smooth_image(40, 37), b = random_image(40, 37, 3);
  const int nt = num_threads();
  set_num_threads(1);
  const double s1 = ssim(a, b);
  set_num_threads(2);
  const double s2 = ssim(a, b);
  set_num_threads(nt);
  CHECK(s1 == s2);
}

TEST_CASE("error heatmap colours |error| on a fixed Turbo scale", "[metrics][eval]") {
  ImageF a(2, 3, 0.5f), b = a;
  // pixel (0,1): error 0.25 in one channel → mean error 1/12 → t = (1/12)/0.25 = 1/3
  b.at(0, 1, 0) = 0.75f;
  // pixel (0,2): error 0.25 in all channels → t = 1 (saturates: dark red)
  for (int c = 0; c < 3; ++c) b.at(0, 2, c) = 0.25f;
  // pixel (1,0): error 0.5 in all channels → clamps to the same colour as t = 1
  for (int c = 0; c < 3; ++c) b.at(1, 0, c) = 1.0f;
  ImageRGB8 h = error_heatmap(a, b, 0.25f);
  REQUIRE(h.H == 2);
  REQUIRE(h.W == 3);
  auto px = [&](int y, int x, int c) { return int(h.rgb[(size_t(y) * 3 + x) * 3 + c]); };
  auto expect = [&](float t, int y, int x) {
    float col[3];
    turbo_colormap(t, col);
    for (int c = 0; c < 3; ++c) CHECK(px(y, x, c) == int(std::lround(col[c] * 255)));
  };
  expect(0.f, 0, 0);
  expect(1.f / 3.f, 0, 1);
  expect(1.f, 0, 2);
  expect(1.f, 1, 0);
  // Zero error is dark, saturated error is red-dominant, the middle is bright green-ish.
  CHECK(px(0, 0, 0) + px(0, 0, 1) + px(0, 0, 2) < 100);
  CHECK(px(0, 2, 0) > 2 * px(0, 2, 1));
  CHECK(px(0, 2, 0) > 2 * px(0, 2, 2));
  float mid[3];
  turbo_colormap(0.5f, mid);
  CHECK(mid[1] > 0.9f);
  CHECK_THROWS_AS(error_heatmap(a, b, 0.f), hashcc::Error);
}
