// Tests of the grid field (model/grid_field.h, docs/math/grid_field.md): the smooth
// straight-through position gradient of the hash grid, the level curriculum, the density
// activation's clamp, and the field inside the whole step. The field's exact gradients (table,
// MLPs, d_x, d_dir, the camera through it, the CC detach on top of it) are checked by the
// [model][grad] cases of test_model.cpp, which run every variant on both fields.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/parallel.h"
#include "kernels/hash_grid.h"
#include "model/grid_field.h"
#include "model/layers.h"
#include "model/step.h"
#include "train/plan.h"
#include "train/trainer.h"
#include "test/fixtures.h"
#include "test/gradcheck.h"
#include "test/tolerance_table.h"

using namespace hashcc;
using hashcc::test::dot;
using hashcc::test::random_vec;
using hashcc::test::rel_err;
using hashcc::test::worst_grad_error;

namespace {

// 5 levels, base 4, max 32, 2^12 entries: levels 0–2 dense, 3–4 hashed (as test_hash_grid.cpp).
HashGridConfig smooth_config() {
  HashGridConfig c;
  c.levels = 5; c.log2_table = 12; c.base_res = 4; c.max_res = 32; c.smooth_dx = true;
  return c;
}

// The function whose exact gradient the smooth straight-through estimator returns, written
// from the formula (docs/math/grid_field.md), not from the kernel:
//   h̃_l(x) = Σ_k w̃_k θ_{l,e_k},  w̃_k = Π_d (k_d ? δ(f_d) : 1 − δ(f_d)),  δ(f) = (1 − cos πf)/2.
// It is C¹ across cell faces (δ(0) = 0, δ(1) = 1, δ'(0) = δ'(1) = 0), so central differences
// of it need no care about faces.
std::vector<double> smooth_interpolant(const std::vector<double>& x, const std::vector<double>& table,
                                       int64_t N, const HashGridConfig& cfg) {
  const int L = cfg.levels, F = cfg.features;
  const int64_t TS = cfg.table_size();
  std::vector<double> out(N * L * F, 0.0);
  for (int64_t n = 0; n < N; ++n)
    for (int l = 0; l < L; ++l) {
      const HashGridLevel lv = hashgrid_level(cfg, l);
      double fr[3], dl[3];
      uint32_t c[3];
      for (int d = 0; d < 3; ++d) {
        const double p = lv.scale * std::clamp(x[n * 3 + d], 0.0, 1.0) + 0.5;
        c[d] = uint32_t(std::floor(p));
        fr[d] = p - std::floor(p);
        dl[d] = (1 - std::cos(M_PI * fr[d])) / 2;
      }
      for (int k = 0; k < 8; ++k) {
        const int b[3] = {k & 1, (k >> 1) & 1, k >> 2};
        const double w = (b[0] ? dl[0] : 1 - dl[0]) * (b[1] ? dl[1] : 1 - dl[1]) * (b[2] ? dl[2] : 1 - dl[2]);
        const uint32_t e = hashgrid_vertex_index(c[0] + b[0], c[1] + b[1], c[2] + b[2], lv, TS);
        for (int f = 0; f < F; ++f) out[(n * L + l) * F + f] += w * table[(int64_t(l) * TS + e) * F + f];
      }
    }
  return out;
}

double max_abs_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double m = 0;
  for (size_t i = 0; i < a.size(); ++i) hashcc::test::keep_worst(m, std::abs(a[i] - b[i]));
  return m;
}

}  // namespace

TEST_CASE("smooth position gradient = central differences of the smooth-weight interpolant",
          "[gridfield][hashgrid][grad]") {
  // Tolerance 1e-6: the interpolant is a smooth function of x everywhere inside [0,1] (C¹ at
  // faces, analytic inside cells) whose third derivative grows like (π·scale)³; h = 1e-4/scale
  // keeps the O(h²) truncation ~1e-8 relative at every level (scale 31 and 511 here).
  const double tol = 1e-6;
  for (HashGridConfig cfg : {smooth_config(), HashGridConfig{16, 2, 9, 16, 512, true}}) {
    const int64_t N = 20;
    Rng rng(7, 1);
    auto x = random_vec(N * 3, rng, 0.02, 0.98);  // inside the clamp; faces are fine here
    auto table = random_vec(cfg.param_count(), rng, -1, 1);
    auto g = random_vec(N * cfg.out_dim(), rng, -1, 1);
    std::vector<double> d_table(cfg.param_count(), 0.0), d_x(N * 3, -7.0), d_x_naive(N * 3);
    std::vector<double> d_table_naive(cfg.param_count(), 0.0);
    HashGridWorkspace<double> ws;
    hashgrid_backward(d_table.data(), d_x.data(), g.data(), x.data(), table.data(), N, cfg, ws);
    hashgrid_backward_naive(d_table_naive.data(), d_x_naive.data(), g.data(), x.data(),
                            table.data(), N, cfg);
    auto loss = [&] { return dot(g, smooth_interpolant(x, table, N, cfg)); };
    double max_scale = 0;
    for (const HashGridLevel& lv : hashgrid_levels(cfg)) max_scale = std::max(max_scale, lv.scale);
    const double worst = worst_grad_error(x, d_x, loss, 1e-4 / max_scale);
    double mag = 0;
    for (double v : d_x) mag = std::max(mag, std::abs(v));
    INFO("levels " << cfg.levels << ": worst rel err " << worst << ", max |d_x| " << mag);
    CHECK(mag > 1.0);
    CHECK(worst < tol);
    CHECK(max_abs_diff(d_x, d_x_naive) < 1e-12 * mag);  // the reference kernel agrees
  }
}

TEST_CASE("smooth position gradient: forward and table gradient unchanged, d_x differs",
          "[gridfield][hashgrid]") {
  HashGridConfig exact = smooth_config(), smooth = smooth_config();
  exact.smooth_dx = false;
  const int64_t N = 3000;  // > 2·1024: the parallel scatter runs at 2 threads
  Rng rng(3, 3);
  auto x = random_vec(N * 3, rng, -0.1, 1.1);
  auto table = random_vec(exact.param_count(), rng, -1, 1);
  auto g = random_vec(N * exact.out_dim(), rng, -1, 1);
  std::vector<double> te(exact.param_count(), 0.0), ts = te, xe(N * 3), xs(N * 3);
  HashGridWorkspace<double> ws;
  hashgrid_backward(te.data(), xe.data(), g.data(), x.data(), table.data(), N, exact, ws);
  hashgrid_backward(ts.data(), xs.data(), g.data(), x.data(), table.data(), N, smooth, ws);
  CHECK(te == ts);                     // the table gradient uses the forward's weights
  CHECK(max_abs_diff(xe, xs) > 1e-2);  // the position gradient does not
  for (int64_t i = 0; i < N * 3; ++i)  // both are zero where the clamp acts
    if (x[i] < 0 || x[i] > 1) { CHECK(xe[i] == 0); CHECK(xs[i] == 0); }
}

TEST_CASE("smooth position gradient is continuous across a cell face; the exact one jumps",
          "[gridfield][hashgrid][hard]") {
  // One dense level of integer scale 8: faces where p = 8x + 0.5 is an integer, x = (k − ½)/8.
  HashGridConfig cfg{1, 2, 12, 9, 9, true};
  Rng rng(9, 9);
  auto table = random_vec(cfg.param_count(), rng, -1, 1);
  std::vector<double> g = {0.7, -1.3};
  auto dx_at = [&](double xv, bool smooth) {
    HashGridConfig c = cfg;
    c.smooth_dx = smooth;
    std::vector<double> x = {xv, 0.37, 0.61}, d_t(c.param_count(), 0.0), d_x(3);
    HashGridWorkspace<double> ws;
    hashgrid_backward(d_t.data(), d_x.data(), g.data(), x.data(), table.data(), 1, c, ws);
    return d_x;
  };
  const double face = 3.5 / 8, eps = 1e-9;
  for (bool smooth : {true, false}) {
    auto lo = dx_at(face - eps, smooth), at = dx_at(face, smooth), hi = dx_at(face + eps, smooth);
    for (double v : at) CHECK(std::isfinite(v));
    INFO((smooth ? "smooth" : "exact") << ": d_x below " << lo[0] << ", at " << at[0]
                                       << ", above " << hi[0]);
    if (smooth) {
      // δ'(0) = δ'(1) = 0: the gradient along the crossing axis fades to 0 from both sides,
      // and the other two components agree on both sides (the interpolant is C¹ there).
      CHECK(std::abs(lo[0]) < 1e-6);
      CHECK(std::abs(hi[0]) < 1e-6);
      CHECK(std::abs(lo[1] - hi[1]) < 1e-6);
      CHECK(std::abs(lo[2] - hi[2]) < 1e-6);
    } else {
      CHECK(std::abs(lo[0] - hi[0]) > 1e-2);  // the trilinear slope changes cell by cell
    }
  }
  // A cell corner (every axis on a face) and a point exactly on a vertex: finite, and zero.
  HashGridConfig c = cfg;
  std::vector<double> x = {face, 1.5 / 8, 6.5 / 8}, d_t(c.param_count(), 0.0), d_x(3, 5.0);
  HashGridWorkspace<double> ws;
  hashgrid_backward(d_t.data(), d_x.data(), g.data(), x.data(), table.data(), 1, c, ws);
  for (double v : d_x) CHECK(std::abs(v) < 1e-9);
}

TEST_CASE("smooth position gradient: float kernel (polynomial δ) agrees with double (libm)",
          "[gridfield][hashgrid][float]") {
  HashGridConfig cfg = smooth_config();
  const int64_t N = 500;
  Rng rng(4, 4);
  auto x = random_vec(N * 3, rng, 0, 1);
  auto table = random_vec(cfg.param_count(), rng, -1, 1);
  auto g = random_vec(N * cfg.out_dim(), rng, -1, 1);
  std::vector<double> dtd(cfg.param_count(), 0.0), dxd(N * 3);
  std::vector<float> xf(x.begin(), x.end()), tf(table.begin(), table.end()), gf(g.begin(), g.end());
  std::vector<float> dtf(cfg.param_count(), 0.f), dxf(N * 3);
  HashGridWorkspace<double> wsd;
  HashGridWorkspace<float> wsf;
  hashgrid_backward(dtd.data(), dxd.data(), g.data(), x.data(), table.data(), N, cfg, wsd);
  hashgrid_backward(dtf.data(), dxf.data(), gf.data(), xf.data(), tf.data(), N, cfg, wsf);
  double num = 0, den = 0;
  for (int64_t i = 0; i < N * 3; ++i) {
    hashcc::test::keep_worst(num, std::abs(double(dxf[i]) - dxd[i]));
    den = std::max(den, std::abs(dxd[i]));
  }
  INFO("float vs double d_x: max abs diff " << num << " of max " << den);
  CHECK(num < 1e-4 * den);  // float rounding of a sum of 5 levels × 8 corners, ×scale 31
}

TEST_CASE("grid field: level curriculum switches whole levels off, values and gradients",
          "[gridfield][model]") {
  ModelConfig cfg = tiny_model_config(Variant::sh, Field::grid);
  cfg.pos_c2f_alpha = 2;  // levels 0 and 1 fully on, 2 and 3 off
  ModelLayout L = make_layout(cfg);
  Rng rng(2, 2);
  std::vector<double> p(L.count);
  init_params(p.data(), cfg, L, rng);
  for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) p[L.grid_table + i] = rng.uniform(-0.5, 0.5);
  const int R = 4, S = 8;
  std::vector<double> x = random_vec(R * S * 3, rng, -0.9, 0.9), dir;
  for (int r = 0; r < R; ++r) dir.insert(dir.end(), {0.6, 0.0, 0.8});
  auto run = [&](std::vector<double>& params, std::vector<double>* grad) {
    ModelCache<double> c;
    c.reserve(cfg, R, S);
    const NetView<double> net{params.data(), cfg, L};
    const ModelIn<double> in{x.data(), dir.data(), x.data(), R, S};
    model_forward(c, net, in);
    std::vector<double> out(c.sigma_raw.begin(), c.sigma_raw.begin() + R * S);
    out.insert(out.end(), c.color.begin(), c.color.begin() + R * S * 3);
    if (grad) {
      std::vector<double> ds(R * S, 1.0), dc(R * S * 3, 0.5), dx(R * S * 3), dd(R * 3);
      model_backward<double>({grad->data(), dx.data(), dd.data()}, {ds.data(), dc.data(), nullptr},
                             c, net, in);
    }
    return out;
  };
  std::vector<double> grad(L.count, 0.0);
  const auto base = run(p, &grad);
  const int64_t per_level = cfg.gf.grid.table_size() * cfg.gf.grid.features;
  // Levels 2, 3: outputs do not depend on them, and they get no gradient.
  std::vector<double> q = p;
  for (int64_t i = 2 * per_level; i < 4 * per_level; ++i) q[L.grid_table + i] += 0.3;
  CHECK(run(q, nullptr) == base);
  double off = 0, on = 0;
  for (int64_t i = 0; i < 4 * per_level; ++i)
    (i < 2 * per_level ? on : off) += std::abs(grad[L.grid_table + i]);
  CHECK(off == 0);
  CHECK(on > 0);
  // α = 2.5: level 2 at weight (1 − cos(π/2))/2 = 1/2 — the same weights as the Fourier c2f.
  double w[4];
  c2f_band_weights(w, 4, 2.5);
  CHECK(w[0] == 1);
  CHECK(w[1] == 1);
  CHECK(w[2] == Approx(0.5).epsilon(1e-15));
  CHECK(w[3] == 0);
}

TEST_CASE("grid field: density clamp, points outside the grid, faces and corners stay finite",
          "[gridfield][model][hard]") {
  ModelConfig cfg = tiny_model_config(Variant::hashcc, Field::grid);
  cfg.gf.grid.smooth_dx = true;
  ModelLayout L = make_layout(cfg);
  Rng rng(6, 6);
  std::vector<double> p(L.count);
  init_params(p.data(), cfg, L, rng);
  const int R = 3, S = 4;
  // Samples on cell faces and corners of every level (x = 0 is u = ½, on a face of every level
  // with an odd scale; scale 3 has faces at u = (k − ½)/3), far outside [−1, 1], and at ±1.
  std::vector<double> x = {0, 0, 0,   -1, -1, -1,   1, 1, 1,   0, 1.0 / 3, -1.0 / 3,
                           5, -7, 0.2,   1e6, -1e6, 3,   0.25, 0.5, 0.75,   -0.5, 0, 0.5,
                           2.0 / 3, 0, -2.0 / 3,   0.1, 0.2, 0.3,   -1.5, 0, 0,   0, 0, 1.5};
  std::vector<double> dir = {0, 0, 1, 0.6, 0, 0.8, 0, -0.6, 0.8};
  // z far above the clamp: the density bias of the last density layer.
  p[L.gd1.b] = 40;
  ModelCache<double> c;
  c.reserve(cfg, R, S);
  const NetView<double> net{p.data(), cfg, L};
  const ModelIn<double> in{x.data(), dir.data(), x.data(), R, S};
  model_forward(c, net, in);
  for (int64_t n = 0; n < R * S; ++n) {
    CHECK(std::isfinite(c.sigma_raw[n]));
    CHECK(c.sigma_raw[n] <= std::exp(kGridMaxLogDensity) * (1 + 1e-12));
  }
  std::vector<double> grad(L.count, 0.0), ds(R * S, 1.0), dc(R * S * 3, 0.5), dcc(R * S * 3, 0.25);
  std::vector<double> dx(R * S * 3, 9.0), dd(R * 3, 9.0);
  model_backward<double>({grad.data(), dx.data(), dd.data()}, {ds.data(), dc.data(), dcc.data()},
                         c, net, in);
  for (double v : grad) REQUIRE(std::isfinite(v));
  for (double v : dx) REQUIRE(std::isfinite(v));
  for (double v : dd) REQUIRE(std::isfinite(v));
  CHECK(grad[L.gd1.b] == 0);  // above the clamp: σ no longer depends on z
  // Outside the grid the position gradient is 0 (the clamp acts): samples 4 and 5 on every
  // axis that is out, and sample 10's x, sample 11's z.
  for (int d = 0; d < 3; ++d) CHECK(dx[5 * 3 + d] == 0);
  CHECK(dx[4 * 3 + 0] == 0);
  CHECK(dx[4 * 3 + 1] == 0);
  CHECK(dx[10 * 3 + 0] == 0);
  CHECK(dx[11 * 3 + 2] == 0);
}

TEST_CASE("grid field: a forward that keeps the position Jacobian gives the same outputs and "
          "parameter gradient bitwise, and d_x, d_dir within rounding (ModelIn::keep_jac)",
          "[gridfield][model][hard]") {
  ModelConfig cfg = tiny_model_config(Variant::hashcc, Field::grid);
  cfg.gf.grid.smooth_dx = GENERATE(false, true);
  ModelLayout L = make_layout(cfg);
  Rng rng(12, 12);
  std::vector<double> p(L.count);
  init_params(p.data(), cfg, L, rng);
  for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) p[L.grid_table + i] = rng.uniform(-0.5, 0.5);
  const int R = 40, S = 60;  // 2,400 points: the kernels' parallel path, several blocks
  auto x = random_vec(int64_t(R) * S * 3, rng, -1.1, 1.1);  // some outside the grid
  std::vector<double> dir;
  for (int r = 0; r < R; ++r) dir.insert(dir.end(), {0.0, 0.6, 0.8});
  auto ds = random_vec(int64_t(R) * S, rng, -1, 1), dc = random_vec(int64_t(R) * S * 3, rng, -1, 1),
       dcc = random_vec(int64_t(R) * S * 3, rng, -1, 1);
  const NetView<double> net{p.data(), cfg, L};
  struct Out { std::vector<double> sigma, color, grad, dx, dd; };
  auto run = [&](bool keep) {
    ModelCache<double> c;
    c.reserve(cfg, R, S);
    ModelIn<double> in{x.data(), dir.data(), x.data(), R, S};
    in.keep_jac = keep;
    model_forward(c, net, in);
    Out o{std::vector<double>(c.sigma_raw.begin(), c.sigma_raw.begin() + R * S),
          std::vector<double>(c.color.begin(), c.color.begin() + R * S * 3),
          std::vector<double>(L.count, 0.0), std::vector<double>(R * S * 3, 9.0),
          std::vector<double>(R * 3, 9.0)};
    model_backward<double>({o.grad.data(), o.dx.data(), o.dd.data()}, {ds.data(), dc.data(), dcc.data()},
                           c, net, in);
    CHECK(c.gjac_valid == keep);
    return o;
  };
  const Out a = run(false), b = run(true);
  CHECK(b.sigma == a.sigma);
  CHECK(b.color == a.color);
  CHECK(b.grad == a.grad);
  CHECK(b.dd == a.dd);
  double num = 0, den = 0;
  int zeros = 0;
  for (size_t i = 0; i < a.dx.size(); ++i) {
    num = std::max(num, std::abs(b.dx[i] - a.dx[i]));
    den = std::max(den, std::abs(a.dx[i]));
    zeros += a.dx[i] == 0;
    if (a.dx[i] == 0) CHECK(b.dx[i] == 0);  // the clamp's zeros stay exact
  }
  INFO("d_x: max abs diff " << num << " of max " << den << ", " << zeros << " clamped");
  CHECK(den > 0);
  CHECK(zeros > 100);
  CHECK(num <= 1e-12 * den);
}

// model/grid_field.cpp and model/model.cpp run the grid field's two MLPs and the CC branch's a
// block of 256 points at a time, the hidden layers in per-thread scratch that the backward
// recomputes (ModelCache::keep_mlp and keep_cc_mlp off, float's default); kept (on), the backward
// reads them back. Kept or not, the outputs, the
// parameter gradient and the camera's d_x / d_dir are the same BIT FOR BIT; and the kept
// activations are those of the batch-wide layers (layers::dense_relu on the encoding), bit for
// bit. 9,200 points: two 4,096-row slabs and a ragged block; 1 and 2 threads.
TEST_CASE("grid field: MLP activations kept or recomputed block by block give the same step "
          "bitwise (ModelCache::keep_mlp)", "[gridfield][model][blocks]") {
  ModelConfig cfg = tiny_model_config(Variant::hashcc, Field::grid);
  ModelLayout L = make_layout(cfg);
  Rng rng(14, 14);
  std::vector<double> pd(L.count);
  init_params(pd.data(), cfg, L, rng);
  for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) pd[L.grid_table + i] = rng.uniform(-0.5, 0.5);
  const std::vector<float> p(pd.begin(), pd.end());
  const int R = 40, S = 230;
  const int64_t N = int64_t(R) * S;
  auto fvec = [&](int64_t n, double lo, double hi) {
    std::vector<float> v(n);
    for (auto& e : v) e = float(rng.uniform(lo, hi));
    return v;
  };
  const std::vector<float> x = fvec(N * 3, -1.1, 1.1), ds = fvec(N, -1, 1), dc = fvec(N * 3, -1, 1),
                           dcc = fvec(N * 3, -1, 1), dsx = fvec(N, -1, 1);
  std::vector<float> dir;
  for (int r = 0; r < R; ++r) dir.insert(dir.end(), {0.f, 0.6f, 0.8f});
  const NetView<float> net{p.data(), cfg, L};
  struct Out { std::vector<float> sigma, color, dcolor, grad, dx, dd, gdh, hid; };
  auto run = [&](bool keep, int threads) {
    const int keep_threads = num_threads();
    set_num_threads(threads);
    ModelCache<float> c;
    c.reserve(cfg, R, S);
    c.keep_mlp = c.keep_cc_mlp = keep;
    ModelIn<float> in{x.data(), dir.data(), x.data(), R, S};
    in.keep_jac = true;
    model_forward(c, net, in);
    Out o{std::vector<float>(c.sigma_raw.begin(), c.sigma_raw.begin() + N),
          std::vector<float>(c.color.begin(), c.color.begin() + N * 3),
          std::vector<float>(c.dcolor.begin(), c.dcolor.begin() + N * 3),
          std::vector<float>(L.count, 0.f), std::vector<float>(N * 3, 9.f),
          std::vector<float>(R * 3, 9.f), {}, {}};
    if (keep) {  // the kept activations against the batch-wide layers
      std::vector<float> h(N * cfg.gf.hidden);
      layers::dense_relu(h.data(), c.genc.data(), p.data(), L.gd0, N);
      CHECK(std::equal(h.begin(), h.end(), c.gdh.begin()));
      o.gdh = h;
    }
    model_backward<float>({o.grad.data(), o.dx.data(), o.dd.data()},
                          {ds.data(), dc.data(), dcc.data(), dsx.data()}, c, net, in);
    set_num_threads(keep_threads);
    return o;
  };
  // (At 2 threads the hash table's scatter rounds differently from 1 thread, by design: compare
  // at equal thread counts.)
  const Out a = run(false, 1), b = run(true, 1), a2 = run(false, 2), b2 = run(true, 2);
  for (const auto& [o, ref] : {std::pair{&b, &a}, std::pair{&b2, &a2}}) {
    CHECK(o->sigma == ref->sigma);
    CHECK(o->color == ref->color);
    CHECK(o->dcolor == ref->dcolor);
    CHECK(o->grad == ref->grad);
    CHECK(o->dx == ref->dx);
    CHECK(o->dd == ref->dd);
  }
  CHECK(a2.sigma == a.sigma);  // the forward has no reduction: the same at any thread count
  CHECK(a2.color == a.color);
  // Not vacuous: every MLP and the CC branch received a gradient, and the camera a d_x.
  for (const LayerView* lv : {&L.gd0, &L.gd1, &L.gr0, &L.gr1, &L.cc0, &L.cc1})
    CHECK(std::any_of(a.grad.begin() + lv->w, a.grad.begin() + lv->b, [](float v) { return v != 0; }));
  CHECK(std::any_of(a.dx.begin(), a.dx.end(), [](float v) { return v != 0 && v != 9.f; }));
}

TEST_CASE("grid field step: float agrees with double, 1 thread equals 2", "[gridfield][model][float]") {
  ModelConfig cfg = tiny_model_config(Variant::hashcc, Field::grid);
  cfg.gf.grid.smooth_dx = true;
  // F = 2 (the shipped grids) takes the kernels' compile-time path; --grid-features 4 and a
  // wider --grid-hidden / --grid-rgb-hidden the general one.
  const int F = GENERATE(2, 4);
  cfg.gf.grid.features = F;
  if (F != 2) cfg.gf.hidden = cfg.gf.rgb_hidden = 12;
  INFO("features " << F);
  ModelLayout L = make_layout(cfg);
  Rng rng(8, 8);
  std::vector<double> p(L.count);
  init_params(p.data(), cfg, L, rng);
  for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) p[L.grid_table + i] = rng.uniform(-0.5, 0.5);
  const int R = 64, S = 16;
  std::vector<double> o, d, s, target;
  for (int i = 0; i < R; ++i) {
    o.insert(o.end(), {rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), -1.0});
    d.insert(d.end(), {rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), 2.0});
    for (int k = 0; k < S; ++k) s.push_back((k + rng.uniform(0.1, 0.9)) / S);
    target.insert(target.end(), {rng.uniform(), rng.uniform(), rng.uniform()});
  }
  auto step = [&](auto zero, int threads, std::vector<double>* grads) {
    using T = decltype(zero);
    const int keep = num_threads();
    set_num_threads(threads);
    std::vector<T> pt(p.begin(), p.end()), ot(o.begin(), o.end()), dt(d.begin(), d.end());
    std::vector<T> st(s.begin(), s.end()), tt(target.begin(), target.end());
    std::vector<T> g(L.count, T(0)), d_o(3 * R), d_d(3 * R);
    StepWorkspace<T> ws;
    StepOptions opt;
    opt.chunk_rays = 16;
    RayBatch<T> batch;
    batch.o = ot.data();
    batch.d = dt.data();
    batch.s = st.data();
    batch.target = tt.data();
    batch.R = R;
    batch.S = S;
    auto res = ray_batch_step(ws, NetView<T>{pt.data(), cfg, L}, batch, opt,
                              RayGrads<T>{g.data(), d_o.data(), d_d.data()});
    set_num_threads(keep);
    grads->assign(g.begin(), g.end());
    grads->insert(grads->end(), d_o.begin(), d_o.end());
    grads->insert(grads->end(), d_d.begin(), d_d.end());
    return res.loss;
  };
  std::vector<double> gd, gf1, gf2;
  const double ld = step(0.0, 1, &gd), lf1 = step(0.f, 1, &gf1), lf2 = step(0.f, 2, &gf2);
  CHECK(rel_err(lf1, ld) < 1e-5);
  CHECK(rel_err(lf2, lf1) < 1e-6);
  double num = 0, den = 0, num2 = 0;
  for (size_t i = 0; i < gd.size(); ++i) {
    hashcc::test::keep_worst(num, std::abs(gf1[i] - gd[i]));
    hashcc::test::keep_worst(num2, std::abs(gf2[i] - gf1[i]));
    den = std::max(den, std::abs(gd[i]));
  }
  INFO("float vs double: " << num << ", 1 vs 2 threads: " << num2 << ", of max " << den);
  CHECK(den > 0);
  CHECK(num < 1e-4 * den);
  CHECK(num2 < 1e-5 * den);
}

TEST_CASE("bootstrap: the grid field's cameras start the paper's network; --cameras-from checks the scene",
          "[gridfield][trainer]") {
  const std::string data = test::sim_scene("boot", 6, 48, 36);
  const std::string out = (std::filesystem::temp_directory_path() / "hashcc_bootstrap_run").string();
  std::filesystem::remove_all(out);
  TrainConfig c = test::tiny_train_config(data, out, 3);
  c.bootstrap_steps = 5;
  std::vector<std::string> given_flags;
  const auto given = [&](const std::string& f) {
    return std::find(given_flags.begin(), given_flags.end(), f) != given_flags.end();
  };
  REQUIRE(bootstrap_cameras(c, nullptr, given));
  // Phase 1 ran the grid field with its defaults into RUN/bootstrap and finished.
  const Trainer boot = Trainer::resume(out + "/bootstrap");
  CHECK(boot.config().model.field == Field::grid);
  CHECK(boot.state().step == 5);
  CHECK(c.cameras_from == out + "/bootstrap");
  CHECK(c.lr_pose == Approx(1e-4));   // the bootstrap's end rate, as no --lr-pose was given
  CHECK(boot.config().lr_pose == Approx(1e-3));  // phase 1's camera rate: the grid field's
  CHECK(c.lr_focal == Approx(1e-4));
  // Phase 2 starts exactly at the cameras phase 1 ended with, on the MLP field.
  Trainer t(c);
  CHECK(t.config().model.field == Field::mlp);
  CHECK(t.state().poses == boot.state().poses);
  CHECK(t.state().focal == boot.state().focal);
  bool moved = false;
  for (float v : t.state().poses) moved = moved || v != 0.f;
  CHECK(moved);
  REQUIRE(t.run());
  // An explicit --lr-pose wins over the bootstrap's end rate.
  TrainConfig c2 = test::tiny_train_config(data, out + "_2", 3);
  c2.bootstrap_steps = 2;
  c2.lr_pose = 5e-4;
  given_flags = {"--lr-pose"};
  REQUIRE(bootstrap_cameras(c2, nullptr, given));
  CHECK(c2.lr_pose == Approx(5e-4));
  // Phase 1 takes the command's camera flags (a focal given and held, the preconditioner) and
  // its grid-field flags; the flags shared with the MLP (--lr-net, --samples) keep the grid's.
  TrainConfig c3 = test::tiny_train_config(data, out + "_5", 3);
  c3.bootstrap_steps = 2;
  c3.focal_fx = 50;
  c3.focal_fy = 40;
  c3.fixed_focal = true;
  c3.pose_precondition = 0.1;
  c3.model.gf.density_init = 1.5;
  c3.model.gf.c2f_start = 1;
  c3.lr_net = 3e-4;
  c3.lr_pose = 7e-4;
  c3.bootstrap_lr_pose = 3e-3;
  given_flags = {"--focal", "--fixed-focal", "--pose-precondition", "--grid-density-init",
                 "--grid-c2f-start", "--lr-net", "--lr-pose", "--bootstrap-lr-pose"};
  REQUIRE(bootstrap_cameras(c3, nullptr, given));
  const Trainer boot3 = Trainer::resume(out + "_5/bootstrap");
  const TrainConfig& b3 = boot3.config();
  CHECK(b3.focal_fx == 50);
  CHECK(b3.focal_fy == 40);
  CHECK(b3.fixed_focal);
  CHECK(b3.pose_precondition == 0.1);
  CHECK(b3.model.gf.density_init == 1.5);
  CHECK(b3.model.gf.c2f_start == 1);
  CHECK(b3.lr_net == Approx(1e-2));  // the grid's rate, not the MLP's 3e-4
  CHECK(b3.lr_pose == Approx(3e-3));  // --bootstrap-lr-pose is phase 1's camera rate ...
  CHECK(c3.lr_pose == Approx(7e-4));  // ... and --lr-pose stays phase 2's
  const FocalParams<float> f3 = boot3.focal();
  const ImageSize sz3 = boot3.image_size();
  CHECK(focal_fx(f3, sz3) == Approx(50).epsilon(1e-5));  // held through phase 1's steps
  CHECK(focal_fy(f3, sz3) == Approx(40).epsilon(1e-5));
  // --refine-poses off: phase 2 holds phase 1's cameras, bitwise, while its network learns.
  TrainConfig c6 = test::tiny_train_config(data, out + "_6", 3);
  c6.bootstrap_steps = 2;
  c6.refine_poses = false;
  given_flags = {"--refine-poses"};
  REQUIRE(bootstrap_cameras(c6, nullptr, given));
  const Trainer boot6 = Trainer::resume(out + "_6/bootstrap");
  CHECK(boot6.config().refine_poses);  // phase 1 learns the cameras whatever the flag
  Trainer t6(c6);
  CHECK(t6.poses_frozen());
  CHECK(t6.focal_frozen());
  const std::vector<float> net6 = t6.state().net;
  REQUIRE(t6.run());
  CHECK(t6.state().step == 3);
  CHECK(t6.state().poses == boot6.state().poses);
  CHECK(t6.state().focal == boot6.state().focal);
  CHECK(t6.state().net != net6);
  // The thread count is this run's, not the run its cameras come from (which loading sets).
  {
    test::ThreadGuard guard;
    TrainConfig two = test::tiny_train_config(data, out + "_7", 1);
    two.threads = 2;
    REQUIRE(Trainer(two).run());
    TrainConfig one = test::tiny_train_config(data, out + "_8", 1);
    one.threads = 1;
    one.cameras_from = out + "_7";
    Trainer t8(one);
    CHECK(num_threads() == 1);
  }
  // --cameras-from a run of another scene is refused, naming the flag.
  TrainConfig other = test::tiny_train_config(test::sim_scene("boot_other", 5, 48, 36), out + "_3", 1);
  other.cameras_from = out + "/bootstrap";
  CHECK_THROWS_WITH(Trainer(other), Catch::Contains("--cameras-from"));
  // The bootstrap belongs to the MLP field: refused with --field grid.
  TrainConfig g = test::tiny_train_config(data, out + "_4", 1);
  g.model.field = Field::grid;
  g.bootstrap_steps = 1;
  CHECK_THROWS_WITH(bootstrap_cameras(g, nullptr, given), Catch::Contains("--bootstrap-minutes"));
}

// The restarts tests' run: a tiny grid-field run with the grid field's defaults, `steps` steps
// (0: the test sets a budget in minutes), on `data`, into `out`.
static TrainConfig tiny_grid_run(const std::string& data, const std::string& out, int64_t steps) {
  TrainConfig c = test::tiny_train_config(data, out, steps);
  c.model.field = Field::grid;
  for (const PresetEntry& e : field_defaults("grid")) e.set(c);
  return c;
}

TEST_CASE("restarts: each stage is a fresh grid field on the cameras the stage before learned",
          "[gridfield][trainer]") {
  const std::string data = test::sim_scene("restarts", 6, 48, 36);
  const std::string out = test::tmp("restarts_run", true);
  TrainConfig c = tiny_grid_run(data, out, 9);
  c.restarts = 2;
  REQUIRE(c.c2f_end == Approx(0.5));
  REQUIRE(grid_restarts(c, nullptr));
  // Stages 1 and 2 ran into RUN/stage1, RUN/stage2, a third of the 9 steps each; stage 1 with
  // the level curriculum, stage 2 from stage 1's end cameras with all levels on.
  const Trainer s1 = Trainer::resume(out + "/stage1");
  const Trainer s2 = Trainer::resume(out + "/stage2");
  CHECK(s1.state().step == 3);
  CHECK(s2.state().step == 3);
  CHECK(s1.config().c2f_end == Approx(0.5));
  CHECK(s2.config().c2f_end == 0);
  CHECK(s2.config().cameras_from == out + "/stage1");
  CHECK(s2.state().poses != s1.state().poses);  // stage 2 moved the cameras on
  // c is now the last stage: the same share of the budget, from stage 2's cameras, in RUN.
  CHECK(c.steps == 3);
  CHECK(c.c2f_end == 0);
  CHECK(c.cameras_from == out + "/stage2");
  Trainer t(c);
  CHECK(t.state().step == 0);  // a fresh field and schedule
  CHECK(t.state().poses == s2.state().poses);
  CHECK(t.state().focal == s2.state().focal);
  REQUIRE(t.run());
  CHECK(t.state().step == 3);
  // Only the grid field restarts, and only within a budget it can cut.
  TrainConfig m = test::tiny_train_config(data, out + "_m", 2);
  m.restarts = 1;
  CHECK_THROWS_WITH(grid_restarts(m, nullptr), Catch::Contains("--restarts"));
  TrainConfig e = c;
  e.steps = 0;
  e.minutes = 0;
  e.restarts = 1;
  CHECK_THROWS_WITH(grid_restarts(e, nullptr), Catch::Contains("--minutes or --steps"));
}

TEST_CASE("restarts with --first-focal-hold: stage 1 holds its focal for its first F, the stages "
          "after learn it from their start", "[gridfield][trainer]") {
  const std::string data = test::sim_scene("restarts_ffh", 6, 48, 36);
  const std::string out = test::tmp("restarts_ffh_run", true);
  TrainConfig c = tiny_grid_run(data, out, 12);
  c.restarts = 2;
  c.first_focal_hold = 0.5;
  validate_train_config(c);
  const std::vector<float> focal0 = Trainer(tiny_grid_run(data, "", 12)).state().focal;
  REQUIRE(grid_restarts(c, nullptr));
  const Trainer s1 = Trainer::open(out + "/stage1");
  const Trainer s2 = Trainer::open(out + "/stage2");
  REQUIRE(s1.state().step == 4);
  CHECK(s1.config().focal_delay == 0.5);
  CHECK(s1.config().first_focal_hold == 0.5);  // the command's record, as in every stage
  CHECK(s1.lr_focal_at(0) == 0);
  CHECK(s1.lr_focal_at(1) == 0);
  CHECK(s1.lr_focal_at(2) > 0);  // released at half of its 4 steps
  CHECK(s1.state().focal != focal0);  // and learned after
  CHECK(s2.config().focal_delay == 0);
  CHECK(s2.lr_focal_at(0) > 0);
  CHECK(c.focal_delay == 0);  // the last stage too
  CHECK(c.first_focal_hold == 0.5);  // the whole run's record
  // With --last-focal-hold (as in --preset fern60) the last stages hold their own focal
  // (--focal-delay in their configs) beside that record: they run, and the last stage is one.
  TrainConfig both = tiny_grid_run(data, out + "_last", 12);
  both.restarts = 2;
  both.first_focal_hold = 0.5;
  both.last_focal_hold = 0.5;
  both.last_focal_stages = 2;
  validate_train_config(both);
  REQUIRE(grid_restarts(both, nullptr));
  CHECK(Trainer::open(out + "_last/stage1").config().focal_delay == 0.5);
  CHECK(Trainer::open(out + "_last/stage2").config().fx_only);
  CHECK(Trainer::open(out + "_last/stage2").config().focal_delay == 0.5);
  CHECK(both.fx_only);
  CHECK(both.focal_delay == 0.5);
  Trainer last(both);
  REQUIRE(last.run());
  // The conflict the flag refuses is the command's own --focal-delay beside it, before any stage
  // runs (the stages' configs carry both: see validate_train_config).
  TrainConfig clash = tiny_grid_run(data, out + "_clash", 12);
  clash.restarts = 2;
  clash.first_focal_hold = 0.5;
  clash.focal_delay = 0.2;
  CHECK_THROWS_WITH(grid_restarts(clash, nullptr),
                    Catch::Contains("--first-focal-hold") && Catch::Contains("--focal-delay"));
  CHECK_FALSE(std::filesystem::exists(out + "_clash/stage1"));
}

TEST_CASE("restarts with --restart-first and --restart-last: those stages take their shares, the "
          "others split the rest", "[gridfield][trainer]") {
  const std::string data = test::sim_scene("restarts_first", 6, 48, 36);
  const std::string out = test::tmp("restarts_first_run", true);
  TrainConfig c = tiny_grid_run(data, out, 10);
  c.restarts = 2;
  c.restart_first = 0.6;  // 6 of the 10 steps, then 2 and 2
  validate_train_config(c);
  REQUIRE(grid_restarts(c, nullptr));
  CHECK(Trainer::resume(out + "/stage1").state().step == 6);
  CHECK(Trainer::resume(out + "/stage2").state().step == 2);
  CHECK(c.steps == 2);
  CHECK(c.cameras_from == out + "/stage2");
  // By minutes: the same shares of the budget.
  TrainConfig m = tiny_grid_run(data, out + "_m", 0);
  m.minutes = 1e-4;
  m.restarts = 3;
  m.restart_first = 0.4;
  const std::string mout = m.out;
  REQUIRE(grid_restarts(m, nullptr));
  CHECK(Trainer::resume(mout + "/stage1").config().minutes == Approx(0.4e-4));
  CHECK(Trainer::resume(mout + "/stage3").config().minutes == Approx(0.2e-4));
  CHECK(m.minutes == Approx(0.2e-4));
  // Both shares: a long first and last stage, short ones between (10 + 2 + 2 + 6 of 20 steps).
  TrainConfig b = tiny_grid_run(data, out + "_b", 20);
  b.restarts = 3;
  b.restart_first = 0.5;
  b.restart_last = 0.3;
  validate_train_config(b);
  const std::string bout = b.out;
  REQUIRE(grid_restarts(b, nullptr));
  CHECK(Trainer::resume(bout + "/stage1").state().step == 10);
  CHECK(Trainer::resume(bout + "/stage2").state().step == 2);
  CHECK(Trainer::resume(bout + "/stage3").state().step == 2);
  CHECK(b.steps == 6);
  // Shares that leave the stages between nothing, or do not fill a two-stage budget: refused.
  TrainConfig full = tiny_grid_run(data, out + "_f", 20);
  full.restarts = 2;
  full.restart_first = 0.6;
  full.restart_last = 0.4;
  CHECK_THROWS_WITH(validate_train_config(full), Catch::Contains("--restart-last"));
  CHECK_THROWS_WITH(grid_restarts(full, nullptr), Catch::Contains("--restart-first"));
  full.restarts = 1;
  full.restart_last = 0.3;
  CHECK_THROWS_WITH(validate_train_config(full), Catch::Contains("sum to 1"));
  full.restart_last = 0.4;
  CHECK_NOTHROW(validate_train_config(full));
}

// The plan --restarts generates (train/plan_generators.cpp): each stage's budget and override,
// as plan.json records them and as `--plan FILE` would take them.
TEST_CASE("restarts_plan: the stages --restarts means, as budgets and overrides",
          "[gridfield][trainer][plan]") {
  using K = StageBudget::Kind;
  TrainConfig w;
  w.model.field = Field::grid;
  w.minutes = 60;
  w.restarts = 4;
  w.restart_first = 0.25;
  w.restart_steps = 1200;
  w.last_focal_hold = 0.1;
  w.last_focal_stages = 2;
  w.last_grid_log2_table = 17;
  w.last_samples = 64;
  w.last_lr_net = 2e-2;
  w.last_lr_net_end = 1e-3;
  w.last_distortion = 0.01;
  validate_train_config(w);
  const TrainPlan p = restarts_plan(w);
  REQUIRE(p.stages.size() == 5);
  CHECK(p.stages[0].budget.kind == K::share);
  CHECK(p.stages[0].budget.value == 0.25);
  CHECK(p.stages[0].set.empty());
  CHECK_FALSE(p.stages[0].cameras_from_previous);
  CHECK(p.stages[2].budget.kind == K::steps);
  CHECK(p.stages[2].budget.value == 1200);
  CHECK(p.stages[2].set == nlohmann::json{{"c2f_end", 0.0}});
  CHECK(p.stages[3].set == nlohmann::json{{"c2f_end", 0.0}, {"fx_only", true}, {"focal_delay", 0.1}});
  CHECK(p.stages[4].budget.kind == K::rest);
  CHECK(p.stages[4].set == nlohmann::json{{"c2f_end", 0.0}, {"fx_only", true}, {"focal_delay", 0.1},
                                          {"grid_log2_table", 17}, {"samples", 64},
                                          {"lr_net", 2e-2}, {"lr_net_end", 1e-3},
                                          {"distortion", 0.01}});
  CHECK(p.stages[4].cameras_from_previous);
  // By steps, equal shares, one held stage, the last field as the others.
  TrainConfig s;
  s.model.field = Field::grid;
  s.steps = 300;
  s.restarts = 2;
  s.last_focal_hold = 0.2;
  validate_train_config(s);
  const TrainPlan q = restarts_plan(s);
  REQUIRE(q.stages.size() == 3);
  CHECK(q.stages[1].budget.kind == K::steps);
  CHECK(q.stages[1].budget.value == 100);
  CHECK(q.stages[2].set == nlohmann::json{{"c2f_end", 0.0}, {"fx_only", true}, {"focal_delay", 0.2}});
}

TEST_CASE("restarts with --restart-steps: the stages between run N steps, the last stage what is "
          "left", "[gridfield][trainer]") {
  const std::string data = test::sim_scene("restarts_steps", 6, 48, 36);
  const std::string out = test::tmp("restarts_steps_run", true);
  // By steps: 20 = stage 1's half (10) + 2 stages between of 3 steps + the 4 left.
  TrainConfig c = tiny_grid_run(data, out, 20);
  c.restarts = 3;
  c.restart_first = 0.5;
  c.restart_steps = 3;
  c.last_focal_hold = 0.5;  // and the last stage: one focal, held for its first 2 of 4 steps
  validate_train_config(c);
  REQUIRE(grid_restarts(c, nullptr));
  const Trainer s3 = Trainer::resume(out + "/stage3");
  CHECK(Trainer::resume(out + "/stage1").state().step == 10);
  CHECK(Trainer::resume(out + "/stage2").state().step == 3);
  CHECK(s3.state().step == 3);
  CHECK(c.steps == 4);
  CHECK(c.cameras_from == out + "/stage3");
  CHECK_FALSE(s3.config().fx_only);  // the stages before learn both focals
  CHECK(c.fx_only);
  CHECK(c.focal_delay == 0.5);
  Trainer last(c);
  const ImageSize sz = last.image_size();
  const double fx0 = focal_fx(s3.focal(), sz);
  CHECK(focal_fx(last.focal(), sz) == Approx(fx0));  // fy starts at the fx learned so far
  CHECK(focal_fy(last.focal(), sz) == Approx(fx0));
  REQUIRE(last.run());
  CHECK(focal_fy(last.focal(), sz) == focal_fx(last.focal(), sz));
  // --last-focal-stages 2: the last stage between learns one focal held for its first half too,
  // started at the fx of the stage before it; the stages before it learn both.
  TrainConfig two = tiny_grid_run(data, out + "_2", 20);
  two.restarts = 3;
  two.restart_first = 0.5;
  two.restart_steps = 3;
  two.last_focal_hold = 0.5;
  two.last_focal_stages = 2;
  validate_train_config(two);
  REQUIRE(grid_restarts(two, nullptr));
  const Trainer t2 = Trainer::resume(out + "_2/stage2");
  const Trainer t3 = Trainer::resume(out + "_2/stage3");
  CHECK_FALSE(t2.config().fx_only);
  CHECK(t3.config().fx_only);
  CHECK(t3.config().focal_delay == 0.5);
  CHECK(t3.state().step == 3);
  CHECK(focal_fy(t3.focal(), sz) == focal_fx(t3.focal(), sz));  // tied through its steps
  CHECK(focal_fx(t2.focal(), sz) != focal_fy(t2.focal(), sz));  // the stage before: two focals
  CHECK(two.fx_only);
  CHECK(two.focal_delay == 0.5);
  // A run that learns both focals from a one-focal run's cameras (the bootstrap's phase 2, a
  // stage chained by hand) starts at the focal that run rendered with: fy = its fx, not its own
  // fy parameter, which --fx-only leaves where stage 2 put it (bug found on fern: fy 377 -> 280).
  TrainConfig after = tiny_grid_run(data, out + "_after", 2);
  after.cameras_from = out + "_2/stage3";
  const Trainer a(after);
  CHECK(focal_fy(a.focal(), sz) == Approx(focal_fx(t3.focal(), sz)).epsilon(1e-6));
  CHECK(focal_fx(a.focal(), sz) == Approx(focal_fx(t3.focal(), sz)).epsilon(1e-6));
  // --last-grid-log2-table, --last-samples: only the last stage's field is sized up; the
  // stages that learn the cameras keep the cheap one.
  TrainConfig big = tiny_grid_run(data, out + "_big", 12);
  big.restarts = 2;
  big.last_grid_log2_table = big.model.gf.grid.log2_table + 2;
  big.last_samples = big.samples * 2;
  const double lr0 = big.lr_net, lr_end0 = big.lr_net_end;
  big.last_lr_net = lr0 * 2;  // --last-lr-net(-end): the last stage's field rate alone
  big.last_lr_net_end = lr_end0 * 10;
  const double lrf_end0 = big.lr_focal_end;  // --last-lr-focal-end: the last stage's focal alone
  REQUIRE(lrf_end0 < big.lr_focal);
  big.last_lr_focal_end = big.lr_focal;       // flat: the last stage's focal never slows
  const double lrp_end0 = big.lr_pose_end;    // --last-lr-pose-end: the last stage's poses alone
  big.last_lr_pose_end = lrp_end0 / 100;      // they end 100x slower than a stage before
  big.last_distortion = 0.01;  // --last-distortion: the last stage's field alone
  big.last_distortion_from = 0.5;   // ... from half of it, with the cameras held from then
  big.last_hold_cameras_from = 0.5;
  validate_train_config(big);
  const int table0 = big.model.gf.grid.log2_table, samples0 = big.samples;
  REQUIRE(grid_restarts(big, nullptr));
  const Trainer b2 = Trainer::resume(out + "_big/stage2");
  CHECK(b2.config().model.gf.grid.log2_table == table0);
  CHECK(b2.config().samples == samples0);
  CHECK(b2.config().lr_net == lr0);
  CHECK(b2.config().lr_net_end == lr_end0);
  CHECK(b2.config().distortion == 0);
  CHECK(b2.config().distortion_from == 0);
  CHECK(b2.config().hold_cameras_from == 0);
  CHECK(b2.config().lr_focal_end == lrf_end0);
  CHECK(b2.config().lr_pose_end == lrp_end0);
  CHECK(big.lr_net == lr0 * 2);
  CHECK(big.lr_net_end == lr_end0 * 10);
  CHECK(big.model.gf.grid.log2_table == table0 + 2);
  CHECK(big.samples == samples0 * 2);
  CHECK(big.lr_focal_end == big.lr_focal);
  CHECK(big.lr_pose_end == lrp_end0 / 100);
  Trainer bl(big);
  REQUIRE(bl.run());
  CHECK(bl.lr_focal_at(bl.state().step - 1) == Approx(big.lr_focal));  // still at its start rate
  CHECK(b2.lr_focal_at(b2.state().step - 1) < 0.5 * big.lr_focal);      // the stage before slowed
  // The poses: the last stage ends below what the stage before ended at (both decay).
  CHECK(bl.lr_pose_at(bl.state().step - 1) < 0.5 * b2.lr_pose_at(b2.state().step - 1));
  const Trainer b3 = Trainer::resume(out + "_big");  // its checkpoint holds the larger table
  CHECK(b3.config().model.gf.grid.log2_table == table0 + 2);
  CHECK(b3.config().samples == samples0 * 2);
  CHECK(b3.config().lr_net == lr0 * 2);
  CHECK(b3.config().distortion == 0.01);
  CHECK(b3.config().distortion_from == 0.5);
  CHECK(b3.config().hold_cameras_from == 0.5);
  CHECK(b3.config().lr_focal_end == big.lr_focal);
  CHECK(b3.config().lr_pose_end == lrp_end0 / 100);
  // By minutes: the stages between run their steps whatever the time (minutes 0 in their
  // config.json), stage 1 its share, and the last stage the minutes left, at least a twentieth.
  TrainConfig m = tiny_grid_run(data, out + "_m", 0);
  m.minutes = 1e-3;  // 60 ms
  m.restarts = 2;
  m.restart_steps = 2;
  const std::string mout = m.out;
  REQUIRE(grid_restarts(m, nullptr));
  const Trainer m1 = Trainer::resume(mout + "/stage1");
  const Trainer m2 = Trainer::resume(mout + "/stage2");
  CHECK(m1.config().minutes == Approx(1e-3 / 3));  // no --restart-first: an equal share
  CHECK(m2.state().step == 2);
  CHECK(m2.config().minutes == 0);
  CHECK(m.steps == 0);
  CHECK(m.minutes <= 1e-3 - 1e-3 / 3);
  CHECK(m.minutes >= 1e-3 / 20);
  // Stages between that leave the last stage nothing of a steps budget: refused before any runs.
  TrainConfig full = tiny_grid_run(data, out + "_f", 10);
  full.restarts = 3;
  full.restart_first = 0.5;
  full.restart_steps = 3;  // 5 + 2 x 3 > 10
  const std::string fout = full.out;
  CHECK_THROWS_WITH(grid_restarts(full, nullptr), Catch::Contains("--restart-steps"));
  CHECK_FALSE(std::filesystem::exists(fout + "/stage1"));
}

// The --minutes path of the bootstrap, through the CLI as a user types it. Phase 2's config keeps
// bootstrap_minutes as a record while its minutes are the rest; a check of "bootstrap < minutes"
// on that config stopped every such run after its bootstrap (exit 2; found by a fern study).
TEST_CASE("bootstrap by minutes: both phases run, the run resumes; a bootstrap as long as the "
          "budget is refused", "[gridfield][cli]") {
  const std::string data = test::sim_scene("boot_min", 6, 48, 36);
  const std::string out = test::tmp("boot_min_run", true);
  const std::vector<std::string> base = {"train", "--data", data, "--out", out, "--width", "16",
                                         "--samples", "8", "--rays", "64", "--no-progress",
                                         "--threads", "1"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> a = base;
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
  };
  REQUIRE(test::cli(with({"--minutes", "0.04", "--bootstrap-minutes", "0.02"})) == 0);
  CHECK(std::filesystem::exists(out + "/bootstrap/checkpoint.bin"));
  // The bootstrap's pose curve is recorded as for any run (the simulated scene has references).
  CHECK(std::filesystem::exists(out + "/bootstrap/camera_error.csv"));
  CHECK(std::filesystem::exists(out + "/camera_error.csv"));
  const Trainer t = Trainer::resume(out);  // its config.json validates
  CHECK(t.config().bootstrap_minutes == 0.02);
  CHECK(t.config().minutes == Approx(0.02));
  CHECK(t.config().cameras_from == out + "/bootstrap");
  CHECK(test::cli(with({"--minutes", "0.02", "--bootstrap-minutes", "0.02"})) == 2);
}

TEST_CASE("grid field: --grid-density-init B adds B to z only: σ starts e^B times the plain init",
          "[gridfield][model]") {
  // The start the field's density takes decides where fern's cameras settle (an opaque screen
  // at the near plane, B = 2, lets them turn more: docs/results/grid). The option must move the
  // density output's bias and nothing else: same draws, same colours, σ × e^B at every sample.
  ModelConfig cfg = tiny_model_config(Variant::hashcc, Field::grid);
  ModelLayout L = make_layout(cfg);
  std::vector<double> p0(L.count), p2(L.count);
  Rng r0(5, 1), r2(5, 1);
  init_params(p0.data(), cfg, L, r0);
  ModelConfig cfg2 = cfg;
  cfg2.gf.density_init = 2;
  init_params(p2.data(), cfg2, L, r2);
  int64_t moved = 0;
  for (int64_t i = 0; i < L.count; ++i)
    if (p0[i] != p2[i]) {
      ++moved;
      CHECK(i == L.gd1.b);  // z is output 0 of grid.density.1
      CHECK(p2[i] - p0[i] == Approx(2.0).epsilon(1e-15));
    }
  CHECK(moved == 1);
  const int R = 3, S = 6;
  Rng rng(6, 1);
  std::vector<double> x = random_vec(R * S * 3, rng, -0.9, 0.9), dir;
  for (int r = 0; r < R; ++r) dir.insert(dir.end(), {0.0, 0.6, 0.8});
  auto run = [&](const std::vector<double>& params, std::vector<double>& sigma, std::vector<double>& rgb) {
    ModelCache<double> c;
    c.reserve(cfg, R, S);
    model_forward(c, NetView<double>{params.data(), cfg, L},
                  ModelIn<double>{x.data(), dir.data(), x.data(), R, S});
    sigma.assign(c.sigma_raw.begin(), c.sigma_raw.begin() + R * S);
    rgb.assign(c.color.begin(), c.color.begin() + R * S * 3);
  };
  std::vector<double> s0, c0, s2, c2;
  run(p0, s0, c0);
  run(p2, s2, c2);
  CHECK(c2 == c0);
  for (int i = 0; i < R * S; ++i) CHECK(s2[i] / s0[i] == Approx(std::exp(2.0)).epsilon(1e-12));
}

// The fern60 recipe (--plan fern60; --preset fern60 is now the default, issue 49) is a whole
// recipe: it chooses the grid field and its restarts, so it must be applied before the grid
// field's own defaults, which may not overwrite what it set (its field rate 2e-2 against the
// field's default 1e-2), while an explicit flag still wins over both.
TEST_CASE("plan fern60: the grid field's restarts recipe through the CLI; its values beat the "
          "field's defaults, explicit flags beat it", "[gridfield][cli][preset][plan]") {
  const std::string data = test::sim_scene("fern60_preset", 6, 48, 36);
  const std::string out = test::tmp("fern60_preset_run", true);
  // A budget in steps the recipe's 1,200-step restarts would not fit: stages 2-4 get 2 steps.
  const std::vector<std::string> base = {"train", "--data", data, "--out", out, "--width", "16",
                                         "--samples", "8", "--rays", "64", "--no-progress",
                                         "--threads", "1", "--steps", "12", "--set", "2-4.steps=2",
                                         "--plan", "fern60"};
  REQUIRE(test::cli(base) == 0);
  for (int k = 1; k <= 4; ++k) CHECK(std::filesystem::exists(out + "/stage" + std::to_string(k)));
  CHECK_FALSE(std::filesystem::exists(out + "/stage5"));  // 4 restarts: 5 stages, the last in out/
  const Trainer last = Trainer::resume(out);
  const TrainConfig& c = last.config();
  CHECK(c.preset == "fern60");
  CHECK(c.model.field == Field::grid);
  CHECK(c.model.gf.density_init == 2);
  CHECK(c.lr_pose == 3e-3);
  CHECK(c.lr_net == 2e-2);      // the preset's, not the grid field's default 1e-2
  CHECK(c.lr_net_end == 1e-3);  // not 1e-4
  CHECK(c.model.gf.grid.log2_table == 17);  // the last stage's table
  CHECK(Trainer::open(out + "/stage3").state().step == 2);  // the --set budget
  CHECK(c.samples == 64);       // the preset's --last-samples, over the explicit --samples 8
  CHECK(c.lr_pose_end == 1e-5);  // the last stage's cameras settle, then are held
  CHECK(c.hold_cameras_from == 0.7);
  CHECK(c.distortion == 0);       // measured no gain on the held cameras: not in the preset
  CHECK(c.c2f_end == 0);        // restarts: the last stage runs all levels from its start
  const Trainer s1 = Trainer::resume(out + "/stage1");
  CHECK(s1.config().c2f_end == 0.5);  // stage 1 keeps the grid field's curriculum (not in the preset)
  CHECK(s1.config().lr_net == 2e-2);
  CHECK(s1.config().samples == 8);   // the camera stages: the explicit --samples
  CHECK(s1.config().lr_pose_end == 1e-4);  // the grid field's default; nothing held
  CHECK(s1.config().hold_cameras_from == 0);
  // An explicit field rate wins over the preset's.
  const std::string out2 = test::tmp("fern60_preset_run2", true);
  std::vector<std::string> a2 = base;
  a2[4] = out2;
  a2.insert(a2.end(), {"--lr-net", "5e-3"});
  REQUIRE(test::cli(a2) == 0);
  CHECK(Trainer::resume(out2).config().lr_net == 5e-3);
  // The preset chooses the grid field; an explicit --field mlp wins and its restarts are refused.
  std::vector<std::string> a3 = base;
  a3[4] = test::tmp("fern60_preset_run3", true);
  a3.insert(a3.end(), {"--field", "mlp"});
  CHECK(test::cli(a3) == 2);
}

// --grid-decay reaches the step: with it the table moves differently (the decay's gradient joins
// the data gradient before Adam), and the MLP field refuses it.
TEST_CASE("grid decay: the option reaches the table's update; refused for the MLP field",
          "[gridfield][trainer][decay]") {
  const std::string data = test::sim_scene("decay", 6, 48, 36);
  TrainConfig a = tiny_grid_run(data, test::tmp("decay_a", true), 3);
  TrainConfig b = a;
  b.out = test::tmp("decay_b", true);
  b.grid_decay = 10.0;
  CHECK_NOTHROW(validate_train_config(b));
  Trainer ta(a), tb(b);
  REQUIRE(ta.run());
  REQUIRE(tb.run());
  const ModelLayout& L = ta.layout();
  const std::vector<float>& pa = ta.state().net;
  const std::vector<float>& pb = tb.state().net;
  const int64_t table_end = L.grid_table + a.model.gf.grid.param_count();
  int64_t table_moved = 0;
  for (int64_t i = L.grid_table; i < table_end; ++i) table_moved += pa[size_t(i)] != pb[size_t(i)];
  CHECK(table_moved > 0);
  CHECK(train_config_from_json(train_config_json(b), "config.json").grid_decay == 10.0);
  TrainConfig m = test::tiny_train_config(data, test::tmp("decay_m", true), 3);
  m.grid_decay = 1.0;
  CHECK_THROWS_WITH(validate_train_config(m), Catch::Contains("--grid-decay"));
}

// The empty-field guard must see the data gradient alone. With --grid-decay the table's gradient
// is never all 0, so a decay added before the guard would hide an empty field from it (and the
// run would sit on a black render for good). Under --distortion every weight of an empty field is
// 0, so the loss's gradient is 0 too. The grid field's density bias at -1e4: σ = 0 at every
// sample, a black render, all-zero data gradient.
TEST_CASE("regularisers (decay, distortion): an empty grid field is still caught by the guard",
          "[gridfield][trainer][decay][distortion][hard]") {
  const std::string data = test::sim_scene("decay_empty", 6, 48, 36);
  for (const bool decay : {true, false}) {
    DYNAMIC_SECTION((decay ? "--grid-decay 10" : "--distortion 10")) {
      TrainConfig c = tiny_grid_run(data, test::tmp("decay_empty_run", true), 3);
      (decay ? c.grid_decay : c.distortion) = 10.0;
      Trainer t(c);
      const std::vector<float> good = t.state().net;
      t.mutable_state().net[size_t(t.layout().gd1.b)] = -1e4f;  // z, the density's pre-activation
      const auto r = t.step_once();
      CHECK(r.loss > 0);
      CHECK(t.state().diverged == 1);  // the guard fired
      CHECK(t.state().net == good);    // restored
      CHECK(t.state().step == 0);
    }
  }
}

// --distortion reaches the step (render/distortion.h): the run's parameters differ from the same
// run without it, the loss it logs is the colour loss plus λ·L_dist, the config round-trips, and
// the MLP field takes it too (the loss is on the weights, whichever field made them).
TEST_CASE("distortion: the option reaches the step and the config, on both fields",
          "[gridfield][trainer][distortion]") {
  const std::string data = test::sim_scene("dist", 6, 48, 36);
  for (const bool grid : {true, false}) {
    DYNAMIC_SECTION((grid ? "grid" : "mlp") << " field") {
      TrainConfig a = grid ? tiny_grid_run(data, test::tmp("dist_a", true), 3)
                           : test::tiny_train_config(data, test::tmp("dist_a", true), 3);
      TrainConfig b = a;
      b.out = test::tmp("dist_b", true);
      b.distortion = 1e3;  // large enough to move a 3-step run's parameters in float
      CHECK_NOTHROW(validate_train_config(b));
      Trainer ta(a), tb(b);
      const StepResult<float> ra = ta.step_once(), rb = tb.step_once();
      // The first step sees identical parameters: the same colour loss; the logged loss adds the term.
      CHECK(ra.mse == rb.mse);
      CHECK(ra.distortion == 0);
      CHECK(rb.distortion > 0);
      CHECK(rb.loss == Approx(ra.loss + b.distortion * rb.distortion).epsilon(1e-12));
      const std::vector<float>&pa = ta.state().net, &pb = tb.state().net;
      int64_t moved = 0;
      for (size_t i = 0; i < pa.size(); ++i) moved += pa[i] != pb[i];
      CHECK(moved > 0);
      CHECK(train_config_from_json(train_config_json(b), "config.json").distortion == 1e3);
    }
  }
  TrainConfig bad = test::tiny_train_config(data, test::tmp("dist_bad", true), 3);
  bad.distortion = -1;
  CHECK_THROWS_WITH(validate_train_config(bad), Catch::Contains("--distortion"));
}

// --grid-features, --grid-hidden, --grid-rgb-hidden reach the model a run trains (and its
// config.json, so a resumed run or `hashcc eval` rebuilds the same network): the table holds F
// values an entry, and the two MLPs have the widths asked for.
TEST_CASE("grid field sizes through the CLI: features an entry and the MLPs' widths",
          "[gridfield][cli]") {
  const std::string data = test::sim_scene("grid_sizes", 6, 48, 36);
  const std::string out = test::tmp("grid_sizes_run", true);
  REQUIRE(test::cli({"train", "--data", data, "--out", out, "--field", "grid", "--samples", "8",
                     "--rays", "64", "--no-progress", "--threads", "1", "--steps", "3",
                     "--grid-levels", "4", "--grid-log2-table", "8", "--grid-features", "4",
                     "--grid-hidden", "24", "--grid-rgb-hidden", "8"}) == 0);
  const Trainer t = Trainer::resume(out);
  const ModelConfig& m = t.config().model;
  CHECK(m.gf.grid.features == 4);
  CHECK(m.gf.hidden == 24);
  CHECK(m.gf.rgb_hidden == 8);
  bool table = false, density_in = false, rgb_out = false;
  for (const auto& tensor : t.layout().tensors) {
    if (tensor.name == "grid.table") table = tensor.shape == std::vector<int64_t>{4, 1 << 8, 4};
    if (tensor.shape == std::vector<int64_t>{24, 4 * 4}) density_in = true;  // L·F → hidden
    if (tensor.shape == std::vector<int64_t>{3, 8}) rgb_out = true;          // rgb hidden → 3
  }
  CHECK(table);  // (L, 2^T, F)
  CHECK(density_in);
  CHECK(rgb_out);
  CHECK(int64_t(t.state().net.size()) == t.layout().count);  // the trained parameters fit it
  CHECK(test::cli({"train", "--data", data, "--out", test::tmp("grid_sizes_bad", true), "--field",
                   "grid", "--steps", "1", "--grid-features", "0"}) != 0);
}

TEST_CASE("grid field: NaN and inf positions, z → −∞, a huge step: clamped and finite, or a NaN the "
          "step's gradient carries to the guard", "[gridfield][model][hard]") {
  // Issue 52's hard cases, in double, at the field (model_forward/model_backward of hashcc on
  // the grid field, CC on top). What the code does, each checked:
  //  - NaN, +inf, −inf positions: the hash grid clamps them into [0, 1] (NaN → 0,
  //    kernels/hash_grid.cpp clamp01), so σ and c are finite, d_x is 0 on those coordinates (the
  //    clamp acts), and the table gradient is that of the clamped field: central differences of
  //    ⟨g, [σ, c, Δc]⟩ over the table and the MLPs agree with it (h = 1e-6, tolerance 1e-6: the
  //    outputs are smooth in the parameters away from ReLU kinks).
  //  - a NaN direction (a camera that went NaN): finite colours (the colour MLP's ReLU maps the
  //    NaN pre-activations to 0), a NaN parameter and direction gradient; the step hands that
  //    to the trainer's divergence guard (Trainer::bad_step, "non-finite loss or gradient"),
  //    which restores the last good state: not silent.
  //  - z → −∞ (density bias −1e300, and −inf): σ = 0 exactly, every output and gradient finite,
  //    no gradient through z.
  //  - a huge step (every parameter ×1e6, as after a diverging update): σ clamped at e^15, c
  //    in [0, 1], every gradient finite.
  ModelConfig cfg = tiny_model_config(Variant::hashcc, Field::grid);
  const ModelLayout L = make_layout(cfg);
  Rng rng(52, 1);
  std::vector<double> p(L.count);
  init_params(p.data(), cfg, L, rng);
  for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) p[L.grid_table + i] = rng.uniform(-0.5, 0.5);
  for (int64_t i = 0; i < cfg.cc.param_count(); ++i) p[L.cc_table + i] = rng.uniform(-0.5, 0.5);
  const int R = 3, S = 4, N = R * S;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  std::vector<double> x = random_vec(N * 3, rng, -0.9, 0.9);
  x[0] = nan;  x[4] = inf;  x[8] = -inf;  x[9] = nan;  x[10] = nan;  x[11] = nan;
  std::vector<double> dir = {0, 0, 1, 0.6, 0, 0.8, 0, -0.6, 0.8};
  const std::vector<double> g = random_vec(N * 7, rng);  // the projection of [σ, c, Δc]
  struct Run { std::vector<double> out, grad, dx, dd; };
  auto run = [&](const std::vector<double>& params, const std::vector<double>& xs,
                 const std::vector<double>& dirs, bool backward) {
    ModelCache<double> c;
    c.reserve(cfg, R, S);
    const NetView<double> net{params.data(), cfg, L};
    const ModelIn<double> in{xs.data(), dirs.data(), xs.data(), R, S};
    model_forward(c, net, in);
    Run r;
    r.out.assign(c.sigma_raw.begin(), c.sigma_raw.begin() + N);
    r.out.insert(r.out.end(), c.color.begin(), c.color.begin() + N * 3);
    r.out.insert(r.out.end(), c.dcolor.begin(), c.dcolor.begin() + N * 3);
    if (backward) {
      std::vector<double> ds(g.begin(), g.begin() + N), dc(g.begin() + N, g.begin() + 4 * N),
          dcc(g.begin() + 4 * N, g.end());
      r.grad.assign(L.count, 0.0);
      r.dx.assign(N * 3, 9.0);
      r.dd.assign(R * 3, 9.0);
      model_backward<double>({r.grad.data(), r.dx.data(), r.dd.data()}, {ds.data(), dc.data(), dcc.data()},
                             c, net, in);
    }
    return r;
  };
  auto all_finite = [](const std::vector<double>& v) {
    return std::all_of(v.begin(), v.end(), [](double a) { return std::isfinite(a); });
  };

  SECTION("NaN and inf positions: clamped, finite, the clamped field's gradient") {
    const Run r = run(p, x, dir, true);
    CHECK(all_finite(r.out));
    CHECK(all_finite(r.grad));
    CHECK(all_finite(r.dx));
    CHECK(all_finite(r.dd));
    for (int i : {0, 4, 8, 9, 10, 11}) CHECK(r.dx[i] == 0);
    // A NaN position is the point at u = 0 on that axis: the same outputs.
    std::vector<double> x0 = x;
    x0[0] = -1; x0[4] = 1; x0[8] = -1; x0[9] = x0[10] = x0[11] = -1;
    CHECK(run(p, x0, dir, false).out == r.out);
    std::vector<double> theta = p;
    auto loss = [&] { return dot(g, run(theta, x, dir, false).out); };
    std::vector<size_t> idx;
    for (const auto& t : L.tensors)
      for (int k = 0; k < 4; ++k) idx.push_back(size_t(t.offset + rng.below(uint32_t(t.size()))));
    // The table rows the NaN sample (0, then u = 0 on x) reads on the dense level 0: corner 0.
    idx.push_back(size_t(L.grid_table));
    const double e = worst_grad_error(theta, r.grad, loss, 1e-6, idx, 1e-6);
    test::record_tolerance("[gridfield][hard] NaN/inf positions, parameters", "hashcc grid, 4 levels", e, 1e-6);
    CHECK(e < 1e-6);
  }
  SECTION("a NaN direction: finite colours, a NaN gradient the step hands to the guard") {
    // What the code does: the direction's NaN encoding makes the colour MLP's pre-activations
    // NaN; its ReLU (v > 0 ? v : 0) maps them to 0, so the colours stay finite (that ray's are
    // wrong, the other rays' untouched). The backward multiplies the NaN inputs by those zero
    // gradients: grid.rgb.0.weight and the ray's d_dir get NaN. So the step's loss is finite
    // but its gradient is not, and the trainer's divergence guard (Trainer::bad_step checks
    // every gradient entry: "non-finite loss or gradient") refuses the step: not silent.
    FiniteChecksOff nan_on_purpose;  // the sanitizer build's kernel asserts would abort here
    std::vector<double> d2 = dir;
    d2[3] = nan;  // ray 1
    const Run a = run(p, x, dir, true), b = run(p, x, d2, true);
    CHECK(all_finite(b.out));
    for (int n = 0; n < N; ++n) {
      CHECK(b.out[n] == a.out[n]);  // σ does not read the direction
      if (n / S != 1)
        for (int k = 0; k < 3; ++k) CHECK(b.out[N + 3 * n + k] == a.out[N + 3 * n + k]);
    }
    CHECK_FALSE(all_finite(b.grad));
    CHECK_FALSE(std::isfinite(b.dd[3]));
    // Through the step: a finite loss, a non-finite gradient (what bad_step refuses).
    StepWorkspace<double> ws;
    std::vector<double> o = {0, 0, -1, 0.1, 0, -1, 0, 0.1, -1}, d = {0, 0, 2, nan, 0, 2, 0, 0.1, 2};
    std::vector<double> s, target(R * 3, 0.5);
    for (int i = 0; i < R; ++i)
      for (int k = 0; k < S; ++k) s.push_back((k + 0.5) / S);
    const NetView<double> net{p.data(), cfg, L};
    std::vector<double> grad(L.count, 0.0), d_o(3 * R), d_d(3 * R);
    const auto res = ray_batch_step(ws, net, RayBatch<double>{o.data(), d.data(), s.data(), target.data(), R, S, nullptr},
                                    StepOptions{}, {grad.data(), d_o.data(), d_d.data()});
    CHECK(std::isfinite(res.loss));
    CHECK_FALSE((all_finite(grad) && all_finite(d_o) && all_finite(d_d)));
  }
  SECTION("z → −∞: σ = 0, finite, no gradient through z") {
    // A −inf bias is a non-finite parameter on purpose: the density MLP's pre-activation is −inf
    // (the sanitizer build's kernel check would abort there), its clamp makes σ = 0.
    FiniteChecksOff inf_on_purpose;
    for (double b : {-1e300, -inf}) {
      INFO("density bias " << b);
      std::vector<double> q = p;
      q[L.gd1.b] = b;
      const Run r = run(q, x, dir, true);
      CHECK(all_finite(r.out));
      for (int n = 0; n < N; ++n) CHECK(r.out[n] == 0);
      CHECK(all_finite(r.grad));
      CHECK(all_finite(r.dx));
      CHECK(all_finite(r.dd));
      CHECK(r.grad[L.gd1.b] == 0);
    }
  }
  SECTION("a huge step: every parameter ×1e6, clamped and finite") {
    std::vector<double> q = p;
    for (double& v : q) v *= 1e6;
    const Run r = run(q, x, dir, true);
    CHECK(all_finite(r.out));
    for (int n = 0; n < N; ++n) CHECK(r.out[n] <= std::exp(kGridMaxLogDensity) * (1 + 1e-12));
    for (int i = N; i < 4 * N; ++i) CHECK((r.out[i] >= 0 && r.out[i] <= 1));
    CHECK(all_finite(r.grad));
    CHECK(all_finite(r.dx));
    CHECK(all_finite(r.dd));
  }
}
