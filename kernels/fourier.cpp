// kernels/fourier.cpp — see fourier.h; derivation in docs/math/fourier.md.
#include "kernels/fourier.h"

#include <cmath>

#include "kernels/chunked_for.h"

namespace hashcc {
namespace {
constexpr int64_t kChunk = 2048;  // rows per fixed chunk (kernels/chunked_for.h)
}

template <class T>
void fourier_forward(T* out, const T* x, int64_t N, int D, int L, const T* band_w) {
  const int W = fourier_width(D, L);
  parallel_chunks(N, kChunk, [&](int64_t n0, int64_t n1) {
    for (int64_t n = n0; n < n1; ++n) {
      const T* xn = x + n * D;
      T* on = out + n * W;
      for (int d = 0; d < D; ++d) {
        on[d] = xn[d];  // the raw block is never weighted
        double s = std::sin(double(xn[d])), c = std::cos(double(xn[d]));  // band 0: sin x, cos x
        for (int k = 0; k < L; ++k) {
          const double wk = band_w ? double(band_w[k]) : 1.0;
          on[D * (1 + 2 * k) + d] = T(wk * s);
          on[D * (2 + 2 * k) + d] = T(wk * c);
          const double s2 = 2 * s * c, c2 = (c - s) * (c + s);  // angle 2^k x → 2^{k+1} x
          s = s2; c = c2;
        }
      }
    }
  });
}

template <class T>
void fourier_backward(T* d_x, const T* d_out, const T* x, int64_t N, int D, int L,
                      const T* band_w) {
  const int W = fourier_width(D, L);
  parallel_chunks(N, kChunk, [&](int64_t n0, int64_t n1) {
    for (int64_t n = n0; n < n1; ++n) {
      const T* xn = x + n * D;
      const T* gn = d_out + n * W;
      for (int d = 0; d < D; ++d) {
        // dγ/dx: raw block 1; sin block w_k 2^k cos(2^k x); cos block −w_k 2^k sin(2^k x).
        double acc = double(gn[d]);
        double s = std::sin(double(xn[d])), c = std::cos(double(xn[d])), f = 1.0;  // f = 2^k
        for (int k = 0; k < L; ++k) {
          const double wk = band_w ? double(band_w[k]) : 1.0;
          acc += wk * f * (c * double(gn[D * (1 + 2 * k) + d]) - s * double(gn[D * (2 + 2 * k) + d]));
          const double s2 = 2 * s * c, c2 = (c - s) * (c + s);
          s = s2; c = c2; f *= 2;
        }
        d_x[n * D + d] = T(acc);
      }
    }
  });
}

template <class T>
void fourier_forward_naive(T* out, const T* x, int64_t N, int D, int L, const T* band_w) {
  const int W = fourier_width(D, L);
  for (int64_t n = 0; n < N; ++n)
    for (int d = 0; d < D; ++d) {
      const T v = x[n * D + d];
      out[n * W + d] = v;
      for (int k = 0; k < L; ++k) {
        const T wk = band_w ? band_w[k] : T(1), a = std::ldexp(v, k);
        out[n * W + D * (1 + 2 * k) + d] = wk * std::sin(a);
        out[n * W + D * (2 + 2 * k) + d] = wk * std::cos(a);
      }
    }
}

template <class T>
void fourier_backward_naive(T* d_x, const T* d_out, const T* x, int64_t N, int D, int L,
                            const T* band_w) {
  const int W = fourier_width(D, L);
  for (int64_t n = 0; n < N; ++n)
    for (int d = 0; d < D; ++d) {
      const T v = x[n * D + d];
      T acc = d_out[n * W + d];
      for (int k = 0; k < L; ++k) {
        const T wk = band_w ? band_w[k] : T(1), f = std::ldexp(T(1), k), a = f * v;
        acc += wk * f * std::cos(a) * d_out[n * W + D * (1 + 2 * k) + d];
        acc -= wk * f * std::sin(a) * d_out[n * W + D * (2 + 2 * k) + d];
      }
      d_x[n * D + d] = acc;
    }
}

#define HASHCC_FOURIER_INSTANTIATE(T)                                                         \
  template void fourier_forward<T>(T*, const T*, int64_t, int, int, const T*);                \
  template void fourier_backward<T>(T*, const T*, const T*, int64_t, int, int, const T*);     \
  template void fourier_forward_naive<T>(T*, const T*, int64_t, int, int, const T*);          \
  template void fourier_backward_naive<T>(T*, const T*, const T*, int64_t, int, int, const T*);
HASHCC_FOURIER_INSTANTIATE(float)
HASHCC_FOURIER_INSTANTIATE(double)
#undef HASHCC_FOURIER_INSTANTIATE

}  // namespace hashcc
