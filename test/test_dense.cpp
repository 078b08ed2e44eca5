// Tests for kernels/dense.h: dense layer (plain and fused ReLU), activations, concat.
// Derivations in docs/math/dense.md.
#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

#include "core/buffer.h"
#include "core/parallel.h"
#include "kernels/chunked_for.h"
#include "kernels/dense.h"
#include "test/gradcheck.h"
#include "test/shared_data.h"

using namespace hashcc;
using namespace hashcc::test;
using V = std::vector<double>;

namespace {

struct DenseCase {
  int64_t N;
  int in, out;
  V x, W, b, g;  // g: the random projection of y in L = ⟨g, y⟩
  DenseCase(int64_t N_, int in_, int out_, uint64_t seed) : N(N_), in(in_), out(out_) {
    Rng rng(seed);
    x = random_vec(N * in, rng);
    W = random_vec(size_t(out) * in, rng, -0.5, 0.5);
    b = random_vec(out, rng, -0.3, 0.3);
    g = random_vec(N * out, rng);
  }
};

V dense_out(const DenseCase& c, bool relu) {
  V y(c.N * c.out);
  (relu ? dense_relu_forward<double> : dense_forward<double>)(y.data(), c.x.data(), c.W.data(),
                                                              c.b.data(), c.N, c.in, c.out);
  return y;
}

struct DenseGrads { V dx, dW, db; };

DenseGrads dense_grads(const DenseCase& c, bool relu) {
  DenseGrads r{V(c.N * c.in), V(size_t(c.out) * c.in, 0.0), V(c.out, 0.0)};
  if (relu) {
    V y(c.N * c.out), dpre(c.N * c.out);
    dense_relu_forward(y.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out);
    dense_relu_backward(r.dx.data(), r.dW.data(), r.db.data(), dpre.data(), c.g.data(), y.data(),
                        c.x.data(), c.W.data(), c.N, c.in, c.out);
  } else {
    dense_backward(r.dx.data(), r.dW.data(), r.db.data(), c.g.data(), c.x.data(), c.W.data(), c.N,
                   c.in, c.out);
  }
  return r;
}

// Smallest |pre-activation|: the ReLU checks require it ≫ h so no finite difference crosses 0.
double min_abs_preact(const DenseCase& c) {
  V y(c.N * c.out);
  dense_forward_naive(y.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out);
  double m = 1e300;
  for (double v : y) m = std::min(m, std::abs(v));
  return m;
}

}  // namespace

TEST_CASE("dense layer gradients: x, W, b against central differences", "[dense][grad]") {
  const double tol = 1e-7;  // smooth (bilinear) kernel; central differences are exact up to rounding
  for (bool relu : {false, true}) {
    DYNAMIC_SECTION((relu ? "dense_relu" : "dense")) {
      DenseCase c(6, 7, 5, relu ? 11 : 10);
      if (relu) REQUIRE(min_abs_preact(c) > 1e-3);  // off the ReLU kink by construction (seed)
      DenseGrads a = dense_grads(c, relu);
      CenteredLoss L(c.g);  // L = ⟨g, y⟩
      L.set_origin(dense_out(c, relu));
      auto loss = [&] { return L(dense_out(c, relu)); };
      const double ex = worst_grad_error(c.x, a.dx, loss);
      const double eW = worst_grad_error(c.W, a.dW, loss);
      const double eb = worst_grad_error(c.b, a.db, loss);
      report(relu ? "dense_relu d_x" : "dense d_x", ex, tol);
      report(relu ? "dense_relu d_W" : "dense d_W", eW, tol);
      report(relu ? "dense_relu d_b" : "dense d_b", eb, tol);
      CHECK(ex < tol);
      CHECK(eW < tol);
      CHECK(eb < tol);
    }
  }
}

TEST_CASE("dense layer equals its triple-loop reference, across chunks and slabs", "[dense][exact]") {
  // N spans several 256-row chunks and 4096-row slabs with a ragged tail; in = 63 is unaligned.
  DenseCase c(2 * 4096 + 301, 63, 17, 12);
  V y(c.N * c.out), yn(c.N * c.out);
  dense_forward(y.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out);
  dense_forward_naive(yn.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out);
  DenseGrads a = dense_grads(c, false);
  DenseGrads n{V(c.N * c.in), V(size_t(c.out) * c.in, 0.0), V(c.out, 0.0)};
  dense_backward_naive(n.dx.data(), n.dW.data(), n.db.data(), c.g.data(), c.x.data(), c.W.data(),
                       c.N, c.in, c.out);
  // Relative to each array's largest entry: 63-term and 8493-term sums in different orders.
  const double tol = 1e-13;
  CHECK(report("dense y vs naive", worst_scaled_diff(y, yn), tol) < tol);
  CHECK(report("dense d_x vs naive", worst_scaled_diff(a.dx, n.dx), tol) < tol);
  CHECK(report("dense d_W vs naive", worst_scaled_diff(a.dW, n.dW), tol) < tol);
  CHECK(report("dense d_b vs naive", worst_scaled_diff(a.db, n.db), tol) < tol);

  // The fused ReLU layer equals dense + relu, and its backward equals relu_backward + dense.
  V yr(c.N * c.out), ref(c.N * c.out);
  dense_relu_forward(yr.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out);
  relu_forward(ref.data(), yn.data(), c.N * c.out);
  CHECK(worst_scaled_diff(yr, ref) < tol);
  DenseGrads f = dense_grads(c, true);
  V dpre(c.N * c.out);
  relu_backward(dpre.data(), c.g.data(), ref.data(), c.N * c.out);
  DenseGrads m{V(c.N * c.in), V(size_t(c.out) * c.in, 0.0), V(c.out, 0.0)};
  dense_backward_naive(m.dx.data(), m.dW.data(), m.db.data(), dpre.data(), c.x.data(), c.W.data(),
                       c.N, c.in, c.out);
  CHECK(report("dense_relu d_x vs naive", worst_scaled_diff(f.dx, m.dx), tol) < tol);
  CHECK(report("dense_relu d_W vs naive", worst_scaled_diff(f.dW, m.dW), tol) < tol);
  CHECK(report("dense_relu d_b vs naive", worst_scaled_diff(f.db, m.db), tol) < tol);
}

TEST_CASE("dense backward accumulates parameter gradients and writes d_x", "[dense][exact]") {
  DenseCase c(9, 4, 3, 13);
  DenseGrads once = dense_grads(c, false);
  V dx(c.N * c.in, 123.0), dW(size_t(c.out) * c.in, 0.0), db(c.out, 0.0);
  for (int rep = 0; rep < 2; ++rep)
    dense_backward(dx.data(), dW.data(), db.data(), c.g.data(), c.x.data(), c.W.data(), c.N, c.in,
                   c.out);
  for (size_t i = 0; i < dW.size(); ++i) CHECK(dW[i] == Approx(2 * once.dW[i]).epsilon(1e-14));
  for (size_t i = 0; i < db.size(); ++i) CHECK(db[i] == Approx(2 * once.db[i]).epsilon(1e-14));
  for (size_t i = 0; i < dx.size(); ++i) CHECK(dx[i] == Approx(once.dx[i]).epsilon(1e-14));
  // d_x == nullptr: only parameter gradients.
  V dW2(size_t(c.out) * c.in, 0.0), db2(c.out, 0.0);
  dense_backward<double>(nullptr, dW2.data(), db2.data(), c.g.data(), c.x.data(), c.W.data(), c.N,
                         c.in, c.out);
  CHECK(worst_rel_diff(dW2, once.dW) < 1e-14);
  CHECK(worst_rel_diff(db2, once.db) < 1e-14);
}

TEST_CASE("activation gradients against central differences", "[dense][grad]") {
  const double tol = 1e-7;
  Rng rng(20);
  const int64_t n = 50;
  // Off the ReLU kink by construction: |x| ∈ [0.1, 3].
  V x(n), g = random_vec(n, rng);
  for (auto& v : x) v = (rng.uniform() < 0.5 ? -1 : 1) * rng.uniform(0.1, 3.0);
  using Fwd = void (*)(double*, const double*, int64_t);
  using Bwd = void (*)(double*, const double*, const double*, int64_t);
  struct Act { const char* name; Fwd f; Bwd b; bool uses_x; };
  const Act acts[] = {{"relu d_x", relu_forward<double>, relu_backward<double>, false},
                      {"sigmoid d_x", sigmoid_forward<double>, sigmoid_backward<double>, false},
                      {"softplus d_x", softplus_forward<double>, softplus_backward<double>, true},
                      {"exp d_x", exp_forward<double>, exp_backward<double>, false}};
  for (const Act& a : acts) {
    V y(n), dx(n);
    a.f(y.data(), x.data(), n);
    a.b(dx.data(), g.data(), a.uses_x ? x.data() : y.data(), n);
    CenteredLoss L(g);
    L.set_origin(y);
    auto loss = [&] { V yy(n); a.f(yy.data(), x.data(), n); return L(yy); };
    CHECK(report(a.name, worst_grad_error(x, dx, loss), tol) < tol);
  }
}

TEST_CASE("concat / split gradients", "[dense][grad]") {
  Rng rng(21);
  const int64_t N = 4;
  const int A = 3, B = 5;
  V a = random_vec(N * A, rng), b = random_vec(N * B, rng), g = random_vec(N * (A + B), rng);
  V da(N * A), db(N * B);
  concat_backward(da.data(), db.data(), g.data(), N, A, B);
  auto out = [&] { V o(N * (A + B)); concat_forward(o.data(), a.data(), b.data(), N, A, B); return o; };
  CenteredLoss L(g);
  L.set_origin(out());
  auto loss = [&] { return L(out()); };
  const double tol = 1e-9;
  CHECK(report("concat d_a", worst_grad_error(a, da, loss), tol) < tol);
  CHECK(report("concat d_b", worst_grad_error(b, db, loss), tol) < tol);
  // Layout: row n = [a_n, b_n]; a null half is skipped.
  V o(N * (A + B));
  concat_forward(o.data(), a.data(), b.data(), N, A, B);
  CHECK(o[1 * (A + B) + 0] == a[1 * A + 0]);
  CHECK(o[2 * (A + B) + A + 4] == b[2 * B + 4]);
  V db2(N * B, -1.0);
  concat_backward<double>(nullptr, db2.data(), g.data(), N, A, B);
  CHECK(db2 == db);
}

TEST_CASE("activations at ±80 / ±100 are finite and exact", "[dense][hard]") {
  SECTION("sigmoid at ±80") {
    for (double x : {80.0, -80.0}) {
      double y, dx, g = 1;
      sigmoid_forward(&y, &x, 1);
      sigmoid_backward(&dx, &g, &y, 1);
      const double e = std::exp(-80.0);  // σ(−80) = e/(1+e), σ'(±80) = e/(1+e)²
      if (x > 0) CHECK(y == 1.0);        // 1 − 1.8e-35 rounds to 1
      else CHECK(y == Approx(e / (1 + e)).epsilon(1e-15));
      if (x < 0) CHECK(dx == Approx(e / ((1 + e) * (1 + e))).epsilon(1e-15));
      else CHECK(dx == 0.0);  // y(1 − y) with y == 1: true value 1.8e-35, below double's resolution of 1 − y
      float xf = float(x), yf, dxf, gf = 1;
      sigmoid_forward(&yf, &xf, 1);
      sigmoid_backward(&dxf, &gf, &yf, 1);
      CHECK(std::isfinite(yf));
      CHECK(std::isfinite(dxf));
      if (x < 0) CHECK(yf == Approx(float(e)).epsilon(1e-6));
      else CHECK(yf == 1.0f);
    }
  }
  SECTION("softplus at ±100") {
    double x[2] = {100.0, -100.0}, y[2], g[2] = {1, 1}, dx[2];
    softplus_forward(y, x, 2);
    softplus_backward(dx, g, x, 2);
    CHECK(y[0] == 100.0);                                   // 100 + log1p(e^-100)
    CHECK(y[1] == Approx(std::exp(-100.0)).epsilon(1e-15));  // log1p(e^-100) = e^-100
    CHECK(dx[0] == 1.0);
    CHECK(dx[1] == Approx(std::exp(-100.0)).epsilon(1e-15));
    float xf[2] = {100.0f, -100.0f}, yf[2], gf[2] = {1, 1}, dxf[2];
    softplus_forward(yf, xf, 2);
    softplus_backward(dxf, gf, xf, 2);
    CHECK(yf[0] == 100.0f);
    CHECK(dxf[0] == 1.0f);
    // e^-100 ≈ 3.7e-44 is a float subnormal (few significant bits): check it is that, not 0/NaN.
    CHECK(yf[1] > 0.0f);
    CHECK(yf[1] == Approx(std::exp(-100.0)).epsilon(0.1));
    CHECK(dxf[1] == Approx(std::exp(-100.0)).epsilon(0.1));
  }
  SECTION("exp at ±100 (clamped above at kExpClampMax = 80)") {
    double x[2] = {100.0, -100.0}, y[2], g[2] = {2, 2}, dx[2];
    exp_forward(y, x, 2);
    exp_backward(dx, g, y, 2);
    CHECK(y[0] == std::exp(80.0));
    CHECK(y[1] == std::exp(-100.0));
    CHECK(dx[0] == 2 * std::exp(80.0));  // straight-through past the clamp
    CHECK(dx[1] == 2 * std::exp(-100.0));
    float xf[2] = {100.0f, -100.0f}, yf[2], gf[2] = {2, 2}, dxf[2];
    exp_forward(yf, xf, 2);
    exp_backward(dxf, gf, yf, 2);
    CHECK(std::isfinite(yf[0]));
    CHECK(std::isfinite(dxf[0]));
    CHECK(yf[0] == Approx(std::exp(80.0)).epsilon(1e-6));
    CHECK(yf[1] == Approx(std::exp(-100.0)).epsilon(0.1));  // float subnormal
  }
  SECTION("relu at 0 and in place") {
    double x[3] = {-1.0, 0.0, 2.0}, g[3] = {5, 6, 7};
    relu_forward(x, x, 3);  // in place
    CHECK(x[0] == 0.0);
    CHECK(x[1] == 0.0);
    CHECK(x[2] == 2.0);
    relu_backward(g, g, x, 3);  // in place; kink gets 0
    CHECK(g[0] == 0.0);
    CHECK(g[1] == 0.0);
    CHECK(g[2] == 7.0);
  }
}

TEST_CASE("dense layer on batches of size 0 and 1", "[dense][hard]") {
  DenseCase c(1, 5, 4, 30);
  SECTION("N = 0 writes nothing and leaves the gradients unchanged") {
    V y(4, 7.0), dW(20, 1.5), db(4, 2.5), dx(5, 3.5);
    dense_forward(y.data(), c.x.data(), c.W.data(), c.b.data(), 0, 5, 4);
    dense_relu_forward(y.data(), c.x.data(), c.W.data(), c.b.data(), 0, 5, 4);
    dense_backward(dx.data(), dW.data(), db.data(), c.g.data(), c.x.data(), c.W.data(), 0, 5, 4);
    CHECK(y == V(4, 7.0));
    CHECK(dW == V(20, 1.5));
    CHECK(db == V(4, 2.5));
    CHECK(dx == V(5, 3.5));
  }
  SECTION("N = 1 equals the reference") {
    V y(4), yn(4);
    dense_forward(y.data(), c.x.data(), c.W.data(), c.b.data(), 1, 5, 4);
    dense_forward_naive(yn.data(), c.x.data(), c.W.data(), c.b.data(), 1, 5, 4);
    CHECK(worst_scaled_diff(y, yn) < 1e-14);
    DenseGrads a = dense_grads(c, false);
    DenseGrads n{V(5), V(20, 0.0), V(4, 0.0)};
    dense_backward_naive(n.dx.data(), n.dW.data(), n.db.data(), c.g.data(), c.x.data(),
                         c.W.data(), 1, 5, 4);
    CHECK(worst_scaled_diff(a.dx, n.dx) < 1e-14);
    CHECK(worst_scaled_diff(a.dW, n.dW) < 1e-14);
    CHECK(worst_scaled_diff(a.db, n.db) < 1e-14);
    // d_b of one row is d_y itself.
    for (int o = 0; o < 4; ++o) CHECK(a.db[o] == c.g[o]);
  }
}

TEST_CASE("dense float build agrees with the double build", "[dense][float]") {
  // Float dot products of 128 terms (d_W: 4173) relative to the result's scale: measured ~5e-7;
  // a sign or index error would be O(1).
  const double tol = 5e-6;
  DenseCase c(4096 + 77, 128, 64, 40);
  auto fx = to_float(c.x), fW = to_float(c.W), fb = to_float(c.b), fg = to_float(c.g);
  for (bool relu : {false, true}) {
    V y(c.N * c.out), dy = c.g;
    std::vector<float> yf(c.N * c.out), dyf = fg;
    DenseGrads a{V(c.N * c.in), V(size_t(c.out) * c.in, 0.0), V(c.out, 0.0)};
    std::vector<float> dxf(c.N * c.in), dWf(size_t(c.out) * c.in, 0.f), dbf(c.out, 0.f);
    if (relu) {
      dense_relu_forward(y.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out);
      dense_relu_forward(yf.data(), fx.data(), fW.data(), fb.data(), c.N, c.in, c.out);
      // In place (d_pre aliases d_y), the production usage.
      dense_relu_backward(a.dx.data(), a.dW.data(), a.db.data(), dy.data(), dy.data(), y.data(),
                          c.x.data(), c.W.data(), c.N, c.in, c.out);
      dense_relu_backward(dxf.data(), dWf.data(), dbf.data(), dyf.data(), dyf.data(), yf.data(),
                          fx.data(), fW.data(), c.N, c.in, c.out);
    } else {
      dense_forward(y.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out);
      dense_forward(yf.data(), fx.data(), fW.data(), fb.data(), c.N, c.in, c.out);
      dense_backward(a.dx.data(), a.dW.data(), a.db.data(), dy.data(), c.x.data(), c.W.data(),
                     c.N, c.in, c.out);
      dense_backward(dxf.data(), dWf.data(), dbf.data(), dyf.data(), fx.data(), fW.data(), c.N,
                     c.in, c.out);
    }
    const char* tag = relu ? "dense_relu float: " : "dense float: ";
    CHECK(report((std::string(tag) + "y").c_str(), float_vs_double(yf, y), tol) < tol);
    CHECK(report((std::string(tag) + "d_x").c_str(), float_vs_double(dxf, a.dx), tol) < tol);
    CHECK(report((std::string(tag) + "d_W").c_str(), float_vs_double(dWf, a.dW), tol) < tol);
    CHECK(report((std::string(tag) + "d_b").c_str(), float_vs_double(dbf, a.db), tol) < tol);
  }
}

// The float GEMM path (the AVX2 micro-kernel in AVX2 builds, kernels/dense.h) against (1) the
// double build, which "[dense][grad]" checks against central differences, and (2) Eigen's float
// GEMM (dense_*_eigen), the reference it replaced. Shapes: the paper's layers (in 63/128/191/144,
// out 128/64) plus out = 24 (the 8-column d_W panel) and out = 16 (one panel), at N spanning
// two 4096-row slabs with a ragged 256-row chunk and a ragged 6-row tile.
TEST_CASE("dense micro-kernel agrees with the double build and with Eigen's float GEMM",
          "[dense][kernel][float][isa]") {
#if defined(__AVX512F__)
  // The test is about the micro-kernel: in an AVX-512 build the 14×32 one must be the path taken
  // for out % 16 == 0 (48: a 32-column panel, then a half-empty one and d_W's one-vector tail).
  REQUIRE(dense_microkernel(128));
  REQUIRE(dense_microkernel(48));
  REQUIRE_FALSE(dense_microkernel(24));  // not a multiple of 16 lanes: Eigen
  REQUIRE_FALSE(dense_microkernel(3));   // narrow heads stay on Eigen
#elif defined(__AVX2__) && defined(__FMA__)
  // In an AVX2 build the 6×16 one, for out % 8 == 0 (24: a 16-column panel, then a half one).
  REQUIRE(dense_microkernel(128));
  REQUIRE(dense_microkernel(24));
  REQUIRE_FALSE(dense_microkernel(3));  // narrow heads stay on Eigen
#else
  // Without a micro-kernel the comparison below would be Eigen against itself: a pass would
  // claim a check that did not run, so the test is reported SKIPPED (CTest entry isa_kernel).
  HASHCC_SKIP("no AVX2 + FMA in this build: dense_* run Eigen's GEMM, there is no micro-kernel to check");
#endif
  // vs double: float sums of ≤ 191 terms (d_x ≤ 128, d_W ≤ 4096 per slab) relative to the
  // result's scale, as "[dense][float]" (measured ≤ 1e-6). vs Eigen's float: the same products
  // summed in the same k order, but Eigen splits some sums over two accumulators (measured
  // ≤ 5e-7 where not bitwise equal): a wrong index or a missed tail would be O(1).
  const double tol_double = 5e-6, tol_eigen = 5e-6;
  // The paper's shapes, then tails: 24 (AVX2's half panel), 48 (AVX-512's), 16 (one vector).
  const int shapes[][2] = {{63, 128}, {128, 128}, {191, 128}, {144, 64},
                           {33, 24},  {33, 48},   {20, 16}};
  for (const auto& sh : shapes) {
    DenseCase c(2 * 4096 + 256 + 77, sh[0], sh[1], 60 + sh[0]);
    auto fx = to_float(c.x), fW = to_float(c.W), fb = to_float(c.b), fg = to_float(c.g);
    for (bool relu : {false, true}) {
      DYNAMIC_SECTION(sh[0] << "->" << sh[1] << (relu ? " relu" : "")) {
        V y(c.N * c.out), dy = c.g;
        DenseGrads a{V(c.N * c.in), V(size_t(c.out) * c.in, 0.0), V(c.out, 0.0)};
        dense_forward_eigen(y.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out, relu);
        dense_backward_eigen(a.dx.data(), a.dW.data(), a.db.data(), relu ? dy.data() : nullptr,
                             dy.data(), y.data(), c.x.data(), c.W.data(), c.N, c.in, c.out);
        // k: the production entry points (micro-kernel); e: Eigen's float path.
        std::vector<float> yk(c.N * c.out), ye(c.N * c.out), gk = fg, ge = fg;
        std::vector<float> dxk(c.N * c.in), dxe(c.N * c.in), dWk(size_t(c.out) * c.in, 0.f),
            dWe = dWk, dbk(c.out, 0.f), dbe = dbk;
        if (relu) {
          dense_relu_forward(yk.data(), fx.data(), fW.data(), fb.data(), c.N, c.in, c.out);
          dense_relu_backward(dxk.data(), dWk.data(), dbk.data(), gk.data(), gk.data(), yk.data(),
                              fx.data(), fW.data(), c.N, c.in, c.out);
        } else {
          dense_forward(yk.data(), fx.data(), fW.data(), fb.data(), c.N, c.in, c.out);
          dense_backward(dxk.data(), dWk.data(), dbk.data(), gk.data(), fx.data(), fW.data(), c.N,
                         c.in, c.out);
        }
        dense_forward_eigen(ye.data(), fx.data(), fW.data(), fb.data(), c.N, c.in, c.out, relu);
        dense_backward_eigen(dxe.data(), dWe.data(), dbe.data(), relu ? ge.data() : nullptr,
                             ge.data(), ye.data(), fx.data(), fW.data(), c.N, c.in, c.out);
        auto dbl = [](const std::vector<float>& v) { return V(v.begin(), v.end()); };
        CHECK(report("kernel y vs double", float_vs_double(yk, y), tol_double) < tol_double);
        CHECK(report("kernel d_x vs double", float_vs_double(dxk, a.dx), tol_double) < tol_double);
        CHECK(report("kernel d_W vs double", float_vs_double(dWk, a.dW), tol_double) < tol_double);
        CHECK(report("kernel d_b vs double", float_vs_double(dbk, a.db), tol_double) < tol_double);
        CHECK(report("kernel y vs eigen", worst_scaled_diff(dbl(yk), dbl(ye)), tol_eigen) < tol_eigen);
        CHECK(report("kernel d_x vs eigen", worst_scaled_diff(dbl(dxk), dbl(dxe)), tol_eigen) < tol_eigen);
        CHECK(report("kernel d_W vs eigen", worst_scaled_diff(dbl(dWk), dbl(dWe)), tol_eigen) < tol_eigen);
        // Without the ReLU, d_b is the same double column sum of the same g on both paths (with
        // it, a y within rounding of 0 may take the other side of the mask on one path).
        if (!relu) CHECK(dbk == dbe);
        CHECK(report("kernel d_b vs eigen", worst_scaled_diff(dbl(dbk), dbl(dbe)), tol_eigen) < tol_eigen);
      }
    }
  }
}

// Batches smaller than one row tile (6 rows on AVX2, 14 on AVX-512) and ragged ones, on the
// micro-kernel path (out = 16; the "[dense][hard]" N = 0 / 1 cases use out = 4, which stays on
// Eigen): against the double triple-loop reference, relative to the result's scale as above.
TEST_CASE("dense micro-kernel on batches of 1 to 29 rows", "[dense][kernel][hard]") {
  const double tol = 5e-6;
  for (int64_t N : {1, 2, 5, 6, 7, 13, 14, 15, 29}) {
    DenseCase c(N, 9, 16, 80 + N);
    auto fx = to_float(c.x), fW = to_float(c.W), fb = to_float(c.b), fg = to_float(c.g);
    V yn(c.N * c.out);
    DenseGrads n{V(c.N * c.in), V(size_t(c.out) * c.in, 0.0), V(c.out, 0.0)};
    dense_forward_naive(yn.data(), c.x.data(), c.W.data(), c.b.data(), c.N, c.in, c.out);
    dense_backward_naive(n.dx.data(), n.dW.data(), n.db.data(), c.g.data(), c.x.data(), c.W.data(),
                         c.N, c.in, c.out);
    std::vector<float> y(c.N * c.out), dx(c.N * c.in), dW(size_t(c.out) * c.in, 0.f), db(c.out, 0.f);
    dense_forward(y.data(), fx.data(), fW.data(), fb.data(), c.N, c.in, c.out);
    dense_backward(dx.data(), dW.data(), db.data(), fg.data(), fx.data(), fW.data(), c.N, c.in,
                   c.out);
    INFO("N = " << N);
    CHECK(float_vs_double(y, yn) < tol);
    CHECK(float_vs_double(dx, n.dx) < tol);
    CHECK(float_vs_double(dW, n.dW) < tol);
    CHECK(float_vs_double(db, n.db) < tol);
  }
}

// d_x == nullptr (the first layer's input gradient is often not needed) and accumulation into a
// non-zero d_W on the micro-kernel path, at a paper shape.
TEST_CASE("dense micro-kernel: d_x skipped, d_W and d_b accumulate", "[dense][kernel]") {
  DenseCase c(4096 + 300, 63, 128, 70);
  auto fx = to_float(c.x), fW = to_float(c.W), fg = to_float(c.g);
  std::vector<float> dx(c.N * c.in), dW1(size_t(c.out) * c.in, 0.f), db1(c.out, 0.f);
  dense_backward(dx.data(), dW1.data(), db1.data(), fg.data(), fx.data(), fW.data(), c.N, c.in,
                 c.out);
  std::vector<float> dW2(dW1.size(), 0.5f), db2(c.out, 0.25f);
  dense_backward<float>(nullptr, dW2.data(), db2.data(), fg.data(), fx.data(), fW.data(), c.N,
                        c.in, c.out);
  // d_b: one add of the same double sum; d_W: two slab partials added, so 0.5 + p0 + p1 rounds
  // differently from p0 + p1 + 0.5 (≤ a few float ulps of the entries, which are O(100)).
  double worst = 0, scale = 0;
  for (size_t i = 0; i < dW1.size(); ++i) {
    hashcc::test::keep_worst(worst, std::abs(double(dW2[i]) - (double(dW1[i]) + 0.5)));
    scale = std::max(scale, std::abs(double(dW1[i])));
  }
  CHECK(report("d_W accumulates", worst / scale, 1e-6) < 1e-6);
  for (int o = 0; o < c.out; ++o) CHECK(db2[o] == db1[o] + 0.25f);
  // d_W and d_b skipped (input gradients only): the same d_x, bitwise, on both paths, with and
  // without the ReLU.
  for (bool eigen : {false, true}) {
    dense_force_eigen(eigen);
    std::vector<float> dxa(dx.size()), dxb(dx.size()), dWa(dW1.size(), 0.f), dba(c.out, 0.f);
    dense_backward(dxa.data(), dWa.data(), dba.data(), fg.data(), fx.data(), fW.data(), c.N, c.in,
                   c.out);
    dense_backward<float>(dxb.data(), nullptr, nullptr, fg.data(), fx.data(), fW.data(), c.N,
                          c.in, c.out);
    CHECK(dxa == dxb);
    std::vector<float> y(size_t(c.N) * c.out), pa(y.size()), pb(y.size());
    dense_relu_forward(y.data(), fx.data(), fW.data(), db1.data(), c.N, c.in, c.out);
    dense_relu_backward(dxa.data(), dWa.data(), dba.data(), pa.data(), fg.data(), y.data(),
                        fx.data(), fW.data(), c.N, c.in, c.out);
    dense_relu_backward<float>(dxb.data(), nullptr, nullptr, pb.data(), fg.data(), y.data(),
                               fx.data(), fW.data(), c.N, c.in, c.out);
    CHECK(dxa == dxb);
    CHECK(pa == pb);
  }
  dense_force_eigen(false);
}

TEST_CASE("activations float build agrees with the double build", "[dense][float]") {
  const double tol = 1e-6;  // one or two float roundings of O(1) values
  Rng rng(41);
  const int64_t n = 100000;  // above the parallel threshold
  V x = random_vec(n, rng, -8, 8), g = random_vec(n, rng);
  auto xf = to_float(x), gf = to_float(g);
  using FwdD = void (*)(double*, const double*, int64_t);
  using BwdD = void (*)(double*, const double*, const double*, int64_t);
  using FwdF = void (*)(float*, const float*, int64_t);
  using BwdF = void (*)(float*, const float*, const float*, int64_t);
  struct Act { const char* name; FwdD fd; BwdD bd; FwdF ff; BwdF bf; bool uses_x; };
  const Act acts[] = {
      {"relu", relu_forward<double>, relu_backward<double>, relu_forward<float>, relu_backward<float>, false},
      {"sigmoid", sigmoid_forward<double>, sigmoid_backward<double>, sigmoid_forward<float>, sigmoid_backward<float>, false},
      {"softplus", softplus_forward<double>, softplus_backward<double>, softplus_forward<float>, softplus_backward<float>, true},
      {"exp", exp_forward<double>, exp_backward<double>, exp_forward<float>, exp_backward<float>, false}};
  for (const Act& a : acts) {
    V y(n), dx(n);
    std::vector<float> yf(n), dxf(n);
    a.fd(y.data(), x.data(), n);
    a.bd(dx.data(), g.data(), a.uses_x ? x.data() : y.data(), n);
    a.ff(yf.data(), xf.data(), n);
    a.bf(dxf.data(), gf.data(), a.uses_x ? xf.data() : yf.data(), n);
    INFO(a.name);
    // Forward values element-wise (each is computed independently: float rounding ≈ 6e-8·|v|
    // plus exp's argument rounding |x|·6e-8 ≤ 5e-7). Backward relative to the array's scale:
    // sigmoid's y(1 − y) from a float y loses 1 − y's relative precision as y → 1.
    double worst = 0;
    for (int64_t i = 0; i < n; ++i) hashcc::test::keep_worst(worst, rel_err(yf[i], y[i], 1e-30));
    hashcc::test::keep_worst(worst, float_vs_double(dxf, dx));
    CHECK(report((std::string(a.name) + " float vs double").c_str(), worst, tol) < tol);
  }
}

TEST_CASE("dense results at 1 thread equal those at 2 threads", "[dense][threads]") {
  // Fixed chunks and slabs, each computed serially: bit-identical at any thread count.
  DenseCase c(3 * 4096 + 5, 33, 40, 50);
  auto fx = to_float(c.x), fW = to_float(c.W), fb = to_float(c.b), fg = to_float(c.g);
  auto run = [&](int threads) {
    set_num_threads(threads);
    std::vector<float> y(c.N * c.out), dy = fg, dx(c.N * c.in), dW(size_t(c.out) * c.in, 0.f),
        db(c.out, 0.f), act(c.N * c.out);
    dense_relu_forward(y.data(), fx.data(), fW.data(), fb.data(), c.N, c.in, c.out);
    dense_relu_backward(dx.data(), dW.data(), db.data(), dy.data(), dy.data(), y.data(), fx.data(),
                        fW.data(), c.N, c.in, c.out);
    sigmoid_forward(act.data(), y.data(), c.N * c.out);
    std::vector<float> all;
    for (auto* v : {&y, &dx, &dW, &db, &act}) all.insert(all.end(), v->begin(), v->end());
    return all;
  };
  const int keep = num_threads();
  auto one = run(1), two = run(2);
  set_num_threads(keep);
  CHECK(one == two);
}

// kernels/dense.h, "One layer, block by block": a two-layer network (in → 64, ReLU, → out) run
// a block of 256 rows at a time, both layers on the block before the next (the grid field's and
// the CC branch's way, model/grid_field.cpp), gives the batch-wide calls' results BIT FOR BIT:
// the forward, d_x, and d_W / d_b accumulated into non-zero gradients by slabs. N spans two
// 4096-row slabs and a ragged block; out = 16 (the micro-kernel's one-vector panel in AVX-512
// builds) and 3 (a narrow head); float (the micro-kernel, where the build has one) and double
// (Eigen), at 1 and 2 threads. A block misplaced in its slab, a partial added twice or out of
// order, or a block-local buffer shared between threads, would show as a difference.
template <class T>
void check_block_chain(int in, int out, int threads) {
  const int H = 64;
  const int64_t N = 2 * kDenseSlabRows + 3 * kDenseBlockRows + 77;
  Rng rng(900 + in + out);
  auto vec = [&](int64_t n, double s) {
    std::vector<T> v(n);
    for (auto& e : v) e = T(rng.uniform(-s, s));
    return v;
  };
  const std::vector<T> x = vec(N * in, 1), W0 = vec(int64_t(H) * in, 0.4), b0 = vec(H, 0.2),
                       W1 = vec(int64_t(out) * H, 0.4), b1 = vec(out, 0.2), gy = vec(N * out, 1);
  const int keep = num_threads();
  set_num_threads(threads);
  // Batch-wide: layer after layer over all rows.
  std::vector<T> h(N * H), y(N * out), dh(N * H), dx(N * in), dW0(W0.size(), T(0.5)),
      db0(H, T(0.25)), dW1(W1.size(), T(-0.5)), db1(out, T(0.125));
  dense_relu_forward(h.data(), x.data(), W0.data(), b0.data(), N, in, H);
  dense_forward(y.data(), h.data(), W1.data(), b1.data(), N, H, out);
  dense_backward(dh.data(), dW1.data(), db1.data(), gy.data(), h.data(), W1.data(), N, H, out);
  dense_relu_backward(dx.data(), dW0.data(), db0.data(), dh.data(), dh.data(), h.data(), x.data(),
                      W0.data(), N, in, H);
  // Block by block: the hidden layer in block-local storage, recomputed by the backward.
  DenseLayer<T> L0, L1;
  DenseGradSlabs<T> G0, G1;
  dense_prepare(L0, W0.data(), b0.data(), in, H, true, true);
  dense_prepare(L1, W1.data(), b1.data(), H, out, true, true);
  std::vector<T> y2(N * out), dx2(N * in), dW0b(W0.size(), T(0.5)), db0b(H, T(0.25)),
      dW1b(W1.size(), T(-0.5)), db1b(out, T(0.125));
  parallel_chunks(N, kDenseBlockRows, [&](int64_t r0, int64_t r1) {
    std::vector<T> hb(kDenseBlockRows * H);
    dense_forward_block(hb.data(), x.data() + r0 * in, L0, r1 - r0, true);
    dense_forward_block(y2.data() + r0 * out, hb.data(), L1, r1 - r0, false);
  });
  dense_grads_begin(G0, L0, N, true, true);
  dense_grads_begin(G1, L1, N, true, true);
  parallel_chunks(N, kDenseSlabRows, [&](int64_t s0, int64_t s1) {
    std::vector<T> hb(kDenseBlockRows * H), dhb(kDenseBlockRows * H);
    for (int64_t r0 = s0; r0 < s1; r0 += kDenseBlockRows) {
      const int64_t rows = std::min(kDenseBlockRows, s1 - r0);
      dense_forward_block(hb.data(), x.data() + r0 * in, L0, rows, true);
      dense_backward_block(dhb.data(), &G1, r0, (T*)nullptr, gy.data() + r0 * out,
                           (const T*)nullptr, hb.data(), L1, rows);
      dense_backward_block(dx2.data() + r0 * in, &G0, r0, dhb.data(), dhb.data(), hb.data(),
                           x.data() + r0 * in, L0, rows);
    }
  });
  dense_grads_end(dW0b.data(), db0b.data(), G0, L0);
  dense_grads_end(dW1b.data(), db1b.data(), G1, L1);
  set_num_threads(keep);
  CHECK(y2 == y);
  CHECK(dx2 == dx);
  CHECK(dW0b == dW0);
  CHECK(db0b == db0);
  CHECK(dW1b == dW1);
  CHECK(db1b == db1);
}

TEST_CASE("dense layers block by block equal the batch-wide calls bit for bit", "[dense][blocks]") {
  for (int threads : {1, 2})
    for (int out : {16, 3}) {
      INFO("threads " << threads << ", out " << out);
      check_block_chain<float>(32, out, threads);
      check_block_chain<float>(31, out, threads);
      check_block_chain<double>(32, out, threads);
    }
}

// `hashcc bench --dense-probe`: one row per N, in the order given, with finite positive rates
// where the layer runs the micro-kernel; nothing where it does not (Eigen's path: out = 3).
TEST_CASE("dense micro-kernel probe: a row per working set, none off the kernel", "[dense][kernel]") {
  const std::vector<int64_t> Ns = {256, 300};
  const std::vector<DenseProbeRow> rows = dense_microkernel_probe(20, 32, Ns, 1);
  if (!dense_microkernel(32)) {
    CHECK(rows.empty());
    return;
  }
  REQUIRE(rows.size() == Ns.size());
  for (size_t k = 0; k < rows.size(); ++k) {
    CHECK(rows[k].N == Ns[k]);
    for (double g : {rows[k].fwd_gflops, rows[k].dx_gflops, rows[k].dw_gflops}) {
      CHECK(std::isfinite(g));
      CHECK(g > 0);
    }
  }
  CHECK(dense_microkernel_probe(20, 3, Ns, 1).empty());
}

// Hidden throughput probe (never a timed assertion): `hashcc_tests "[.bench]"` prints GFLOP/s of
// (tagged only [.bench], so that "[dense]" does not select it)
// dense_forward + dense_backward for the paper's 131072 × 128 → 128 float layer.
TEST_CASE("dense GEMM throughput", "[.bench]") {
  const int64_t N = 131072;
  const int in = 128, out = 128;
  AlignedVec<float> x(N * in), y(N * out), dy(N * out), dx(N * in), W(out * in), b(out),
      dW(out * in, 0.f), db(out, 0.f);
  Rng rng(1);
  for (auto* v : {&x, &dy, &W, &b})
    for (auto& e : *v) e = rng.uniformf() - 0.5f;
  auto now = [] { return std::chrono::steady_clock::now(); };
  auto sec = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
  const double flop = 2.0 * N * in * out;  // one GEMM
  double best_f = 1e9, best_b = 1e9, best_rf = 1e9, best_rb = 1e9;
  for (int it = 0; it < 10; ++it) {
    auto t0 = now();
    dense_forward(y.data(), x.data(), W.data(), b.data(), N, in, out);
    auto t1 = now();
    dense_backward(dx.data(), dW.data(), db.data(), dy.data(), x.data(), W.data(), N, in, out);
    auto t2 = now();
    dense_relu_forward(y.data(), x.data(), W.data(), b.data(), N, in, out);
    auto t3 = now();
    AlignedVec<float>& dpre = dy;  // in place, as in training
    dense_relu_backward(dx.data(), dW.data(), db.data(), dpre.data(), dy.data(), y.data(),
                        x.data(), W.data(), N, in, out);
    auto t4 = now();
    best_f = std::min(best_f, sec(t0, t1));
    best_b = std::min(best_b, sec(t1, t2));
    best_rf = std::min(best_rf, sec(t2, t3));
    best_rb = std::min(best_rb, sec(t3, t4));
  }
  std::printf("threads %d: dense fwd %.1f GFLOP/s (%.1f ms), bwd %.1f GFLOP/s (%.1f ms), "
              "fwd+bwd %.1f GFLOP/s; dense_relu fwd %.1f, bwd %.1f, fwd+bwd %.1f GFLOP/s\n",
              num_threads(), flop / best_f * 1e-9, best_f * 1e3, 2 * flop / best_b * 1e-9,
              best_b * 1e3, 3 * flop / (best_f + best_b) * 1e-9, flop / best_rf * 1e-9,
              2 * flop / best_rb * 1e-9, 3 * flop / (best_rf + best_rb) * 1e-9);
  SUCCEED();
}
