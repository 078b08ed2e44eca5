// Tests of eval/lpips: conv/ReLU/pool by hand, the whole pipeline against a naive double
// reference on a small random network, LPIPS axioms, weight loading (real heads when present,
// malformed files, a full random VGG16 set written and read back).
#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <tuple>
#include <unistd.h>

#include "core/error.h"
#include "core/parallel.h"
#include "eval/lpips.h"
#include "test/shared_data.h"
#include "test/gradcheck.h"

using namespace hashcc;
namespace fs = std::filesystem;

namespace {

// The LPIPS v0.1 linear heads, from the data the repository does not ship (test/shared_data.h).
std::string shared_heads() { return hashcc::test::shared_data_dir() + "/lpips/weights/v0.1_npy"; }

// Test helper: a network with random weights (He-normal convs so activations stay O(1) through
// 13 layers, small random biases, heads uniform in [0, 1)).
LpipsVgg random_lpips(std::array<int, 5> widths, uint64_t seed) {
  LpipsVgg net(widths);
  Rng rng(seed);
  for (auto& c : net.convs) {
    const double sd = std::sqrt(2.0 / (9.0 * c.in));
    for (float& w : c.weight) w = float(sd * rng.normal());
    for (float& b : c.bias) b = float(0.05 * rng.normal());
  }
  for (auto& l : net.lin) for (float& w : l) w = rng.uniformf();
  return net;
}

ImageF random_image(int H, int W, uint64_t seed) {
  Rng rng(seed);
  ImageF im(H, W);
  for (float& v : im.rgb) v = rng.uniformf();
  return im;
}

// Naive double reference of the whole LPIPS-VGG pipeline, written from the paper's recipe with
// direct loops (no im2col, no tiling, no shared code with the library).
double lpips_naive(const LpipsVgg& net, const ImageF& a, const ImageF& b) {
  const double shift[3] = {-0.030, -0.088, -0.188}, scale[3] = {0.458, 0.448, 0.450};
  using Act = std::vector<double>;  // (C, H, W)
  auto features = [&](const ImageF& im) {
    int H = im.H, W = im.W, C = 3;
    Act x(size_t(3) * H * W);
    for (int c = 0; c < 3; ++c)
      for (int y = 0; y < H; ++y)
        for (int xx = 0; xx < W; ++xx)
          x[(c * H + y) * W + xx] = (2.0 * im.at(y, xx, c) - 1.0 - shift[c]) / scale[c];
    std::vector<std::tuple<Act, int, int, int>> taps;
    int layer = 0;
    for (int k = 0; k < 5; ++k) {
      if (k > 0) {
        Act p(size_t(C) * (H / 2) * (W / 2));
        for (int c = 0; c < C; ++c)
          for (int y = 0; y < H / 2; ++y)
            for (int xx = 0; xx < W / 2; ++xx) {
              double m = -1e300;
              for (int dy = 0; dy < 2; ++dy)
                for (int dx = 0; dx < 2; ++dx) m = std::max(m, x[(c * H + 2 * y + dy) * W + 2 * xx + dx]);
              p[(c * (H / 2) + y) * (W / 2) + xx] = m;
            }
        x = p; H /= 2; W /= 2;
      }
      for (int j = 0; j < LpipsVgg::kConvsPerBlock[k]; ++j, ++layer) {
        const auto& cv = net.convs[layer];
        Act out(size_t(cv.out) * H * W);
        for (int o = 0; o < cv.out; ++o)
          for (int y = 0; y < H; ++y)
            for (int xx = 0; xx < W; ++xx) {
              double s = cv.bias[o];
              for (int c = 0; c < C; ++c)
                for (int ky = 0; ky < 3; ++ky)
                  for (int kx = 0; kx < 3; ++kx) {
                    int sy = y + ky - 1, sx = xx + kx - 1;
                    if (sy < 0 || sy >= H || sx < 0 || sx >= W) continue;
                    s += double(cv.weight[((o * C + c) * 3 + ky) * 3 + kx]) * x[(c * H + sy) * W + sx];
                  }
              out[(o * H + y) * W + xx] = std::max(0.0, s);
            }
        x = out; C = cv.out;
      }
      taps.emplace_back(x, C, H, W);
    }
    return taps;
  };
  auto ta = features(a), tb = features(b);
  double total = 0;
  for (int k = 0; k < 5; ++k) {
    auto& [fa, C, H, W] = ta[k];
    auto& fb = std::get<0>(tb[k]);
    double acc = 0;
    for (int p = 0; p < H * W; ++p) {
      double na = 0, nb = 0;
      for (int c = 0; c < C; ++c) { na += fa[c * H * W + p] * fa[c * H * W + p]; nb += fb[c * H * W + p] * fb[c * H * W + p]; }
      na = std::sqrt(na) + 1e-10; nb = std::sqrt(nb) + 1e-10;
      for (int c = 0; c < C; ++c) {
        double d = fa[c * H * W + p] / na - fb[c * H * W + p] / nb;
        acc += net.lin[k][c] * d * d;
      }
    }
    total += acc / (H * W);
  }
  return total;
}

// Writes a little-endian .npy (version 1) with the given descr and raw bytes.
void write_npy(const fs::path& path, const std::string& descr, const std::vector<int64_t>& shape,
               const void* data, size_t nbytes, const char* fortran = "False") {
  std::string sh = "(";
  for (size_t i = 0; i < shape.size(); ++i) sh += std::to_string(shape[i]) + (shape.size() == 1 ? "," : (i + 1 < shape.size() ? ", " : ""));
  sh += ")";
  std::string header = "{'descr': '" + descr + "', 'fortran_order': " + fortran + ", 'shape': " + sh + ", }";
  while ((10 + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  std::ofstream f(path, std::ios::binary);
  f.write("\x93NUMPY\x01\x00", 8);
  const uint16_t hl = uint16_t(header.size());
  f.write(reinterpret_cast<const char*>(&hl), 2);
  f.write(header.data(), header.size());
  f.write(static_cast<const char*>(data), nbytes);
}

void write_f32(const fs::path& path, const std::vector<int64_t>& shape, const std::vector<float>& v) {
  write_npy(path, "<f4", shape, v.data(), v.size() * 4);
}

fs::path fresh_dir(const std::string& name) {
  fs::path d = fs::temp_directory_path() / ("hashcc_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void write_heads(const fs::path& dir, const LpipsVgg& net) {
  for (int k = 0; k < 5; ++k)
    write_f32(dir / ("vgg.lin" + std::to_string(k) + ".model.1.weight.npy"),
              {1, int64_t(net.lin[k].size()), 1, 1}, net.lin[k]);
}

template <class Fn>
std::string error_message(Fn&& fn) {
  try { fn(); } catch (const hashcc::Error& e) { return e.what(); }
  return "(no hashcc::Error thrown)";
}

}  // namespace

TEST_CASE("conv3x3 on a 4x4 image, checked by hand", "[metrics][eval]") {
  // x[y][x] = 4y + x + 1 (1..16); kernel k[ky][kx] = 3ky + kx + 1 (1..9, asymmetric so a
  // flipped kernel, i.e. convolution instead of cross-correlation, would fail); bias 0.5.
  std::vector<float> x(16), k(9), y(16);
  for (int i = 0; i < 16; ++i) x[i] = float(i + 1);
  for (int i = 0; i < 9; ++i) k[i] = float(i + 1);
  const float b = 0.5f;
  conv3x3_forward(y.data(), x.data(), k.data(), &b, 1, 1, 4, 4);
  // (0,0): 1·5 + 2·6 + 5·8 + 6·9 = 111
  CHECK(y[0] == 111.5f);
  // (0,3): 3·4 + 4·5 + 7·7 + 8·8 = 145
  CHECK(y[3] == 145.5f);
  // (1,1): full window 1 2 3 / 5 6 7 / 9 10 11 · 1..9 = 14 + 92 + 242 = 348
  CHECK(y[5] == 348.5f);
  // (2,1): 5 6 7 / 9 10 11 / 13 14 15 · 1..9 = 38 + 152 + 338 = 528
  CHECK(y[9] == 528.5f);
  // (3,3): 11·1 + 12·2 + 15·4 + 16·5 = 175
  CHECK(y[15] == 175.5f);
  // Tiling (one row per im2col tile) gives the same numbers.
  std::vector<float> y1(16);
  conv3x3_forward(y1.data(), x.data(), k.data(), &b, 1, 1, 4, 4, /*max_col_floats=*/1);
  CHECK(y1 == y);
}

TEST_CASE("conv3x3 with several channels matches direct loops; relu; max-pool by hand", "[metrics][eval]") {
  const int C = 3, O = 4, H = 7, W = 6;
  Rng rng(5);
  std::vector<float> x(C * H * W), w(O * C * 9), b(O), y(O * H * W), y_tiled(O * H * W);
  for (float& v : x) v = float(rng.normal());
  for (float& v : w) v = float(rng.normal());
  for (float& v : b) v = float(rng.normal());
  conv3x3_forward(y.data(), x.data(), w.data(), b.data(), C, O, H, W);
  conv3x3_forward(y_tiled.data(), x.data(), w.data(), b.data(), C, O, H, W, 2 * C * 9 * W);
  double max_err = 0;
  for (int o = 0; o < O; ++o)
    for (int i = 0; i < H; ++i)
      for (int j = 0; j < W; ++j) {
        double s = b[o];
        for (int c = 0; c < C; ++c)
          for (int ky = 0; ky < 3; ++ky)
            for (int kx = 0; kx < 3; ++kx) {
              int si = i + ky - 1, sj = j + kx - 1;
              if (si >= 0 && si < H && sj >= 0 && sj < W)
                s += double(w[((o * C + c) * 3 + ky) * 3 + kx]) * x[(c * H + si) * W + sj];
            }
        hashcc::test::keep_worst(max_err, std::fabs(s - y[(o * H + i) * W + j]));
        REQUIRE(y_tiled[(o * H + i) * W + j] == Approx(y[(o * H + i) * W + j]).margin(1e-5));
      }
  CHECK(max_err < 1e-4);

  std::vector<float> r = {-1.f, 0.f, 2.5f, -0.f};
  relu_inplace(r.data(), 4);
  CHECK(r == std::vector<float>{0.f, 0.f, 2.5f, 0.f});

  // 2×2 max-pool of 1..16 (4×4) = [[6, 8], [14, 16]]; of a 5×5 (1..25) floors to 2×2:
  // [[7, 9], [17, 19]]; channels are independent (second channel negated: max of negatives).
  std::vector<float> p4(32), q4(8);
  for (int i = 0; i < 16; ++i) { p4[i] = float(i + 1); p4[16 + i] = -float(i + 1); }
  maxpool2x2_forward(q4.data(), p4.data(), 2, 4, 4);
  CHECK(q4 == std::vector<float>{6, 8, 14, 16, -1, -3, -9, -11});
  std::vector<float> p5(25), q5(4);
  for (int i = 0; i < 25; ++i) p5[i] = float(i + 1);
  maxpool2x2_forward(q5.data(), p5.data(), 1, 5, 5);
  CHECK(q5 == std::vector<float>{7, 9, 17, 19});
}

TEST_CASE("lpips with random weights: zero on equal images, symmetric, matches a naive reference",
          "[metrics][eval]") {
  const LpipsVgg net = random_lpips({4, 6, 8, 8, 10}, 11);
  const ImageF x = random_image(32, 40, 1), y = random_image(32, 40, 2);
  ImageF x_noisy = x;
  Rng rng(3);
  for (float& v : x_noisy.rgb) v = std::clamp(float(v + 0.02 * rng.normal()), 0.f, 1.f);

  CHECK(net.distance(x, x) == 0.0);
  const double dxy = net.distance(x, y), dyx = net.distance(y, x);
  CHECK(dxy == dyx);
  CHECK(dxy > 0.0);
  const double d_noisy = net.distance(x, x_noisy);
  CHECK(d_noisy > 0.0);
  CHECK(d_noisy < 0.5 * dxy);
  // Each tap contributes (random weights leave every tap alive).
  for (double t : net.distance_per_tap(x, y)) CHECK(t > 0.0);
  CHECK(dxy == Approx(lpips_naive(net, x, y)).epsilon(1e-5));
  CHECK(d_noisy == Approx(lpips_naive(net, x, x_noisy)).epsilon(1e-5));
  // Odd sizes exercise floor pooling: 37×21 → 18×10 → 9×5 → 4×2 → 2×1.
  const ImageF a = random_image(37, 21, 4), b = random_image(37, 21, 5);
  CHECK(net.distance(a, b) == Approx(lpips_naive(net, a, b)).epsilon(1e-5));
  CHECK_THROWS_AS(net.distance(random_image(15, 30, 1), random_image(15, 30, 2)), hashcc::Error);
  CHECK_THROWS_AS(net.distance(x, a), hashcc::Error);
}

TEST_CASE("lpips does not depend on the thread count beyond float rounding", "[metrics][eval]") {
  const LpipsVgg net = random_lpips({8, 8, 16, 16, 16}, 12);
  const ImageF x = random_image(48, 40, 1), y = random_image(48, 40, 2);
  const int nt = num_threads();
  set_num_threads(1);
  const double d1 = net.distance(x, y);
  set_num_threads(2);
  const double d2 = net.distance(x, y);
  set_num_threads(nt);
  CHECK(d1 == Approx(d2).epsilon(1e-6));
}

TEST_CASE("lpips: the real v0.1 VGG linear heads load from shared data", "[metrics][eval][shared]") {
  // Skipped visibly without the data, a failure when HASHCC_REQUIRE_DATA=1 (test/shared_data.h).
  const std::string kSharedHeads = shared_heads();
  HASHCC_NEED_DATA(kSharedHeads);
  auto heads = load_lpips_vgg_heads(kSharedHeads);
  const int C[5] = {64, 128, 256, 512, 512};
  // First values and sums, read independently with Python's struct module from the files.
  const double first[5] = {0.05011165887117386, 0.039409372955560684, 0.05793386325240135,
                           0.05780801177024841, 0.04268040508031845};
  const double sums[5] = {6.925991700962186, 8.858334008604288, 17.5150060467422,
                          51.521323032677174, 47.03485375829041};
  for (int k = 0; k < 5; ++k) {
    REQUIRE(int(heads[k].size()) == C[k]);
    CHECK(heads[k][0] == float(first[k]));
    double s = 0;
    for (float v : heads[k]) { CHECK(v >= 0.f); s += v; }
    CHECK(s == Approx(sums[k]).epsilon(1e-6));
  }
  // The VGG backbone is not shipped: not available, and load() names the first missing file.
  CHECK_FALSE(lpips_available(kSharedHeads));
  const std::string msg = error_message([&] { LpipsVgg::load(kSharedHeads); });
  CHECK_THAT(msg, Catch::Contains("features.0.weight.npy"));
  CHECK_THAT(msg, Catch::Contains("no such file"));
}

TEST_CASE("lpips weight files: malformed heads give errors naming the file", "[metrics][eval]") {
  const fs::path dir = fresh_dir("heads");
  LpipsVgg net;  // VGG16 widths, zero backbone: only the heads are used here
  Rng rng(1);
  for (auto& l : net.lin) for (float& w : l) w = rng.uniformf();
  write_heads(dir, net);
  auto heads = load_lpips_vgg_heads(dir.string());
  const bool same3 = heads[3] == net.lin[3];
  CHECK(same3);

  const fs::path f2 = dir / "vgg.lin2.model.1.weight.npy";
  // float64 is accepted and converted.
  std::vector<double> d64(net.lin[2].begin(), net.lin[2].end());
  write_npy(f2, "<f8", {1, 256, 1, 1}, d64.data(), d64.size() * 8);
  const bool same2 = load_lpips_vgg_heads(dir.string())[2] == net.lin[2];
  CHECK(same2);

  auto expect_error = [&](const char* what) {
    const std::string msg = error_message([&] { load_lpips_vgg_heads(dir.string()); });
    INFO(msg);
    CHECK_THAT(msg, Catch::Contains("vgg.lin2.model.1.weight.npy"));
    CHECK_THAT(msg, Catch::Contains(what));
  };
  write_npy(f2, "<f4", {1, 256, 1, 1}, net.lin[2].data(), 100 * 4);  // truncated data
  expect_error("bytes of data");
  write_npy(f2, "<f4", {1, 255, 1, 1}, net.lin[2].data(), 255 * 4);  // wrong shape
  expect_error("(1, 256, 1, 1)");
  write_npy(f2, ">f4", {1, 256, 1, 1}, net.lin[2].data(), 256 * 4);  // big-endian
  expect_error("unsupported dtype");
  // Fortran order is read (core/npy re-lays it out in C order; this shape is the same either way).
  write_npy(f2, "<f4", {1, 256, 1, 1}, net.lin[2].data(), 256 * 4, "True");
  const bool same_f = load_lpips_vgg_heads(dir.string())[2] == net.lin[2];
  CHECK(same_f);
  { std::ofstream(f2, std::ios::binary) << "not numpy at all"; }
  expect_error("not a .npy file");
  std::vector<float> neg = net.lin[2];
  neg[7] = -0.5f;
  write_f32(f2, {1, 256, 1, 1}, neg);
  expect_error(">= 0");
  fs::remove(f2);
  expect_error("no such file");
  fs::remove_all(dir);
}

TEST_CASE("lpips: a complete (random) VGG16 weight folder loads and reproduces the network",
          "[metrics][eval]") {
  const fs::path dir = fresh_dir("vgg");
  const LpipsVgg net = random_lpips({64, 128, 256, 512, 512}, 21);
  CHECK_FALSE(lpips_available(dir.string()));
  for (int l = 0; l < 13; ++l) {
    const auto& c = net.convs[l];
    const std::string base = "features." + std::to_string(LpipsVgg::kFeatureIndex[l]);
    write_f32(dir / (base + ".weight.npy"), {c.out, c.in, 3, 3}, c.weight);
    write_f32(dir / (base + ".bias.npy"), {c.out}, c.bias);
  }
  write_heads(dir, net);
  REQUIRE(lpips_available(dir.string()));
  REQUIRE(lpips_vgg_file_names().size() == 31);
  const LpipsVgg loaded = LpipsVgg::load(dir.string());
  for (int l = 0; l < 13; ++l) {
    INFO("layer " << l);  // compared as bools: Catch would print millions of values on failure
    const bool same_w = loaded.convs[l].weight == net.convs[l].weight;
    const bool same_b = loaded.convs[l].bias == net.convs[l].bias;
    REQUIRE(same_w);
    REQUIRE(same_b);
  }
  const ImageF x = random_image(16, 20, 1), y = random_image(16, 20, 2);
  const double d = loaded.distance(x, y);
  CHECK(d == net.distance(x, y));
  CHECK(d > 0.0);
  // A backbone tensor of the wrong shape is reported with its file name.
  write_f32(dir / "features.7.weight.npy", {128, 64, 3, 3}, net.convs[2].weight);
  const std::string msg = error_message([&] { LpipsVgg::load(dir.string()); });
  CHECK_THAT(msg, Catch::Contains("features.7.weight.npy"));
  CHECK_THAT(msg, Catch::Contains("(128, 128, 3, 3)"));
  fs::remove_all(dir);
}
