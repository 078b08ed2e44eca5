// render/compositor.h — volume compositing (spec §3). CONTRACT.
#pragma once
#include <cstdint>
namespace hashcc {

// Per ray r (R rays, S samples): sigma (R, S) is already ≥ 0 (relu applied before);
// color (R, S, 3); color2 (R, S, 3) optional second colour set sharing sigma (HashCC's c+Δc);
// s (R, S) increasing sample positions; δ_i = s_{i+1} − s_i, last δ = 1e10;
// α = 1 − exp(−σδ); T_i = Π_{j<i}(1 − α_j + 1e-10); w = Tα.
// Outputs: rgb (R,3) = Σ w c; rgb2 (R,3) = Σ w c2 (when color2); depth (R) = Σ w s;
// opacity (R) = Σ w. depth/opacity may be null.
template <class T>
void composite_forward(T* rgb, T* rgb2, T* depth, T* opacity, const T* sigma, const T* color,
                       const T* color2, const T* s, int64_t R, int S);

// Backward in O(S) per ray with no per-sample storage (second pass + suffix sums).
// d_sigma (R,S), d_color (R,S,3), d_color2 (R,S,3) WRITTEN (d_color2 null when no color2).
// d_rgb2, d_depth, d_opacity may be null (no gradient from them). rgb, rgb2, depth, opacity
// are the forward outputs (needed for the "still to come" suffix); pass them as computed.
template <class T>
void composite_backward(T* d_sigma, T* d_color, T* d_color2, const T* d_rgb, const T* d_rgb2,
                        const T* d_depth, const T* d_opacity, const T* sigma, const T* color,
                        const T* color2, const T* s, const T* rgb, const T* rgb2,
                        const T* depth, const T* opacity, int64_t R, int S);

}  // namespace hashcc
