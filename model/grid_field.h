// model/grid_field.h — the grid radiance field (`--field grid`): what learns the cameras on a
// laptop. Math, gradients and the tests that prove them: docs/math/grid_field.md.
//
//   x (N,3) NDC ─ u = (x+1)/2 ─ hash grid (L levels × F, 2^T entries a level) ─ × w_l(α)
//     ─ Linear(L·F → 64)+ReLU ─ Linear(64 → 1+G) ─ [z | geo]          σ_raw = exp(min(z, 15))
//   [geo (G), dir encoding (E, per ray)] ─ Linear(G+E → 64)+ReLU ─ Linear(64 → 3) ─ sigmoid ─ c
//
// Why it learns cameras where a raw grid does not (Heo et al., ICML 2023):
//   - the position gradient is the smooth straight-through one (HashGridConfig::smooth_dx): the
//     forward stays trilinear, the gradient is that of the interpolant with weights
//     δ(f) = (1 − cos πf)/2, so it does not jump at every cell face;
//   - a coarse-to-fine curriculum over levels: level l is weighted by
//     w_l(α) = (1 − cos(π·clamp(α − l, 0, 1)))/2 (the Fourier c2f formula, one level a band);
//     the trainer raises α from GridFieldConfig::c2f_start to L over --c2f of the run.
// σ_raw = exp(z) > 0, so the step's σ = relu(σ_raw) is the identity here: the field owns its
// density activation (exp: opacity needs σ·δ ≫ 1 with δ ≈ 1/128, far from a small MLP's init).
// z is clamped at 15 (σ ≤ 3.3e6), with zero gradient above, so no step can overflow.
//
// Gradient-write policy as in model.h: d_params +=, d_x (N,3) and d_dir (R,3) WRITTEN.
#pragma once
#include "model/model.h"

namespace hashcc {

constexpr double kGridMaxLogDensity = 15;  // σ_raw = exp(min(z, 15))

template <class T>
void grid_field_reserve(ModelCache<T>& c, const ModelConfig& cfg, int R, int S);
// The floats grid_field_reserve allocates (its part of cache_floats).
int64_t grid_field_floats(const ModelConfig& cfg, int R, int S);

// Whether a training step (table gradient and d_x) should keep the hash encoding's position
// Jacobian (ModelIn::keep_jac): when a level's table outgrows half a core's L2 (512 KiB: more than
// 2^16 rows of 2 floats), the backward's second gather misses and the Jacobian saves it: measured
// −7% a step at 2^17 and 64 samples (horns, 1 and 2 threads), and nothing at 2^15 (+1.7% at 1
// thread, −0.5% at 2; docs/performance.md). A frozen field (eval's refinement: d_x alone) keeps
// it at every size (no scatter is left in its backward).
inline bool grid_jac_pays(const GridFieldConfig& g) {
  return g.grid.table_size() * g.grid.features * int64_t(sizeof(float)) > (int64_t(512) << 10);
}

// Fills c.sigma_raw (N) and c.color (N,3) from in.x (R·S, 3) and the unit directions in.dir
// (R, 3); in.cc_x is the CC branch's (model_forward), not read here.
template <class T>
void grid_field_forward(ModelCache<T>& c, const NetView<T>& net, const ModelIn<T>& in);

// Backward of grid_field_forward, from d_out.d_sigma_raw and d_out.d_color (d_dcolor belongs to
// the CC branch). d_in.d_params +=, d_in.d_x and d_in.d_dir WRITTEN when non-null.
template <class T>
void grid_field_backward(const ModelInGrads<T>& d_in, const ModelOutGrads<T>& d_out,
                         ModelCache<T>& c, const NetView<T>& net, const ModelIn<T>& in);

}  // namespace hashcc
