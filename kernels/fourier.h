// kernels/fourier.h — Fourier position/direction encoding γ(x) (formulas.md §4).
//
// Derivation: docs/math/fourier.md (proved by test/test_fourier.cpp, "[fourier][grad]").
// Gradient-write policy: d_x is an activation gradient, WRITTEN (=); no parameters.
// The bands are produced by the double-angle recurrence (one sin/cos per input value, then
// sin 2a = 2 sin a cos a, cos 2a = (cos a − sin a)(cos a + sin a)), carried in double: the error
// doubles per band, so band 9 is within ~1e-13 of the directly evaluated sin/cos — exact in
// float, and ~10× cheaper than 2L libm calls. fourier_*_naive evaluate sin/cos directly.
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

// References with one std::sin/std::cos per band (same contracts), for the tests.
template <class T>
void fourier_forward_naive(T* out, const T* x, int64_t N, int D, int L, const T* band_w = nullptr);
template <class T>
void fourier_backward_naive(T* d_x, const T* d_out, const T* x, int64_t N, int D, int L,
                            const T* band_w = nullptr);

}  // namespace hashcc
