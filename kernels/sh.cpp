// kernels/sh.cpp — see sh.h; derivation in docs/math/sh.md.
#include "kernels/sh.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "kernels/chunked_for.h"

namespace hashcc {
namespace {

#include "kernels/sh_generated.inc"

constexpr int64_t kChunk = 4096;  // rows per fixed chunk (kernels/chunked_for.h)

inline void check_degree(int degree) {
  HCC_REQUIRE(degree >= 1 && degree <= 4, "", "sh degree", "degree {} is not supported",
              degree);
}

// Forward-mode dual number a + b·ε (ε² = 0): evaluating Y_k on (x + ε) gives ∂Y_k/∂x exactly,
// an independent check of the generated derivative code.
template <class T>
struct Dual {
  T a, b;
  Dual(T a_ = 0, T b_ = 0) : a(a_), b(b_) {}
  friend Dual operator+(Dual p, Dual q) { return {p.a + q.a, p.b + q.b}; }
  friend Dual operator-(Dual p, Dual q) { return {p.a - q.a, p.b - q.b}; }
  friend Dual operator-(Dual p) { return {-p.a, -p.b}; }
  friend Dual operator*(Dual p, Dual q) { return {p.a * q.a, p.a * q.b + p.b * q.a}; }
};

// Spec §8, typed from the table (degree² values into o).
template <class S>
void sh_eval_spec(S* o, S x, S y, S z, int degree) {
  using C = S;
  o[0] = C(0.28209479177387814);
  if (degree < 2) return;
  o[1] = C(-0.48860251190291987) * y;
  o[2] = C(0.48860251190291987) * z;
  o[3] = C(-0.48860251190291987) * x;
  if (degree < 3) return;
  o[4] = C(1.0925484305920792) * x * y;
  o[5] = C(-1.0925484305920792) * y * z;
  o[6] = C(0.94617469575755997) * z * z - C(0.31539156525251999);
  o[7] = C(-1.0925484305920792) * x * z;
  o[8] = C(0.54627421529603959) * (x * x - y * y);
  if (degree < 4) return;
  o[9] = C(0.59004358992664352) * y * (C(-3) * x * x + y * y);
  o[10] = C(2.8906114426405538) * x * y * z;
  o[11] = C(0.45704579946446572) * y * (C(1) - C(5) * z * z);
  o[12] = C(0.3731763325901154) * z * (C(5) * z * z - C(3));
  o[13] = C(0.45704579946446572) * x * (C(1) - C(5) * z * z);
  o[14] = C(1.4453057213202769) * z * (x * x - y * y);
  o[15] = C(0.59004358992664352) * x * (-x * x + C(3) * y * y);
}

// inv = 1/|v| (0 for v = 0). Scaled by the largest component first so |v|² neither overflows
// nor underflows in float (|v| from 1e-30 to 1e30 stays exact to rounding).
template <class T>
inline void inverse_norm(const T* v, T& inv) {
  const T m = std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])});
  if (!(m > T(0))) { inv = T(0); return; }
  const T a = v[0] / m, b = v[1] / m, c = v[2] / m;
  inv = T(1) / (m * std::sqrt(a * a + b * b + c * c));
}

}  // namespace

template <class T>
void sh_forward(T* out, const T* dir, int64_t N, int degree) {
  check_degree(degree);
  const int K = degree * degree;
  parallel_chunks(N, kChunk, [&](int64_t n0, int64_t n1) {
    for (int64_t n = n0; n < n1; ++n) {
      const T* d = dir + 3 * n;
      sh_eval_generated<T>(out + n * K, d[0], d[1], d[2], degree);
    }
  });
}

template <class T>
void sh_backward(T* d_dir, const T* d_out, const T* dir, int64_t N, int degree) {
  check_degree(degree);
  const int K = degree * degree;
  parallel_chunks(N, kChunk, [&](int64_t n0, int64_t n1) {
    for (int64_t n = n0; n < n1; ++n) {
      const T* d = dir + 3 * n;
      sh_grad_generated<T>(d_dir + 3 * n, d_out + n * K, d[0], d[1], d[2], degree);
    }
  });
}

template <class T>
void sh_forward_naive(T* out, const T* dir, int64_t N, int degree) {
  check_degree(degree);
  const int K = degree * degree;
  for (int64_t n = 0; n < N; ++n)
    sh_eval_spec<T>(out + n * K, dir[3 * n], dir[3 * n + 1], dir[3 * n + 2], degree);
}

template <class T>
void sh_backward_naive(T* d_dir, const T* d_out, const T* dir, int64_t N, int degree) {
  check_degree(degree);
  const int K = degree * degree;
  for (int64_t n = 0; n < N; ++n)
    for (int a = 0; a < 3; ++a) {  // seed ε on component a
      Dual<T> v[3] = {dir[3 * n], dir[3 * n + 1], dir[3 * n + 2]};
      v[a].b = 1;
      Dual<T> o[16];
      sh_eval_spec<Dual<T>>(o, v[0], v[1], v[2], degree);
      T acc = 0;
      for (int k = 0; k < K; ++k) acc += d_out[n * K + k] * o[k].b;
      d_dir[3 * n + a] = acc;
    }
}

template <class T>
void normalize3_forward(T* u, const T* v, int64_t N) {
  parallel_chunks(N, kChunk, [&](int64_t n0, int64_t n1) {
    for (int64_t n = n0; n < n1; ++n) {
      T inv;
      const T* vn = v + 3 * n;
      inverse_norm(vn, inv);
      for (int a = 0; a < 3; ++a) u[3 * n + a] = vn[a] * inv;
    }
  });
}

template <class T>
void normalize3_backward(T* d_v, const T* d_u, const T* v, int64_t N) {
  parallel_chunks(N, kChunk, [&](int64_t n0, int64_t n1) {
    for (int64_t n = n0; n < n1; ++n) {
      const T* vn = v + 3 * n;
      const T* g = d_u + 3 * n;
      T inv;
      inverse_norm(vn, inv);
      // du/dv = (I − u uᵀ)/|v|, symmetric: d_v = (d_u − u ⟨u, d_u⟩)/|v|.
      const T u0 = vn[0] * inv, u1 = vn[1] * inv, u2 = vn[2] * inv;
      const T ug = u0 * g[0] + u1 * g[1] + u2 * g[2];
      d_v[3 * n + 0] = (g[0] - u0 * ug) * inv;
      d_v[3 * n + 1] = (g[1] - u1 * ug) * inv;
      d_v[3 * n + 2] = (g[2] - u2 * ug) * inv;
    }
  });
}

#define HASHCC_SH_INSTANTIATE(T)                                                  \
  template void sh_forward<T>(T*, const T*, int64_t, int);                        \
  template void sh_backward<T>(T*, const T*, const T*, int64_t, int);             \
  template void sh_forward_naive<T>(T*, const T*, int64_t, int);                  \
  template void sh_backward_naive<T>(T*, const T*, const T*, int64_t, int);       \
  template void normalize3_forward<T>(T*, const T*, int64_t);                     \
  template void normalize3_backward<T>(T*, const T*, const T*, int64_t);
HASHCC_SH_INSTANTIATE(float)
HASHCC_SH_INSTANTIATE(double)
#undef HASHCC_SH_INSTANTIATE

}  // namespace hashcc
