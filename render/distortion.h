// render/distortion.h — the distortion loss of mip-NeRF 360 (Barron et al. 2022, eq. 15) on the
// compositing weights along a ray: --distortion λ (beyond the paper; off by default).
//
//   L = Σ_i Σ_j w_i w_j |m_i − m_j|  +  (1/3) Σ_i w_i² h_i
//
// over the ray's samples i, j = 0..S−1, with w_i the compositor's weights (CompositeOut::weights),
// sample i standing for the interval [s_i, s_i + h_i], h_i = s_{i+1} − s_i (the last sample's h is
// the gap before it: its compositing δ of 1e10 only means "absorb what is left"), midpoint
// m_i = s_i + h_i/2. The first term pulls a ray's weight together (two lumps far apart cost their
// distance); the second shrinks each lump (a weight spread over one interval costs a third of its
// width). Its minimum, for a fixed opacity, is all the weight in one narrow interval: a surface.
// It is what removes "floaters", semi-transparent density in front of the surface that the
// training views do not see but the held-out ones do.
//
// Derivation and proof: docs/math/distortion.md; test/test_distortion.cpp ("[distortion]").
// O(S) per ray, forward and backward (prefix sums, valid because m_i is non-decreasing when s is
// increasing), against an O(S²) double sum in the tests. Accumulated in double for both
// instantiations. Threading: rays are split over threads.
#pragma once
#include <cstdint>

namespace hashcc {

// loss (R) WRITTEN: each ray's L. w, s (R, S).
template <class T>
void distortion_forward(T* loss, const T* w, const T* s, int64_t R, int S);

// d_w (R, S) WRITTEN: d_loss_r · dL_r/dw_i. d_loss (R): the upstream gradient of each ray's L.
//   dL/dw_i = 2 Σ_j w_j |m_i − m_j| + (2/3) w_i h_i
template <class T>
void distortion_backward(T* d_w, const T* d_loss, const T* w, const T* s, int64_t R, int S);

}  // namespace hashcc
