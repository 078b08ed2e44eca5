// kernels/dense.h — dense layer y = x Wᵀ + b over a batch, activations, concat. CONTRACT.
#pragma once
#include <cstdint>
namespace hashcc {

// y (N, out) = x (N, in) · Wᵀ + b.  W (out, in) row-major (PyTorch layout), b (out).
template <class T>
void dense_forward(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out);

// d_x (N, in) written = d_y · W (skipped when d_x == nullptr); d_W (out, in) += d_yᵀ · x;
// d_b (out) += Σ_n d_y.
template <class T>
void dense_backward(T* d_x, T* d_W, T* d_b, const T* d_y, const T* x, const T* W, int64_t N,
                    int in, int out);

// Elementwise activations over n values; forward may run in place (y == x).
// Backward uses the forward OUTPUT y (relu: y > 0; sigmoid: y(1−y); exp: y), softplus uses x.
// d_x written; may alias d_y.
template <class T> void relu_forward(T* y, const T* x, int64_t n);
template <class T> void relu_backward(T* d_x, const T* d_y, const T* y, int64_t n);
template <class T> void sigmoid_forward(T* y, const T* x, int64_t n);
template <class T> void sigmoid_backward(T* d_x, const T* d_y, const T* y, int64_t n);
template <class T> void softplus_forward(T* y, const T* x, int64_t n);
template <class T> void softplus_backward(T* d_x, const T* d_y, const T* x, int64_t n);
template <class T> void exp_forward(T* y, const T* x, int64_t n);
template <class T> void exp_backward(T* d_x, const T* d_y, const T* y, int64_t n);

// Row-wise concat: out (N, A+B) = [a (N, A), b (N, B)]; split is its backward
// (d_a (N, A), d_b (N, B) written; either may be null).
template <class T> void concat_forward(T* out, const T* a, const T* b, int64_t N, int A, int B);
template <class T> void concat_backward(T* d_a, T* d_b, const T* d_out, int64_t N, int A, int B);

}  // namespace hashcc
