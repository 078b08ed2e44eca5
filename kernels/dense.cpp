// kernels/dense.cpp — see dense.h for contracts, docs/math/dense.md for the derivations.
#include "kernels/dense.h"

#include <algorithm>
#include <cmath>
#include <Eigen/Core>

#include "core/buffer.h"
#include "kernels/chunked_for.h"

namespace hashcc {
namespace {

// Rows per GEMM chunk: X chunk 256×128 floats = 128 KiB, Y chunk the same, W 64 KiB — all fit
// in the 1 MiB L2 per core, so the epilogue touches hot data. Fixed (not derived from the thread
// count) so every chunk's arithmetic is identical at any thread count.
constexpr int64_t kChunkRows = 256;
// Elementwise kernels: fixed chunks of this many values (kernels/chunked_for.h); below two
// chunks they run serially, where OpenMP would cost more than it saves.
constexpr int64_t kElemChunk = 1 << 15;

// Y = X·Wᵀ (+ b, then ReLU when Relu) over row chunks.
template <class T, bool Relu>
void dense_forward_impl(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out) {
  if (N <= 0) return;
  CMapRM<T> Wm(W, out, in);
  parallel_chunks(N, kChunkRows, [&](int64_t r0, int64_t r1) {
    const int64_t rows = r1 - r0;
    MapRMu<T> Y(y + r0 * out, rows, out);
    Y.noalias() = CMapRM<T>(x + r0 * in, rows, in) * Wm.transpose();
    for (int64_t r = 0; r < rows; ++r) {
      T* yr = y + (r0 + r) * out;
      for (int o = 0; o < out; ++o) {
        T v = yr[o] + b[o];
        if constexpr (Relu) v = v > T(0) ? v : T(0);
        yr[o] = v;
      }
    }
  });
}

// The backward's reduction over the batch (d_W, d_b) is split into fixed slabs of kSlabRows rows
// (16 chunks). Each slab writes its own partial; partials are then added in slab order. Fixed
// slabs make d_W and d_b bit-identical at any thread count, and this K-split measured ~300
// GFLOP/s at 2 threads against ~220 for letting Eigen split the (out, in) result.
constexpr int64_t kSlabRows = 16 * kChunkRows;

// Grow-only per-calling-thread scratch for the slab partials: allocated on the first call (and
// when a larger batch appears), never per step. thread_local keeps concurrent callers apart.
// Tag distinguishes the d_W partials from the d_b partials (both double in the double build).
template <class T, int Tag>
T* slab_scratch(size_t n) {
  thread_local AlignedVec<T> buf;
  return ensure(buf, n);
}

// Shared backward. When d_pre != nullptr: d_pre = d_y ⊙ [y > 0] first (ReLU), then use d_pre.
template <class T>
void dense_backward_impl(T* d_x, T* d_W, T* d_b, T* d_pre, const T* d_y, const T* y, const T* x,
                         const T* W, int64_t N, int in, int out) {
  if (N <= 0) return;
  CMapRM<T> Wm(W, out, in);
  const T* g = d_pre ? d_pre : d_y;  // dL/d(pre-activation) (N, out)
  const int64_t nslabs = (N + kSlabRows - 1) / kSlabRows;
  const int64_t wsize = int64_t(out) * in;
  T* pW = d_W ? slab_scratch<T, 0>(size_t(nslabs * wsize)) : nullptr;        // (nslabs, out, in)
  double* pb = d_b ? slab_scratch<double, 1>(size_t(nslabs * out)) : nullptr;  // (nslabs, out)

  parallel_chunks(N, kSlabRows, [&](int64_t s0, int64_t s1) {
    const int64_t sl = s0 / kSlabRows;
    MapRMu<T> P(pW ? pW + sl * wsize : nullptr, out, pW ? in : 0);
    double* bacc = pb ? pb + sl * out : nullptr;
    if (pW) P.setZero();
    if (bacc) std::fill_n(bacc, out, 0.0);
    // Per 256-row chunk, while the chunk of g is in L2: ReLU mask, d_x = g·W, d_W partial
    // += gᵀ·x, d_b partial += column sums (in double: 131072-term float sums would drift).
    for (int64_t r0 = s0; r0 < s1; r0 += kChunkRows) {
      const int64_t rows = std::min(kChunkRows, s1 - r0);
      if (d_pre) {
        const int64_t e0 = r0 * out, e1 = (r0 + rows) * out;
        // Branch-free select (d_y read unconditionally, omp simd since d_pre may alias d_y
        // index for index): a branchy scalar loop mispredicts on the random mask and measured
        // 58 ms for 131072×128, longer than the two GEMMs of the layer.
#pragma omp simd
        for (int64_t i = e0; i < e1; ++i) {
          const T gi = d_y[i];
          d_pre[i] = y[i] > T(0) ? gi : T(0);
        }
      }
      CMapRM<T> G(g + r0 * out, rows, out);
      if (d_x) MapRMu<T>(d_x + r0 * in, rows, in).noalias() = G * Wm;
      if (pW) P.noalias() += G.transpose() * CMapRM<T>(x + r0 * in, rows, in);
      if (bacc)
        for (int64_t r = 0; r < rows; ++r) {
          const T* gr = g + (r0 + r) * out;
          for (int o = 0; o < out; ++o) bacc[o] += double(gr[o]);
        }
    }
  });

  // Reduce partials in slab order; each output entry is owned by one thread.
  if (pW)
    parallel_blocks(wsize, [&](int64_t i0, int64_t i1, int) {
      for (int64_t sl = 0; sl < nslabs; ++sl) {
        const T* p = pW + sl * wsize;
        for (int64_t i = i0; i < i1; ++i) d_W[i] += p[i];
      }
    }, 4096);
  if (pb)
    for (int o = 0; o < out; ++o) {
      double acc = 0;
      for (int64_t sl = 0; sl < nslabs; ++sl) acc += pb[sl * out + o];
      d_b[o] += T(acc);
    }
}

// f(i) for i in [0, n), in fixed chunks. omp simd: in-place use (y == x, d_x == d_y) is same-index only, so
// vectorising is safe even though the compiler cannot prove the pointers disjoint.
template <class F>
void elementwise(int64_t n, F&& f) {
  parallel_chunks(n, kElemChunk, [&](int64_t b, int64_t e) {
#pragma omp simd
    for (int64_t i = b; i < e; ++i) f(i);
  });
}

}  // namespace

template <class T>
void dense_forward(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out) {
  dense_forward_impl<T, false>(y, x, W, b, N, in, out);
}

template <class T>
void dense_relu_forward(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out) {
  dense_forward_impl<T, true>(y, x, W, b, N, in, out);
}

template <class T>
void dense_backward(T* d_x, T* d_W, T* d_b, const T* d_y, const T* x, const T* W, int64_t N,
                    int in, int out) {
  dense_backward_impl<T>(d_x, d_W, d_b, nullptr, d_y, nullptr, x, W, N, in, out);
}

template <class T>
void dense_relu_backward(T* d_x, T* d_W, T* d_b, T* d_pre, const T* d_y, const T* y, const T* x,
                         const T* W, int64_t N, int in, int out) {
  dense_backward_impl<T>(d_x, d_W, d_b, d_pre, d_y, y, x, W, N, in, out);
}

template <class T>
void dense_forward_naive(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out) {
  for (int64_t n = 0; n < N; ++n)
    for (int o = 0; o < out; ++o) {
      T acc = b[o];
      for (int i = 0; i < in; ++i) acc += x[n * in + i] * W[int64_t(o) * in + i];
      y[n * out + o] = acc;
    }
}

template <class T>
void dense_backward_naive(T* d_x, T* d_W, T* d_b, const T* d_y, const T* x, const T* W,
                          int64_t N, int in, int out) {
  for (int64_t n = 0; n < N; ++n) {
    if (d_x)
      for (int i = 0; i < in; ++i) {
        T acc = 0;
        for (int o = 0; o < out; ++o) acc += d_y[n * out + o] * W[int64_t(o) * in + i];
        d_x[n * in + i] = acc;
      }
    for (int o = 0; o < out; ++o) {
      if (d_b) d_b[o] += d_y[n * out + o];
      if (d_W)
        for (int i = 0; i < in; ++i) d_W[int64_t(o) * in + i] += d_y[n * out + o] * x[n * in + i];
    }
  }
}

template <class T>
void relu_forward(T* y, const T* x, int64_t n) {
  elementwise(n, [=](int64_t i) { y[i] = x[i] > T(0) ? x[i] : T(0); });
}
template <class T>
void relu_backward(T* d_x, const T* d_y, const T* y, int64_t n) {
  // y > 0 ⇔ x > 0; the kink x = 0 gets gradient 0 (PyTorch's choice).
  elementwise(n, [=](int64_t i) {
    const T g = d_y[i];  // read unconditionally: a select, not a mispredicted branch
    d_x[i] = y[i] > T(0) ? g : T(0);
  });
}

template <class T>
void sigmoid_forward(T* y, const T* x, int64_t n) {
  // exp of −|x| only: never overflows; for x ≪ 0, e/(1+e) keeps the tiny value's precision.
  elementwise(n, [=](int64_t i) {
    T v = x[i];
    if (v >= T(0)) {
      y[i] = T(1) / (T(1) + std::exp(-v));
    } else {
      T e = std::exp(v);
      y[i] = e / (T(1) + e);
    }
  });
}
template <class T>
void sigmoid_backward(T* d_x, const T* d_y, const T* y, int64_t n) {
  elementwise(n, [=](int64_t i) { d_x[i] = d_y[i] * y[i] * (T(1) - y[i]); });
}

template <class T>
void softplus_forward(T* y, const T* x, int64_t n) {
  // log(1 + eˣ) = max(x, 0) + log1p(e^{−|x|}): exact for both tails, no overflow.
  elementwise(n, [=](int64_t i) {
    T v = x[i];
    y[i] = std::max(v, T(0)) + std::log1p(std::exp(-std::abs(v)));
  });
}
template <class T>
void softplus_backward(T* d_x, const T* d_y, const T* x, int64_t n) {
  // softplus' = sigmoid(x), evaluated with the same sign branch as sigmoid_forward.
  elementwise(n, [=](int64_t i) {
    T v = x[i], s;
    if (v >= T(0)) {
      s = T(1) / (T(1) + std::exp(-v));
    } else {
      T e = std::exp(v);
      s = e / (T(1) + e);
    }
    d_x[i] = d_y[i] * s;
  });
}

template <class T>
void exp_forward(T* y, const T* x, int64_t n) {
  elementwise(n, [=](int64_t i) { y[i] = std::exp(std::min(x[i], T(kExpClampMax))); });
}
template <class T>
void exp_backward(T* d_x, const T* d_y, const T* y, int64_t n) {
  elementwise(n, [=](int64_t i) { d_x[i] = d_y[i] * y[i]; });
}

template <class T>
void concat_forward(T* out, const T* a, const T* b, int64_t N, int A, int B) {
  const int C = A + B;
  parallel_blocks(N, [&](int64_t r0, int64_t r1, int) {
    for (int64_t r = r0; r < r1; ++r) {
      std::copy_n(a + r * A, A, out + r * C);
      std::copy_n(b + r * B, B, out + r * C + A);
    }
  }, 4096);
}
template <class T>
void concat_backward(T* d_a, T* d_b, const T* d_out, int64_t N, int A, int B) {
  const int C = A + B;
  parallel_blocks(N, [&](int64_t r0, int64_t r1, int) {
    for (int64_t r = r0; r < r1; ++r) {
      if (d_a) std::copy_n(d_out + r * C, A, d_a + r * A);
      if (d_b) std::copy_n(d_out + r * C + A, B, d_b + r * B);
    }
  }, 4096);
}

#define HASHCC_DENSE_INSTANTIATE(T)                                                            \
  template void dense_forward<T>(T*, const T*, const T*, const T*, int64_t, int, int);          \
  template void dense_relu_forward<T>(T*, const T*, const T*, const T*, int64_t, int, int);     \
  template void dense_forward_naive<T>(T*, const T*, const T*, const T*, int64_t, int, int);    \
  template void dense_backward<T>(T*, T*, T*, const T*, const T*, const T*, int64_t, int, int); \
  template void dense_backward_naive<T>(T*, T*, T*, const T*, const T*, const T*, int64_t, int, \
                                        int);                                                   \
  template void dense_relu_backward<T>(T*, T*, T*, T*, const T*, const T*, const T*, const T*,  \
                                       int64_t, int, int);                                      \
  template void relu_forward<T>(T*, const T*, int64_t);                                         \
  template void relu_backward<T>(T*, const T*, const T*, int64_t);                              \
  template void sigmoid_forward<T>(T*, const T*, int64_t);                                      \
  template void sigmoid_backward<T>(T*, const T*, const T*, int64_t);                           \
  template void softplus_forward<T>(T*, const T*, int64_t);                                     \
  template void softplus_backward<T>(T*, const T*, const T*, int64_t);                          \
  template void exp_forward<T>(T*, const T*, int64_t);                                          \
  template void exp_backward<T>(T*, const T*, const T*, int64_t);                               \
  template void concat_forward<T>(T*, const T*, const T*, int64_t, int, int);                   \
  template void concat_backward<T>(T*, T*, const T*, int64_t, int, int);

HASHCC_DENSE_INSTANTIATE(float)
HASHCC_DENSE_INSTANTIATE(double)
#undef HASHCC_DENSE_INSTANTIATE

}  // namespace hashcc
