// model/grid_field.cpp — forward and backward of the grid radiance field (see grid_field.h,
// docs/math/grid_field.md).
#include "model/grid_field.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/error.h"
#include "kernels/chunked_for.h"
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

// One block's activations of both MLPs (rows ≤ kDenseBlockRows): h (rows, 64) the density
// MLP's hidden layer, o (rows, 1+G) its output [z, geo], rin (rows, G+E) the colour MLP's input
// [geo, dir enc], hid (rows, 64) its hidden layer.
template <class T>
struct MlpBlock {
  T *h, *o, *rin, *hid;
};

struct MlpBlockTag;  // thread_scratch's tag: one block's activations and gradients

// A block's activations where the forward kept them (ModelCache::keep_mlp): rows from r0 of the
// cache's gdh, gdo, rgb_in and hid.
template <class T>
MlpBlock<T> kept_block(ModelCache<T>& c, int64_t r0, int H, int G, int E, int RH) {
  return {c.gdh.data() + r0 * H, c.gdo.data() + r0 * (1 + G), c.rgb_in.data() + r0 * (G + E),
          c.hid.data() + r0 * RH};
}

// A block's activations in scratch `sc` of kDenseBlockRows rows: h, o, rin, hid one after another
// (H + 1+G + G+E + RH floats a row).
template <class T>
MlpBlock<T> scratch_block(T* sc, int H, int G, int E) {
  const int64_t B = kDenseBlockRows;
  return {sc, sc + B * H, sc + B * (H + 1 + G), sc + B * (H + 1 + G + G + E)};
}

// Both MLPs' forward on rows [r0, r0 + rows) of the batch, up to the colour MLP's output
// layer: h, o, rin, hid into a (the layers lay[0..2] packed for the forward). The backward
// calls it again to recompute a block's activations: the same function on the same inputs, so
// the same values bit for bit.
template <class T>
void mlp_block_hidden(const MlpBlock<T>& a, const ModelCache<T>& c, const DenseLayer<T>* lay,
                      int64_t r0, int64_t rows, int64_t N, int LF, int G, int E, int S) {
  const T* enc = c.genc.data() + r0 * LF;
  const int64_t r1 = r0 + rows;
  dense_forward_block(a.h, enc, lay[0], rows, true, r1 < N ? enc + rows * LF : nullptr,
                      std::min(kDenseBlockRows, N - r1) * LF);           // (rows, 64)
  dense_forward_block(a.o, a.h, lay[1], rows, false);                    // (rows, 1+G)
  for (int64_t k = 0; k < rows; ++k) {                                   // [geo, dir enc]
    std::memcpy(a.rin + k * (G + E), a.o + k * (1 + G) + 1, sizeof(T) * G);
    std::memcpy(a.rin + k * (G + E) + G, c.dir_ray.data() + ((r0 + k) / S) * E, sizeof(T) * E);
  }
  dense_forward_block(a.hid, a.rin, lay[2], rows, true);                 // (rows, 64)
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
  // Both MLPs a block of 256 points at a time (kernels/dense.h, "One layer, block by block"):
  // each layer's input is the block the layer before just wrote, in per-thread scratch that
  // stays in L1/L2; of it only σ_raw and the colour leave the block (the backward recomputes
  // the rest: writing the 64-wide hidden layers out to memory and reading them back cost more
  // than computing them again, docs/performance.md). ModelCache::keep_mlp (the double build's
  // default: the gradient checks' kink detector reads them) keeps them in gdh, gdo, rgb_in and
  // hid instead. The same arithmetic as four batch-wide layers in the same chunks: the same
  // results bit for bit.
  DenseLayer<T>* lay = c.glayer;
  const LayerView* views[4] = {&L.gd0, &L.gd1, &L.gr0, &L.gr1};
  for (int k = 0; k < 4; ++k)
    dense_prepare(lay[k], p + views[k]->w, p + views[k]->b, views[k]->in, views[k]->out, true,
                  false);
  const int H = g.hidden, RH = g.rgb_hidden;
  const T zmax = T(kGridMaxLogDensity);
  parallel_chunks(N, kDenseBlockRows, [&](int64_t r0, int64_t r1) {
    const int64_t rows = r1 - r0, B = kDenseBlockRows;
    const int64_t act = H + (1 + G) + (G + E) + RH;  // activations a row
    const MlpBlock<T> a = c.keep_mlp ? kept_block(c, r0, H, G, E, RH)
                                     : scratch_block(thread_scratch<T, MlpBlockTag>(size_t(B * act)), H, G, E);
    mlp_block_hidden(a, c, lay, r0, rows, N, LF, G, E, S);
    for (int64_t k = 0; k < rows; ++k)                                   // σ_raw = exp(z)
      c.sigma_raw[r0 + k] = std::exp(std::min(a.o[k * (1 + G)], zmax));
    T* col = c.color.data() + r0 * 3;
    dense_forward_block(col, a.hid, lay[3], rows, false);
    sigmoid_forward(col, col, rows * 3);                                 // c (rows, 3)
  });
  HCC_DEBUG_FINITE(c.sigma_raw.data(), N, "grid field: density MLP");
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
  // Both MLPs' backward a block of 256 points at a time: the block's activations recomputed
  // (as the forward computed them, bit for bit) — or read back when the forward kept them
  // (ModelCache::keep_mlp) — then the layers' backward on them while they are in L1/L2. The
  // same results as batch-wide layers bit for bit: the same chunks, and each layer's d_W / d_b
  // partials added block by block in row order within fixed 4096-row slabs
  // (kernels/dense.h). What outlives the block goes to g1 (the colour input's gradient,
  // (N, G+E): its direction columns are summed per ray below), g2 (the encoding's, (N, L·F))
  // and gcam2 (the camera losses' encoding gradient, (N, L·F)).
  DenseLayer<T>* lay = c.glayer;
  DenseGradSlabs<T>* slabs = d_params ? c.gslabs : nullptr;
  const LayerView* views[4] = {&L.gd0, &L.gd1, &L.gr0, &L.gr1};
  for (int k = 0; k < 4; ++k) {
    dense_prepare(lay[k], p + views[k]->w, p + views[k]->b, views[k]->in, views[k]->out, k < 3,
                  true);
    if (slabs) dense_grads_begin(slabs[k], lay[k], N, true, true);
  }
  const int H = g.hidden, RH = g.rgb_hidden;
  // d[z | geo] (rows, 1+G): dz = dσ_raw · σ_raw below the clamp (d exp(z)/dz = exp(z)), 0
  // above; d_geo = the first G columns of the colour MLP's input gradient. With d_sigma_raw_x,
  // the same for the camera's losses (the colour gradient is the same for both), whose density
  // MLP backward is input gradients only.
  const T zmax = T(kGridMaxLogDensity);
  const T* d_sigma_x = d_x ? d_out.d_sigma_raw_x : nullptr;
  T* gx2 = d_sigma_x ? c.gcam2.data() : nullptr;
  parallel_chunks(N, kDenseSlabRows, [&](int64_t s0, int64_t s1) {
    // Per-thread block scratch: the recomputed activations, then dL/dc (rows, 3), dL/d hidden
    // (rows, 64) of either MLP, dL/d[z | geo] (rows, 1+G), and the camera pass's two.
    const int64_t B = kDenseBlockRows, W = std::max(H, RH);
    const int64_t act = H + (1 + G) + (G + E) + RH;
    T* sc = thread_scratch<T, MlpBlockTag>(size_t(B * (act + 3 + W + (1 + G) + W + (1 + G))));
    const MlpBlock<T> recomputed = scratch_block(sc, H, G, E);
    T* d_c = sc + B * act;
    T* d_hid = d_c + B * 3;
    T* d_o = d_hid + B * W;
    T* d_hx = d_o + B * (1 + G);
    T* d_ox = d_hx + B * W;
    for (int64_t r0 = s0; r0 < s1; r0 += B) {
      const int64_t rows = std::min(B, s1 - r0);
      const T* enc = c.genc.data() + r0 * LF;
      // The block's activations: the forward's, kept (keep_mlp), or computed again.
      const MlpBlock<T> a = c.keep_mlp ? kept_block(c, r0, H, G, E, RH) : recomputed;
      if (!c.keep_mlp) mlp_block_hidden(a, c, lay, r0, rows, N, LF, G, E, S);
      T* d_rin = g1 + r0 * (G + E);
      // Colour MLP: sigmoid → gr1 → ReLU → gr0 → [d_geo, d_dir_enc].
      sigmoid_backward(d_c, d_color + r0 * 3, c.color.data() + r0 * 3, rows * 3);
      dense_backward_block(d_hid, slabs ? &slabs[3] : nullptr, r0, (T*)nullptr, d_c,
                           (const T*)nullptr, a.hid, lay[3], rows);          // (rows, 64)
      dense_backward_block(d_rin, slabs ? &slabs[2] : nullptr, r0, d_hid, d_hid, a.hid, a.rin,
                           lay[2], rows);                                    // (rows, G+E)
      for (int64_t k = 0; k < rows; ++k) {
        const int64_t n = r0 + k;
        const bool below = a.o[k * (1 + G)] < zmax;
        d_o[k * (1 + G)] = below ? d_sigma_raw[n] * c.sigma_raw[n] : T(0);
        std::memcpy(d_o + k * (1 + G) + 1, d_rin + k * (G + E), sizeof(T) * G);
        if (gx2) {
          d_ox[k * (1 + G)] = below ? d_sigma_x[n] * c.sigma_raw[n] : T(0);
          std::memcpy(d_ox + k * (1 + G) + 1, d_rin + k * (G + E), sizeof(T) * G);
        }
      }
      // Density MLP: gd1 → ReLU → gd0 → dL/d encoding.
      dense_backward_block(d_hid, slabs ? &slabs[1] : nullptr, r0, (T*)nullptr, d_o,
                           (const T*)nullptr, a.h, lay[1], rows);            // (rows, 64)
      dense_backward_block(g2 + r0 * LF, slabs ? &slabs[0] : nullptr, r0, d_hid, d_hid, a.h, enc,
                           lay[0], rows);                                    // (rows, L·F)
      if (gx2) {  // the camera's losses: input gradients only
        dense_backward_block(d_hx, (DenseGradSlabs<T>*)nullptr, r0, (T*)nullptr, d_ox,
                             (const T*)nullptr, a.h, lay[1], rows);
        dense_backward_block(gx2 + r0 * LF, (DenseGradSlabs<T>*)nullptr, r0, d_hx, d_hx, a.h, enc,
                             lay[0], rows);
      }
    }
  });
  if (slabs)
    for (int k = 0; k < 4; ++k)
      dense_grads_end(d_params + views[k]->w, d_params + views[k]->b, slabs[k], lay[k]);
  HCC_DEBUG_FINITE(g1, N * (G + E), "grid field: colour MLP backward");
  HCC_DEBUG_FINITE(g2, N * LF, "grid field: density MLP backward");
  if (d_dir) {
    clk.to(kStageEncode);
    // One direction a ray: Σ over its samples of the encoding gradient → (R, E) → dL/ddir.
    T* d_enc = c.d_dir_pt.data();
    sum_dir_grad(d_enc, g1, R, S, G, E);
    encode_dir_backward(d_dir, d_enc, in.dir, R, cfg);
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
