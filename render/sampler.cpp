// render/sampler.cpp — see sampler.h; derivation in docs/math/sampler.md.
#include "render/sampler.h"

#include "kernels/chunked_for.h"

namespace hashcc {
namespace {
constexpr int64_t kRayChunk = 64;  // rays per fixed chunk (kernels/chunked_for.h)
}

template <class T>
void sample_points_forward(T* x, const T* o, const T* d, const T* s, int64_t R, int S) {
  parallel_chunks(R, kRayChunk, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      for (int k = 0; k < S; ++k) {
        const T sk = s[r * S + k];
        T* xk = x + (r * S + k) * 3;
        for (int a = 0; a < 3; ++a) xk[a] = o[3 * r + a] + sk * d[3 * r + a];
      }
    }
  });
}

template <class T>
void sample_points_backward(T* d_o, T* d_d, const T* d_x, const T* s, int64_t R, int S) {
  parallel_chunks(R, kRayChunk, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      double go[3] = {}, gd[3] = {};
      for (int k = 0; k < S; ++k) {
        const double sk = s[r * S + k];
        const T* gk = d_x + (r * S + k) * 3;
        for (int a = 0; a < 3; ++a) {
          go[a] += gk[a];        // ∂x_k/∂o = I
          gd[a] += sk * gk[a];   // ∂x_k/∂d = s_k I
        }
      }
      for (int a = 0; a < 3; ++a) {
        if (d_o) d_o[3 * r + a] = T(go[a]);
        if (d_d) d_d[3 * r + a] = T(gd[a]);
      }
    }
  });
}

template void sample_points_forward<float>(float*, const float*, const float*, const float*,
                                           int64_t, int);
template void sample_points_forward<double>(double*, const double*, const double*,
                                            const double*, int64_t, int);
template void sample_points_backward<float>(float*, float*, const float*, const float*, int64_t,
                                            int);
template void sample_points_backward<double>(double*, double*, const double*, const double*,
                                             int64_t, int);

}  // namespace hashcc
