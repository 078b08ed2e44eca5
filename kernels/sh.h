// kernels/sh.h — real spherical harmonics, degree 1..4 (spec §8). CONTRACT.
#pragma once
#include <cstdint>
namespace hashcc {

// out (N, degree²) basis values of unit directions dir (N, 3).
template <class T>
void sh_forward(T* out, const T* dir, int64_t N, int degree);
// d_dir (N, 3) written: dL/ddir given d_out (N, degree²) (as a function of the raw 3 values).
template <class T>
void sh_backward(T* d_dir, const T* d_out, const T* dir, int64_t N, int degree);

// Normalisation u = v/|v| of (N, 3) vectors and its backward (d_v written).
template <class T>
void normalize3_forward(T* u, const T* v, int64_t N);
template <class T>
void normalize3_backward(T* d_v, const T* d_u, const T* v, int64_t N);

}  // namespace hashcc
