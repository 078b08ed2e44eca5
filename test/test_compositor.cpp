// Tests for render/compositor.h (formulas.md §3 volume compositing) and render/sampler.h.
// Derivations in docs/math/compositor.md and docs/math/sampler.md.
#include <catch2/catch.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "core/parallel.h"
#include "render/compositor.h"
#include "render/sampler.h"
#include "test/gradcheck.h"

using namespace hashcc;
using namespace hashcc::test;
using V = std::vector<double>;

namespace {

template <class T>
using Vec = std::vector<T>;

// One batch of rays: inputs, upstream gradients, and which outputs carry gradient.
template <class T>
struct Rays {
  int64_t R;
  int S;
  Vec<T> sigma, color, color2, s;             // (R,S), (R,S,3), (R,S,3), (R,S)
  Vec<T> delta;                               // (R,S) given δ (CompositeIn::delta); empty = gaps of s
  Vec<T> g_rgb, g_rgb2, g_depth, g_opacity;   // (R,3), (R,3), (R), (R)
  bool use_c2 = true, use_rgb2 = true, use_depth = true, use_opacity = true, use_rgb = true;

  Rays(int64_t R_, int S_) : R(R_), S(S_), sigma(R_ * S_), color(R_ * S_ * 3),
      color2(R_ * S_ * 3), s(R_ * S_), g_rgb(R_ * 3), g_rgb2(R_ * 3), g_depth(R_), g_opacity(R_) {}

  template <class U>
  Rays<U> as() const {
    Rays<U> o(R, S);
    auto cp = [](const Vec<T>& a, Vec<U>& b) { for (size_t i = 0; i < a.size(); ++i) b[i] = U(a[i]); };
    cp(sigma, o.sigma); cp(color, o.color); cp(color2, o.color2); cp(s, o.s);
    o.delta.resize(delta.size()); cp(delta, o.delta);
    cp(g_rgb, o.g_rgb); cp(g_rgb2, o.g_rgb2); cp(g_depth, o.g_depth); cp(g_opacity, o.g_opacity);
    o.use_c2 = use_c2; o.use_rgb2 = use_rgb2; o.use_depth = use_depth;
    o.use_opacity = use_opacity; o.use_rgb = use_rgb;
    return o;
  }

  const T* c2() const { return use_c2 ? color2.data() : nullptr; }
  CompositeIn<T> in() const {
    return {sigma.data(), color.data(), c2(), s.data(), R, S, delta.empty() ? nullptr : delta.data()};
  }

  // Forward outputs concatenated: [rgb (R,3), rgb2 (R,3), depth (R), opacity (R)].
  Vec<T> forward(bool naive = false) const {
    Vec<T> out(R * 8, T(0));
    T *rgb = out.data(), *rgb2 = rgb + R * 3, *depth = rgb2 + R * 3, *op = depth + R;
    (naive ? composite_forward_naive<T> : composite_forward<T>)(
        {rgb, use_c2 ? rgb2 : nullptr, depth, op}, in());
    return out;
  }
  // The projection g of the concatenated outputs (0 where an output carries no gradient).
  Vec<T> projection() const {
    Vec<T> g(R * 8, T(0));
    for (int64_t i = 0; i < R * 3; ++i) {
      if (use_rgb) g[i] = g_rgb[i];
      if (use_c2 && use_rgb2) g[R * 3 + i] = g_rgb2[i];
    }
    for (int64_t r = 0; r < R; ++r) {
      if (use_depth) g[R * 6 + r] = g_depth[r];
      if (use_opacity) g[R * 7 + r] = g_opacity[r];
    }
    return g;
  }

  struct Grads { Vec<T> sigma, color, color2; };
  Grads backward(bool naive = false) const {
    Grads d{Vec<T>(R * S, T(-7)), Vec<T>(R * S * 3, T(-7)), Vec<T>(R * S * 3, T(-7))};
    Vec<T> out = forward();
    Vec<T> zero(R * 3, T(0));
    const T* grgb = use_rgb ? g_rgb.data() : zero.data();  // d_rgb is required by the contract
    const T* grgb2 = use_rgb2 ? g_rgb2.data() : nullptr;
    const T* gdep = use_depth ? g_depth.data() : nullptr;
    const T* gop = use_opacity ? g_opacity.data() : nullptr;
    T* dc2 = use_c2 ? d.color2.data() : nullptr;
    if (naive)
      composite_backward_naive<T>({d.sigma.data(), d.color.data(), dc2}, {grgb, grgb2, gdep, gop},
                                  in());
    else
      composite_backward<T>({d.sigma.data(), d.color.data(), dc2}, {grgb, grgb2, gdep, gop},
                            in(),
                            {out.data(), out.data() + R * 3, out.data() + R * 6,
                             out.data() + R * 7});
    return d;
  }
};

// Jittered sample positions s_i = (i + U)/S (formulas.md §3), random densities and colours.
Rays<double> random_rays(int64_t R, int S, uint64_t seed, double sigma_max = 30,
                         double sigma_min = 0) {
  Rng rng(seed);
  Rays<double> r(R, S);
  for (int64_t i = 0; i < R * S; ++i) {
    r.sigma[i] = rng.uniform(sigma_min, sigma_max);
    r.s[i] = ((i % S) + rng.uniform(0.05, 0.95)) / S;
  }
  for (auto& c : r.color) c = rng.uniform(0, 1);
  for (auto& c : r.color2) c = rng.uniform(-0.2, 1.2);
  for (auto& v : r.g_rgb) v = rng.uniform(-1, 1);
  for (auto& v : r.g_rgb2) v = rng.uniform(-1, 1);
  for (auto& v : r.g_depth) v = rng.uniform(-1, 1);
  for (auto& v : r.g_opacity) v = rng.uniform(-1, 1);
  return r;
}

}  // namespace

TEST_CASE("compositor gradients: sigma, color, color2 against central differences",
          "[compositor][grad]") {
  const double tol = 1e-6;
  // σ ∈ [0.5, 3] with δ ≈ 1/12: every sample keeps a visible weight (w ≳ 1e-4), so each entry's
  // gradient stands well above the central difference's roundoff (~1e-12 absolute here);
  // saturated rays are covered by the [hard] cases against the reference and closed forms.
  Rays<double> rays = random_rays(3, 12, 300, 3.0, 0.5);
  // Last sample: σ·1e10 = O(0.1), so its α is not saturated and its gradient (≈1e10) is live.
  for (int64_t r = 0; r < rays.R; ++r) rays.sigma[r * rays.S + rays.S - 1] = 1e-11 * (r + 1);

  struct Src { const char* name; bool rgb, rgb2, depth, opacity; };
  const Src sources[] = {{"all outputs", true, true, true, true}, {"rgb only", true, false, false, false},
                         {"rgb2 only", false, true, false, false}, {"depth only", false, false, true, false},
                         {"opacity only", false, false, false, true}};
  for (const Src& src : sources) {
    Rays<double> c = rays;
    c.use_rgb = src.rgb; c.use_rgb2 = src.rgb2; c.use_depth = src.depth; c.use_opacity = src.opacity;
    auto d = c.backward();
    CenteredLoss L(c.projection());
    L.set_origin(c.forward());
    auto loss = [&] { return L(c.forward()); };
    std::vector<size_t> inner, last;
    for (int64_t r = 0; r < c.R; ++r)
      for (int i = 0; i < c.S; ++i) (i + 1 < c.S ? inner : last).push_back(r * c.S + i);
    const std::string n = std::string("compositor d_sigma (") + src.name + ")";
    CHECK(report(n.c_str(), worst_grad_error(c.sigma, d.sigma, loss, 1e-5, inner), tol) < tol);
    // The last sample's σ lives at 1e-11: a step of 1e-18 moves σδ by 1e-8.
    CHECK(report((n + ", last sample").c_str(), worst_grad_error(c.sigma, d.sigma, loss, 1e-18, last), tol) < tol);
    if (src.rgb) {
      // Linear in c: a large step has no truncation error and less roundoff.
      CHECK(report("compositor d_color", worst_grad_error(c.color, d.color, loss, 1e-3), tol) < tol);
    } else {
      CHECK(d.color == V(d.color.size(), 0.0));  // d_rgb = 0 → d_color written as 0
    }
    if (src.rgb2) {
      CHECK(report("compositor d_color2", worst_grad_error(c.color2, d.color2, loss, 1e-3), tol) < tol);
    } else {
      CHECK(d.color2 == V(d.color2.size(), 0.0));
    }
    // O(S) kernel against the O(S²) reference.
    auto dn = c.backward(true);
    CHECK(report("compositor y vs naive", worst_scaled_diff(c.forward(), c.forward(true)), 1e-13) < 1e-13);
    // Inner samples and the 1e10-scale last samples separately, so neither hides the other.
    auto pick = [](const V& v, const std::vector<size_t>& idx) { V o; for (size_t i : idx) o.push_back(v[i]); return o; };
    CHECK(report("compositor d_sigma vs naive (inner)", worst_scaled_diff(pick(d.sigma, inner), pick(dn.sigma, inner)), 1e-12) < 1e-12);
    CHECK(report("compositor d_sigma vs naive (last)", worst_scaled_diff(pick(d.sigma, last), pick(dn.sigma, last)), 1e-12) < 1e-12);
    CHECK(worst_scaled_diff(d.color, dn.color) < 1e-13);
    CHECK(worst_scaled_diff(d.color2, dn.color2) < 1e-13);
  }
  SECTION("without color2 (NeRF-- variants): d_color2 untouched, rgb2 ignored") {
    Rays<double> c = rays;
    c.use_c2 = false;
    auto d = c.backward();
    CenteredLoss L(c.projection());
    L.set_origin(c.forward());
    auto loss = [&] { return L(c.forward()); };
    CHECK(report("compositor d_sigma (no color2)", worst_grad_error(c.sigma, d.sigma, loss, 1e-5, {0, 5, 13, 30}), tol) < tol);
    CHECK(d.color2 == V(d.color2.size(), -7.0));
  }
}

TEST_CASE("compositor with given δ (occupancy samples): gradients, and δ = the gaps of s is the "
          "same computation", "[compositor][grad][occupancy]") {
  const double tol = 1e-6;
  Rays<double> rays = random_rays(3, 12, 305, 3.0, 0.5);
  SECTION("δ given as the gaps of s (last 1e10): bitwise the result without δ") {
    Rays<double> c = rays;
    const auto y0 = c.forward();
    const auto d0 = c.backward();
    c.delta.resize(c.R * c.S);
    for (int64_t r = 0; r < c.R; ++r)
      for (int i = 0; i < c.S; ++i)
        c.delta[r * c.S + i] = i + 1 < c.S ? c.s[r * c.S + i + 1] - c.s[r * c.S + i] : kLastDelta;
    CHECK(c.forward() == y0);
    const auto d1 = c.backward();
    CHECK(d1.sigma == d0.sigma);
    CHECK(d1.color == d0.color);
    CHECK(d1.color2 == d0.color2);
  }
  SECTION("δ unlike the gaps: central differences, and the O(S²) reference") {
    Rays<double> c = rays;
    Rng rng(306);
    c.delta.resize(c.R * c.S);
    for (int64_t r = 0; r < c.R; ++r)
      for (int i = 0; i < c.S; ++i)  // equal shares of an occupied length, as occupancy_samples
        c.delta[r * c.S + i] = i + 1 < c.S ? 0.03 + 0.01 * r : kLastDelta;
    for (int64_t r = 0; r < c.R; ++r) c.sigma[r * c.S + c.S - 1] = 1e-11 * (r + 1);
    const auto d = c.backward();
    CenteredLoss L(c.projection());
    L.set_origin(c.forward());
    auto loss = [&] { return L(c.forward()); };
    std::vector<size_t> inner;
    for (int64_t r = 0; r < c.R; ++r)
      for (int i = 0; i + 1 < c.S; ++i) inner.push_back(r * c.S + i);
    CHECK(report("compositor d_sigma (given δ)", worst_grad_error(c.sigma, d.sigma, loss, 1e-5, inner), tol) < tol);
    CHECK(report("compositor d_color (given δ)", worst_grad_error(c.color, d.color, loss, 1e-3), tol) < tol);
    const auto dn = c.backward(true);
    CHECK(worst_scaled_diff(c.forward(), c.forward(true)) < 1e-13);
    CHECK(worst_scaled_diff(d.sigma, dn.sigma) < 1e-12);
    // And δ matters: the same rays with the gaps of s composite differently.
    Rays<double> g = c;
    g.delta.clear();
    CHECK(clearly_differs(worst_scaled_diff(g.forward(), c.forward()), 1e-3));
  }
}

TEST_CASE("compositor hard cases", "[compositor][hard]") {
  SECTION("sigma = 0 everywhere: nothing is drawn; dσ has its closed form") {
    Rays<double> c = random_rays(2, 10, 310);
    for (auto& v : c.sigma) v = 0;
    Vec<double> out = c.forward();
    CHECK(out == V(out.size(), 0.0));
    auto d = c.backward();
    CHECK(d.color == V(d.color.size(), 0.0));
    CHECK(d.color2 == V(d.color2.size(), 0.0));
    for (int64_t r = 0; r < c.R; ++r)
      for (int i = 0; i < c.S; ++i) {
        // w = 0 everywhere so the suffix is 0: dσ_i = δ_i T_i ⟨g, v_i⟩, T_i = (1 + 1e-10)^i.
        const int64_t ri = r * c.S + i;
        const double delta = i + 1 < c.S ? c.s[ri + 1] - c.s[ri] : 1e10;
        double gv = c.g_depth[r] * c.s[ri] + c.g_opacity[r];
        for (int a = 0; a < 3; ++a)
          gv += c.g_rgb[3 * r + a] * c.color[ri * 3 + a] + c.g_rgb2[3 * r + a] * c.color2[ri * 3 + a];
        CHECK(d.sigma[ri] == Approx(delta * std::pow(1 + 1e-10, i) * gv).epsilon(1e-13));
      }
  }
  SECTION("sigma = 1e4 on one sample: α saturates (e^{-σδ} underflows to 0)") {
    for (int k : {0, 3, 7}) {
      INFO("saturated sample " << k);
      Rays<double> c = random_rays(1, 8, 320 + k);
      for (auto& v : c.sigma) v = 0;
      c.sigma[k] = 1e4;  // σδ ≥ 1e4·0.1/8 = 125 (k < 7) or 1e14 (last): e ≤ 5e-55
      Vec<double> out = c.forward();
      const double Tk = std::pow(1 + 1e-10, k);  // transmittance up to k (earlier α = 0)
      const double ek = std::exp(-1e4 * (k + 1 < c.S ? c.s[k + 1] - c.s[k] : 1e10));
      const double wk = Tk * (1 - ek);
      for (int a = 0; a < 3; ++a) {
        CHECK(out[a] == Approx(wk * c.color[3 * k + a]).epsilon(1e-15));
        CHECK(out[3 + a] == Approx(wk * c.color2[3 * k + a]).epsilon(1e-15));
      }
      CHECK(out[6] == Approx(wk * c.s[k]).epsilon(1e-15));
      CHECK(out[7] == Approx(wk).epsilon(1e-15));
      auto d = c.backward();
      auto dn = c.backward(true);
      auto gv = [&](int i) {
        double v = c.g_depth[0] * c.s[i] + c.g_opacity[0];
        for (int a = 0; a < 3; ++a) v += c.g_rgb[a] * c.color[3 * i + a] + c.g_rgb2[a] * c.color2[3 * i + a];
        return v;
      };
      for (int i = 0; i < c.S; ++i) {
        INFO("sample " << i);
        const double delta = i + 1 < c.S ? c.s[i + 1] - c.s[i] : 1e10;
        double expect;
        if (i < k)  // δ_i [T_i ⟨g,v_i⟩ − ⟨g, w_k v_k⟩ / (1 + 1e-10)]
          expect = delta * (std::pow(1 + 1e-10, i) * gv(i) - wk * gv(k) / (1 + 1e-10));
        else if (i == k)  // δ_k e_k T_k ⟨g, v_k⟩ with e_k ≈ 0
          expect = delta * ek * Tk * gv(k);
        else  // behind the wall: T_i = T_k (e_k + 1e-10)(1 + 1e-10)^{i−k−1}, nothing after
          expect = delta * Tk * (ek + 1e-10) * std::pow(1 + 1e-10, i - k - 1) * gv(i);
        CHECK(std::isfinite(d.sigma[i]));
        CHECK(d.sigma[i] == Approx(expect).epsilon(1e-12).margin(1e-300));
        CHECK(d.sigma[i] == Approx(dn.sigma[i]).epsilon(1e-12).margin(1e-300));
        for (int a = 0; a < 3; ++a)
          CHECK(d.color[3 * i + a] == (i == k ? wk * c.g_rgb[a] : 0.0));
      }
      // The float build: same closed forms to float precision, nothing non-finite.
      auto cf = c.as<float>();
      auto outf = cf.forward();
      auto df = cf.backward();
      for (int a = 0; a < 8; ++a) CHECK(outf[a] == Approx(out[a]).epsilon(1e-6).margin(1e-7));
      for (int i = 0; i < c.S; ++i) {
        CHECK(std::isfinite(df.sigma[i]));
        CHECK(df.sigma[i] == Approx(d.sigma[i]).epsilon(1e-5).margin(1e-30));
      }
    }
  }
  SECTION("a run of saturated samples: T underflows to 0 without NaN") {
    Rays<double> c = random_rays(1, 64, 330);
    for (auto& v : c.sigma) v = 1e4;  // σδ ≈ 156: α = 1, each T factor is ≈ 1e-10
    Vec<double> out = c.forward();
    // w_i = T_i α_i = (e + 1e-10)^i: rgb = Σ_i 1e-10^i c_i, dominated by c_0 + 1e-10 c_1.
    double rgb0 = 0, Ti = 1;
    for (int i = 0; i < 64; ++i) {
      const double delta = i + 1 < 64 ? c.s[i + 1] - c.s[i] : 1e10;
      rgb0 += Ti * c.color[3 * i];
      Ti *= std::exp(-1e4 * delta) + 1e-10;
    }
    CHECK(Ti == 0.0);  // the transmittance did underflow
    CHECK(out[0] == Approx(rgb0).epsilon(1e-15));
    CHECK(out[7] == Approx(1 + 1e-10).epsilon(1e-15));
    auto d = c.backward();
    auto dn = c.backward(true);
    // Here the suffix "total − prefix" behind sample 0 is ≈ 1e-10·c_1 taken from a total ≈ c_0:
    // it carries the absolute error ε·|C| of the ray's output, the documented bound of the
    // O(S) backward (docs/math/compositor.md): |Δ dσ_j| ≤ δ_j (e_j/q_j)·(S+2)·ε·Σ_k|g_k|·|C_k|.
    double sum_gC = 0;
    for (int k = 0; k < 8; ++k) sum_gC += std::abs(c.projection()[k] * out[k]);
    for (int j = 0; j < 64; ++j) {
      INFO("sample " << j);
      const double delta = j + 1 < 64 ? c.s[j + 1] - c.s[j] : 1e10;
      const double e = std::exp(-1e4 * delta), q = e + 1e-10;
      const double bound = delta * (e / q) * 66 * 2.3e-16 * sum_gC + 1e-13 * std::abs(dn.sigma[j]);
      CHECK(std::isfinite(d.sigma[j]));
      CHECK(std::abs(d.sigma[j] - dn.sigma[j]) <= bound);
    }
    CHECK(worst_scaled_diff(d.sigma, dn.sigma) < 1e-5);  // the bound above, relative: ≈ 1e-6
    CHECK(worst_scaled_diff(d.color, dn.color) < 1e-15);
    CHECK(d.sigma[63] == 0.0);  // e^{-1e14} = 0 exactly: no gradient through a saturated last α
  }
  SECTION("last δ = 1e10 with large σ: the last sample takes all that is left") {
    for (double last : {1e3, 1e4, 1e8}) {
      Rays<double> c = random_rays(4, 16, 340, 5.0);
      for (int64_t r = 0; r < c.R; ++r) c.sigma[r * 16 + 15] = last;
      Vec<double> out = c.forward(), outn = c.forward(true);
      CHECK(worst_scaled_diff(out, outn) < 1e-14);
      for (int64_t r = 0; r < c.R; ++r) {
        // α_last = 1, so opacity = Σ_{i<15} T_i α_i + T_15 = 1 − (ε-terms) ≈ 1.
        CHECK(out[7 * c.R + r] == Approx(1.0).epsilon(1e-8));
      }
      auto d = c.backward();
      auto dn = c.backward(true);
      for (double v : d.sigma) CHECK(std::isfinite(v));
      for (int64_t r = 0; r < c.R; ++r) CHECK(d.sigma[r * 16 + 15] == 0.0);
      CHECK(worst_scaled_diff(d.sigma, dn.sigma) < 1e-12);
      CHECK(worst_scaled_diff(d.color, dn.color) < 1e-14);
      CHECK(worst_scaled_diff(d.color2, dn.color2) < 1e-14);
    }
  }
  SECTION("last δ = 1e10 with tiny σ: a finite 1e10-scale gradient") {
    Rays<double> c = random_rays(1, 4, 350);
    for (auto& v : c.sigma) v = 0;
    c.sigma[3] = 1e-12;  // σδ = 0.01
    auto d = c.backward();
    double gv = c.g_depth[0] * c.s[3] + c.g_opacity[0];
    for (int a = 0; a < 3; ++a) gv += c.g_rgb[a] * c.color[9 + a] + c.g_rgb2[a] * c.color2[9 + a];
    const double expect = 1e10 * std::exp(-0.01) * std::pow(1 + 1e-10, 3) * gv;
    CHECK(d.sigma[3] == Approx(expect).epsilon(1e-12));
  }
  SECTION("batches of size 0 and 1, and a single sample") {
    Rays<double> c = random_rays(1, 6, 360);
    Vec<double> rgb(3, 5.0), dsig(6, 5.0), dcol(18, 5.0);
    composite_forward<double>({rgb.data()}, {c.sigma.data(), c.color.data(), nullptr, c.s.data(), 0, 6});
    composite_backward<double>({dsig.data(), dcol.data()}, {c.g_rgb.data()},
                               {c.sigma.data(), c.color.data(), nullptr, c.s.data(), 0, 6},
                               {rgb.data()});
    CHECK(rgb == V(3, 5.0));
    CHECK(dsig == V(6, 5.0));
    CHECK(dcol == V(18, 5.0));
    CHECK(worst_scaled_diff(c.forward(), c.forward(true)) < 1e-15);
    CHECK(worst_scaled_diff(c.backward().sigma, c.backward(true).sigma) < 1e-13);
    Rays<double> one = random_rays(1, 1, 361);  // S = 1: its only δ is the 1e10 one
    Vec<double> out = one.forward();
    const double a = -std::expm1(-one.sigma[0] * 1e10);
    CHECK(out[0] == Approx(a * one.color[0]).epsilon(1e-15));
    CHECK(out[7] == Approx(a).epsilon(1e-15));
  }
}

TEST_CASE("compositor float build agrees with the double build", "[compositor][float]") {
  // Float inputs, double accumulation inside: outputs and gradients are the double results at
  // the float inputs, rounded once. Tolerance relative to each array's scale.
  const double tol = 1e-6;
  Rays<double> c = random_rays(64, 128, 370, 50);
  auto cf = c.as<float>();
  Rays<double> cr = cf.as<double>();  // the double build at the float-rounded inputs
  auto out = cr.forward();
  auto outf = cf.forward();
  auto d = cr.backward();
  auto df = cf.backward();
  CHECK(report("compositor float outputs", float_vs_double(outf, out), tol) < tol);
  CHECK(report("compositor float d_sigma", float_vs_double(df.sigma, d.sigma), tol) < tol);
  CHECK(report("compositor float d_color", float_vs_double(df.color, d.color), tol) < tol);
  CHECK(report("compositor float d_color2", float_vs_double(df.color2, d.color2), tol) < tol);
  // And against the unrounded double inputs (s rounding moves δ by ~1e-7 relative).
  auto d0 = c.backward();
  CHECK(report("compositor float d_sigma vs exact inputs", float_vs_double(df.sigma, d0.sigma), 1e-4) < 1e-4);
}

TEST_CASE("compositor results at 1 thread equal those at 2 threads", "[compositor][threads]") {
  auto cf = random_rays(300, 64, 380).as<float>();
  auto run = [&](int t) {
    set_num_threads(t);
    auto out = cf.forward();
    auto d = cf.backward();
    for (auto* v : {&d.sigma, &d.color, &d.color2}) out.insert(out.end(), v->begin(), v->end());
    // The sampler on the same rays (o, d taken from the colours, any values do).
    std::vector<float> x(cf.R * cf.S * 3), dO(cf.R * 3), dD(cf.R * 3);
    sample_points_forward(x.data(), cf.color.data(), cf.color2.data(), cf.s.data(), cf.R, cf.S);
    sample_points_backward(dO.data(), dD.data(), cf.color.data(), cf.s.data(), cf.R, cf.S);
    for (auto* v : {&x, &dO, &dD}) out.insert(out.end(), v->begin(), v->end());
    return out;
  };
  const int keep = num_threads();
  auto one = run(1), two = run(2);
  set_num_threads(keep);
  CHECK(one == two);
}

TEST_CASE("sampler gradients d_o, d_d against central differences", "[compositor][grad]") {
  const double tol = 1e-8;  // linear in o and d
  Rng rng(400);
  const int64_t R = 3;
  const int S = 5;
  V o = random_vec(R * 3, rng), d = random_vec(R * 3, rng), s(R * S);
  for (int64_t i = 0; i < R * S; ++i) s[i] = ((i % S) + rng.uniform()) / S;
  auto out = [&] { V x(R * S * 3); sample_points_forward(x.data(), o.data(), d.data(), s.data(), R, S); return x; };
  CenteredLoss L(random_vec(R * S * 3, rng));
  L.set_origin(out());
  V dO(R * 3), dD(R * 3);
  sample_points_backward(dO.data(), dD.data(), L.g.data(), s.data(), R, S);
  auto loss = [&] { return L(out()); };
  CHECK(report("sampler d_o", worst_grad_error(o, dO, loss), tol) < tol);
  CHECK(report("sampler d_d", worst_grad_error(d, dD, loss), tol) < tol);
  V x = out();
  CHECK(x[(1 * S + 2) * 3 + 1] == Approx(o[3 + 1] + s[S + 2] * d[3 + 1]).epsilon(1e-15));
}

TEST_CASE("sampler hard cases and float build", "[compositor][hard][float]") {
  SECTION("R = 0 writes nothing; R = 1, S = 1 is o + s d") {
    V o = {1, 2, 3}, d = {0.5, -1, 2}, s = {0.25}, x(3, 9.0), g = {1, 1, 1}, dO(3, 9.0), dD(3, 9.0);
    sample_points_forward(x.data(), o.data(), d.data(), s.data(), 0, 1);
    sample_points_backward(dO.data(), dD.data(), g.data(), s.data(), 0, 1);
    CHECK(x == V(3, 9.0));
    CHECK(dO == V(3, 9.0));
    sample_points_forward(x.data(), o.data(), d.data(), s.data(), 1, 1);
    CHECK(x == V{1.125, 1.75, 3.5});
    sample_points_backward(dO.data(), dD.data(), g.data(), s.data(), 1, 1);
    CHECK(dO == V{1, 1, 1});
    CHECK(dD == V{0.25, 0.25, 0.25});
  }
  SECTION("float agrees with double") {
    Rng rng(410);
    const int64_t R = 200;
    const int S = 128;
    V o = random_vec(R * 3, rng), d = random_vec(R * 3, rng), s(R * S), g = random_vec(R * S * 3, rng);
    for (int64_t i = 0; i < R * S; ++i) s[i] = ((i % S) + rng.uniform()) / S;
    auto of = to_float(o), df = to_float(d), sf = to_float(s), gf = to_float(g);
    V orr(of.begin(), of.end()), dr(df.begin(), df.end()), sr(sf.begin(), sf.end()), gr(gf.begin(), gf.end());
    V x(R * S * 3), dO(R * 3), dD(R * 3);
    std::vector<float> xf(R * S * 3), dOf(R * 3), dDf(R * 3);
    sample_points_forward(x.data(), orr.data(), dr.data(), sr.data(), R, S);
    sample_points_forward(xf.data(), of.data(), df.data(), sf.data(), R, S);
    sample_points_backward(dO.data(), dD.data(), gr.data(), sr.data(), R, S);
    sample_points_backward(dOf.data(), dDf.data(), gf.data(), sf.data(), R, S);
    const double tol = 1e-6;
    CHECK(report("sampler float x", float_vs_double(xf, x), tol) < tol);
    CHECK(report("sampler float d_o", float_vs_double(dOf, dO), tol) < tol);
    CHECK(report("sampler float d_d", float_vs_double(dDf, dD), tol) < tol);
  }
}
