// kernels/fourier.h — Fourier position/direction encoding γ(x) (spec §4).
// CONTRACT (implementation pending in the kernels issue).
#pragma once
#include <cstdint>
namespace hashcc {

// Output width of γ for D input dims and L bands: D·(1 + 2L)  (63 for D=3, L=10; 27 for L=4).
constexpr int fourier_width(int D, int L) { return D * (1 + 2 * L); }

// out (N, D(1+2L)) = [x, sin(2^0 x), cos(2^0 x), …, sin(2^{L-1} x), cos(2^{L-1} x)], each block D
// values, no π factor. band_w (L,) optional per-band weights (coarse-to-fine / BARF); nullptr = 1.
template <class T>
void fourier_forward(T* out, const T* x, int64_t N, int D, int L, const T* band_w = nullptr);

// d_x (N, D) = (written, not accumulated) dL/dx given d_out (N, D(1+2L)).
template <class T>
void fourier_backward(T* d_x, const T* d_out, const T* x, int64_t N, int D, int L,
                      const T* band_w = nullptr);

}  // namespace hashcc
