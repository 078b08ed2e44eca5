// render/sampler.h — samples along rays (formulas.md §2–§3).
//
// Derivation: docs/math/sampler.md (proved by test/test_compositor.cpp, "[compositor][grad]").
// Gradient-write policy: d_o, d_d are activation gradients, WRITTEN (=). The per-ray sums over
// samples are accumulated in double and in sample order (same result at any thread count).
#pragma once
#include <cstdint>
namespace hashcc {

// x (R·S, 3) = o (R,3) + s (R,S) · d (R,3), ray-major (sample k of ray r at row r·S + k).
template <class T>
void sample_points_forward(T* x, const T* o, const T* d, const T* s, int64_t R, int S);
// d_o (R,3), d_d (R,3) WRITTEN from d_x (R·S, 3): d_o = Σ_k d_x, d_d = Σ_k s_k d_x.
template <class T>
void sample_points_backward(T* d_o, T* d_d, const T* d_x, const T* s, int64_t R, int S);

}  // namespace hashcc
