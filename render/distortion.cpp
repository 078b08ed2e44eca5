// render/distortion.cpp — see distortion.h; derivation in docs/math/distortion.md.
#include "render/distortion.h"

#include "kernels/chunked_for.h"

namespace hashcc {
namespace {

constexpr int64_t kRayChunk = 16;  // rays per fixed chunk (kernels/chunked_for.h)

// Sample i's interval: width h_i and midpoint m_i (distortion.h).
struct Interval {
  double h, m;
};
template <class T>
inline Interval interval(const T* s, int i, int S) {
  const int j = i + 1 < S ? i : S - 2;  // the last sample: the gap before it
  const double h = S < 2 ? 0.0 : double(s[j + 1]) - double(s[j]);
  return {h, double(s[i]) + 0.5 * h};
}

}  // namespace

template <class T>
void distortion_forward(T* loss, const T* w, const T* s, int64_t R, int S) {
  parallel_chunks(R, kRayChunk, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      const T* wr = w + r * S;
      const T* sr = s + r * S;
      // Σ_{i,j} w_i w_j |m_i − m_j| = 2 Σ_i w_i Σ_{j<i} w_j (m_i − m_j) = 2 Σ_i w_i (m_i A_i − B_i),
      // A_i = Σ_{j<i} w_j, B_i = Σ_{j<i} w_j m_j  (m non-decreasing: |m_i − m_j| = m_i − m_j).
      double A = 0, B = 0, pairs = 0, self = 0;
      for (int i = 0; i < S; ++i) {
        const double wi = double(wr[i]);
        const auto [h, m] = interval(sr, i, S);
        pairs += wi * (m * A - B);
        self += wi * wi * h;
        A += wi;
        B += wi * m;
      }
      loss[r] = T(2 * pairs + self / 3);
    }
  });
}

template <class T>
void distortion_backward(T* d_w, const T* d_loss, const T* w, const T* s, int64_t R, int S) {
  parallel_chunks(R, kRayChunk, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      const T* wr = w + r * S;
      const T* sr = s + r * S;
      double At = 0, Bt = 0;  // totals Σ w_j, Σ w_j m_j
      for (int i = 0; i < S; ++i) {
        const double wi = double(wr[i]), m = interval(sr, i, S).m;
        At += wi;
        Bt += wi * m;
      }
      // Σ_j w_j |m_i − m_j| = Σ_{j<i} w_j (m_i − m_j) + Σ_{j>i} w_j (m_j − m_i)
      //                     = m_i (2 A_i − At) + Bt − 2 B_i   (the j = i term is 0)
      const double g = double(d_loss[r]);
      double A = 0, B = 0;
      for (int i = 0; i < S; ++i) {
        const double wi = double(wr[i]);
        const auto [h, m] = interval(sr, i, S);
        const double spread = m * (2 * A - At) + Bt - 2 * B;
        d_w[r * S + i] = T(g * (2 * spread + (2.0 / 3.0) * wi * h));
        A += wi;
        B += wi * m;
      }
    }
  });
}

#define HASHCC_DISTORTION_INSTANTIATE(T)                                         \
  template void distortion_forward<T>(T*, const T*, const T*, int64_t, int);     \
  template void distortion_backward<T>(T*, const T*, const T*, const T*, int64_t, int);
HASHCC_DISTORTION_INSTANTIATE(float)
HASHCC_DISTORTION_INSTANTIATE(double)
#undef HASHCC_DISTORTION_INSTANTIATE

}  // namespace hashcc
