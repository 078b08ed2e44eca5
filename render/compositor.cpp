// render/compositor.cpp — see compositor.h; derivation in docs/math/compositor.md.
#include "render/compositor.h"

#include <cmath>
#include <type_traits>

#include "kernels/chunked_for.h"

namespace hashcc {
namespace {

constexpr int64_t kRayChunk = 16;  // rays per fixed chunk (kernels/chunked_for.h)

// One sample's compositing factors, in double.
struct SampleFactors {
  double delta;  // δ_i = s_{i+1} − s_i, last δ = 1e10; or the caller's δ_i (CompositeIn::delta)
  double e;      // exp(−σδ) = 1 − α
  double alpha;  // α = 1 − exp(−σδ), via expm1: accurate when σδ ≪ 1
  double q;      // 1 − α + 1e-10, formed as e + 1e-10 (no cancellation), ≥ 1e-10
};

template <class T>
inline SampleFactors factors(const T* sigma_r, const T* s_r, const T* delta_r, int i, int S) {
  SampleFactors f;
  if (delta_r) f.delta = double(delta_r[i]);
  else f.delta = i + 1 < S ? double(s_r[i + 1]) - double(s_r[i]) : kLastDelta;
  const double x = double(sigma_r[i]) * f.delta;
  f.e = std::exp(-x);
  f.alpha = -std::expm1(-x);
  f.q = f.e + kTransmittanceEps;
  return f;
}

// Per-ray totals: [rgb 0..2, rgb2 3..5, depth 6, opacity 7, Σ w·dL/dw 8]. Slot 8 is the
// backward's only (the weights' own upstream gradient dw_i, CompositeOut::weights): 0 forward.
struct Totals { double v[9]; };

// The one forward recursion, shared by composite_forward and the backward's prefix pass so that
// "total − prefix" uses bit-identical sums (the last suffix is then exactly 0).
template <class T>
inline void accumulate_sample(double* acc, double Ti, const SampleFactors& f, const T* c,
                              const T* c2, double si, double dwi) {
  const double w = Ti * f.alpha;  // formulas.md §3: w_i = T_i α_i
  for (int a = 0; a < 3; ++a) acc[a] += w * double(c[a]);
  if (c2)
    for (int a = 0; a < 3; ++a) acc[3 + a] += w * double(c2[a]);
  acc[6] += w * si;
  acc[7] += w;
  acc[8] += w * dwi;
}

// dw_r: the ray's dL/dw_i (null = 0); w_out: where to write the ray's w_i (null = not).
template <class T>
Totals ray_totals(const T* sigma_r, const T* color_r, const T* color2_r, const T* s_r,
                  const T* delta_r, int S, const T* dw_r = nullptr, T* w_out = nullptr) {
  Totals t{};
  double Ti = 1;  // T_0 = 1 (empty product)
  for (int i = 0; i < S; ++i) {
    const SampleFactors f = factors(sigma_r, s_r, delta_r, i, S);
    if (w_out) w_out[i] = T(Ti * f.alpha);
    accumulate_sample(t.v, Ti, f, color_r + 3 * i, color2_r ? color2_r + 3 * i : nullptr,
                      double(s_r[i]), dw_r ? double(dw_r[i]) : 0.0);
    Ti *= f.q;  // formulas.md §3: T_{i+1} = T_i (1 − α_i + 1e-10)
  }
  return t;
}

}  // namespace

template <class T>
void composite_forward(const CompositeOut<T>& out, const CompositeIn<T>& in) {
  T *rgb = out.rgb, *rgb2 = out.rgb2, *depth = out.depth, *opacity = out.opacity;
  const T *sigma = in.sigma, *color = in.color, *color2 = in.color2, *s = in.s;
  const int64_t R = in.R;
  const int S = in.S;
  parallel_chunks(R, kRayChunk, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      const Totals t = ray_totals(sigma + r * S, color + r * S * 3,
                                  color2 ? color2 + r * S * 3 : nullptr, s + r * S,
                                  in.delta ? in.delta + r * S : nullptr, S, (const T*)nullptr,
                                  out.weights ? out.weights + r * S : nullptr);
      for (int a = 0; a < 3; ++a) rgb[3 * r + a] = T(t.v[a]);
      if (rgb2 && color2)
        for (int a = 0; a < 3; ++a) rgb2[3 * r + a] = T(t.v[3 + a]);
      if (depth) depth[r] = T(t.v[6]);
      if (opacity) opacity[r] = T(t.v[7]);
    }
  });
}

template <class T>
void composite_backward(const CompositeInGrads<T>& d_in, const CompositeOut<const T>& d_out,
                        const CompositeIn<T>& in, const CompositeOut<const T>& out) {
  T *d_sigma = d_in.d_sigma, *d_color = d_in.d_color, *d_color2 = d_in.d_color2;
  const T *d_rgb = d_out.rgb, *d_rgb2_in = d_out.rgb2, *d_depth = d_out.depth,
          *d_opacity = d_out.opacity;
  const T *sigma = in.sigma, *color = in.color, *color2 = in.color2, *s = in.s;
  const int64_t R = in.R;
  const int S = in.S;
  const T *rgb = out.rgb, *rgb2 = out.rgb2, *depth = out.depth, *opacity = out.opacity;
  const T* d_rgb2 = color2 ? d_rgb2_in : nullptr;
  const T* d_w = d_out.weights;  // (R,S) dL/dw_i, or null
  // Use the caller's totals only when they carry the full double precision of the prefix sums
  // (see compositor.h); otherwise one extra O(S) pass recomputes them. A weights' gradient always
  // takes that pass: its total Σ w_i dL/dw_i is no forward output.
  const bool given = std::is_same_v<T, double> && !d_w && rgb && (!d_rgb2 || rgb2) &&
                     (!d_depth || depth) && (!d_opacity || opacity);
  parallel_chunks(R, kRayChunk, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      const T* sig = sigma + r * S;
      const T* col = color + r * S * 3;
      const T* col2 = color2 ? color2 + r * S * 3 : nullptr;
      const T* sr = s + r * S;
      const T* dr = in.delta ? in.delta + r * S : nullptr;
      Totals tot{};
      if (given) {
        for (int a = 0; a < 3; ++a) tot.v[a] = double(rgb[3 * r + a]);
        if (d_rgb2)
          for (int a = 0; a < 3; ++a) tot.v[3 + a] = double(rgb2[3 * r + a]);
        if (d_depth) tot.v[6] = double(depth[r]);
        if (d_opacity) tot.v[7] = double(opacity[r]);
      } else {
        tot = ray_totals(sig, col, col2, sr, dr, S, d_w ? d_w + r * S : nullptr);
      }
      // Upstream gradients as one 8-vector g over [rgb, rgb2, depth, opacity] (0 when absent).
      double g[8] = {};
      for (int a = 0; a < 3; ++a) g[a] = double(d_rgb[3 * r + a]);
      if (d_rgb2)
        for (int a = 0; a < 3; ++a) g[3 + a] = double(d_rgb2[3 * r + a]);
      if (d_depth) g[6] = double(d_depth[r]);
      if (d_opacity) g[7] = double(d_opacity[r]);

      double prefix[9] = {};
      double Ti = 1;
      for (int i = 0; i < S; ++i) {
        const SampleFactors f = factors(sig, sr, dr, i, S);
        const T* ci = col + 3 * i;
        const T* c2i = col2 ? col2 + 3 * i : nullptr;
        const double si = double(sr[i]);
        const double w = Ti * f.alpha;
        const double dwi = d_w ? double(d_w[r * S + i]) : 0.0;
        accumulate_sample(prefix, Ti, f, ci, c2i, si, dwi);
        // ⟨g, per-sample value⟩ and ⟨g, suffix⟩, suffix = total − prefix up to and including i
        // = Σ_{k>i} w_k (value)_k: the "colour still to come". Nothing comes after the last sample.
        // A weight's own gradient dw_i is one more such value, with g = 1 (slot 8).
        double gc = g[6] * si + g[7] + dwi, gs = 0;
        for (int a = 0; a < 3; ++a) gc += g[a] * double(ci[a]);
        if (c2i)
          for (int a = 0; a < 3; ++a) gc += g[3 + a] * double(c2i[a]);
        if (i + 1 < S) {
          for (int k = 0; k < 8; ++k) gs += g[k] * (tot.v[k] - prefix[k]);
          gs += tot.v[8] - prefix[8];
        }
        // dL/dσ_i = δ_i [T_i e_i ⟨g, c_i⟩ − (e_i / q_i) ⟨g, suffix_i⟩]  (docs/math/compositor.md)
        d_sigma[r * S + i] = T(f.delta * (Ti * f.e * gc - (f.e / f.q) * gs));
        // dL/dc_i = w_i d_rgb, dL/dc2_i = w_i d_rgb2
        for (int a = 0; a < 3; ++a) d_color[(r * S + i) * 3 + a] = T(w * g[a]);
        if (d_color2 && col2)
          for (int a = 0; a < 3; ++a) d_color2[(r * S + i) * 3 + a] = T(w * g[3 + a]);
        Ti *= f.q;
      }
    }
  });
}

template <class T>
void composite_forward_naive(const CompositeOut<T>& out, const CompositeIn<T>& in) {
  T *rgb = out.rgb, *rgb2 = out.rgb2, *depth = out.depth, *opacity = out.opacity;
  const T *sigma = in.sigma, *color = in.color, *color2 = in.color2, *s = in.s;
  const int64_t R = in.R;
  const int S = in.S;
  for (int64_t r = 0; r < R; ++r) {
    T acc[8] = {};
    for (int i = 0; i < S; ++i) {
      const int64_t ri = r * S + i;
      T Ti = 1;  // T_i = Π_{j<i} (1 − α_j + 1e-10), recomputed from scratch: O(S²)
      for (int j = 0; j < i; ++j) {
        const T dj = in.delta ? in.delta[ri - i + j]
                              : j + 1 < S ? s[ri - i + j + 1] - s[ri - i + j] : T(kLastDelta);
        Ti *= T(1) - (T(1) - std::exp(-sigma[ri - i + j] * dj)) + T(kTransmittanceEps);
      }
      const T di = in.delta ? in.delta[ri] : i + 1 < S ? s[ri + 1] - s[ri] : T(kLastDelta);
      const T w = Ti * (T(1) - std::exp(-sigma[ri] * di));
      if (out.weights) out.weights[ri] = w;
      for (int a = 0; a < 3; ++a) acc[a] += w * color[ri * 3 + a];
      if (color2)
        for (int a = 0; a < 3; ++a) acc[3 + a] += w * color2[ri * 3 + a];
      acc[6] += w * s[ri];
      acc[7] += w;
    }
    for (int a = 0; a < 3; ++a) rgb[3 * r + a] = acc[a];
    if (rgb2 && color2)
      for (int a = 0; a < 3; ++a) rgb2[3 * r + a] = acc[3 + a];
    if (depth) depth[r] = acc[6];
    if (opacity) opacity[r] = acc[7];
  }
}

template <class T>
void composite_backward_naive(const CompositeInGrads<T>& d_in, const CompositeOut<const T>& d_out,
                              const CompositeIn<T>& in) {
  T *d_sigma = d_in.d_sigma, *d_color = d_in.d_color, *d_color2 = d_in.d_color2;
  const T *d_rgb = d_out.rgb, *d_rgb2 = d_out.rgb2, *d_depth = d_out.depth,
          *d_opacity = d_out.opacity;
  const T *sigma = in.sigma, *color = in.color, *color2 = in.color2, *s = in.s;
  const int64_t R = in.R;
  const int S = in.S;
  for (int64_t r = 0; r < R; ++r) {
    const T* sig = sigma + r * S;
    const T* sr = s + r * S;
    auto delta = [&](int i) {
      if (in.delta) return in.delta[r * S + i];
      return i + 1 < S ? sr[i + 1] - sr[i] : T(kLastDelta);
    };
    auto alpha = [&](int i) { return T(1) - std::exp(-sig[i] * delta(i)); };
    auto q = [&](int i) { return T(1) - alpha(i) + T(kTransmittanceEps); };
    // dL/dw_i = ⟨d_rgb, c_i⟩ + ⟨d_rgb2, c2_i⟩ + d_depth s_i + d_opacity
    auto dL_dw = [&](int i) {
      const int64_t ri = r * S + i;
      T v = 0;
      for (int a = 0; a < 3; ++a) v += d_rgb[3 * r + a] * color[ri * 3 + a];
      if (color2 && d_rgb2)
        for (int a = 0; a < 3; ++a) v += d_rgb2[3 * r + a] * color2[ri * 3 + a];
      if (d_depth) v += d_depth[r] * sr[i];
      if (d_opacity) v += d_opacity[r];
      if (d_out.weights) v += d_out.weights[ri];
      return v;
    };
    for (int j = 0; j < S; ++j) {
      const T dj = delta(j), ej = std::exp(-sig[j] * dj);
      T Tj = 1;
      for (int k = 0; k < j; ++k) Tj *= q(k);
      // dw_j/dσ_j = T_j δ_j e_j
      T acc = dL_dw(j) * Tj * dj * ej;
      // dw_i/dσ_j = −α_i δ_j e_j Π_{k<i, k≠j} q_k for i > j (T_i without its q_j factor)
      T Tnoj = Tj;
      for (int i = j + 1; i < S; ++i) {
        acc += dL_dw(i) * (-alpha(i) * dj * ej * Tnoj);
        Tnoj *= q(i);
      }
      d_sigma[r * S + j] = acc;
      const T wj = Tj * alpha(j);
      for (int a = 0; a < 3; ++a) d_color[(r * S + j) * 3 + a] = wj * d_rgb[3 * r + a];
      if (d_color2 && color2)
        for (int a = 0; a < 3; ++a)
          d_color2[(r * S + j) * 3 + a] = d_rgb2 ? wj * d_rgb2[3 * r + a] : T(0);
    }
  }
}

#define HASHCC_COMPOSITOR_INSTANTIATE(T)                                                      \
  template void composite_forward<T>(const CompositeOut<T>&, const CompositeIn<T>&);          \
  template void composite_backward<T>(const CompositeInGrads<T>&, const CompositeOut<const T>&, \
                                      const CompositeIn<T>&, const CompositeOut<const T>&);   \
  template void composite_forward_naive<T>(const CompositeOut<T>&, const CompositeIn<T>&);    \
  template void composite_backward_naive<T>(const CompositeInGrads<T>&,                       \
                                            const CompositeOut<const T>&, const CompositeIn<T>&);
HASHCC_COMPOSITOR_INSTANTIATE(float)
HASHCC_COMPOSITOR_INSTANTIATE(double)
#undef HASHCC_COMPOSITOR_INSTANTIATE

}  // namespace hashcc
