// Tests for kernels/sh.h (real SH degree 1..4, formulas.md §8; normalize3). Derivation in
// docs/math/sh.md.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "core/parallel.h"
#include "kernels/sh.h"
#include "test/gradcheck.h"

using namespace hashcc;
using namespace hashcc::test;
using V = std::vector<double>;

namespace {

// Spec §8 constants, for closed-form expectations.
constexpr double C0 = 0.28209479177387814, C1 = 0.48860251190291987, C2a = 1.0925484305920792,
                 C6a = 0.94617469575755997, C6b = 0.31539156525251999,
                 C8 = 0.54627421529603959, C9 = 0.59004358992664352, C10 = 2.8906114426405538,
                 C11 = 0.45704579946446572, C12 = 0.3731763325901154, C14 = 1.4453057213202769;

V sh_out(const V& dir, int64_t N, int degree) {
  V out(N * degree * degree);
  sh_forward(out.data(), dir.data(), N, degree);
  return out;
}

// Random directions near the unit sphere (the basis is differentiated as a polynomial in the
// raw values, so off-sphere points are valid test points too).
V random_dirs(int64_t N, Rng& rng) {
  V d(N * 3);
  for (int64_t n = 0; n < N; ++n) {
    double v[3], len = 0;
    for (auto& c : v) { c = rng.normal(); len += c * c; }
    const double scale = rng.uniform(0.8, 1.2) / std::sqrt(len);
    for (int a = 0; a < 3; ++a) d[3 * n + a] = v[a] * scale;
  }
  return d;
}

}  // namespace

TEST_CASE("sh gradient d_dir against central differences, degrees 1..4", "[sh][grad]") {
  const double tol = 1e-7;  // cubic polynomials: FD truncation ~h², roundoff ~1e-16/h
  for (int degree = 1; degree <= 4; ++degree) {
    Rng rng(200 + degree);
    const int64_t N = 9;
    V dir = random_dirs(N, rng);
    CenteredLoss L(random_vec(N * degree * degree, rng));
    L.set_origin(sh_out(dir, N, degree));
    V dd(N * 3, -1.0), ddn(N * 3);
    sh_backward(dd.data(), L.g.data(), dir.data(), N, degree);
    sh_backward_naive(ddn.data(), L.g.data(), dir.data(), N, degree);
    INFO("degree " << degree);
    if (degree == 1) {
      CHECK(dd == V(N * 3, 0.0));  // Y_0 is constant
    } else {
      auto loss = [&] { return L(sh_out(dir, N, degree)); };
      const std::string name = "sh degree " + std::to_string(degree) + " d_dir";
      CHECK(report(name.c_str(), worst_grad_error(dir, dd, loss), tol) < tol);
    }
    // Generated code against the hand-typed §8 formulas (forward) and their dual-number
    // derivatives (backward).
    V yn(N * degree * degree);
    sh_forward_naive(yn.data(), dir.data(), N, degree);
    CHECK(report("sh generated y vs hand-typed", worst_scaled_diff(sh_out(dir, N, degree), yn), 1e-15) < 1e-15);
    CHECK(report("sh generated d_dir vs dual numbers", worst_scaled_diff(dd, ddn), 1e-14) < 1e-14);
  }
}

TEST_CASE("normalize3 gradient against central differences", "[sh][grad]") {
  const double tol = 1e-7;
  Rng rng(210);
  const int64_t N = 8;
  V v = random_vec(N * 3, rng, -2, 2);
  auto out = [&] { V u(N * 3); normalize3_forward(u.data(), v.data(), N); return u; };
  CenteredLoss L(random_vec(N * 3, rng));
  L.set_origin(out());
  V dv(N * 3);
  normalize3_backward(dv.data(), L.g.data(), v.data(), N);
  auto loss = [&] { return L(out()); };
  CHECK(report("normalize3 d_v", worst_grad_error(v, dv, loss), tol) < tol);
  V u = out();
  for (int64_t n = 0; n < N; ++n)
    CHECK(u[3 * n] * u[3 * n] + u[3 * n + 1] * u[3 * n + 1] + u[3 * n + 2] * u[3 * n + 2] ==
          Approx(1.0).epsilon(1e-15));
}

TEST_CASE("sh at the poles and along the axes equals the closed forms", "[sh][hard]") {
  for (double s : {1.0, -1.0}) {
    INFO("sign " << s);
    SECTION("pole (0, 0, " + std::to_string(int(s)) + ")") {
      V dir = {0, 0, s};
      V y = sh_out(dir, 1, 4);
      V expect(16, 0.0);
      expect[0] = C0;
      expect[2] = C1 * s;
      expect[6] = C6a - C6b;
      expect[12] = C12 * s * (5 - 3);
      for (int k = 0; k < 16; ++k) CHECK(y[k] == Approx(expect[k]).epsilon(1e-15).margin(0));
      // Gradient for d_out = 1: closed forms of Σ_k ∂Y_k/∂(x, y, z) at the pole.
      V g(16, 1.0), dd(3), ddn(3);
      sh_backward(dd.data(), g.data(), dir.data(), 1, 4);
      sh_backward_naive(ddn.data(), g.data(), dir.data(), 1, 4);
      const double gx = -C1 - C2a * s + C11 * (1 - 5);    // Y3, Y7, Y13
      const double gy = -C1 - C2a * s + C11 * (1 - 5);    // Y1, Y5, Y11
      const double gz = C1 + 2 * C6a * s + C12 * (15 - 3);  // Y2, Y6, Y12
      CHECK(dd[0] == Approx(gx).epsilon(1e-15));
      CHECK(dd[1] == Approx(gy).epsilon(1e-15));
      CHECK(dd[2] == Approx(gz).epsilon(1e-15));
      CHECK(worst_scaled_diff(dd, ddn) < 1e-15);
      // And against central differences at the pole itself.
      CenteredLoss L(g);
      L.set_origin(y);
      auto loss = [&] { return L(sh_out(dir, 1, 4)); };
      CHECK(report("sh d_dir at pole", worst_grad_error(dir, dd, loss), 1e-7) < 1e-7);
    }
    SECTION("x axis (" + std::to_string(int(s)) + ", 0, 0)") {
      V y = sh_out({s, 0, 0}, 1, 4);
      V expect(16, 0.0);
      expect[0] = C0; expect[3] = -C1 * s; expect[6] = -C6b; expect[8] = C8;
      expect[13] = C11 * s; expect[15] = -C9 * s;
      for (int k = 0; k < 16; ++k) CHECK(y[k] == Approx(expect[k]).epsilon(1e-15).margin(0));
    }
    SECTION("y axis (0, " + std::to_string(int(s)) + ", 0)") {
      V y = sh_out({0, s, 0}, 1, 4);
      V expect(16, 0.0);
      expect[0] = C0; expect[1] = -C1 * s; expect[6] = -C6b; expect[8] = -C8;
      expect[9] = C9 * s; expect[11] = C11 * s;
      for (int k = 0; k < 16; ++k) CHECK(y[k] == Approx(expect[k]).epsilon(1e-15).margin(0));
    }
  }
  SECTION("axis gradients: one basis function at a time, against dual numbers and closed forms") {
    for (V dir : {V{1, 0, 0}, V{0, 1, 0}, V{0, 0, 1}, V{-1, 0, 0}}) {
      for (int k = 0; k < 16; ++k) {
        V g(16, 0.0), dd(3), ddn(3);
        g[k] = 1;
        sh_backward(dd.data(), g.data(), dir.data(), 1, 4);
        sh_backward_naive(ddn.data(), g.data(), dir.data(), 1, 4);
        for (int a = 0; a < 3; ++a) {
          CHECK(std::isfinite(dd[a]));
          CHECK(dd[a] == Approx(ddn[a]).epsilon(1e-15).margin(1e-15));
        }
      }
    }
    // Spot closed forms at (1, 0, 0): ∂Y15/∂x = −3·C9·x² = −3 C9; ∂Y14/∂z = C14 (x² − y²) = C14;
    // ∂Y10/∂y = C10·x·z = 0; ∂Y4/∂y = C2a·x = C2a.
    auto grad_of = [](int k) {
      V g(16, 0.0), dd(3), dir = {1, 0, 0};
      g[k] = 1;
      sh_backward(dd.data(), g.data(), dir.data(), 1, 4);
      return dd;
    };
    CHECK(grad_of(15)[0] == Approx(-3 * C9).epsilon(1e-15));
    CHECK(grad_of(14)[2] == Approx(C14).epsilon(1e-15));
    CHECK(grad_of(10)[1] == 0.0);
    CHECK(grad_of(4)[1] == Approx(C2a).epsilon(1e-15));
  }
  SECTION("lower degrees write only degree² values") {
    V out(16, 9.0);
    V dir = {0.6, 0.0, 0.8};
    sh_forward(out.data(), dir.data(), 1, 2);
    CHECK(out[3] == Approx(-C1 * 0.6).epsilon(1e-15));
    CHECK(out[4] == 9.0);
    CHECK_THROWS(sh_forward(out.data(), dir.data(), 1, 5));
  }
  SECTION("normalize3 along an axis, at extreme scales, and at zero") {
    V v = {0, 0, 5}, u(3), g = {1, 2, 3}, dv(3);
    normalize3_forward(u.data(), v.data(), 1);
    normalize3_backward(dv.data(), g.data(), v.data(), 1);
    CHECK(u == V{0, 0, 1});
    CHECK(dv[0] == Approx(1.0 / 5).epsilon(1e-15));  // (g − u⟨u, g⟩)/|v| = (1, 2, 0)/5
    CHECK(dv[1] == Approx(2.0 / 5).epsilon(1e-15));
    CHECK(dv[2] == 0.0);
    float big[3] = {3e30f, 4e30f, 0}, tiny[3] = {0, 3e-30f, -4e-30f}, uf[3];
    normalize3_forward(uf, big, 1);  // |v|² = 2.5e61 would overflow float
    CHECK(uf[0] == Approx(0.6f).epsilon(1e-6));
    CHECK(uf[1] == Approx(0.8f).epsilon(1e-6));
    normalize3_forward(uf, tiny, 1);  // |v|² = 2.5e-59 would underflow to 0
    CHECK(uf[1] == Approx(0.6f).epsilon(1e-6));
    CHECK(uf[2] == Approx(-0.8f).epsilon(1e-6));
    V zero = {0, 0, 0};
    normalize3_forward(u.data(), zero.data(), 1);
    normalize3_backward(dv.data(), g.data(), zero.data(), 1);
    CHECK(u == V{0, 0, 0});
    CHECK(dv == V{0, 0, 0});
  }
  SECTION("batches of size 0 and 1") {
    V dir = {0.48, 0.6, 0.64}, out(16, 4.0), g(16, 1.0), dd(3, 4.0);
    sh_forward(out.data(), dir.data(), 0, 4);
    sh_backward(dd.data(), g.data(), dir.data(), 0, 4);
    CHECK(out == V(16, 4.0));
    CHECK(dd == V(3, 4.0));
    V outn(16), ddn(3);
    sh_forward(out.data(), dir.data(), 1, 4);
    sh_forward_naive(outn.data(), dir.data(), 1, 4);
    sh_backward(dd.data(), g.data(), dir.data(), 1, 4);
    sh_backward_naive(ddn.data(), g.data(), dir.data(), 1, 4);
    CHECK(worst_scaled_diff(out, outn) < 1e-15);
    CHECK(worst_scaled_diff(dd, ddn) < 1e-15);
  }
}

TEST_CASE("sh and normalize3 float build agrees with the double build", "[sh][float]") {
  const double tol = 1e-6;  // cubic monomials of O(1) values: a few float roundings
  Rng rng(220);
  const int64_t N = 10000;
  V dir = random_dirs(N, rng), g = random_vec(N * 16, rng);
  auto dirf = to_float(dir), gf = to_float(g);
  V dr(dirf.begin(), dirf.end()), gr(gf.begin(), gf.end());  // double build at the float inputs
  V y(N * 16), dd(N * 3), u(N * 3), dv(N * 3);
  std::vector<float> yf(N * 16), ddf(N * 3), uf(N * 3), dvf(N * 3);
  sh_forward(y.data(), dr.data(), N, 4);
  sh_forward(yf.data(), dirf.data(), N, 4);
  sh_backward(dd.data(), gr.data(), dr.data(), N, 4);
  sh_backward(ddf.data(), gf.data(), dirf.data(), N, 4);
  normalize3_forward(u.data(), dr.data(), N);
  normalize3_forward(uf.data(), dirf.data(), N);
  normalize3_backward(dv.data(), gr.data(), dr.data(), N);
  normalize3_backward(dvf.data(), gf.data(), dirf.data(), N);
  CHECK(report("sh float y", float_vs_double(yf, y), tol) < tol);
  CHECK(report("sh float d_dir", float_vs_double(ddf, dd), tol) < tol);
  CHECK(report("normalize3 float u", float_vs_double(uf, u), tol) < tol);
  CHECK(report("normalize3 float d_v", float_vs_double(dvf, dv), tol) < tol);
}

TEST_CASE("sh results at 1 thread equal those at 2 threads", "[sh][threads]") {
  Rng rng(230);
  const int64_t N = 30000;
  auto dirf = to_float(random_dirs(N, rng)), gf = to_float(random_vec(N * 16, rng));
  auto run = [&](int t) {
    set_num_threads(t);
    std::vector<float> y(N * 16), dd(N * 3), u(N * 3), dv(N * 3);
    sh_forward(y.data(), dirf.data(), N, 4);
    sh_backward(dd.data(), gf.data(), dirf.data(), N, 4);
    normalize3_forward(u.data(), dirf.data(), N);
    normalize3_backward(dv.data(), gf.data(), dirf.data(), N);
    for (auto* v : {&dd, &u, &dv}) y.insert(y.end(), v->begin(), v->end());
    return y;
  };
  const int keep = num_threads();
  auto one = run(1), two = run(2);
  set_num_threads(keep);
  CHECK(one == two);
}
