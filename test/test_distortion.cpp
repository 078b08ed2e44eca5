// Tests for render/distortion.h (mip-NeRF 360's distortion loss) and for the compositor's
// per-sample weights (CompositeOut::weights) through which it reaches the densities.
// Derivation in docs/math/distortion.md.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "core/parallel.h"
#include "render/compositor.h"
#include "render/distortion.h"
#include "test/gradcheck.h"

using namespace hashcc;
using namespace hashcc::test;
using V = std::vector<double>;

namespace {

// The definition, O(S²), straight from distortion.h: L = Σ_i Σ_j w_i w_j |m_i − m_j| + (1/3) Σ w_i² h_i.
double naive_loss(const double* w, const double* s, int S) {
  auto h = [&](int i) { return S < 2 ? 0.0 : i + 1 < S ? s[i + 1] - s[i] : s[S - 1] - s[S - 2]; };
  auto m = [&](int i) { return s[i] + 0.5 * h(i); };
  long double L = 0;
  for (int i = 0; i < S; ++i) {
    for (int j = 0; j < S; ++j) L += (long double)w[i] * w[j] * std::abs(m(i) - m(j));
    L += (long double)w[i] * w[i] * h(i) / 3;
  }
  return double(L);
}

// R rays of S jittered, increasing samples in [0, 1) and weights in [0, 1/S·2) (a ray's total ≲ 1).
struct Batch {
  int64_t R;
  int S;
  V w, s;
  Batch(int64_t R_, int S_, Rng& rng) : R(R_), S(S_), w(R_ * S_), s(R_ * S_) {
    for (int64_t r = 0; r < R; ++r)
      for (int i = 0; i < S; ++i) {
        s[r * S + i] = (i + rng.uniform(0.05, 0.95)) / S;
        w[r * S + i] = rng.uniform(0, 2.0 / S);
      }
  }
  V loss() const {
    V L(R);
    distortion_forward(L.data(), w.data(), s.data(), R, S);
    return L;
  }
  V grad(const V& g) const {
    V d(R * S, -7.0);
    distortion_backward(d.data(), g.data(), w.data(), s.data(), R, S);
    return d;
  }
};

}  // namespace

TEST_CASE("distortion loss: forward against its O(S²) definition, dL/dw against central differences",
          "[distortion][grad]") {
  Rng rng(21, 5);
  for (int S : {1, 2, 3, 16, 64}) {
    DYNAMIC_SECTION("S = " << S) {
      Batch b(5, S, rng);
      const V L = b.loss();
      for (int64_t r = 0; r < b.R; ++r)
        CHECK(rel_err(L[r], naive_loss(&b.w[r * S], &b.s[r * S], S), 1e-300) < 1e-13);
      // ⟨g, L(w)⟩ with a random projection g over the rays.
      const V g = random_vec(b.R, rng);
      const V d = b.grad(g);
      CenteredLoss proj(g);
      proj.set_origin(L);
      // L is quadratic in w: the central difference is exact up to rounding (h = 1e-4 keeps that
      // rounding ~1e-12 of the gradient). Tolerance 1e-8.
      const double e = worst_grad_error(b.w, d, [&] { return proj(b.loss()); }, 1e-4);
      HCC_TEST_PRINTF("distortion S=%d: worst dL/dw error %.2e (tol 1e-8)\n", S, e);
      CHECK(e < 1e-8);
    }
  }
}

TEST_CASE("distortion loss: hard cases", "[distortion][hard]") {
  const int S = 8;
  V s(S);
  for (int i = 0; i < S; ++i) s[i] = 0.1 * i + 0.01 * (i % 3);  // uneven gaps
  auto h = [&](int i) { return i + 1 < S ? s[i + 1] - s[i] : s[S - 1] - s[S - 2]; };
  auto m = [&](int i) { return s[i] + 0.5 * h(i); };
  auto run = [&](const V& w, V* d) {
    double L;
    const double one = 1;
    distortion_forward(&L, w.data(), s.data(), 1, S);
    d->assign(S, -7);
    distortion_backward(d->data(), &one, w.data(), s.data(), 1, S);
    return L;
  };
  V d;
  SECTION("no weight: L = 0 and dL/dw_i = 0 exactly") {
    CHECK(run(V(S, 0.0), &d) == 0);
    for (double v : d) CHECK(v == 0);
  }
  SECTION("all the weight in one sample (a surface): L = w² h / 3; the last sample's h is the gap before it") {
    for (int k : {0, 3, S - 1}) {
      V w(S, 0.0);
      w[k] = 0.9;
      const double L = run(w, &d);
      CHECK(L == Approx(0.81 * h(k) / 3).epsilon(1e-14));
      // dL/dw_i = 2 w_k |m_i − m_k| (i ≠ k), (2/3) w_k h_k (i = k)
      for (int i = 0; i < S; ++i)
        CHECK(d[i] == Approx(i == k ? 0.6 * h(k) : 1.8 * std::abs(m(i) - m(k))).epsilon(1e-13));
    }
  }
  SECTION("two lumps: the cost of their distance, 2 w_a w_b |m_a − m_b|, on top of their widths") {
    V w(S, 0.0);
    w[1] = 0.3;
    w[6] = 0.5;
    const double L = run(w, &d);
    CHECK(L == Approx(2 * 0.15 * (m(6) - m(1)) + (0.09 * h(1) + 0.25 * h(6)) / 3).epsilon(1e-14));
  }
  SECTION("saturated weights (a ray's w sums to 1 in one sample out of 64, the rest underflowed)") {
    const int S2 = 64;
    V s2(S2), w2(S2, 1e-300), d2(S2);
    for (int i = 0; i < S2; ++i) s2[i] = double(i) / S2;
    w2[40] = 1;
    double L;
    const double one = 1;
    distortion_forward(&L, w2.data(), s2.data(), 1, S2);
    distortion_backward(d2.data(), &one, w2.data(), s2.data(), 1, S2);
    CHECK(L == Approx(1.0 / S2 / 3).epsilon(1e-13));
    for (int i = 0; i < S2; ++i) CHECK(std::isfinite(d2[i]));
    CHECK(d2[0] == Approx(2 * 40.0 / S2).epsilon(1e-12));
  }
  SECTION("R = 0 writes nothing") {
    double L = -7, dd = -7;
    distortion_forward<double>(&L, nullptr, nullptr, 0, S);
    distortion_backward<double>(&dd, nullptr, nullptr, nullptr, 0, S);
    CHECK(L == -7);
    CHECK(dd == -7);
  }
}

TEST_CASE("distortion loss: float agrees with double; 1 thread equals 2", "[distortion][float][threads]") {
  Rng rng(22, 5);
  Batch b(40, 32, rng);
  const V g = random_vec(b.R, rng);
  const V L = b.loss(), d = b.grad(g);
  std::vector<float> wf = cast<float>(b.w), sf = cast<float>(b.s), gf = cast<float>(g);
  std::vector<float> Lf(b.R), df(b.R * b.S);
  distortion_forward(Lf.data(), wf.data(), sf.data(), b.R, b.S);
  distortion_backward(df.data(), gf.data(), wf.data(), sf.data(), b.R, b.S);
  // The float inputs are the double ones rounded once; everything is accumulated in double.
  CHECK(float_vs_double(Lf, L) < 1e-5);
  CHECK(float_vs_double(df, d) < 1e-5);
  const int keep = num_threads();
  set_num_threads(1);
  const V L1 = b.loss(), d1 = b.grad(g);
  set_num_threads(2);
  const V L2 = b.loss(), d2 = b.grad(g);
  set_num_threads(keep);
  CHECK(L1 == L2);
  CHECK(d1 == d2);
}

TEST_CASE("compositor weights: w_i out, dL/dw_i in, against the O(S²) reference and central "
          "differences in σ (the distortion loss composed)", "[compositor][distortion][grad]") {
  Rng rng(23, 5);
  const int64_t R = 4;
  const int S = 12;
  V sigma(R * S), color(R * S * 3), s(R * S);
  for (int64_t r = 0; r < R; ++r)
    for (int i = 0; i < S; ++i) {
      sigma[r * S + i] = rng.uniform(0, 8);
      s[r * S + i] = (i + rng.uniform(0.1, 0.9)) / S;
    }
  for (double& c : color) c = rng.uniform();
  const V g_rgb = random_vec(R * 3, rng), g_dist = random_vec(R, rng);
  auto in = [&] { return CompositeIn<double>{sigma.data(), color.data(), nullptr, s.data(), R, S}; };
  // Forward: the weights equal the reference's and sum to the opacity.
  V rgb(R * 3), op(R), w(R * S), rgb_n(R * 3), w_n(R * S);
  composite_forward<double>({rgb.data(), nullptr, nullptr, op.data(), w.data()}, in());
  composite_forward_naive<double>({rgb_n.data(), nullptr, nullptr, nullptr, w_n.data()}, in());
  CHECK(worst_rel_diff(w, w_n) < 1e-14);
  for (int64_t r = 0; r < R; ++r) {
    double sum = 0;
    for (int i = 0; i < S; ++i) sum += w[r * S + i];
    CHECK(sum == Approx(op[r]).epsilon(1e-15));
  }
  // J(σ) = ⟨g_rgb, rgb⟩ + ⟨g_dist, L_dist(w)⟩: dL/dw from the distortion kernel, then the
  // compositor carries it (and d_rgb) to σ.
  auto J = [&] {
    V rgb2(R * 3), w2(R * S), L(R);
    composite_forward<double>({rgb2.data(), nullptr, nullptr, nullptr, w2.data()}, in());
    distortion_forward(L.data(), w2.data(), s.data(), R, S);
    return double(dot_ld(g_rgb, rgb2) + dot_ld(g_dist, L));
  };
  V d_w(R * S), d_sigma(R * S), d_color(R * S * 3), d_sigma_n(R * S), d_color_n(R * S * 3);
  distortion_backward(d_w.data(), g_dist.data(), w.data(), s.data(), R, S);
  const CompositeOut<const double> d_out{g_rgb.data(), nullptr, nullptr, nullptr, d_w.data()};
  composite_backward<double>({d_sigma.data(), d_color.data(), nullptr}, d_out, in(),
                             {rgb.data(), nullptr, nullptr, op.data()});
  composite_backward_naive<double>({d_sigma_n.data(), d_color_n.data(), nullptr}, d_out, in());
  CHECK(worst_scaled_diff(d_sigma, d_sigma_n) < 1e-13);
  CHECK(worst_scaled_diff(d_color, d_color_n) < 1e-15);
  // Inner samples at h = 1e-4 (σ ∈ (0, 8): J is smooth there, the O(h²) error ~1e-9; at h = 1e-6
  // rounding gives 1.7e-6 in a build without FMA, measured); the last sample's δ is 1e10, so its
  // α is 1 and its dσ exactly 0 for any σ this large.
  std::vector<size_t> idx;
  for (int64_t r = 0; r < R; ++r)
    for (int i = 0; i + 1 < S; ++i) idx.push_back(size_t(r * S + i));
  const double e = worst_grad_error(sigma, d_sigma, J, 1e-4, idx, 1e-9);
  HCC_TEST_PRINTF("compositor + distortion: worst dJ/dσ error %.2e (tol 1e-6)\n", e);
  CHECK(e < 1e-6);
  for (int64_t r = 0; r < R; ++r) CHECK(d_sigma[r * S + S - 1] == 0);
  // Without the weights' gradient the backward is bit for bit what it was (off costs nothing).
  V a(R * S), b(R * S), ca(R * S * 3), cb(R * S * 3);
  composite_backward<double>({a.data(), ca.data(), nullptr}, {g_rgb.data()}, in(),
                             {rgb.data(), nullptr, nullptr, op.data()});
  const V zero(R * S, 0.0);
  composite_backward<double>({b.data(), cb.data(), nullptr},
                             {g_rgb.data(), nullptr, nullptr, nullptr, zero.data()}, in(),
                             {rgb.data(), nullptr, nullptr, op.data()});
  CHECK(worst_scaled_diff(a, b) < 1e-15);
}
