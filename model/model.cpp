#include "model/model.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/error.h"
#include "kernels/chunked_for.h"
#include "kernels/dense.h"
#include "kernels/fourier.h"
#include "kernels/sh.h"
#include "model/grid_field.h"
#include "model/layers.h"

namespace hashcc {

using namespace layers;

namespace {
struct CcBlockTag;  // thread_scratch's tag: the CC MLP's per-block hidden layer (and its gradient)
}  // namespace

Variant parse_variant(const std::string& s) {
  if (s == "nerfmm") return Variant::nerfmm;
  if (s == "sh") return Variant::sh;
  if (s == "hashcc") return Variant::hashcc;
  throw Error("--model", "", fmt::format("unknown model '{}'", s), "nerfmm, sh or hashcc");
}

const char* variant_name(Variant v) {
  switch (v) {
    case Variant::nerfmm: return "nerfmm";
    case Variant::sh: return "sh";
    default: return "hashcc";
  }
}

Field parse_field(const std::string& s) {
  if (s == "mlp") return Field::mlp;
  if (s == "grid") return Field::grid;
  throw Error("--field", "", fmt::format("unknown field '{}'", s), "mlp or grid");
}

const char* field_name(Field f) { return f == Field::grid ? "grid" : "mlp"; }

int ModelConfig::dir_dim() const {
  return variant == Variant::nerfmm ? 3 * (1 + 2 * dir_bands) : sh_degree * sh_degree;
}

ModelConfig tiny_model_config(Variant v, Field f) {
  ModelConfig c;
  c.variant = v;
  c.field = f;
  c.gf.grid = HashGridConfig{4, 2, 6, 4, 32, false};
  c.gf.hidden = 8;
  c.gf.geo = 3;
  c.gf.rgb_hidden = 8;
  c.width = 16;
  c.rgb_width = 8;
  c.cc.levels = 4;
  c.cc.log2_table = 6;
  c.cc.base_res = 4;
  c.cc.max_res = 32;
  c.cc_hidden = 8;
  return c;
}

ModelLayout make_layout(const ModelConfig& cfg) {
  ModelLayout L;
  int64_t off = 0;
  auto add = [&](LayerView& lv, const std::string& name, int in, int out) {
    lv.name = name;
    lv.in = in;
    lv.out = out;
    lv.w = off;
    L.tensors.push_back({name + ".weight", {out, in}, off});
    off += int64_t(in) * out;
    lv.b = off;
    L.tensors.push_back({name + ".bias", {out}, off});
    off += out;
  };
  if (cfg.field == Field::grid) {
    const GridFieldConfig& g = cfg.gf;
    L.grid_table = off;
    L.tensors.push_back({"grid.table", {g.grid.levels, g.grid.table_size(), g.grid.features}, off});
    off += g.grid.param_count();
    add(L.gd0, "grid.density.0", g.grid.out_dim(), g.hidden);
    add(L.gd1, "grid.density.1", g.hidden, 1 + g.geo);
    add(L.gr0, "grid.rgb.0", g.geo + cfg.dir_dim(), g.rgb_hidden);
    add(L.gr1, "grid.rgb.1", g.rgb_hidden, 3);
  } else {
    const int W = cfg.width, P = cfg.pos_dim();
    for (int k = 0; k < 8; ++k)
      add(L.trunk[k], "trunk." + std::to_string(k), k == 0 ? P : (k == 4 ? W + P : W), W);
    add(L.density, "density", W, 1);
    add(L.feature, "feature", W, W);
    add(L.rgb_hidden, "rgb_hidden", W + cfg.dir_dim(), cfg.rgb_width);
    add(L.rgb, "rgb", cfg.rgb_width, 3);
  }
  if (cfg.has_cc()) {
    L.cc_table = off;
    L.tensors.push_back({"cc.table", {cfg.cc.levels, cfg.cc.table_size(), cfg.cc.features}, off});
    off += cfg.cc.param_count();
    add(L.cc0, "cc.0", cfg.cc.out_dim(), cfg.cc_hidden);
    add(L.cc1, "cc.1", cfg.cc_hidden, 3);
  }
  L.count = off;
  return L;
}

template <class T>
void c2f_band_weights(T* w, int L, double alpha) {
  for (int k = 0; k < L; ++k) {
    if (alpha < 0) { w[k] = T(1); continue; }
    double a = std::clamp(alpha - k, 0.0, 1.0);
    w[k] = T((1.0 - std::cos(M_PI * a)) / 2.0);
  }
}
template void c2f_band_weights<float>(float*, int, double);
template void c2f_band_weights<double>(double*, int, double);

template <class T>
void init_params(T* p, const ModelConfig& cfg, const ModelLayout& L, Rng& rng) {
  auto init_layer = [&](const LayerView& lv) {
    double bound = 1.0 / std::sqrt(double(lv.in));  // PyTorch nn.Linear default
    for (int64_t i = 0; i < int64_t(lv.in) * lv.out; ++i) p[lv.w + i] = T(rng.uniform(-bound, bound));
    for (int i = 0; i < lv.out; ++i) p[lv.b + i] = T(rng.uniform(-bound, bound));
  };
  if (cfg.field == Field::grid) {
    // Table ±1e-4 (instant-ngp), layers ±1/√fan_in; σ = exp(z) starts near e^density_init
    // everywhere (1 by default).
    hashgrid_init_table(p + L.grid_table, cfg.gf.grid, rng);
    for (const LayerView* lv : {&L.gd0, &L.gd1, &L.gr0, &L.gr1}) init_layer(*lv);
    p[L.gd1.b] += T(cfg.gf.density_init);  // output 0 of grid.density.1 is z: σ = exp(z)
  } else {
    for (auto& t : L.trunk) init_layer(t);
    init_layer(L.density);
    init_layer(L.feature);
    init_layer(L.rgb_hidden);
    init_layer(L.rgb);
    p[L.density.b] = T(0.1);                                // formulas.md §4: density bias 0.1
    for (int i = 0; i < 3; ++i) p[L.rgb.b + i] = T(0.02);   // formulas.md §4: rgb bias 0.02
  }
  if (cfg.has_cc()) {
    hashgrid_init_table(p + L.cc_table, cfg.cc, rng);
    init_layer(L.cc0);
    init_layer(L.cc1);
  }
}

template <class T>
void ModelCache<T>::reserve(const ModelConfig& cfg, int R_, int S_) {
  R = R_;
  S = S_;
  N = int64_t(R_) * S_;
  if (cfg.field == Field::grid) {
    grid_field_reserve(*this, cfg, R_, S_);
  } else {
  const int64_t W = cfg.width, P = cfg.pos_dim(), E = cfg.dir_dim(), H = cfg.rgb_width;
  ensure(gamma, N * P);
  for (auto& b : h) ensure(b, N * W);
  ensure(cat, N * (W + P));
  ensure(sigma_raw, N);
  ensure(feat, N * W);
  ensure(dir_ray, int64_t(R_) * E);
  ensure(rgb_in, N * (W + E));
  ensure(hid, N * H);
  ensure(color, N * 3);
  int64_t wide = std::max(W + P, W + E);
  ensure(g1, N * wide);
  ensure(g2, N * wide);
  ensure(g3, N * std::max<int64_t>(P, 3));
  ensure(d_dir_pt, int64_t(R_) * E);
  }
  if (cfg.has_cc()) {
    ensure(cc_x, N * 3);
    ensure(cc_enc, N * cfg.cc.out_dim());
    ensure(cc_h, N * cfg.cc_hidden);
    ensure(dcolor, N * 3);
  }
}

template <class T>
int64_t ModelCache<T>::floats() const {
  int64_t n = 0;
  for (const AlignedVec<T>* v : {&gamma, &cat, &sigma_raw, &feat, &dir_ray, &rgb_in, &hid, &color,
                                 &gx, &genc, &gdh, &gdo, &cc_x, &cc_enc, &cc_h, &dcolor, &g1, &g2,
                                 &g3, &d_dir_pt, &gcam1, &gcam2})
    n += int64_t(v->size());
  for (const auto& b : h) n += int64_t(b.size());
  return n;
}

int64_t cache_floats(const ModelConfig& cfg, int R, int S) {
  // reserve()'s buffers, in its order.
  const int64_t N = int64_t(R) * S;
  int64_t n = 0;
  if (cfg.field == Field::grid) {
    n = grid_field_floats(cfg, R, S);
  } else {
    const int64_t W = cfg.width, P = cfg.pos_dim(), E = cfg.dir_dim(), H = cfg.rgb_width;
    const int64_t wide = std::max(W + P, W + E);
    n = N * (P + 8 * W + (W + P) + 1 + W) + int64_t(R) * E + N * ((W + E) + H + 3) +
        N * (2 * wide + std::max<int64_t>(P, 3)) + int64_t(R) * E;
  }
  if (cfg.has_cc()) n += N * (3 + cfg.cc.out_dim() + cfg.cc_hidden + 3);
  return n;
}

namespace {

// The paper's field (formulas.md §4): γ(x) → 8-layer trunk → σ_raw, feature → colour head → c.
template <class T>
void mlp_field_forward(ModelCache<T>& c, const NetView<T>& net, const ModelIn<T>& pts) {
  const T* p = net.params;
  const ModelConfig& cfg = net.cfg;
  const ModelLayout& L = net.L;
  const T* x = pts.x;
  const T* dir = pts.dir;
  const int R = pts.R, S = pts.S;
  const int64_t N = int64_t(R) * S;
  const int W = cfg.width, P = cfg.pos_dim(), E = cfg.dir_dim();
  StageClock clk(c.prof, kStageEncode);
  T band_w[32];
  const bool c2f = cfg.pos_c2f_alpha >= 0;
  if (c2f) c2f_band_weights(band_w, cfg.pos_bands, cfg.pos_c2f_alpha);
  fourier_forward(c.gamma.data(), x, N, 3, cfg.pos_bands, c2f ? band_w : (const T*)nullptr);  // γ(x) (N, 63)
  HCC_DEBUG_FINITE(c.gamma.data(), N * P, "fourier_forward (position)");
  clk.to(kStageMlpFwd);
  const T* in = c.gamma.data();
  for (int k = 0; k < 8; ++k) {
    if (k == 4) {  // skip connection: [h3, γ(x)] (N, W+63) into layer 5
      concat_forward(c.cat.data(), c.h[3].data(), c.gamma.data(), N, W, P);
      in = c.cat.data();
    }
    dense_relu(c.h[k].data(), in, p, L.trunk[k], N);
    HCC_DEBUG_FINITE(c.h[k].data(), N * W, "trunk dense_relu_forward");
    in = c.h[k].data();
  }
  dense(c.sigma_raw.data(), c.h[7].data(), p, L.density, N);             // σ_raw (N, 1)
  dense(c.feat.data(), c.h[7].data(), p, L.feature, N);                  // feature (N, W)
  HCC_DEBUG_FINITE(c.sigma_raw.data(), N, "density dense_forward");
  HCC_DEBUG_FINITE(c.feat.data(), N * W, "feature dense_forward");

  // The view direction is one per ray: encode per ray (R, E), then broadcast per sample.
  clk.to(kStageEncode);
  encode_dir(c.dir_ray.data(), dir, R, cfg);
  HCC_DEBUG_FINITE(c.dir_ray.data(), int64_t(R) * E, "direction encoding (sh/fourier)_forward");
  clk.to(kStageMlpFwd);
  parallel_for(N, [&](int64_t n) {
    T* row = c.rgb_in.data() + n * (W + E);
    std::memcpy(row, c.feat.data() + n * W, sizeof(T) * W);
    std::memcpy(row + W, c.dir_ray.data() + (n / S) * E, sizeof(T) * E);
  }, 1024);
  dense_relu(c.hid.data(), c.rgb_in.data(), p, L.rgb_hidden, N);
  HCC_DEBUG_FINITE(c.hid.data(), N * cfg.rgb_width, "rgb_hidden dense_relu_forward");
  dense(c.color.data(), c.hid.data(), p, L.rgb, N);
  sigmoid_forward(c.color.data(), c.color.data(), N * 3);                // c (N, 3)
  HCC_DEBUG_FINITE(c.color.data(), N * 3, "rgb dense_forward + sigmoid_forward");

}

}  // namespace

template <class T>
void model_forward(ModelCache<T>& c, const NetView<T>& net, const ModelIn<T>& in) {
  const T* p = net.params;
  const ModelConfig& cfg = net.cfg;
  const ModelLayout& L = net.L;
  const int R = in.R, S = in.S;
  const T* cc_x = in.cc_x;
  HCC_ASSERT(int64_t(R) * S <= c.N || c.N == 0);
  const int64_t N = int64_t(R) * S;
  c.R = R; c.S = S;
  if (N == 0) return;
  if (cfg.field == Field::grid) grid_field_forward(c, net, in);
  else mlp_field_forward(c, net, in);

  if (cfg.has_cc()) {
    StageClock clk(c.prof, kStageCC);
    // formulas.md §5: detached NDC position mapped to [0,1]³ (clamped).
    parallel_for(N * 3, [&](int64_t i) {
      T v = (cc_x[i] + T(1)) * T(0.5);
      c.cc_x[i] = v < T(0) ? T(0) : (v > T(1) ? T(1) : v);
    }, 4096);
    hashgrid_forward(c.cc_enc.data(), c.cc_x.data(), p + L.cc_table, N, cfg.cc);
    HCC_DEBUG_FINITE(c.cc_enc.data(), N * cfg.cc.out_dim(), "hashgrid_forward");
    // The MLP a block of 256 points at a time, its hidden layer in per-thread scratch unless
    // keep_cc_mlp (as the grid field's MLPs: model/grid_field.cpp), else the backward recomputes it.
    // Bitwise the batch-wide layers' results.
    DenseLayer<T>* lay = c.cclayer;
    dense_prepare(lay[0], p + L.cc0.w, p + L.cc0.b, L.cc0.in, L.cc0.out, true, false);
    dense_prepare(lay[1], p + L.cc1.w, p + L.cc1.b, L.cc1.in, L.cc1.out, true, false);
    const int CE = cfg.cc.out_dim(), CH = cfg.cc_hidden;
    parallel_chunks(N, kDenseBlockRows, [&](int64_t r0, int64_t r1) {
      const int64_t rows = r1 - r0;
      T* h = c.keep_cc_mlp ? c.cc_h.data() + r0 * CH : thread_scratch<T, CcBlockTag>(size_t(kDenseBlockRows * CH));
      const T* enc = c.cc_enc.data() + r0 * CE;
      dense_forward_block(h, enc, lay[0], rows, true, r1 < N ? enc + rows * CE : nullptr,
                          std::min(kDenseBlockRows, N - r1) * CE);     // (rows, 64)
      dense_forward_block(c.dcolor.data() + r0 * 3, h, lay[1], rows, false);  // Δc (rows, 3)
    });
    HCC_DEBUG_FINITE(c.dcolor.data(), N * 3, "CC MLP forward");
  }
}

namespace {

// The density head's share of dL/dh7, added to dh7 (N, W) (h7 fans out to density and feature);
// its weight and bias gradients +=.
template <class T>
void density_backward(T* dh7, T* d_params, const T* d_sigma_raw, const ModelCache<T>& c,
                      const NetView<T>& net) {
  const int64_t N = int64_t(c.R) * c.S;
  const int W = net.cfg.width;
  const ModelLayout& L = net.L;
  const T* wd = net.params + L.density.w;  // (1, W)
  parallel_for(N, [&](int64_t n) {
    T ds = d_sigma_raw[n];
    T* row = dh7 + n * W;
    for (int j = 0; j < W; ++j) row[j] += ds * wd[j];
  }, 1024);
  if (d_params) {
    // d_W_density += Σ_n dσ_n h7_n ; d_b += Σ_n dσ_n (a 1-row GEMM: do it via the kernel).
    dense_backward((T*)nullptr, d_params + L.density.w, d_params + L.density.b, d_sigma_raw,
                   c.h[7].data(), wd, N, W, 1);
  }
}

// Backward of mlp_field_forward: d_params +=, d_x (N,3) and d_dir (R,3) WRITTEN when non-null.
template <class T>
void mlp_field_backward(const ModelInGrads<T>& d_in, const ModelOutGrads<T>& d_out,
                        ModelCache<T>& c, const NetView<T>& net, const ModelIn<T>& pts) {
  // σ comes out of the trunk the colour also needs: one dσ for both (the step runs the MLP
  // field's detach as two backwards, step.cpp camera_losses_backward).
  HCC_ASSERT(!d_out.d_sigma_raw_x);
  T* d_params = d_in.d_params;
  T* d_x = d_in.d_x;
  T* d_dir = d_in.d_dir;
  const T* d_sigma_raw = d_out.d_sigma_raw;
  const T* d_color = d_out.d_color;
  const T* p = net.params;
  const ModelConfig& cfg = net.cfg;
  const ModelLayout& L = net.L;
  const T* x = pts.x;
  const T* dir = pts.dir;
  const int R = c.R, S = c.S;
  const int64_t N = int64_t(R) * S;
  const int W = cfg.width, P = cfg.pos_dim(), E = cfg.dir_dim();
  T* g1 = c.g1.data();
  T* g2 = c.g2.data();
  StageClock clk(c.prof, kStageMlpBwd);
  // Colour head: sigmoid → rgb → ReLU → rgb_hidden → split [feature, dir encoding].
  sigmoid_backward(g1, d_color, c.color.data(), N * 3);                             // (N, 3)
  HCC_DEBUG_FINITE(g1, N * 3, "sigmoid_backward");
  dense_bwd(g2, d_params, g1, c.hid.data(), p, L.rgb, N);                   // (N, H)
  dense_relu_bwd(g1, d_params, g2, c.hid.data(), c.rgb_in.data(), p, L.rgb_hidden, N);  // (N, W+E)
  HCC_DEBUG_FINITE(g1, N * (W + E), "rgb_hidden dense_relu_backward");
  if (d_dir) {
    clk.to(kStageEncode);
    // Σ over each ray's samples of the direction-encoding gradient → (R, E) → dL/ddir.
    T* d_enc = c.d_dir_pt.data();
    sum_dir_grad(d_enc, g1, R, S, W, E);
    encode_dir_backward(d_dir, d_enc, dir, R, cfg);
    HCC_DEBUG_FINITE(d_dir, 3 * int64_t(R), "direction encoding (sh/fourier)_backward");
  }
  clk.to(kStageMlpBwd);
  // d_feature = first W columns of g1 → g2 (N, W)
  concat_backward(g2, (T*)nullptr, g1, N, W, E);
  // h7 receives from feature (= ) and density (+= fan-in).
  dense_bwd(g1, d_params, g2, c.h[7].data(), p, L.feature, N);             // (N, W)
  density_backward(g1, d_params, d_sigma_raw, c, net);
  HCC_DEBUG_FINITE(g1, N * W, "feature + density dense_backward");
  // Trunk, top to bottom. g1 holds dL/dh_k (post-ReLU) on entry to each layer.
  T* d_gamma_skip = nullptr;
  for (int k = 7; k >= 0; --k) {
    const T* in = k == 0 ? c.gamma.data() : (k == 4 ? c.cat.data() : c.h[k - 1].data());
    bool need_dx = k > 0 || d_x != nullptr;
    dense_relu_bwd(need_dx ? g2 : (T*)nullptr, d_params, g1, c.h[k].data(), in, p, L.trunk[k], N);
    if (need_dx) HCC_DEBUG_FINITE(g2, N * L.trunk[k].in, "trunk relu_backward + dense_backward");
    if (k == 4) {
      // split [h3, γ] gradient: dL/dh3 → g1, dL/dγ (skip) kept in g3
      concat_backward(g1, c.g3.data(), g2, N, W, P);
      d_gamma_skip = c.g3.data();
    } else if (need_dx) {
      std::swap(g1, g2);
    }
  }
  if (d_x) {
    clk.to(kStageEncode);
    // g1 = dL/dγ from layer 0, plus the skip's share (fan-in).
    parallel_for(N * P, [&](int64_t i) { g1[i] += d_gamma_skip[i]; }, 4096);
    T band_w[32];
    const bool c2f = cfg.pos_c2f_alpha >= 0;
    if (c2f) c2f_band_weights(band_w, cfg.pos_bands, cfg.pos_c2f_alpha);
    fourier_backward(d_x, g1, x, N, 3, cfg.pos_bands, c2f ? band_w : (const T*)nullptr);
    HCC_DEBUG_FINITE(d_x, N * 3, "fourier_backward (position)");
  }
}

}  // namespace

template <class T>
void model_backward(const ModelInGrads<T>& d_in, const ModelOutGrads<T>& d_out,
                    ModelCache<T>& c, const NetView<T>& net, const ModelIn<T>& in) {
  T* d_params = d_in.d_params;
  const T* d_dcolor = d_out.d_dcolor;
  const T* p = net.params;
  const ModelConfig& cfg = net.cfg;
  const ModelLayout& L = net.L;
  const int R = c.R;
  const int64_t N = int64_t(R) * c.S;
  if (N == 0) {
    if (d_in.d_dir) std::fill(d_in.d_dir, d_in.d_dir + 3 * R, T(0));
    return;
  }
  // CC branch: Δc → cc1 → ReLU → cc0 → hash table. Stops there (input detached), so its only
  // outputs are parameter gradients: with frozen networks (d_params null: eval's test-pose
  // refinement) nothing of it runs.
  if (cfg.has_cc() && d_dcolor && d_params) {
    StageClock clk(c.prof, kStageCC);
    T* g2 = c.g2.data();
    // A block at a time, as the forward: the hidden layer recomputed, then cc1's and cc0's
    // backward on it while it is in L1/L2; d_W, d_b by slabs (kernels/dense.h). Bitwise the
    // batch-wide layers' results.
    DenseLayer<T>* lay = c.cclayer;
    const LayerView* views[2] = {&L.cc0, &L.cc1};
    for (int k = 0; k < 2; ++k) {
      dense_prepare(lay[k], p + views[k]->w, p + views[k]->b, views[k]->in, views[k]->out, k == 0,
                    true);
      dense_grads_begin(c.ccslabs[k], lay[k], N, true, true);
    }
    const int CE = cfg.cc.out_dim(), CH = cfg.cc_hidden;
    parallel_chunks(N, kDenseSlabRows, [&](int64_t s0, int64_t s1) {
      const int64_t B = kDenseBlockRows;
      T* scratch = thread_scratch<T, CcBlockTag>(size_t(2 * B * CH));
      T* dh = scratch + B * CH;
      for (int64_t r0 = s0; r0 < s1; r0 += B) {
        const int64_t rows = std::min(B, s1 - r0);
        const T* enc = c.cc_enc.data() + r0 * CE;
        T* h = c.keep_cc_mlp ? c.cc_h.data() + r0 * CH : scratch;         // kept, or
        if (!c.keep_cc_mlp) dense_forward_block(h, enc, lay[0], rows, true);  // recomputed (rows, 64)
        dense_backward_block(dh, &c.ccslabs[1], r0, (T*)nullptr, d_dcolor + r0 * 3,
                             (const T*)nullptr, h, lay[1], rows);       // (rows, 64)
        dense_backward_block(g2 + r0 * CE, &c.ccslabs[0], r0, dh, dh, h, enc, lay[0],
                             rows);                                     // (rows, 32)
      }
    });
    for (int k = 0; k < 2; ++k)
      dense_grads_end(d_params + views[k]->w, d_params + views[k]->b, c.ccslabs[k], lay[k]);
    HCC_DEBUG_FINITE(g2, N * cfg.cc.out_dim(), "cc0 dense_relu_backward");
    hashgrid_backward(d_params + L.cc_table, (T*)nullptr, g2, c.cc_x.data(), p + L.cc_table, N,
                      cfg.cc, c.grid_ws);
  }
  if (cfg.field == Field::grid)
    grid_field_backward(d_in, d_out, c, net, in);
  else
    mlp_field_backward(d_in, d_out, c, net, in);
}

void model_density(ModelCache<float>& cache, const NetView<float>& net, const float* x, int64_t n,
                   float* sigma) {
  constexpr int kBatch = 4096;
  std::vector<float> dir(3 * kBatch);
  for (int i = 0; i < kBatch; ++i) dir[3 * i + 2] = -1.f;
  for (int64_t b = 0; b < n; b += kBatch) {
    const int m = int(std::min<int64_t>(kBatch, n - b));
    if (cache.N < m) cache.reserve(net.cfg, m, 1);
    model_forward(cache, net, ModelIn<float>{x + 3 * b, dir.data(), x + 3 * b, m, 1});
    for (int i = 0; i < m; ++i) sigma[b + i] = std::max(cache.sigma_raw[i], 0.f);
  }
}


template void init_params<float>(float*, const ModelConfig&, const ModelLayout&, Rng&);
template void init_params<double>(double*, const ModelConfig&, const ModelLayout&, Rng&);
template struct ModelCache<float>;
template struct ModelCache<double>;
template void model_forward<float>(ModelCache<float>&, const NetView<float>&,
                                   const ModelIn<float>&);
template void model_forward<double>(ModelCache<double>&, const NetView<double>&,
                                    const ModelIn<double>&);
template void model_backward<float>(const ModelInGrads<float>&, const ModelOutGrads<float>&,
                                    ModelCache<float>&, const NetView<float>&,
                                    const ModelIn<float>&);
template void model_backward<double>(const ModelInGrads<double>&, const ModelOutGrads<double>&,
                                     ModelCache<double>&, const NetView<double>&,
                                     const ModelIn<double>&);

}  // namespace hashcc
