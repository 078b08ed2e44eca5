// kernels/hash_grid.h — multiresolution hash encoding (formulas.md §5, tiny-cuda-nn).
//
// Buffers (row-major):  x (N, 3) in [0,1]³ (clamped; NaN reads as 0) · table (L, 2^T, F) ·
// out (N, L·F) level-major ([l0 f0, l0 f1, l1 f0, …]) · d_out (N, L·F) · d_x (N, 3) ·
// d_table (L, 2^T, F).
// Gradient-write policy: d_table is a parameter gradient, ACCUMULATED (+=) after the trainer's
// one zero per step; d_x is an activation gradient, WRITTEN (=), and only when non-null.
// Derivation (chain rule in formulas.md §5's symbols) and the tests that prove it:
// docs/math/hash_grid.md.
#pragma once
#include <cmath>  // before core/parallel.h, whose Rng::normal uses std::sqrt/log/cos
#include <cstdint>
#include <vector>
#include "core/parallel.h"
namespace hashcc {

struct HashGridConfig {
  int levels = 16;       // L
  int features = 2;      // F per level
  int log2_table = 9;    // table size 2^T per level
  double base_res = 16;  // N_min
  double max_res = 512;  // N_max (spec default 512)
  // Position gradient (only used when d_x is requested): false = the exact derivative of the
  // trilinear forward; true = Heo et al.'s smooth straight-through estimator: the forward stays
  // trilinear, the gradient is that of the interpolant with per-axis weights δ(f) =
  // (1 − cos πf)/2, which is continuous across cell faces (docs/math/grid_field.md).
  bool smooth_dx = false;
  int out_dim() const { return levels * features; }
  int64_t table_size() const { return int64_t(1) << log2_table; }
  int64_t param_count() const { return int64_t(levels) * table_size() * features; }
};

// Per-thread scatter buffers for the backward (no atomics; reduced in fixed order).
// Grow-only: reuse one workspace across calls and steps, it never shrinks or reallocates
// once large enough.
template <class T>
struct HashGridWorkspace { std::vector<std::vector<T>> per_thread; };

// out (N, L·F) level-major; x (N, 3), clamped to [0,1]; table (L, 2^T, F).
// jac (optional, (N, 3, L·F)): also WRITES the position Jacobian, jac[n][d][j] = ∂out[n][j]/∂x[n][d]
// (the gradient hashgrid_backward's d_x uses: exact or smooth per cfg.smooth_dx; 0 where the clamp
// is active). Where a backward will want d_x, this costs arithmetic on corners the forward has
// loaded anyway, and saves the backward a second gather of the table: hashgrid_dx_from_jac.
template <class T>
void hashgrid_forward(T* out, const T* x, const T* table, int64_t N, const HashGridConfig& cfg,
                      T* jac = nullptr);

// The float forward's F = 2 gather: one point a SIMD lane (AVX-512 or AVX2 gather
// instructions), or the scalar loop, one point at a time. The same values bit for bit either way
// (test [hashgrid][simd]); which is faster depends on the CPU's gather instructions (a Zen 4:
// SIMD; an Ice Lake-SP: scalar, docs/performance.md). kAuto (the default) times both once, on the
// first forward of the process, and keeps the faster; kSimd / kScalar force one (that test,
// `hashcc bench --hashgrid`'s comparison). Not to be changed while a kernel runs.
enum class GatherMode { kAuto, kSimd, kScalar };
void hashgrid_set_gather(GatherMode m);
bool hashgrid_has_simd_gather();  // the build has the SIMD gather (AVX-512 or AVX2)
bool hashgrid_simd_gather();      // the forward uses it now (kAuto: measures on the first call)

// d_x (N, 3) WRITTEN: d_x[n][d] = Σ_j d_out[n][j] · jac[n][d][j], the chain rule through the
// Jacobian hashgrid_forward kept. The same d_x as hashgrid_backward's up to rounding (another
// order of the sums: docs/math/hash_grid.md).
template <class T>
void hashgrid_dx_from_jac(T* d_x, const T* d_out, const T* jac, int64_t N,
                          const HashGridConfig& cfg);

// d_table (L, 2^T, F) accumulated (+=); null: no table gradient (frozen tables: the scatter is
// skipped). d_x (N, 3) written only when non-null (the CC branch passes nullptr: its input is
// detached); cfg.smooth_dx picks the exact or the smooth straight-through position gradient.
// d_out_x (optional, (N, L·F)): the output gradient whose position derivative d_x gets, when it
// is not d_out's — a loss that reaches the table but not the positions (the detached distortion
// loss: d_out carries every loss, d_out_x the camera's). null: d_out. One pass either way.
template <class T>
void hashgrid_backward(T* d_table, T* d_x, const T* d_out, const T* x, const T* table, int64_t N,
                       const HashGridConfig& cfg, HashGridWorkspace<T>& ws,
                       const T* d_out_x = nullptr);

// One level's table gradient alone, for a scatter split over levels instead of points (the
// data-parallel step's: model/step.cpp): d_table (L, 2^T, F) accumulated (+=) at `level` only,
// from d_out_level (N, F) = that level's columns of hashgrid_backward's d_out, and x (N, 3).
// Points in order in the fused backward's blocks, corners in order, the same arithmetic: over
// all levels, the same d_table as hashgrid_backward's one-thread scatter, bit for bit.
template <class T>
void hashgrid_scatter_level(T* d_table, const T* d_out_level, const T* x, int64_t N,
                            const HashGridConfig& cfg, int level);

// ---- level geometry, init, and the plain reference kernels ----

// One level's geometry (formulas.md §5): scale_l = N_min·b^l − 1, res_l = ceil(scale_l) + 1 vertices
// per axis, dense iff res_l³ ≤ 2^T.
struct HashGridLevel {
  double scale;
  int64_t res;
  bool dense;
};
HashGridLevel hashgrid_level(const HashGridConfig& cfg, int level);
std::vector<HashGridLevel> hashgrid_levels(const HashGridConfig& cfg);  // (L,)

// Table entry of integer vertex (cx, cy, cz) at a level: dense cx + cy·res + cz·res², else
// cx·1 ⊕ cy·2654435761 ⊕ cz·805459861 in uint32; either taken modulo 2^T.
uint32_t hashgrid_vertex_index(uint32_t cx, uint32_t cy, uint32_t cz, const HashGridLevel& lv,
                               int64_t table_size);

// table (L, 2^T, F) = uniform ±1e-4 (formulas.md §5), drawn in index order from rng.
template <class T>
void hashgrid_init_table(T* table, const HashGridConfig& cfg, Rng& rng);

// --grid-decay λ: the feature decay of Zip-NeRF (Barron et al. 2023, "normalised weight decay"),
// R = λ Σ_l mean_l(θ²) over the table's L levels (the mean over the level's 2^T·F slots), added
// to the loss of the step. Its gradient ∂R/∂θ = 2λ θ / (2^T·F) is added to d_table (the data
// gradient is already there); returns R. Pulls the entries no ray needs towards 0, so that what
// a training view does not see is not left at whatever an earlier step wrote.
template <class T>
double hashgrid_decay(T* d_table, const T* table, const HashGridConfig& cfg, double lambda);

// Plain serial references (one point, one level, one corner at a time) for the tests. Same
// shapes and write policy as the optimised pair; no workspace.
template <class T>
void hashgrid_forward_naive(T* out, const T* x, const T* table, int64_t N,
                            const HashGridConfig& cfg);
template <class T>
void hashgrid_backward_naive(T* d_table, T* d_x, const T* d_out, const T* x, const T* table,
                             int64_t N, const HashGridConfig& cfg, const T* d_out_x = nullptr);

}  // namespace hashcc
