// model/model.h — the networks of NeRF--, NeRF--+SH and HashCC as one composed model.
//
//   x (N,3) ─ Fourier L=10 ─ γ (N,63) ─ trunk: 4×[Linear+ReLU], concat γ, 4×[Linear+ReLU] ─ h7
//   h7 ─ density Linear(W→1) ─ σ_raw                     (σ = relu(σ_raw) in model/step)
//   h7 ─ feature Linear(W→W) ─ ⊕ dir encoding (per ray, broadcast to its samples)
//      ─ Linear(→64)+ReLU ─ Linear(64→3) ─ sigmoid ─ c
//   hashcc only: clamp((x+1)/2) ─ hash grid (16×2) ─ Linear(32→64)+ReLU ─ Linear(64→3) ─ Δc
//   The CC branch's input is detached: its backward stops at the hash table (no dL/dx), so the
//   cameras learn only through the main network (formulas.md §5).
//
// All parameters of the networks (main + CC) live in ONE flat arena (the Adam group
// "networks"); layers are views at fixed offsets (design.md practice 3). Weights use PyTorch's
// (out, in) layout so a state dict maps onto the arena one tensor at a time.
#pragma once
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "core/buffer.h"
#include "core/parallel.h"
#include "core/profile.h"
#include "kernels/dense.h"
#include "kernels/hash_grid.h"

namespace hashcc {

enum class Variant { nerfmm, sh, hashcc };
Variant parse_variant(const std::string& s);  // throws hashcc::Error for unknown names
const char* variant_name(Variant v);

// The radiance field behind σ and c. mlp: the paper's 8×128 trunk on Fourier features (formulas.md §4).
// grid: a multiresolution hash grid with two tiny MLPs (model/grid_field.h), ~30× fewer FLOPs a
// sample, built to learn cameras on a laptop. The variant still picks the direction encoding
// and whether the CC branch exists, so `hashcc` + grid is HashCC on a grid field.
enum class Field { mlp, grid };
Field parse_field(const std::string& s);  // throws hashcc::Error naming --field
const char* field_name(Field f);

// --field grid. The grid is the CC branch's kernel with a bigger table and, for the cameras, the
// smooth straight-through position gradient; its level curriculum uses ModelConfig's c2f α.
constexpr double kGridDensityInitMax = 10;  // |--grid-density-init|: σ from e^-10 to e^10

struct GridFieldConfig {
  HashGridConfig grid{16, 2, 15, 16, 512, true};  // levels, features, log2 table, N_min, N_max, smooth
  int hidden = 64;        // density MLP: Linear(L·F → hidden)+ReLU, Linear(hidden → 1 + geo)
  int geo = 15;           // geometry features handed to the colour MLP
  int rgb_hidden = 64;    // colour MLP: Linear(geo + dir → rgb_hidden)+ReLU, Linear(→ 3)
  double c2f_start = 2;   // curriculum: the level α at the start (levels below it fully on)
  // Added to the density output's bias at init: σ starts near exp(density_init) everywhere.
  // 0 = the plain init (σ ≈ 1: a haze through the whole ray); 2 = an opaque screen at the near
  // plane, from which fern's cameras learn more of their turn (docs/results/grid).
  double density_init = 0;
};

struct ModelConfig {
  Variant variant = Variant::hashcc;
  int width = 128;       // trunk and feature width (formulas.md §4)
  int rgb_width = 64;    // colour hidden layer
  int pos_bands = 10;    // Fourier L for positions (63 values)
  int dir_bands = 4;     // Fourier L for directions, nerfmm (27 values)
  int sh_degree = 4;     // SH degree for sh/hashcc (16 values)
  HashGridConfig cc;     // formulas.md §5 defaults: 16 levels × 2, 2^9, base 16, max 512
  int cc_hidden = 64;
  // Coarse-to-fine position encoding (BARF; off by default = the paper's recipe):
  // band k of γ(x) is weighted by (1 − cos(π·clamp(α − k, 0, 1)))/2. α < 0: off (all weights 1).
  // The trainer sets α from the run's progress; the weights are constants for the backward.
  double pos_c2f_alpha = -1;
  Field field = Field::mlp;
  GridFieldConfig gf;     // used when field == grid
  bool has_cc() const { return variant == Variant::hashcc; }
  int pos_dim() const { return 3 * (1 + 2 * pos_bands); }
  int dir_dim() const;
};

// One dense layer's place in the arena: W (out, in) at w, b (out) at b.
struct LayerView {
  int in = 0, out = 0;
  int64_t w = 0, b = 0;
  std::string name;  // PyTorch-style name, e.g. "trunk.4"
};

// A named tensor of the arena (for checkpoints, the golden step and debugging).
struct TensorView {
  std::string name;
  std::vector<int64_t> shape;
  int64_t offset = 0;
  int64_t size() const { int64_t n = 1; for (auto s : shape) n *= s; return n; }
};

struct ModelLayout {
  LayerView trunk[8], density, feature, rgb_hidden, rgb;
  LayerView gd0, gd1, gr0, gr1;  // grid field: density MLP, colour MLP (field grid only)
  int64_t grid_table = -1;       // grid field table (levels, 2^T, F) offset (field grid only)
  LayerView cc0, cc1;       // CC MLP (hashcc only)
  int64_t cc_table = -1;    // hash table (levels, 2^T, F) offset (hashcc only)
  int64_t count = 0;        // total parameters
  std::vector<TensorView> tensors;
};
ModelLayout make_layout(const ModelConfig& cfg);

// A tiny instance of a variant (width 16, colour width 8, a 4-level CC grid of 2^6 entries,
// base 4, finest 32, CC hidden 8): the gradient checks' model and `hashcc step --make-inputs`.
// With f = grid: the main network is a tiny grid field instead (4 levels × 2 of 2^6 entries,
// base 4, finest 32, hidden 8, 3 geometry features, colour hidden 8) with the EXACT position
// gradient, so finite differences can check it.
ModelConfig tiny_model_config(Variant v, Field f = Field::mlp);

// Band weights of the coarse-to-fine encoding for α (L values); all 1 when α < 0.
template <class T>
void c2f_band_weights(T* w, int L, double alpha);

// Initialises the arena as formulas.md §4–§5: uniform ±1/√fan_in (PyTorch nn.Linear), density bias
// 0.1, rgb bias 0.02, hash table uniform ±1e-4.
template <class T>
void init_params(T* params, const ModelConfig& cfg, const ModelLayout& L, Rng& rng);

// Forward activations of one batch of N points from R rays × S samples (ray-major). Allocated
// once for the largest batch and reused (grow-only), so steps never allocate.
template <class T>
struct ModelCache {
  int64_t N = 0;
  int R = 0, S = 0;
  AlignedVec<T> gamma, h[8], cat, sigma_raw, feat, dir_ray, rgb_in, hid, color;  // main
  AlignedVec<T> gx, genc, gdh, gdo;   // grid field: (x+1)/2, encoding, density hidden, [z, geo]
  AlignedVec<T> cc_x, cc_enc, cc_h, dcolor;                                        // CC
  AlignedVec<T> g1, g2, g3, d_dir_pt;   // backward scratch
  AlignedVec<T> gcam1, gcam2;           // grid field: the density MLP backward of d_sigma_raw_x
  // Grid field: the hash encoding's position Jacobian (N, 3, L·F), kept by a forward whose
  // ModelIn::keep_jac is set (gjac_valid), so that the backward's d_x reads it instead of
  // gathering the table again (kernels/hash_grid.h). Allocated by the first such forward and not
  // counted by floats()/cache_floats: the automatic chunk keeps its size (and the step its sums'
  // order) whether or not the camera learns.
  AlignedVec<T> gjac;
  bool gjac_valid = false;
  // Grid field: its four layers (gd0, gd1, gr0, gr1) packed for block-by-block use, and their
  // d_W / d_b slab partials (kernels/dense.h; model/grid_field.cpp runs both MLPs a block at a
  // time). Grow-only, a few KiB each.
  DenseLayer<T> glayer[4];
  DenseGradSlabs<T> gslabs[4];
  DenseLayer<T> cclayer[2];  // the CC MLP (cc0, cc1), the same way (model/model.cpp)
  DenseGradSlabs<T> ccslabs[2];
  // Grid field (keep_mlp) and CC branch (keep_cc_mlp): keep the MLPs' activations of the last
  // forward in gdh, gdo, rgb_in, hid (grid) and cc_h (CC), and the backward reads them back.
  // Off (float, training): they stay in per-block scratch and the backward recomputes them
  // (model/grid_field.cpp, model/model.cpp). On by default in double, whose gradient checks read
  // them (the kink detector of test/fixtures.h); keep_mlp also in eval's test-pose refinement
  // (StepOptions::keep_mlp, which the step sets here), whose CC branch runs no backward at all.
  // Either way the same results.
  bool keep_mlp = std::is_same_v<T, double>;
  bool keep_cc_mlp = std::is_same_v<T, double>;
  HashGridWorkspace<T> grid_ws;
  // Grid field, a backward with a table gradient: when defer_g is set, the backward does not
  // scatter into the table but leaves what the scatter needs for a later level-parallel one
  // (hashgrid_scatter_level; the data-parallel step, model/step.cpp): its encoding gradient,
  // level-major, at defer_g[l · defer_n + defer_n0 + n][f], and its points at
  // defer_x[(defer_n0 + n) · 3 + d], for the batch's defer_n points of which this call's are
  // defer_n0, defer_n0 + 1, …
  T* defer_g = nullptr;
  T* defer_x = nullptr;
  int64_t defer_n = 0, defer_n0 = 0;
  StageTimes* prof = nullptr;  // optional profiler (hashcc bench); null: no timing
  void reserve(const ModelConfig& cfg, int R, int S);
  int64_t floats() const;  // the floats its buffers hold (after one reserve: cache_floats)
};

// The floats ModelCache::reserve(cfg, R, S) allocates, counted without allocating: what the
// automatic chunk (model/step.h) sizes a chunk by. test_model checks it against reserve.
int64_t cache_floats(const ModelConfig& cfg, int R, int S);

// The networks as one read-only view: the parameter arena, its config and its layout.
template <class T>
struct NetView {
  const T* params = nullptr;
  const ModelConfig& cfg;
  const ModelLayout& L;
};

// One batch of N = R·S points, R rays × S samples (ray-major).
// x (N,3) sample positions; dir (R,3) UNIT view direction per ray.
// cc_x (N,3): the CC branch's input, DETACHED — model_backward sends no gradient through it.
// A step passes x itself; a finite difference over the camera passes a fixed copy, so the CC
// branch does not move with the camera (formulas.md §5).
// keep_jac: a backward asking for d_x follows (the camera learns): the grid field's forward keeps
// its encoding's position Jacobian (ModelCache::gjac). Any forward may set it; it only saves time.
template <class T>
struct ModelIn {
  const T* x = nullptr;
  const T* dir = nullptr;
  const T* cc_x = nullptr;
  int R = 0, S = 0;
  bool keep_jac = false;
};

// Gradients of the model's outputs: d_sigma_raw (N), d_color (N,3), d_dcolor (N,3) (hashcc;
// may be null: no gradient reaches the CC branch).
// d_sigma_raw_x (N, grid field only, optional): the density gradient of the losses that reach
// the positions, when it is not d_sigma_raw's — a loss on σ alone that the camera must not see
// (the detached distortion loss). d_params get d_sigma_raw's; d_x gets d_sigma_raw_x's (with
// the same d_color). One backward: only the small density MLP runs twice, for d_x alone.
template <class T>
struct ModelOutGrads {
  const T* d_sigma_raw = nullptr;
  const T* d_color = nullptr;
  const T* d_dcolor = nullptr;
  const T* d_sigma_raw_x = nullptr;
};

// Gradients of the model's inputs and parameters. d_params (L.count) += (null: no parameter
// gradients); d_x (N,3) and d_dir (R,3) WRITTEN when non-null (the camera path). The CC branch
// never contributes to d_x or d_dir.
template <class T>
struct ModelInGrads {
  T* d_params = nullptr;
  T* d_x = nullptr;
  T* d_dir = nullptr;
};

// Fills cache.sigma_raw (N), cache.color (N,3) = sigmoid(rgb), and for hashcc
// cache.dcolor (N,3) = Δc.
template <class T>
void model_forward(ModelCache<T>& cache, const NetView<T>& net, const ModelIn<T>& in);

// σ = max(σ_raw, 0) at n points x (n, 3), for the occupancy grid (render/occupancy.h): batches
// of model_forward, each point its own ray of one sample seen along −z (σ does not depend on
// the direction; the colour branches run too and are discarded).
void model_density(ModelCache<float>& cache, const NetView<float>& net, const float* x, int64_t n,
                   float* sigma);

// Backward of model_forward(cache, net, in), whose activations cache still holds (in.cc_x is
// not read: the CC branch stops at its hash table).
template <class T>
void model_backward(const ModelInGrads<T>& d_in, const ModelOutGrads<T>& d_out,
                    ModelCache<T>& cache, const NetView<T>& net, const ModelIn<T>& in);

}  // namespace hashcc
