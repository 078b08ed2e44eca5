// render/compositor.h — volume compositing (formulas.md §3).
//
// Derivation: docs/math/compositor.md (proved by test/test_compositor.cpp,
// "[compositor][grad]" and "[compositor][hard]").
// Gradient-write policy: d_sigma, d_color, d_color2 are activation gradients, WRITTEN (=); the
// caller adds them where σ and c fan in (the two HashCC losses meet here through rgb and rgb2,
// which this kernel already sums into one d_sigma). No parameters.
// Precision: each ray is accumulated in double for both instantiations (compositing is < 1% of
// a step), so the float build's outputs are the double results rounded once.
// Stability: α = −expm1(−σδ) and the transmittance factor 1 − α + 1e-10 is formed as
// exp(−σδ) + 1e-10 (the same number, without the cancellation 1 − α); it is ≥ 1e-10, and the
// backward divides by nothing: dσ uses the ratio exp(−σδ)/(exp(−σδ) + 1e-10) ∈ [0, 1].
// Threading: rays are split over threads; each ray is computed by one thread, in order.
#pragma once
#include <cstdint>
namespace hashcc {

// The last sample's δ (formulas.md §3): "infinite" so the last sample absorbs what is left.
inline constexpr double kLastDelta = 1e10;
// The guard inside the transmittance product T_i = Π_{j<i}(1 − α_j + 1e-10).
inline constexpr double kTransmittanceEps = 1e-10;

// One batch of R rays × S samples: sigma (R, S) is already ≥ 0 (relu applied before);
// color (R, S, 3); color2 (R, S, 3) optional second colour set sharing sigma (HashCC's c+Δc);
// s (R, S) increasing sample positions; δ_i = s_{i+1} − s_i, last δ = 1e10 — unless delta (R, S)
// is given: then δ_i = delta_i (occupancy sampling, render/occupancy.h: samples packed into the
// occupied stretches of a ray stand for equal lengths of them, not for the gaps between them).
template <class T>
struct CompositeIn {
  const T* sigma = nullptr;
  const T* color = nullptr;
  const T* color2 = nullptr;
  const T* s = nullptr;
  int64_t R = 0;
  int S = 0;
  const T* delta = nullptr;
};

// Per-ray values: rgb (R,3) = Σ w c; rgb2 (R,3) = Σ w c2 (when color2); depth (R) = Σ w s;
// opacity (R) = Σ w; and, per sample, weights (R,S) = w itself (for a loss on the weights
// along a ray, e.g. render/distortion.h). U = T for the outputs, U = const T for the forward
// outputs and their gradients read by the backward. All but rgb may be null.
template <class U>
struct CompositeOut {
  U* rgb = nullptr;
  U* rgb2 = nullptr;
  U* depth = nullptr;
  U* opacity = nullptr;
  U* weights = nullptr;
};

// Gradients of the inputs: d_sigma (R,S), d_color (R,S,3), d_color2 (R,S,3) (null when no color2).
template <class T>
struct CompositeInGrads {
  T* d_sigma = nullptr;
  T* d_color = nullptr;
  T* d_color2 = nullptr;
};

// α = 1 − exp(−σδ); T_i = Π_{j<i}(1 − α_j + 1e-10); w = Tα.
template <class T>
void composite_forward(const CompositeOut<T>& out, const CompositeIn<T>& in);

// Backward in O(S) per ray with no per-sample storage (second pass + suffix sums).
// d_in WRITTEN. d_out: d_rgb required; d_rgb2, d_depth, d_opacity, d_weights may be null (no
// gradient from them; d_weights (R,S) is dL/dw_i, each sample's weight's own gradient).
// out: the forward outputs (needed for the "still to come" suffix); pass them as computed.
// (In the float build the totals are recomputed in double instead: a float-rounded total would
// leave float-ulp cancellation noise in every suffix "total − prefix". An output whose gradient
// is requested but which is passed as null is recomputed too.)
template <class T>
void composite_backward(const CompositeInGrads<T>& d_in, const CompositeOut<const T>& d_out,
                        const CompositeIn<T>& in, const CompositeOut<const T>& out);

// O(S²) references (same contracts), written straight from formulas.md §3 with the literal
// 1 − α + 1e-10 and dw_i/dσ_j = −α_i δ_j e^{−σ_jδ_j} Π_{k<i, k≠j}(1 − α_k + 1e-10) (no suffix
// trick), in T arithmetic; the backward ignores the forward outputs.
template <class T>
void composite_forward_naive(const CompositeOut<T>& out, const CompositeIn<T>& in);
template <class T>
void composite_backward_naive(const CompositeInGrads<T>& d_in, const CompositeOut<const T>& d_out,
                              const CompositeIn<T>& in);

}  // namespace hashcc
