// model/layers.h — a dense layer addressed by its LayerView in the parameter arena: the
// forward/backward wrappers the networks (model.cpp, grid_field.cpp) are written with.
#pragma once
#include "core/buffer.h"
#include "kernels/dense.h"
#include "kernels/fourier.h"
#include "kernels/sh.h"
#include "model/model.h"

namespace hashcc::layers {

template <class T>
inline void dense(T* y, const T* x, const T* p, const LayerView& lv, int64_t N) {
  dense_forward(y, x, p + lv.w, p + lv.b, N, lv.in, lv.out);
}
// Linear + ReLU fused: bias and ReLU in the GEMM chunk's epilogue, while the chunk is hot.
template <class T>
inline void dense_relu(T* y, const T* x, const T* p, const LayerView& lv, int64_t N) {
  dense_relu_forward(y, x, p + lv.w, p + lv.b, N, lv.in, lv.out);
}

// d_params may be null (input gradients only: the test-pose refinement's frozen networks, the
// camera's pass of a detached loss): then the layer's d_W and d_b are null and the dense kernels
// skip their GEMM and sums (kernels/dense.h).
template <class T>
inline void grad_slots(T** dW, T** db, T* d_params, const LayerView& lv) {
  *dW = d_params ? d_params + lv.w : nullptr;
  *db = d_params ? d_params + lv.b : nullptr;
}

template <class T>
inline void dense_bwd(T* d_x, T* d_params, const T* d_y, const T* x, const T* p, const LayerView& lv,
               int64_t N) {
  T *dW, *db;
  grad_slots(&dW, &db, d_params, lv);
  dense_backward(d_x, dW, db, d_y, x, p + lv.w, N, lv.in, lv.out);
}

// Backward of dense_relu. g (N, out) holds dL/dy of the ReLU output on entry and is overwritten
// with dL/d(pre-activation); y (N, out) is the forward output.
template <class T>
inline void dense_relu_bwd(T* d_x, T* d_params, T* g, const T* y, const T* x, const T* p,
                    const LayerView& lv, int64_t N) {
  T *dW, *db;
  grad_slots(&dW, &db, d_params, lv);
  dense_relu_backward(d_x, dW, db, g, g, y, x, p + lv.w, N, lv.in, lv.out);
}

// The view direction's encoding, one row per ray: Fourier (L = dir_bands) for nerfmm, real SH
// of degree sh_degree otherwise. out (R, E); dir (R, 3) unit.
template <class T>
inline void encode_dir(T* out, const T* dir, int R, const ModelConfig& cfg) {
  if (cfg.variant == Variant::nerfmm) fourier_forward(out, dir, R, 3, cfg.dir_bands);
  else sh_forward(out, dir, R, cfg.sh_degree);
}
// d_dir (R, 3) WRITTEN from d_enc (R, E).
template <class T>
inline void encode_dir_backward(T* d_dir, const T* d_enc, const T* dir, int R, const ModelConfig& cfg) {
  if (cfg.variant == Variant::nerfmm) fourier_backward(d_dir, d_enc, dir, R, 3, cfg.dir_bands);
  else sh_backward(d_dir, d_enc, dir, R, cfg.sh_degree);
}

// The backward of broadcasting one direction encoding to a ray's S samples: d_enc (R, E) =
// Σ over each ray's samples of columns [F, F+E) of g (R·S, F+E), the colour input's gradient
// [feature-or-geometry (F), direction encoding (E)].
template <class T>
inline void sum_dir_grad(T* d_enc, const T* g, int R, int S, int F, int E) {
  parallel_for(R, [&](int64_t r) {
    T* out = d_enc + r * E;
    for (int e = 0; e < E; ++e) out[e] = T(0);
    for (int k = 0; k < S; ++k) {
      const T* row = g + (r * S + k) * int64_t(F + E) + F;
      for (int e = 0; e < E; ++e) out[e] += row[e];
    }
  });
}

}  // namespace hashcc::layers
