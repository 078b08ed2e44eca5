// Tests for kernels/fourier.h (γ(x), formulas.md §4). Derivation in docs/math/fourier.md.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "core/parallel.h"
#include "kernels/fourier.h"
#include "test/gradcheck.h"

using namespace hashcc;
using namespace hashcc::test;
using V = std::vector<double>;

namespace {

V gamma(const V& x, int64_t N, int D, int L, const double* w) {
  V out(N * fourier_width(D, L));
  fourier_forward(out.data(), x.data(), N, D, L, w);
  return out;
}

}  // namespace

TEST_CASE("fourier gradient d_x against central differences", "[fourier][grad]") {
  // Band 9 has frequency 512: h = 1e-7 keeps the truncation error (512 h)²/6 ≈ 4e-10 relative;
  // the centred long-double loss keeps roundoff ≈ 1e-16·|L|/h out of it.
  const double tol = 1e-6;
  struct Cfg { int D, L; bool weighted; const char* name; };
  for (Cfg cfg : {Cfg{3, 10, false, "fourier L=10 d_x"}, Cfg{3, 4, false, "fourier L=4 d_x"},
                  Cfg{3, 10, true, "fourier L=10 weighted d_x"}}) {
    Rng rng(100 + cfg.L + cfg.weighted);
    const int64_t N = 7;
    V x = random_vec(N * cfg.D, rng, -1.5, 1.5);
    V w = random_vec(cfg.L, rng, 0.0, 1.0);
    const double* wp = cfg.weighted ? w.data() : nullptr;
    CenteredLoss loss_of(random_vec(N * fourier_width(cfg.D, cfg.L), rng));
    loss_of.set_origin(gamma(x, N, cfg.D, cfg.L, wp));
    V dx(N * cfg.D), dxn(N * cfg.D);
    fourier_backward(dx.data(), loss_of.g.data(), x.data(), N, cfg.D, cfg.L, wp);
    auto loss = [&] { return loss_of(gamma(x, N, cfg.D, cfg.L, wp)); };
    CHECK(report(cfg.name, worst_grad_error(x, dx, loss, 1e-7), tol) < tol);
    // Recurrence-based kernel against direct sin/cos: the recurrence's error doubles per band.
    fourier_backward_naive(dxn.data(), loss_of.g.data(), x.data(), N, cfg.D, cfg.L, wp);
    V yn(N * fourier_width(cfg.D, cfg.L));
    fourier_forward_naive(yn.data(), x.data(), N, cfg.D, cfg.L, wp);
    CHECK(report("fourier y vs naive", worst_scaled_diff(gamma(x, N, cfg.D, cfg.L, wp), yn), 1e-12) <
          1e-12);
    CHECK(report("fourier d_x vs naive", worst_scaled_diff(dx, dxn), 1e-12) < 1e-12);
  }
}

TEST_CASE("fourier layout and closed-form values", "[fourier][hard]") {
  SECTION("x = 0 gives [0, sin 0 = 0, cos 0 = 1, …] and d_x = raw + Σ 2^k·d_sin") {
    const int D = 3, L = 10, W = fourier_width(D, L);
    REQUIRE(W == 63);
    REQUIRE(fourier_width(3, 4) == 27);
    V x(D, 0.0), out(W, -9.0), g(W), dx(D);
    fourier_forward(out.data(), x.data(), 1, D, L);
    for (int d = 0; d < D; ++d) {
      CHECK(out[d] == 0.0);
      for (int k = 0; k < L; ++k) {
        CHECK(out[D * (1 + 2 * k) + d] == 0.0);
        CHECK(out[D * (2 + 2 * k) + d] == 1.0);
      }
    }
    for (int i = 0; i < W; ++i) g[i] = 1.0;
    fourier_backward(dx.data(), g.data(), x.data(), 1, D, L);
    // d/dx [x + Σ sin(2^k x) + cos(2^k x)] at 0 = 1 + Σ 2^k = 1 + (2^10 − 1) = 1024.
    for (int d = 0; d < D; ++d) CHECK(dx[d] == 1024.0);
  }
  SECTION("block order: x then sin, cos per band; band weights scale both, not x") {
    const int D = 2, L = 3;
    V x = {0.3, -1.1}, w = {0.5, 0.0, 2.0};
    V out = gamma(x, 1, D, L, w.data());
    for (int d = 0; d < D; ++d) {
      CHECK(out[d] == x[d]);
      for (int k = 0; k < L; ++k) {
        CHECK(out[D * (1 + 2 * k) + d] == Approx(w[k] * std::sin(std::ldexp(x[d], k))).epsilon(1e-14).margin(1e-15));
        CHECK(out[D * (2 + 2 * k) + d] == Approx(w[k] * std::cos(std::ldexp(x[d], k))).epsilon(1e-14).margin(1e-15));
      }
    }
    // All weights 0: γ = [x, 0, …]; d_x is the raw block's gradient alone.
    V zero(L, 0.0), g(fourier_width(D, L), 3.0), dx(D);
    fourier_backward(dx.data(), g.data(), x.data(), 1, D, L, zero.data());
    CHECK(dx[0] == 3.0);
    CHECK(dx[1] == 3.0);
  }
  SECTION("batches of size 0 and 1") {
    V x = {0.7, -0.2, 0.4}, out(63, 5.0), g(63, 1.0), dx(3, 7.0);
    fourier_forward(out.data(), x.data(), 0, 3, 10);
    fourier_backward(dx.data(), g.data(), x.data(), 0, 3, 10);
    CHECK(out == V(63, 5.0));
    CHECK(dx == V(3, 7.0));
    V outn(63), dxn(3);
    fourier_forward(out.data(), x.data(), 1, 3, 10);
    fourier_forward_naive(outn.data(), x.data(), 1, 3, 10);
    fourier_backward(dx.data(), g.data(), x.data(), 1, 3, 10);
    fourier_backward_naive(dxn.data(), g.data(), x.data(), 1, 3, 10);
    CHECK(worst_scaled_diff(out, outn) < 1e-13);
    CHECK(worst_scaled_diff(dx, dxn) < 1e-13);
  }
}

TEST_CASE("fourier float build agrees with the double build", "[fourier][float]") {
  // Outputs are O(1) values rounded once (the recurrence runs in double): ≈ 6e-8. d_x sums 21
  // terms up to 2^9 in size; relative to its scale ≈ 1e-7. A wrong band is O(1).
  const double tol = 1e-6;
  Rng rng(110);
  const int64_t N = 5000;
  const int D = 3, L = 10, W = fourier_width(D, L);
  V x = random_vec(N * D, rng, -1, 1), g = random_vec(N * W, rng), w = random_vec(L, rng, 0, 1);
  auto xf = to_float(x), gf = to_float(g), wf = to_float(w);
  V y(N * W), dx(N * D);
  std::vector<float> yf(N * W), dxf(N * D);
  fourier_forward(yf.data(), xf.data(), N, D, L, wf.data());
  fourier_backward(dxf.data(), gf.data(), xf.data(), N, D, L, wf.data());
  // The float input itself is rounded: x_f − x ≈ 6e-8·|x| moves sin(512 x) by up to 3e-5, so
  // compare against the double build evaluated AT the float input.
  V xr(xf.begin(), xf.end()), gr(gf.begin(), gf.end()), wr(wf.begin(), wf.end());
  fourier_forward(y.data(), xr.data(), N, D, L, wr.data());
  fourier_backward(dx.data(), gr.data(), xr.data(), N, D, L, wr.data());
  CHECK(report("fourier float y", float_vs_double(yf, y), tol) < tol);
  CHECK(report("fourier float d_x", float_vs_double(dxf, dx), tol) < tol);
}

TEST_CASE("fourier results at 1 thread equal those at 2 threads", "[fourier][threads]") {
  Rng rng(120);
  const int64_t N = 20000;
  std::vector<float> x(N * 3), g(N * 63);
  for (auto& v : x) v = float(rng.uniform(-1, 1));
  for (auto& v : g) v = float(rng.uniform(-1, 1));
  auto run = [&](int t) {
    set_num_threads(t);
    std::vector<float> y(N * 63), dx(N * 3);
    fourier_forward(y.data(), x.data(), N, 3, 10);
    fourier_backward(dx.data(), g.data(), x.data(), N, 3, 10);
    y.insert(y.end(), dx.begin(), dx.end());
    return y;
  };
  const int keep = num_threads();
  auto one = run(1), two = run(2);
  set_num_threads(keep);
  CHECK(one == two);
}
