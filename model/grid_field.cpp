// model/grid_field.cpp — forward and backward of the grid radiance field (see grid_field.h,
// docs/math/grid_field.md).
#include "model/grid_field.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/error.h"
#include "kernels/hash_grid.h"
#include "model/layers.h"

namespace hashcc {

using namespace layers;

namespace {

// Level weights w_l(α) (all 1 when α < 0: no curriculum), broadcast over the F features of
// each level: scale (N, L·F) in place. Used on the encoding (forward) and on its gradient.
template <class T>
void scale_levels(T* v, int64_t N, const HashGridConfig& g, double alpha) {
  if (alpha < 0) return;
  T w[64];
  c2f_band_weights(w, g.levels, alpha);
  const int F = g.features, LF = g.out_dim();
  parallel_for(N, [&](int64_t n) {
    T* row = v + n * LF;
    for (int l = 0; l < g.levels; ++l)
      for (int f = 0; f < F; ++f) row[l * F + f] *= w[l];
  }, 1024);
}

}  // namespace

template <class T>
void grid_field_reserve(ModelCache<T>& c, const ModelConfig& cfg, int R, int S) {
  const GridFieldConfig& g = cfg.gf;
  const int64_t N = int64_t(R) * S, LF = g.grid.out_dim(), E = cfg.dir_dim(), G = g.geo;
  ensure(c.gx, N * 3);
  ensure(c.genc, N * LF);
  ensure(c.gdh, N * g.hidden);
  ensure(c.gdo, N * (1 + G));
  ensure(c.sigma_raw, N);
  ensure(c.dir_ray, int64_t(R) * E);
  ensure(c.d_dir_pt, int64_t(R) * E);
  ensure(c.rgb_in, N * (G + E));
  ensure(c.hid, N * g.rgb_hidden);
  ensure(c.color, N * 3);
  // g1/g2: the widest gradient of either MLP, and of the CC branch (model_backward shares them).
  int64_t wide = std::max({LF, int64_t(g.hidden), 1 + G, G + E, int64_t(g.rgb_hidden), int64_t(3)});
  if (cfg.has_cc()) wide = std::max({wide, int64_t(cfg.cc_hidden), int64_t(cfg.cc.out_dim())});
  ensure(c.g1, N * wide);
  ensure(c.g2, N * wide);
  ensure(c.gcam1, N * std::max(int64_t(g.hidden), 1 + G));
  ensure(c.gcam2, N * std::max(LF, 1 + G));
}

int64_t grid_field_floats(const ModelConfig& cfg, int R, int S) {
  // grid_field_reserve's buffers, in its order.
  const GridFieldConfig& g = cfg.gf;
  const int64_t N = int64_t(R) * S, LF = g.grid.out_dim(), E = cfg.dir_dim(), G = g.geo;
  int64_t wide = std::max({LF, int64_t(g.hidden), 1 + G, G + E, int64_t(g.rgb_hidden), int64_t(3)});
  if (cfg.has_cc()) wide = std::max({wide, int64_t(cfg.cc_hidden), int64_t(cfg.cc.out_dim())});
  return N * (3 + LF + g.hidden + (1 + G) + 1) + 2 * int64_t(R) * E +
         N * ((G + E) + g.rgb_hidden + 3 + 2 * wide) +
         N * (std::max(int64_t(g.hidden), 1 + G) + std::max(LF, 1 + G));
}

template <class T>
void grid_field_forward(ModelCache<T>& c, const NetView<T>& net, const ModelIn<T>& in) {
  const T *p = net.params, *x = in.x, *dir = in.dir;
  const ModelConfig& cfg = net.cfg;
  const ModelLayout& L = net.L;
  const int R = in.R, S = in.S;
  const GridFieldConfig& g = cfg.gf;
  const int64_t N = int64_t(R) * S;
  [[maybe_unused]] const int LF = g.grid.out_dim();
  const int G = g.geo, E = cfg.dir_dim();
  StageClock clk(c.prof, kStageEncode);
  // u = (x+1)/2, NOT clamped here: the kernel clamps, and its d_x is 0 where the clamp acts.
  T* gx = c.gx.data();
  parallel_for(N * 3, [&](int64_t i) { gx[i] = (x[i] + T(1)) * T(0.5); }, 4096);
  c.gjac_valid = in.keep_jac;  // the position Jacobian too when a backward will want d_x
  if (in.keep_jac) ensure(c.gjac, N * 3 * LF);
  hashgrid_forward(c.genc.data(), gx, p + L.grid_table, N, g.grid,
                   in.keep_jac ? c.gjac.data() : (T*)nullptr);                 // (N, L·F)
  scale_levels(c.genc.data(), N, g.grid, cfg.pos_c2f_alpha);
  HCC_DEBUG_FINITE(c.genc.data(), N * LF, "grid field: hashgrid_forward");
  encode_dir(c.dir_ray.data(), dir, R, cfg);                                    // (R, E)

  clk.to(kStageMlpFwd);
  dense_relu(c.gdh.data(), c.genc.data(), p, L.gd0, N);                        // (N, 64)
  dense(c.gdo.data(), c.gdh.data(), p, L.gd1, N);                              // (N, 1+G)
  HCC_DEBUG_FINITE(c.gdo.data(), N * (1 + G), "grid field: density MLP");
  const T zmax = T(kGridMaxLogDensity);
  parallel_for(N, [&](int64_t n) {
    const T* o = c.gdo.data() + n * (1 + G);
    c.sigma_raw[n] = std::exp(std::min(o[0], zmax));                          // σ_raw = exp(z)
    T* row = c.rgb_in.data() + n * (G + E);                                    // [geo, dir enc]
    std::memcpy(row, o + 1, sizeof(T) * G);
    std::memcpy(row + G, c.dir_ray.data() + (n / S) * E, sizeof(T) * E);
  }, 1024);
  dense_relu(c.hid.data(), c.rgb_in.data(), p, L.gr0, N);                      // (N, 64)
  dense(c.color.data(), c.hid.data(), p, L.gr1, N);
  sigmoid_forward(c.color.data(), c.color.data(), N * 3);                      // c (N, 3)
  HCC_DEBUG_FINITE(c.color.data(), N * 3, "grid field: colour MLP");
}

template <class T>
void grid_field_backward(const ModelInGrads<T>& d_in, const ModelOutGrads<T>& d_out,
                         ModelCache<T>& c, const NetView<T>& net, const ModelIn<T>& in) {
  T *d_params = d_in.d_params, *d_x = d_in.d_x, *d_dir = d_in.d_dir;
  const T *d_sigma_raw = d_out.d_sigma_raw, *d_color = d_out.d_color;
  const T* p = net.params;
  const ModelConfig& cfg = net.cfg;
  const ModelLayout& L = net.L;
  const GridFieldConfig& g = cfg.gf;
  const int R = c.R, S = c.S;
  const int64_t N = int64_t(R) * S;
  [[maybe_unused]] const int LF = g.grid.out_dim();
  const int G = g.geo, E = cfg.dir_dim();
  T* g1 = c.g1.data();
  T* g2 = c.g2.data();
  StageClock clk(c.prof, kStageMlpBwd);
  // Colour MLP: sigmoid → gr1 → ReLU → gr0 → [d_geo, d_dir_enc].
  sigmoid_backward(g1, d_color, c.color.data(), N * 3);                        // (N, 3)
  dense_bwd(g2, d_params, g1, c.hid.data(), p, L.gr1, N);             // (N, 64)
  dense_relu_bwd(g1, d_params, g2, c.hid.data(), c.rgb_in.data(), p, L.gr0, N);  // (N, G+E)
  HCC_DEBUG_FINITE(g1, N * (G + E), "grid field: colour MLP backward");
  if (d_dir) {
    clk.to(kStageEncode);
    // One direction a ray: Σ over its samples of the encoding gradient → (R, E) → dL/ddir.
    T* d_enc = c.d_dir_pt.data();
    sum_dir_grad(d_enc, g1, R, S, G, E);
    encode_dir_backward(d_dir, d_enc, in.dir, R, cfg);
    clk.to(kStageMlpBwd);
  }
  // d[z | geo] (N, 1+G): dz = dσ_raw · σ_raw below the clamp (d exp(z)/dz = exp(z)), 0 above;
  // d_geo = the first G columns of the colour MLP's input gradient. With d_sigma_raw_x, the
  // same for the camera's losses into gcam2 (the colour gradient is the same for both).
  const T zmax = T(kGridMaxLogDensity);
  const T* d_sigma_x = d_x ? d_out.d_sigma_raw_x : nullptr;
  T* gx2 = d_sigma_x ? c.gcam2.data() : nullptr;
  parallel_for(N, [&](int64_t n) {
    const bool below = c.gdo[n * (1 + G)] < zmax;
    T* o = g2 + n * (1 + G);
    o[0] = below ? d_sigma_raw[n] * c.sigma_raw[n] : T(0);
    std::memcpy(o + 1, g1 + n * (G + E), sizeof(T) * G);
    if (gx2) {
      T* ox = gx2 + n * (1 + G);
      ox[0] = below ? d_sigma_x[n] * c.sigma_raw[n] : T(0);
      std::memcpy(ox + 1, g1 + n * (G + E), sizeof(T) * G);
    }
  }, 1024);
  dense_bwd(g1, d_params, g2, c.gdh.data(), p, L.gd1, N);             // (N, 64)
  dense_relu_bwd(g2, d_params, g1, c.gdh.data(), c.genc.data(), p, L.gd0, N);  // (N, L·F)
  HCC_DEBUG_FINITE(g2, N * LF, "grid field: density MLP backward");
  if (gx2) {  // the camera's losses: input gradients only (d_params null)
    dense_bwd(c.gcam1.data(), (T*)nullptr, gx2, c.gdh.data(), p, L.gd1, N);
    dense_relu_bwd(gx2, (T*)nullptr, c.gcam1.data(), c.gdh.data(), c.genc.data(), p, L.gd0,
                   N);                                                         // (N, L·F)
  }
  clk.to(kStageEncode);
  scale_levels(g2, N, g.grid, cfg.pos_c2f_alpha);                              // × w_l(α)
  if (gx2) scale_levels(gx2, N, g.grid, cfg.pos_c2f_alpha);
  T* d_table = d_params ? d_params + L.grid_table : nullptr;  // null: no scatter (eval's frozen field)
  T* d_u = d_x ? g1 : nullptr;  // g1 is free again: dL/du (N, 3)
  // dL/du from the forward's Jacobian when it kept one (one dot product a point and axis); the
  // table's scatter alone is left to the kernel. Otherwise the kernel gathers the table again.
  const bool from_jac = d_u && c.gjac_valid;
  if (d_table && c.defer_g) {
    // The scatter is the caller's, split over levels (ModelCache::defer_g): hand it this
    // chunk's points and encoding gradient, level-major; the kernel below computes d_x alone.
    const int F = g.grid.features, Lv = g.grid.levels;
    std::memcpy(c.defer_x + c.defer_n0 * 3, c.gx.data(), sizeof(T) * N * 3);
    for (int l = 0; l < Lv; ++l) {
      T* dst = c.defer_g + (int64_t(l) * c.defer_n + c.defer_n0) * F;
      for (int64_t n = 0; n < N; ++n)
        for (int f = 0; f < F; ++f) dst[n * F + f] = g2[n * LF + l * F + f];
    }
    d_table = nullptr;
  }
  hashgrid_backward(d_table, from_jac ? (T*)nullptr : d_u, g2, c.gx.data(), p + L.grid_table, N,
                    g.grid, c.grid_ws, gx2 ? (const T*)gx2 : nullptr);
  if (from_jac) hashgrid_dx_from_jac(d_u, gx2 ? (const T*)gx2 : (const T*)g2, c.gjac.data(), N, g.grid);
  if (d_x) {
    // x = 2u − 1: dL/dx = dL/du / 2.
    parallel_for(N * 3, [&](int64_t i) { d_x[i] = d_u[i] * T(0.5); }, 4096);
    HCC_DEBUG_FINITE(d_x, N * 3, "grid field: hashgrid_backward (d_x)");
  }
}

#define HCC_INST(T)                                                                            \
  template void grid_field_reserve<T>(ModelCache<T>&, const ModelConfig&, int, int);          \
  template void grid_field_forward<T>(ModelCache<T>&, const NetView<T>&, const ModelIn<T>&);  \
  template void grid_field_backward<T>(const ModelInGrads<T>&, const ModelOutGrads<T>&,       \
                                       ModelCache<T>&, const NetView<T>&, const ModelIn<T>&);
HCC_INST(float)
HCC_INST(double)

}  // namespace hashcc
