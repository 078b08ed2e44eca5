// eval/lpips.cpp — LPIPS-VGG forward pass (see lpips.h).
#include "eval/lpips.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <fmt/ranges.h>

#include "core/buffer.h"
#include "core/error.h"
#include "core/npy.h"
#include "core/parallel.h"

namespace hashcc {
namespace {


std::string join_path(const std::string& dir, const std::string& name) {
  return (std::filesystem::path(dir) / name).string();
}

std::string shape_str(const std::vector<int64_t>& s) { return fmt::format("({})", fmt::join(s, ", ")); }

constexpr std::array<int, 5> kVggWidths = {64, 128, 256, 512, 512};
// LPIPS ScalingLayer constants.
constexpr float kShift[3] = {-0.030f, -0.088f, -0.188f};
constexpr float kScale[3] = {0.458f, 0.448f, 0.450f};

std::string head_name(int k) { return fmt::format("vgg.lin{}.model.1.weight.npy", k); }
std::string conv_name(int l, const char* what) {
  return fmt::format("features.{}.{}.npy", LpipsVgg::kFeatureIndex[l], what);
}

}  // namespace

// ---- layers -----------------------------------------------------------------------------------

void conv3x3_forward(float* y, const float* x, const float* Wt, const float* b, int C, int O,
                     int H, int W, int64_t max_col_floats) {
  const int K = C * 9;
  const int64_t HW = int64_t(H) * W;
  const int rows_per_tile =
      int(std::clamp<int64_t>(max_col_floats / (int64_t(K) * W), 1, H));
  AlignedVec<float> col;
  CMapRM<float> Wm(Wt, O, K);  // (O, C·9): torch (O, C, 3, 3) flattened
  Eigen::Map<const Eigen::VectorXf> bias(b, O);
  for (int y0 = 0; y0 < H; y0 += rows_per_tile) {
    const int y1 = std::min(H, y0 + rows_per_tile);
    const int64_t n = int64_t(y1 - y0) * W;
    ensure(col, size_t(K) * n);
    // col (C·9, n): row (c, ky, kx) holds x[c, yy + ky − 1, xx + kx − 1] (0 outside).
    parallel_for(K, [&](int64_t r) {
      const int c = int(r / 9), ky = int(r % 9) / 3, kx = int(r % 3);
      float* dst = col.data() + r * n;
      const float* plane = x + int64_t(c) * HW;
      for (int yy = y0; yy < y1; ++yy) {
        const int sy = yy + ky - 1;
        float* d = dst + int64_t(yy - y0) * W;
        if (sy < 0 || sy >= H) { std::fill(d, d + W, 0.f); continue; }
        const float* srow = plane + int64_t(sy) * W;
        for (int xx = 0; xx < W; ++xx) {
          const int sx = xx + kx - 1;
          d[xx] = (sx >= 0 && sx < W) ? srow[sx] : 0.f;
        }
      }
    });
    Eigen::Map<const MatRM<float>> Cm(col.data(), K, n);
    Eigen::Map<MatRM<float>, 0, Eigen::OuterStride<>> Y(y + int64_t(y0) * W, O, n,
                                                        Eigen::OuterStride<>(HW));
    Y.noalias() = Wm * Cm;
    Y.colwise() += bias;
  }
}

void relu_inplace(float* x, int64_t n) {
  parallel_for(n, [&](int64_t i) { x[i] = x[i] > 0.f ? x[i] : 0.f; }, 1 << 14);
}

void maxpool2x2_forward(float* y, const float* x, int C, int H, int W) {
  const int h = H / 2, w = W / 2;
  parallel_for(int64_t(C) * h, [&](int64_t r) {
    const int64_t c = r / h, i = r % h;
    const float* r0 = x + (c * H + 2 * i) * W;
    const float* r1 = r0 + W;
    float* d = y + (c * h + i) * w;
    for (int j = 0; j < w; ++j)
      d[j] = std::max(std::max(r0[2 * j], r0[2 * j + 1]), std::max(r1[2 * j], r1[2 * j + 1]));
  });
}

// ---- the network ------------------------------------------------------------------------------

LpipsVgg::LpipsVgg(std::array<int, 5> widths_) : widths(widths_) {
  int in = 3;
  for (int k = 0; k < 5; ++k) {
    HCC_REQUIRE(widths[k] > 0, "", "lpips", "block {} width {} (expected > 0)", k, widths[k]);
    for (int j = 0; j < kConvsPerBlock[k]; ++j) {
      Conv c;
      c.in = in; c.out = widths[k];
      c.weight.assign(size_t(c.out) * c.in * 9, 0.f);
      c.bias.assign(size_t(c.out), 0.f);
      convs.push_back(std::move(c));
      in = widths[k];
    }
    lin[k].assign(size_t(widths[k]), 0.f);
  }
}

std::vector<std::string> lpips_vgg_file_names() {
  std::vector<std::string> names;
  for (int l = 0; l < 13; ++l) {
    names.push_back(conv_name(l, "weight"));
    names.push_back(conv_name(l, "bias"));
  }
  for (int k = 0; k < 5; ++k) names.push_back(head_name(k));
  return names;
}

bool lpips_available(const std::string& dir) {
  if (dir.empty()) return false;
  std::error_code ec;
  for (const std::string& n : lpips_vgg_file_names())
    if (!std::filesystem::is_regular_file(join_path(dir, n), ec)) return false;
  return true;
}

std::array<std::vector<float>, 5> load_lpips_vgg_heads(const std::string& dir) {
  std::array<std::vector<float>, 5> heads;
  for (int k = 0; k < 5; ++k) {
    const std::string path = join_path(dir, head_name(k));
    NpyArrayF32 a = read_npy_f32(path);
    const std::vector<int64_t> want = {1, kVggWidths[k], 1, 1};
    if (a.shape != want)
      throw Error(path, "shape", "shape " + shape_str(a.shape), shape_str(want));
    for (size_t i = 0; i < a.data.size(); ++i)
      if (!(std::isfinite(a.data[i]) && a.data[i] >= 0.f))
        throw Error(path, fmt::format("value {}", i), fmt::format("{}", a.data[i]),
                    "finite and >= 0 (LPIPS heads are non-negative)");
    heads[k] = std::move(a.data);
  }
  return heads;
}

LpipsVgg LpipsVgg::load(const std::string& dir) {
  LpipsVgg net(kVggWidths);
  for (int l = 0; l < 13; ++l) {
    Conv& c = net.convs[l];
    const std::string wpath = join_path(dir, conv_name(l, "weight"));
    const std::string bpath = join_path(dir, conv_name(l, "bias"));
    NpyArrayF32 w = read_npy_f32(wpath), b = read_npy_f32(bpath);
    const std::vector<int64_t> wwant = {c.out, c.in, 3, 3}, bwant = {c.out};
    if (w.shape != wwant)
      throw Error(wpath, "shape", "shape " + shape_str(w.shape),
                  shape_str(wwant) + " (torchvision vgg16 features)");
    if (b.shape != bwant)
      throw Error(bpath, "shape", "shape " + shape_str(b.shape), shape_str(bwant));
    c.weight = std::move(w.data);
    c.bias = std::move(b.data);
  }
  net.lin = load_lpips_vgg_heads(dir);
  return net;
}

namespace {

// One tap of LPIPS: fa, fb (C, HW) the two images' features; the spatial mean over pixels of
// Σ_c w_c (fa/|fa| − fb/|fb|)²_c (per_pixel: scratch, HW values).
double tap_distance(const float* fa, const float* fb, const std::vector<float>& w, int C,
                    int64_t HW, std::vector<double>& per_pixel) {
  per_pixel.assign(size_t(HW), 0.0);
  parallel_blocks(HW, [&](int64_t p0, int64_t p1, int) {
    // The unit-normalised features are stored before they are subtracted: with FMA
    // contraction, fa·ia − fb·ib computed in one expression rounds only one of the two
    // products, which would make LPIPS(x, x) ≠ 0 and LPIPS(x, y) ≠ LPIPS(y, x) in the last bits.
    std::vector<double> ua(static_cast<size_t>(C)), ub(static_cast<size_t>(C));
    for (int64_t p = p0; p < p1; ++p) {
      double na = 0, nb = 0;
      for (int c = 0; c < C; ++c) {
        double va = fa[c * HW + p], vb = fb[c * HW + p];
        na += va * va; nb += vb * vb;
      }
      const double ia = 1.0 / (std::sqrt(na) + 1e-10), ib = 1.0 / (std::sqrt(nb) + 1e-10);
      for (int c = 0; c < C; ++c) {
        ua[c] = fa[c * HW + p] * ia;
        ub[c] = fb[c * HW + p] * ib;
      }
      double s = 0;
      for (int c = 0; c < C; ++c) {
        const double d = ua[c] - ub[c];
        s += double(w[c]) * d * d;
      }
      per_pixel[size_t(p)] = s;
    }
  }, 256);
  double sum = 0;  // fixed order: independent of the thread count
  for (double v : per_pixel) sum += v;
  return sum / double(HW);
}

}  // namespace

std::array<double, 5> LpipsVgg::distance_per_tap(const ImageF& a, const ImageF& b) const {
  HCC_REQUIRE(a.H == b.H && a.W == b.W, "", "lpips", "image sizes differ: {}x{} vs {}x{}", a.H,
              a.W, b.H, b.W);
  HCC_REQUIRE(a.H >= 16 && a.W >= 16, "", "lpips", "image {}x{} too small (expected >= 16x16)",
              a.H, a.W);
  HCC_REQUIRE(a.rgb.size() == size_t(a.H) * a.W * 3 && b.rgb.size() == a.rgb.size(), "",
              "lpips", "pixel buffer size does not match H*W*3");
  HCC_REQUIRE(convs.size() == 13, "", "lpips", "network has {} conv layers (expected 13)",
              convs.size());
  int H = a.H, W = a.W;
  // Two buffers per image, ping-pong: cur holds the live activation (C, H, W).
  std::array<AlignedVec<float>, 2> bufA, bufB;
  size_t max_elems = size_t(3) * H * W;
  for (int k = 0; k < 5; ++k)
    max_elems = std::max(max_elems, size_t(widths[k]) * size_t(H >> k) * size_t(W >> k));
  for (auto* v : {&bufA[0], &bufA[1], &bufB[0], &bufB[1]}) v->resize(max_elems);
  // [0,1] → [−1,1] → ScalingLayer, interleaved (H, W, 3) → planar (3, H, W).
  auto prepare = [&](float* dst, const ImageF& im) {
    parallel_for(int64_t(H) * W, [&](int64_t p) {
      for (int c = 0; c < 3; ++c)
        dst[c * int64_t(H) * W + p] = (2.f * im.rgb[p * 3 + c] - 1.f - kShift[c]) / kScale[c];
    }, 4096);
  };
  prepare(bufA[0].data(), a);
  prepare(bufB[0].data(), b);
  int cur = 0, C = 3, layer = 0;
  std::array<double, 5> taps{};
  std::vector<double> per_pixel;
  for (int k = 0; k < 5; ++k) {
    if (k > 0) {  // 2×2 max-pool between blocks (torchvision indices 4, 9, 16, 23)
      maxpool2x2_forward(bufA[1 - cur].data(), bufA[cur].data(), C, H, W);
      maxpool2x2_forward(bufB[1 - cur].data(), bufB[cur].data(), C, H, W);
      cur = 1 - cur; H /= 2; W /= 2;
    }
    for (int j = 0; j < kConvsPerBlock[k]; ++j, ++layer) {
      const Conv& cv = convs[layer];
      HCC_ASSERT(cv.in == C);
      for (auto* buf : {&bufA, &bufB}) {
        float* out = (*buf)[1 - cur].data();
        conv3x3_forward(out, (*buf)[cur].data(), cv.weight.data(), cv.bias.data(), C, cv.out, H, W);
        relu_inplace(out, int64_t(cv.out) * H * W);
      }
      cur = 1 - cur; C = cv.out;
    }
    // Tap: unit-normalise over channels, squared difference, linear head, spatial mean.
    HCC_ASSERT(int(lin[k].size()) == C);
    taps[k] = tap_distance(bufA[cur].data(), bufB[cur].data(), lin[k], C, int64_t(H) * W, per_pixel);
  }
  return taps;
}

double LpipsVgg::distance(const ImageF& a, const ImageF& b) const {
  std::array<double, 5> t = distance_per_tap(a, b);
  return t[0] + t[1] + t[2] + t[3] + t[4];
}

}  // namespace hashcc
