// Tests of kernels/hash_grid (formulas.md §5; derivation in docs/math/hash_grid.md).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <vector>

#include "core/parallel.h"
#include "kernels/hash_grid.h"
#include "test/fixtures.h"
#include "test/gradcheck.h"

using namespace hashcc;
using hashcc::test::dot;
using hashcc::test::random_vec;
using hashcc::test::rel_err;
using hashcc::test::worst_grad_error;

namespace {

// 5 levels, base 4, max 32, table 2^12: scales 3, 5.73, 10.31, 17.03, 31 → res 4, 7, 12, 19, 32;
// levels 0–2 dense (64, 343, 1728 ≤ 4096), levels 3–4 hashed. Level 0 has integer scale 3, so
// x = 1 reaches vertex 4 = res_0 (tcnn's aliasing path).
HashGridConfig mixed_config() {
  HashGridConfig c;
  c.levels = 5; c.log2_table = 12; c.base_res = 4; c.max_res = 32;
  return c;
}

// The same grid with F features an entry: the kernels dispatch F = 2 (every shipped config) to
// a compile-time path and any other F (`--grid-features`) to the general one; both are checked.
HashGridConfig mixed_config_features(int F) {
  HashGridConfig c = mixed_config();
  c.features = F;
  return c;
}

// x (n, 3) with frac ∈ [0.1, 0.9] on every axis at every level, so the encoding is smooth
// (multilinear) within ±0.1/scale_max of every input: off cell faces by construction. Each
// coordinate is drawn until it satisfies the condition, which is then asserted.
std::vector<double> off_face_inputs(const HashGridConfig& cfg, int64_t n, Rng& rng) {
  auto lv = hashgrid_levels(cfg);
  std::vector<double> x(n * 3);
  for (auto& v : x) {
    int tries = 0;
    for (;;) {
      REQUIRE(++tries < 100000);
      v = rng.uniform(0.01, 0.99);
      bool ok = true;
      for (auto& L : lv) {
        double p = L.scale * v + 0.5, f = p - std::floor(p);
        ok = ok && f >= 0.1 && f <= 0.9;
      }
      if (ok) break;
    }
  }
  return x;
}

double max_scale(const HashGridConfig& cfg) {
  double s = 0;
  for (auto& L : hashgrid_levels(cfg)) s = std::max(s, L.scale);
  return s;
}

using test::cast;
using test::vec_rel;
using test::clearly_differs;


}  // namespace

TEST_CASE("hash grid level geometry and indices follow formulas.md §5", "[hashgrid][hard]") {
  HashGridConfig def;  // 16 levels, 2^9 table, base 16, max 512
  auto lv = hashgrid_levels(def);
  REQUIRE(lv.size() == 16);
  CHECK(lv[0].scale == 15.0);
  CHECK(lv[0].res == 16);
  CHECK(lv[3].scale == Approx(31.0).epsilon(1e-12));
  CHECK(lv[15].scale == 511.0);  // exactly: ceil() must not see rounding noise in b^15
  CHECK(lv[15].res == 512);
  CHECK(lv[6].res == 64);  // 16·b^6 − 1 = 63 (raw double gives 63.000000000000014 → 65)
  CHECK(lv[9].res == 128);
  CHECK(lv[12].res == 256);
  // The default config has NO dense level: res_0³ = 4096 > 512.
  for (auto& L : lv) CHECK_FALSE(L.dense);
  for (int l = 0; l < 16; ++l)
    HCC_TEST_PRINTF("default level %2d: scale %9.4f res %4lld %s\n", l, lv[l].scale,
                (long long)lv[l].res, lv[l].dense ? "dense" : "hashed");

  auto mx = hashgrid_levels(mixed_config());
  REQUIRE(mx.size() == 5);
  CHECK(mx[0].res == 4);
  CHECK(mx[4].scale == 31.0);
  CHECK(mx[0].dense);
  CHECK(mx[1].dense);
  CHECK(mx[2].dense);
  CHECK_FALSE(mx[3].dense);
  CHECK_FALSE(mx[4].dense);

  // The dense rule is res³ ≤ 2^T, inclusive: res 16 (scale 15) with 2^12 = 16³ entries is dense.
  HashGridConfig edge;
  edge.levels = 1; edge.base_res = 16; edge.max_res = 16; edge.log2_table = 12;
  CHECK(hashgrid_level(edge, 0).res == 16);
  CHECK(hashgrid_level(edge, 0).dense);
  edge.log2_table = 11;
  CHECK_FALSE(hashgrid_level(edge, 0).dense);

  // Hand-computed indices: 1 ⊕ 2654435761 ⊕ 805459861 = … ≡ 37 (mod 512);
  // 3 ⊕ 5·2654435761 ⊕ 7·805459861 (uint32 wrap) ≡ 357 (mod 512); dense 1 + 2·4 + 3·16 = 57.
  CHECK(hashgrid_vertex_index(1, 1, 1, lv[0], 512) == 37u);
  CHECK(hashgrid_vertex_index(3, 5, 7, lv[0], 512) == 357u);
  CHECK(hashgrid_vertex_index(1, 2, 3, mx[0], 4096) == 57u);

  // Init is uniform ±1e-4 and not degenerate.
  std::vector<float> tab(def.param_count());
  Rng rng(7);
  hashgrid_init_table(tab.data(), def, rng);
  float lo = *std::min_element(tab.begin(), tab.end()), hi = *std::max_element(tab.begin(), tab.end());
  CHECK(lo >= -1e-4f);
  CHECK(hi <= 1e-4f);
  CHECK(lo < -0.9e-4f);
  CHECK(hi > 0.9e-4f);
}

TEST_CASE("hash grid table gradient matches central differences", "[hashgrid][grad]") {
  // Output is linear in the table, so the central difference has no truncation error at any
  // step: a large h = 0.5 keeps rounding (≈ 1e-16·|L|/h) far below the smallest entries
  // (corner weights can be ~1e-6). Tolerance 1e-6, the brief's bound for smooth parts.
  const double tol = 1e-6;
  struct Case { const char* name; HashGridConfig cfg; int64_t N; };
  HashGridConfig tiny;  // heavy collisions: 16 levels into 4 entries each
  tiny.log2_table = 2;
  Case cases[] = {{"mixed dense/hashed", mixed_config(), 40},
                  {"default", HashGridConfig{}, 30},
                  {"tiny table 2^2", tiny, 30},
                  {"mixed, F = 1", mixed_config_features(1), 40},
                  {"mixed, F = 4", mixed_config_features(4), 40}};
  for (auto& cs : cases) {
    const auto& cfg = cs.cfg;
    Rng rng(11);
    auto x = random_vec(cs.N * 3, rng, 0, 1);
    auto table = random_vec(cfg.param_count(), rng, -1, 1);
    auto g = random_vec(cs.N * cfg.out_dim(), rng, -1, 1);
    std::vector<double> out(cs.N * cfg.out_dim()), d_table(cfg.param_count(), 0.0);
    HashGridWorkspace<double> ws;
    hashgrid_backward(d_table.data(), (double*)nullptr, g.data(), x.data(), table.data(), cs.N,
                      cfg, ws);
    auto loss = [&] {
      hashgrid_forward(out.data(), x.data(), table.data(), cs.N, cfg);
      return dot(g, out);
    };
    // Every entry when the table is small; else every touched entry plus 200 untouched ones.
    std::vector<size_t> idx;
    size_t untouched = 0;
    for (size_t i = 0; i < d_table.size(); ++i) {
      if (d_table[i] != 0 || cfg.param_count() <= 4096) idx.push_back(i);
      else if (untouched++ < 200) idx.push_back(i);
    }
    size_t touched = std::count_if(d_table.begin(), d_table.end(), [](double v) { return v != 0; });
    REQUIRE(touched > 100);  // the check really exercises non-zero gradients
    double worst = worst_grad_error(table, d_table, loss, 0.5, idx);
    HCC_TEST_PRINTF("[hashgrid][grad] d_table %-20s: %zu entries (%zu non-zero), worst rel err %.2e "
                "(tol %.0e)\n", cs.name, idx.size(), touched, worst, tol);
    CHECK(worst < tol);
  }
}

TEST_CASE("hash grid input gradient matches central differences off cell faces",
          "[hashgrid][grad]") {
  const double tol = 1e-6;
  HashGridConfig cfgs[] = {HashGridConfig{}, mixed_config(), mixed_config_features(1),
                           mixed_config_features(4)};
  for (auto& cfg : cfgs) {
    const int64_t N = 25;
    Rng rng(5);
    auto x = off_face_inputs(cfg, N, rng);
    auto table = random_vec(cfg.param_count(), rng, -1, 1);
    auto g = random_vec(N * cfg.out_dim(), rng, -1, 1);
    // frac ∈ [0.1, 0.9] ⇒ the nearest face is ≥ 0.1/scale_max away in x; h moves frac by
    // scale_max·h ≤ 0.01, so both probes stay inside the cell (where y is multilinear in x).
    const double h = 1e-5;
    REQUIRE(max_scale(cfg) * h <= 0.01);
    std::vector<double> out(N * cfg.out_dim()), d_table(cfg.param_count(), 0.0), d_x(N * 3, -7.0);
    HashGridWorkspace<double> ws;
    hashgrid_backward(d_table.data(), d_x.data(), g.data(), x.data(), table.data(), N, cfg, ws);
    // The frozen-table call (eval's test-pose refinement: no table gradient, positions only)
    // writes the same d_x, bit for bit, and it is checked against the differences too.
    std::vector<double> d_x_frozen(N * 3, -7.0);
    hashgrid_backward((double*)nullptr, d_x_frozen.data(), g.data(), x.data(), table.data(), N, cfg, ws);
    CHECK(d_x_frozen == d_x);
    auto loss = [&] {
      hashgrid_forward(out.data(), x.data(), table.data(), N, cfg);
      return dot(g, out);
    };
    double worst = worst_grad_error(x, d_x_frozen, loss, h);
    double mag = 0;
    for (double v : d_x) mag = std::max(mag, std::abs(v));
    HCC_TEST_PRINTF("[hashgrid][grad] d_x levels=%d F=%d: worst rel err %.2e (tol %.0e), max |d_x| %.3g\n",
                cfg.levels, cfg.features, worst, tol, mag);
    CHECK(mag > 1.0);
    CHECK(worst < tol);
  }
}

TEST_CASE("hash grid optimised kernels match the naive reference", "[hashgrid][exact]") {
  test::ThreadGuard guard;
  HashGridConfig cfgs[] = {HashGridConfig{}, mixed_config(), mixed_config_features(1),
                           mixed_config_features(4)};
  for (int threads : {1, 2}) {
    set_num_threads(threads);
    for (auto& cfg : cfgs) {
      // > 2·1024: the parallel path runs at 2 threads; > 2·256 (kBlock): several blocks a
      // thread, the last one partial
      const int64_t N = 9000;
      Rng rng(21);
      auto x = random_vec(N * 3, rng, -0.2, 1.2);  // some clamped coordinates too
      x[0] = 0; x[1] = 1; x[2] = 0.5;
      auto table = random_vec(cfg.param_count(), rng, -1, 1);
      auto g = random_vec(N * cfg.out_dim(), rng, -1, 1);
      auto prior = random_vec(cfg.param_count(), rng, -1, 1);  // checks "+=" in both
      std::vector<double> out(N * cfg.out_dim()), out_n(out.size());
      std::vector<double> dt = prior, dt_n = prior, dx(N * 3), dx_n(N * 3);
      HashGridWorkspace<double> ws;
      hashgrid_forward(out.data(), x.data(), table.data(), N, cfg);
      hashgrid_forward_naive(out_n.data(), x.data(), table.data(), N, cfg);
      hashgrid_backward(dt.data(), dx.data(), g.data(), x.data(), table.data(), N, cfg, ws);
      hashgrid_backward_naive(dt_n.data(), dx_n.data(), g.data(), x.data(), table.data(), N, cfg);
      double eo = vec_rel(out, out_n), et = vec_rel(dt, dt_n), ex = vec_rel(dx, dx_n);
      HCC_TEST_PRINTF("[hashgrid] opt vs naive (levels=%d, %d thr): out %.1e d_table %.1e d_x %.1e\n",
                  cfg.levels, threads, eo, et, ex);
      CHECK(eo < 1e-13);
      CHECK(et < 1e-13);
      CHECK(ex < 1e-12);
      CHECK(clearly_differs(vec_rel(dt, prior), 1e-3));  // the gradient is not trivially zero
    }
  }
}

TEST_CASE("hash grid forward's position Jacobian: every entry by central differences off cell "
          "faces; through hashgrid_dx_from_jac it gives the backward's d_x (exact and smooth, "
          "clamped and NaN inputs, collisions, 1 and 2 threads)", "[hashgrid][grad][hard]") {
  test::ThreadGuard guard;
  HashGridConfig cfgs[] = {HashGridConfig{}, mixed_config(), mixed_config_features(1),
                           mixed_config_features(4)};
  // 1. jac[n][d][j] = ∂out[n][j]/∂x[n][d]: one point moved at a time (the exact gradient, which
  //    the differences measure; the smooth one is a different function by design). The outputs
  //    are the same with and without the Jacobian, bit for bit.
  for (auto& cfg : cfgs) {
    cfg.smooth_dx = false;
    const int64_t N = 12, D = cfg.out_dim();
    Rng rng(31);
    auto x = off_face_inputs(cfg, N, rng);
    auto table = random_vec(cfg.param_count(), rng, -1, 1);
    std::vector<double> out(N * D), out_j(N * D), jac(N * 3 * D, -7.0);
    hashgrid_forward(out.data(), x.data(), table.data(), N, cfg);
    hashgrid_forward(out_j.data(), x.data(), table.data(), N, cfg, jac.data());
    CHECK(out_j == out);
    const double h = 1e-5;  // as the d_x check above: both probes stay in the cell
    REQUIRE(max_scale(cfg) * h <= 0.01);
    double worst = 0, mag = 0;
    for (int64_t n = 0; n < N; ++n)
      for (int d = 0; d < 3; ++d) {
        double xp[3] = {x[n * 3], x[n * 3 + 1], x[n * 3 + 2]}, xm[3] = {xp[0], xp[1], xp[2]};
        xp[d] += h;
        xm[d] -= h;
        std::vector<double> op(D), om(D);
        hashgrid_forward(op.data(), xp, table.data(), 1, cfg);
        hashgrid_forward(om.data(), xm, table.data(), 1, cfg);
        for (int64_t j = 0; j < D; ++j) {
          const double fd = (op[j] - om[j]) / (2 * h), an = jac[(n * 3 + d) * D + j];
          worst = std::max(worst, std::abs(an - fd) / (1 + std::abs(fd)));
          mag = std::max(mag, std::abs(an));
        }
      }
    HCC_TEST_PRINTF("[hashgrid][grad] jacobian levels=%d F=%d: worst err %.2e (tol 1e-6), max |J| %.3g\n",
                    cfg.levels, cfg.features, worst, mag);
    CHECK(mag > 1.0);
    CHECK(worst < 1e-6);
  }
  // 2. d_x through the Jacobian = the backward's d_x (which the naive reference and the
  //    differences above pin), in both gradient modes, with clamped, NaN and infinite
  //    coordinates (their rows 0 exactly), a colliding 2^4 table, and the parallel path.
  HashGridConfig tiny = mixed_config();
  tiny.log2_table = 4;  // every hashed level collides
  std::vector<HashGridConfig> all(std::begin(cfgs), std::end(cfgs));
  all.push_back(tiny);
  for (int threads : {1, 2})
    for (bool smooth : {false, true})
      for (HashGridConfig cfg : all) {
        set_num_threads(threads);
        cfg.smooth_dx = smooth;
        const int64_t N = 9000, D = cfg.out_dim();  // > 2·1024 and several blocks a thread
        Rng rng(41);
        auto x = random_vec(N * 3, rng, -0.2, 1.2);
        x[0] = std::nan("");
        x[4] = std::numeric_limits<double>::infinity();
        x[5] = 1.0;
        x[6] = 0.0;
        auto table = random_vec(cfg.param_count(), rng, -1, 1);
        auto g = random_vec(N * D, rng, -1, 1);
        std::vector<double> out(N * D), jac(N * 3 * D), dx(N * 3), dxj(N * 3, -7.0);
        HashGridWorkspace<double> ws;
        hashgrid_forward(out.data(), x.data(), table.data(), N, cfg, jac.data());
        hashgrid_backward((double*)nullptr, dx.data(), g.data(), x.data(), table.data(), N, cfg, ws);
        hashgrid_dx_from_jac(dxj.data(), g.data(), jac.data(), N, cfg);
        const double e = vec_rel(dxj, dx);
        HCC_TEST_PRINTF("[hashgrid] d_x via the Jacobian vs the backward (levels=%d F=%d T=%d smooth=%d, %d thr): %.1e\n",
                        cfg.levels, cfg.features, cfg.log2_table, int(smooth), threads, e);
        CHECK(e < 1e-12);
        int clamped = 0;
        for (int64_t i = 0; i < N * 3; ++i)
          if (!(x[i] >= 0 && x[i] <= 1)) {
            ++clamped;
            for (int64_t j = 0; j < D; ++j) REQUIRE(jac[((i / 3) * 3 + i % 3) * D + j] == 0.0);
            REQUIRE(dxj[i] == 0.0);
          }
        CHECK(clamped > 1000);
      }
}

TEST_CASE("hash grid backward with d_out_x: the table gets d_out's gradient, the positions "
          "d_out_x's, in one pass", "[hashgrid][exact]") {
  // The grid field's detached distortion loss (model.h ModelOutGrads::d_sigma_raw_x): one
  // backward must equal two, each with one output gradient, bitwise (the same arithmetic).
  test::ThreadGuard guard;
  for (bool smooth : {false, true})
    for (int threads : {1, 2}) {
      set_num_threads(threads);
      HashGridConfig cfg = mixed_config();
      cfg.smooth_dx = smooth;
      const int64_t N = 9000;
      Rng rng(31);
      auto x = random_vec(N * 3, rng, -0.1, 1.1);
      auto table = random_vec(cfg.param_count(), rng, -1, 1);
      auto g = random_vec(N * cfg.out_dim(), rng, -1, 1);
      auto gx = random_vec(N * cfg.out_dim(), rng, -1, 1);
      std::vector<double> dt(cfg.param_count(), 0.0), dx(N * 3), dt_g = dt, dx_g(N * 3),
          dt_gx = dt, dx_gx(N * 3), dt_n = dt, dx_n(N * 3);
      HashGridWorkspace<double> ws;
      hashgrid_backward(dt.data(), dx.data(), g.data(), x.data(), table.data(), N, cfg, ws, gx.data());
      hashgrid_backward(dt_g.data(), dx_g.data(), g.data(), x.data(), table.data(), N, cfg, ws);
      hashgrid_backward(dt_gx.data(), dx_gx.data(), gx.data(), x.data(), table.data(), N, cfg, ws);
      INFO("smooth " << smooth << ", " << threads << " thread(s)");
      CHECK(dt == dt_g);
      CHECK(dx == dx_gx);
      CHECK(clearly_differs(vec_rel(dx, dx_g), 1e-3));  // the two really differ
      hashgrid_backward_naive(dt_n.data(), dx_n.data(), g.data(), x.data(), table.data(), N, cfg,
                              gx.data());
      CHECK(vec_rel(dt, dt_n) < 1e-13);
      CHECK(vec_rel(dx, dx_n) < 1e-12);
      // No table gradient (frozen tables): the same d_x, bit for bit, and nothing scattered.
      std::vector<double> dx_only(N * 3);
      hashgrid_backward((double*)nullptr, dx_only.data(), g.data(), x.data(), table.data(), N, cfg,
                        ws, gx.data());
      CHECK(dx_only == dx);
    }
}

TEST_CASE("hash grid at vertices, at 0 and 1, outside [0,1], NaN: exact, finite, in bounds",
          "[hashgrid][hard]") {
  // Config with an integer scale 16 (base 17, one level): x = (2k+1)/32 gives p = k + 1
  // exactly, so the output must equal the vertex's table row bit for bit. Dense (2^13 ≥ 17³)
  // and hashed (2^9) variants.
  for (int log2_table : {13, 9}) {
    HashGridConfig cfg;
    cfg.levels = 1; cfg.base_res = 17; cfg.max_res = 17; cfg.log2_table = log2_table;
    auto L0 = hashgrid_level(cfg, 0);
    REQUIRE(L0.scale == 16.0);
    REQUIRE(L0.dense == (log2_table == 13));
    Rng rng(3);
    auto table = random_vec(cfg.param_count(), rng, -1, 1);
    for (int kx : {0, 5, 14}) for (int ky : {1, 7}) for (int kz : {2, 15}) {
      double x[3] = {(2 * kx + 1) / 32.0, (2 * ky + 1) / 32.0, (2 * kz + 1) / 32.0}, out[2];
      hashgrid_forward(out, x, table.data(), 1, cfg);
      uint32_t e = hashgrid_vertex_index(kx + 1, ky + 1, kz + 1, L0, cfg.table_size());
      if (L0.dense) REQUIRE(e == uint32_t((kx + 1) + (ky + 1) * 17 + (kz + 1) * 289));
      CHECK(out[0] == table[e * 2 + 0]);
      CHECK(out[1] == table[e * 2 + 1]);
    }
  }

  // Outside [0,1] (and NaN/inf) equals the clamped input exactly; the gradient along a
  // clamped axis is 0, along an inside axis it is not. Table and d_table are embedded between
  // guard bands: NaN before/after the table (any out-of-bounds read poisons the output) and a
  // sentinel around d_table (any out-of-bounds write changes it).
  const double inf = std::numeric_limits<double>::infinity(), nan = std::nan("");
  HashGridConfig cfgs[] = {HashGridConfig{}, mixed_config()};
  for (auto& cfg : cfgs) {
    const int64_t P = cfg.param_count(), G = 4096;
    Rng rng(9);
    std::vector<double> tbuf(P + 2 * G, nan), dbuf(P + 2 * G, 12345.0);
    auto tv = random_vec(P, rng, -1, 1);
    std::copy(tv.begin(), tv.end(), tbuf.begin() + G);
    std::fill(dbuf.begin() + G, dbuf.begin() + G + P, 0.0);
    const double* table = tbuf.data() + G;
    double* d_table = dbuf.data() + G;
    std::vector<double> xs = {-0.3, 0.4, 0.7,   1.7, 0.4, 0.7,   0, 0.4, 0.7,   1, 0.4, 0.7,
                              nan, 0.4, 0.7,    -inf, 1, inf,    1, 1, 1,       0, 0, 0,
                              1e30, -1e30, 0.5};
    std::vector<double> cl = {0, 0.4, 0.7,      1, 0.4, 0.7,     0, 0.4, 0.7,   1, 0.4, 0.7,
                              0, 0.4, 0.7,      0, 1, 1,         1, 1, 1,       0, 0, 0,
                              1, 0, 0.5};
    const int64_t N = int64_t(xs.size() / 3);
    const int D = cfg.out_dim();
    std::vector<double> o(N * D), oc(N * D), on(N * D), g(N * D), dx(N * 3), dxn(N * 3);
    auto gg = random_vec(N * D, rng, -1, 1);
    hashgrid_forward(o.data(), xs.data(), table, N, cfg);
    hashgrid_forward(oc.data(), cl.data(), table, N, cfg);
    hashgrid_forward_naive(on.data(), xs.data(), table, N, cfg);
    for (int64_t i = 0; i < N * D; ++i) {
      REQUIRE(std::isfinite(o[i]));
      CHECK(o[i] == oc[i]);
      CHECK(std::abs(o[i] - on[i]) <= 1e-13);
    }
    HashGridWorkspace<double> ws;
    hashgrid_backward(d_table, dx.data(), gg.data(), xs.data(), table, N, cfg, ws);
    std::vector<double> dtn(P, 0.0);
    hashgrid_backward_naive(dtn.data(), dxn.data(), gg.data(), xs.data(), table, N, cfg);
    for (int64_t i = 0; i < G; ++i) {
      REQUIRE(dbuf[i] == 12345.0);
      REQUIRE(dbuf[G + P + i] == 12345.0);
    }
    for (int64_t i = 0; i < P; ++i) REQUIRE(std::isfinite(d_table[i]));
    for (int64_t i = 0; i < N * 3; ++i) {
      REQUIRE(std::isfinite(dx[i]));
      CHECK(std::abs(dx[i] - dxn[i]) <= 1e-12 * (1 + std::abs(dxn[i])));
      const double v = xs[i];
      const bool inside = v >= 0 && v <= 1;
      if (!inside) CHECK(dx[i] == 0.0);
      else CHECK(dx[i] != 0.0);  // random table: a non-zero slope on every inside axis
    }
    CHECK(vec_rel(std::vector<double>(d_table, d_table + P), dtn) < 1e-13);
  }
}

TEST_CASE("hash grid collisions: a shared entry receives the SUM of both contributions",
          "[hashgrid][hard]") {
  // One hashed level, scale 32, table 2^4: index bits depend only on the low 4 bits of each
  // coordinate (primes are odd), so vertex (cx + 16, cy, cz) lands on the entry of (cx, cy, cz).
  HashGridConfig cfg;
  cfg.levels = 1; cfg.base_res = 33; cfg.max_res = 33; cfg.log2_table = 4; cfg.features = 2;
  auto L0 = hashgrid_level(cfg, 0);
  REQUIRE(L0.scale == 32.0);
  REQUIRE_FALSE(L0.dense);
  // A in cell (1,2,3), B in cell (17,2,3): p = 32x + 0.5.
  const double xa[3] = {(1.3 - 0.5) / 32, (2.6 - 0.5) / 32, (3.2 - 0.5) / 32};
  const double xb[3] = {(17.7 - 0.5) / 32, (2.25 - 0.5) / 32, (3.8 - 0.5) / 32};
  const uint32_t e = hashgrid_vertex_index(1, 2, 3, L0, 16);
  REQUIRE(hashgrid_vertex_index(17, 2, 3, L0, 16) == e);  // distinct vertices, one entry
  Rng rng(4);
  auto table = random_vec(cfg.param_count(), rng, -1, 1);
  const double ga[2] = {0.7, -1.3}, gb[2] = {-0.4, 0.9};
  auto grad_of = [&](std::vector<double> x, std::vector<double> g) {
    std::vector<double> dt(cfg.param_count(), 0.0);
    HashGridWorkspace<double> ws;
    hashgrid_backward(dt.data(), (double*)nullptr, g.data(), x.data(), table.data(),
                      int64_t(x.size() / 3), cfg, ws);
    return dt;
  };
  auto dA = grad_of({xa[0], xa[1], xa[2]}, {ga[0], ga[1]});
  auto dB = grad_of({xb[0], xb[1], xb[2]}, {gb[0], gb[1]});
  auto dAB = grad_of({xa[0], xa[1], xa[2], xb[0], xb[1], xb[2]}, {ga[0], ga[1], gb[0], gb[1]});
  // Hand values: every corner k of A and of B with index e contributes w_k·g (frac from p).
  auto hand = [&](const double* x, const double* g, int f) {
    double s = 0;
    uint32_t c[3];
    double fr[3];
    for (int d = 0; d < 3; ++d) {
      double p = 32 * x[d] + 0.5;
      c[d] = uint32_t(std::floor(p));
      fr[d] = p - std::floor(p);
    }
    for (int k = 0; k < 8; ++k) {
      int b0 = k & 1, b1 = (k >> 1) & 1, b2 = k >> 2;
      if (hashgrid_vertex_index(c[0] + b0, c[1] + b1, c[2] + b2, L0, 16) != e) continue;
      s += (b0 ? fr[0] : 1 - fr[0]) * (b1 ? fr[1] : 1 - fr[1]) * (b2 ? fr[2] : 1 - fr[2]) * g[f];
    }
    return s;
  };
  for (int f = 0; f < 2; ++f) {
    const double a = hand(xa, ga, f), b = hand(xb, gb, f);
    REQUIRE(std::abs(a) > 0.01);
    REQUIRE(std::abs(b) > 0.01);
    CHECK(dA[e * 2 + f] == Approx(a).epsilon(1e-14));
    CHECK(dB[e * 2 + f] == Approx(b).epsilon(1e-14));
    CHECK(dAB[e * 2 + f] == Approx(a + b).epsilon(1e-14));
  }
  // And every entry of the pair's gradient is the sum of the singles.
  for (size_t i = 0; i < dAB.size(); ++i) CHECK(dAB[i] == Approx(dA[i] + dB[i]).margin(1e-15));
}

TEST_CASE("hash grid batches of size 0 and 1", "[hashgrid][hard]") {
  HashGridConfig cfg;
  Rng rng(8);
  auto table = random_vec(cfg.param_count(), rng, -1, 1);
  HashGridWorkspace<double> ws;
  // N = 0: nothing is written, d_table unchanged.
  std::vector<double> out(cfg.out_dim(), 42.0), dt(cfg.param_count(), 3.0), dx(3, 42.0);
  double x0[3] = {0.5, 0.5, 0.5};
  hashgrid_forward(out.data(), x0, table.data(), 0, cfg);
  hashgrid_backward(dt.data(), dx.data(), out.data(), x0, table.data(), 0, cfg, ws);
  for (double v : out) CHECK(v == 42.0);
  for (double v : dt) CHECK(v == 3.0);
  for (double v : dx) CHECK(v == 42.0);
  // N = 1: gradients match central differences (inputs off faces by construction).
  auto x = off_face_inputs(cfg, 1, rng);
  auto g = random_vec(cfg.out_dim(), rng, -1, 1);
  std::fill(dt.begin(), dt.end(), 0.0);
  hashgrid_backward(dt.data(), dx.data(), g.data(), x.data(), table.data(), 1, cfg, ws);
  auto loss = [&] {
    hashgrid_forward(out.data(), x.data(), table.data(), 1, cfg);
    return dot(g, out);
  };
  double ex = worst_grad_error(x, dx, loss, 1e-5);
  std::vector<size_t> idx;
  for (size_t i = 0; i < dt.size(); ++i) if (dt[i] != 0) idx.push_back(i);
  CHECK(idx.size() >= 16 * 2 * 4);  // ≥ 4 distinct entries per level survive collisions
  double et = worst_grad_error(table, dt, loss, 0.5, idx);  // linear in the table
  HCC_TEST_PRINTF("[hashgrid][hard] N=1: d_x worst %.2e, d_table worst %.2e (tol 1e-6)\n", ex, et);
  CHECK(ex < 1e-6);
  CHECK(et < 1e-6);
}

// kernels/hash_grid.h, GatherMode::kAuto: the default measures both gathers once (on its first
// forward) and keeps the faster; whichever it keeps, the forward's values are the forced
// gathers' bit for bit, and the choice does not change within the process.
TEST_CASE("hash grid: the default gather (measured once) gives the forced gathers' values",
          "[hashgrid][simd]") {
  HashGridConfig cfg{16, 2, 9, 16, 512, true};
  const int64_t N = 3000;
  Rng rng(77);
  std::vector<float> table(cfg.param_count()), x(N * 3);
  for (float& v : table) v = float(rng.uniform(-1, 1));
  for (float& v : x) v = float(rng.uniform(-0.1, 1.1));
  const int64_t D = cfg.out_dim();
  auto run = [&](GatherMode m) {
    hashgrid_set_gather(m);
    std::vector<float> out(N * D), jac(N * 3 * D);
    hashgrid_forward(out.data(), x.data(), table.data(), N, cfg, jac.data());
    out.insert(out.end(), jac.begin(), jac.end());
    return out;
  };
  const std::vector<float> a = run(GatherMode::kAuto);
  const bool choice = hashgrid_simd_gather();
  INFO("the default gather on this CPU: " << (choice ? "SIMD" : "scalar"));
  const std::vector<float> s = run(GatherMode::kScalar), v = run(GatherMode::kSimd);
  hashgrid_set_gather(GatherMode::kAuto);
  CHECK(std::memcmp(a.data(), s.data(), a.size() * sizeof(float)) == 0);
  CHECK(std::memcmp(a.data(), v.data(), a.size() * sizeof(float)) == 0);
  CHECK(hashgrid_simd_gather() == choice);  // measured once: the same answer again
  if (!hashgrid_has_simd_gather()) CHECK_FALSE(choice);
  hashgrid_set_gather(GatherMode::kScalar);
  CHECK_FALSE(hashgrid_simd_gather());
  hashgrid_set_gather(GatherMode::kSimd);
  CHECK(hashgrid_simd_gather() == hashgrid_has_simd_gather());
  hashgrid_set_gather(GatherMode::kAuto);
}

TEST_CASE("hash grid float build agrees with the double build", "[hashgrid][float]") {
  // Same (float-representable) inputs and table in both; off faces so both precisions pick
  // the same cells. Tolerance 1e-4 relative to each buffer's largest magnitude: in float,
  // p = scale·x + 0.5 fixes frac only to ~scale·2^-24 ≈ 3e-5 at the finest level (scale 511),
  // so weights move by ~3e-5 and out by ~3e-5 × (neighbouring table differences ≈ |table|).
  // The grid field's smooth position gradient too: its float weights are polynomials
  // (smooth_weight), evaluated 16 points a vector by level_dx.
  HashGridConfig smooth{16, 2, 15, 16, 512, true};
  for (auto cfg : {HashGridConfig{}, mixed_config(), smooth}) {
    const int64_t N = 4000;
    Rng rng(31);
    auto xd = cast<double>(cast<float>(off_face_inputs(cfg, N, rng)));
    std::vector<double> td(cfg.param_count());
    hashgrid_init_table(td.data(), cfg, rng);  // production init, ±1e-4
    td = cast<double>(cast<float>(td));
    auto gd = cast<double>(cast<float>(random_vec(N * cfg.out_dim(), rng, -1, 1)));
    std::vector<double> od(N * cfg.out_dim()), dtd(cfg.param_count(), 0.0), dxd(N * 3);
    HashGridWorkspace<double> wsd;
    hashgrid_forward(od.data(), xd.data(), td.data(), N, cfg);
    hashgrid_backward(dtd.data(), dxd.data(), gd.data(), xd.data(), td.data(), N, cfg, wsd);
    auto xf = cast<float>(xd), tf = cast<float>(td), gf = cast<float>(gd);
    std::vector<float> of(od.size()), dtf(dtd.size(), 0.f), dxf(dxd.size());
    HashGridWorkspace<float> wsf;
    hashgrid_forward(of.data(), xf.data(), tf.data(), N, cfg);
    hashgrid_backward(dtf.data(), dxf.data(), gf.data(), xf.data(), tf.data(), N, cfg, wsf);
    double eo = vec_rel(of, od), et = vec_rel(dtf, dtd), ex = vec_rel(dxf, dxd);
    HCC_TEST_PRINTF("[hashgrid][float] levels=%d: out %.1e d_table %.1e d_x %.1e (tol 1e-4 each)\n",
                cfg.levels, eo, et, ex);
    CHECK(eo < 1e-4);
    CHECK(et < 1e-4);
    CHECK(ex < 1e-4);
  }
}

TEST_CASE("hash grid backward, positions only (frozen table): the d_x of the full backward, "
          "bitwise, at 1 and 2 threads, several blocks", "[hashgrid][exact]") {
  // Eval's test-pose refinement calls hashgrid_backward with d_table = null: the gather pass
  // then only forms the corner sums, and level_dx does the rest. It must be the d_x the
  // training step gets, for the exact and the smooth gradient.
  test::ThreadGuard guard;
  for (bool smooth_dx : {false, true}) {
    HashGridConfig cfg{16, 2, 15, 16, 512, smooth_dx};
    const int64_t N = 9000;  // several blocks of 256 (kBlock) a thread, the last one partial
    Rng rng(78);
    auto x = cast<float>(random_vec(N * 3, rng, -0.1, 1.1));  // some clamped coordinates
    std::vector<float> table(cfg.param_count());
    hashgrid_init_table(table.data(), cfg, rng);
    auto g = cast<float>(random_vec(N * cfg.out_dim(), rng, -1, 1));
    for (int threads : {1, 2}) {
      set_num_threads(threads);
      HashGridWorkspace<float> ws;
      std::vector<float> dt(cfg.param_count(), 0.f), dx_full(N * 3, 0.f), dx_frozen(N * 3, 5.f);
      hashgrid_backward(dt.data(), dx_full.data(), g.data(), x.data(), table.data(), N, cfg, ws);
      hashgrid_backward((float*)nullptr, dx_frozen.data(), g.data(), x.data(), table.data(), N, cfg, ws);
      INFO("smooth " << smooth_dx << ", " << threads << " threads");
      CHECK(dx_frozen == dx_full);
      double mag = 0;
      for (float v : dx_frozen) mag = std::max(mag, double(std::abs(v)));
      CHECK(mag > 0);
    }
  }
}

TEST_CASE("hash grid backward: 1 thread equals 2 threads; workspace reused", "[hashgrid][hard]") {
  test::ThreadGuard guard;
  HashGridConfig cfg;
  const int64_t N = 20000;
  Rng rng(77);
  auto x = cast<float>(random_vec(N * 3, rng, 0, 1));
  std::vector<float> table(cfg.param_count());
  hashgrid_init_table(table.data(), cfg, rng);
  auto g = cast<float>(random_vec(N * cfg.out_dim(), rng, -1, 1));
  auto run = [&](int threads, HashGridWorkspace<float>& ws, std::vector<float>& dt,
                 std::vector<float>& dx) {
    set_num_threads(threads);
    dt.assign(cfg.param_count(), 0.5f);  // non-zero prior: the kernel adds to it
    dx.assign(N * 3, 0.f);
    hashgrid_backward(dt.data(), dx.data(), g.data(), x.data(), table.data(), N, cfg, ws);
  };
  HashGridWorkspace<float> ws;
  std::vector<float> dt1, dx1, dt2, dx2, dt2b, dx2b;
  run(1, ws, dt1, dx1);
  run(2, ws, dt2, dx2);
  const float* buf0 = ws.per_thread[0].data();
  run(2, ws, dt2b, dx2b);
  CHECK(ws.per_thread[0].data() == buf0);  // grow-only: no reallocation on reuse
  CHECK(dx1 == dx2);    // d_x is per point: bitwise independent of the split
  CHECK(dt2 == dt2b);   // same thread count: bitwise reproducible
  double et = vec_rel(dt1, dt2);
  HCC_TEST_PRINTF("[hashgrid] d_table 1 vs 2 threads: rel %.1e (tol 1e-5)\n", et);
  CHECK(et < 1e-5);
  CHECK(clearly_differs(vec_rel(dt1, std::vector<float>(dt1.size(), 0.5f)), 1e-3));  // real gradient added
}

// hashgrid_scatter_level: the data-parallel step scatters the table gradient one level at a
// time over all points (model/step.cpp, StepOptions::level_scatter). Over every level it must be
// the one-thread fused backward's table gradient bit for bit — the same points in the same
// order, the same corners, the same arithmetic — on a grid with dense and hashed levels, a table
// small enough for collisions (2^5 rows against up to 32^3 vertices), points at vertices, at 0
// and 1, outside [0, 1] and NaN, a non-zero prior (the kernel adds), F = 2 and the general F.
TEST_CASE("hash grid scatter one level at a time: the fused backward's table gradient, bit for bit",
          "[hashgrid][exact][hard]") {
  test::ThreadGuard guard(1);
  for (int F : {2, 3}) {
    for (int log2t : {12, 5}) {
      HashGridConfig cfg = mixed_config_features(F);
      cfg.log2_table = log2t;
      INFO("F " << F << ", table 2^" << log2t);
      const int64_t N = 700;  // two full 256-point blocks and a partial one
      Rng rng(91 + F + log2t);
      auto x = cast<float>(random_vec(N * 3, rng, -0.05, 1.05));
      x[0] = 0.f; x[1] = 1.f; x[2] = 0.5f;  // a vertex of every level, the cube's faces
      x[3] = std::numeric_limits<float>::quiet_NaN();
      x[7] = -2.f; x[8] = 3.f;
      std::vector<float> table(cfg.param_count());
      hashgrid_init_table(table.data(), cfg, rng);
      const auto g = cast<float>(random_vec(N * cfg.out_dim(), rng, -1, 1));
      HashGridWorkspace<float> ws;
      std::vector<float> fused(cfg.param_count(), 0.25f), split(cfg.param_count(), 0.25f);
      hashgrid_backward(fused.data(), (float*)nullptr, g.data(), x.data(), table.data(), N, cfg, ws);
      std::vector<float> gl(N * F);
      for (int l = cfg.levels - 1; l >= 0; --l) {  // any level order: each writes its own rows
        for (int64_t n = 0; n < N; ++n)
          for (int f = 0; f < F; ++f) gl[n * F + f] = g[n * cfg.out_dim() + l * F + f];
        hashgrid_scatter_level(split.data(), gl.data(), x.data(), N, cfg, l);
      }
      CHECK(std::memcmp(split.data(), fused.data(), sizeof(float) * split.size()) == 0);
      // Not vacuous: the gradient moved entries of every level away from the prior.
      const int64_t per_level = cfg.table_size() * F;
      for (int l = 0; l < cfg.levels; ++l) {
        int64_t moved = 0;
        for (int64_t i = 0; i < per_level; ++i) moved += split[l * per_level + i] != 0.25f;
        INFO("level " << l);
        CHECK(moved > 0);
      }
    }
  }
}

// --grid-decay: R = λ Σ_l mean_l(θ²). Its gradient is checked by central differences in double
// (tolerance 1e-8 relative: R is quadratic, so the difference quotient is exact up to rounding),
// it is ADDED to the data gradient already in d_table, levels are normalised by their own size,
// and λ = 0 leaves d_table bit for bit.
TEST_CASE("hash grid decay: value, gradient by central differences, added to the data gradient",
          "[hashgrid][grad][decay]") {
  HashGridConfig cfg = mixed_config();
  cfg.log2_table = 6;  // 5 levels x 64 x 2: small enough to check every entry
  const int64_t n = cfg.param_count(), per_level = cfg.table_size() * cfg.features;
  Rng rng(31, 1);
  std::vector<double> table = random_vec(n, rng, -0.5, 0.5);
  table[0] = 0;                                             // a zero entry: gradient exactly 0
  table[per_level] = 1e-300;                                 // an underflowing square: finite
  const std::vector<double> data_grad = random_vec(n, rng, -1, 1);
  const double lambda = 0.37;
  std::vector<double> g = data_grad;
  const double r = hashgrid_decay(g.data(), table.data(), cfg, lambda);
  double want = 0;
  for (int l = 0; l < cfg.levels; ++l) {
    double sq = 0;
    for (int64_t i = 0; i < per_level; ++i) sq += table[l * per_level + i] * table[l * per_level + i];
    want += lambda * sq / double(per_level);
  }
  CHECK(r == Approx(want).epsilon(1e-14));
  const auto R = [&](const std::vector<double>& t) {
    std::vector<double> scratch(n, 0.0);
    return hashgrid_decay(scratch.data(), t.data(), cfg, lambda);
  };
  const double h = 1e-4;
  // The error is relative to max(|num|, 1% of the largest gradient): R sums every entry, so its
  // difference quotient has an absolute rounding floor ~ eps·R/h ≈ 1e-13, which near-zero entries'
  // tiny gradients (θ ≈ 1e-4) cannot be measured against.
  double largest = 0;
  for (int64_t i = 0; i < n; ++i) largest = std::max(largest, std::abs(g[i] - data_grad[i]));
  double worst = 0;
  for (int64_t i = 0; i < n; ++i) {
    std::vector<double> tp = table, tm = table;
    tp[i] += h;
    tm[i] -= h;
    const double num = (R(tp) - R(tm)) / (2 * h);
    const double ana = g[i] - data_grad[i];  // what the decay added
    hashcc::test::keep_worst(worst, std::abs(num - ana) / std::max(1e-2 * largest, std::abs(num)));
  }
  CHECK(worst < 1e-8);
  CHECK(g[0] == data_grad[0]);  // θ = 0: nothing added
  CHECK(std::isfinite(g[per_level]));
  // λ = 0: bitwise nothing.
  std::vector<double> g0 = data_grad;
  CHECK(hashgrid_decay(g0.data(), table.data(), cfg, 0.0) == 0.0);
  CHECK(g0 == data_grad);
  // Float agrees with double.
  std::vector<float> tf(table.begin(), table.end()), gf(n, 0.f);
  CHECK(hashgrid_decay(gf.data(), tf.data(), cfg, lambda) == Approx(want).epsilon(1e-6));
  for (int64_t i = 0; i < n; i += 7) CHECK(gf[i] == Approx(g[i] - data_grad[i]).epsilon(1e-5).margin(1e-12));
}

TEST_CASE("hash grid SIMD gather: the float forward's values and Jacobian bit for bit the scalar loop's, at "
          "every table size, batch size and hard input", "[hashgrid][simd][hard]") {
  // The F = 2 float forward gathers 8 (AVX-512) or 4 (AVX2) points' rows a corner in one
  // instruction, each lane running the scalar loop's arithmetic in its order; the points left
  // over (N not a multiple of the lanes) take the scalar loop. Every output's bits must equal
  // the scalar loop's: dense and hashed levels, a colliding 2^4 table, the CC branch's 2^9 (no
  // prefetch) and the grid field's 2^15 and 2^17 (prefetched), batches from 1 point to several
  // blocks of 256, 1 and 2 threads, inputs on vertices, faces, outside [0,1] and NaN; the
  // plain forward and the one that keeps the position Jacobian (smooth weights), its Jacobian too.
  if (!hashgrid_has_simd_gather()) {
    WARN("this build has no SIMD gather (neither AVX-512 nor AVX2): nothing to compare");
    return;
  }
  struct Case { int log2; int levels; double base, max; };
  const Case cases[] = {{4, 4, 4, 32}, {9, 16, 16, 512}, {12, 5, 4, 32}, {15, 16, 16, 512},
                        {17, 16, 16, 512}};
  const float nan = std::nanf(""), inf = std::numeric_limits<float>::infinity();
  const float hard[] = {0.f, 1.f, 0.5f, 1.f / 32, 31.f / 32, -0.25f, 1.5f, nan, inf, -inf};
  int64_t compared = 0;
  const int threads_before = num_threads();
  for (const Case& c : cases) {
    HashGridConfig cfg;
    cfg.levels = c.levels; cfg.log2_table = c.log2; cfg.base_res = c.base; cfg.max_res = c.max;
    Rng rng(uint64_t(41 + c.log2));
    std::vector<float> table(cfg.param_count());
    for (float& v : table) v = float(rng.uniform(-1, 1));
    for (int64_t N : {1, 3, 7, 8, 9, 255, 256, 257, 1030, 4099}) {
      std::vector<float> x(N * 3);
      for (int64_t i = 0; i < N * 3; ++i)
        x[i] = (i % 7 == 3) ? hard[(i / 7) % 10] : float(rng.uniform(0, 1));
      for (int t : {1, 2}) {
        set_num_threads(t);
        for (bool with_jac : {false, true}) {  // the plain forward, and the one keeping ∂out/∂x
          cfg.smooth_dx = with_jac;
          const int64_t D = cfg.out_dim();
          std::vector<float> a(N * D, -1.f), b(N * D, -2.f), ja, jb;
          if (with_jac) ja.assign(N * 3 * D, -3.f), jb.assign(N * 3 * D, -4.f);
          hashgrid_set_gather(GatherMode::kSimd);
          hashgrid_forward(a.data(), x.data(), table.data(), N, cfg, with_jac ? ja.data() : nullptr);
          hashgrid_set_gather(GatherMode::kScalar);
          hashgrid_forward(b.data(), x.data(), table.data(), N, cfg, with_jac ? jb.data() : nullptr);
          hashgrid_set_gather(GatherMode::kAuto);
          int64_t differ = 0, differ_jac = 0;
          for (size_t i = 0; i < a.size(); ++i)
            differ += std::memcmp(&a[i], &b[i], sizeof(float)) != 0;
          for (size_t i = 0; i < ja.size(); ++i)
            differ_jac += std::memcmp(&ja[i], &jb[i], sizeof(float)) != 0;
          INFO("2^" << c.log2 << ", " << N << " points, " << t << " thread(s), Jacobian "
                    << with_jac);
          CHECK(differ == 0);
          CHECK(differ_jac == 0);
          compared += int64_t(a.size() + ja.size());
        }
      }
    }
  }
  set_num_threads(threads_before);
  CHECK(compared > 0);
}
