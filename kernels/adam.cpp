// kernels/adam.cpp — Adam step and exponential lr decay (see adam.h, docs/math/adam.md).
#include "kernels/adam.h"

#include <cmath>

#include "core/error.h"
#include "core/parallel.h"

namespace hashcc {

namespace {

// One thread's share of the update, element-wise. A function of its own with restrict pointers
// and scalars by value: written inside the lambda, through its captured references, every store
// to m or v could have changed the pointers, and the loop stayed scalar; here (with
// -fno-math-errno for the sqrt: CMakeLists.txt) it is one vector loop — the same values.
template <class T>
void adam_block(T* __restrict param, const T* __restrict grad, T* __restrict m, T* __restrict v,
                int64_t b, int64_t e, T b1, T omb1, T b2, T omb2, T step_size, T inv_sqrt_bc2,
                T eps) {
  for (int64_t i = b; i < e; ++i) {
    const T g = grad[i];
    const T mi = b1 * m[i] + omb1 * g;      // m = β1 m + (1−β1) g
    const T vi = b2 * v[i] + omb2 * g * g;  // v = β2 v + (1−β2) g²
    m[i] = mi;
    v[i] = vi;
    param[i] -= step_size * mi / (std::sqrt(vi) * inv_sqrt_bc2 + eps);
  }
}

}  // namespace

template <class T>
void adam_step(T* param, const T* grad, T* m, T* v, int64_t n, double lr, int64_t t,
               const AdamHyper& h) {
  HCC_REQUIRE(t >= 1, "", "adam step", "t = {} (expected the 1-based step count)", t);
  if (n <= 0) return;
  // Bias corrections 1 − β^t computed once in double (β^t underflows gracefully to 0).
  const double bc1 = 1.0 - std::pow(h.beta1, double(t));
  const double bc2 = 1.0 - std::pow(h.beta2, double(t));
  // PyTorch's arrangement: p −= (lr/bc1) · m / (sqrt(v)/sqrt(bc2) + eps).
  const T step_size = T(lr / bc1);
  const T inv_sqrt_bc2 = T(1.0 / std::sqrt(bc2));
  const T b1 = T(h.beta1), b2 = T(h.beta2), omb1 = T(1.0 - h.beta1), omb2 = T(1.0 - h.beta2);
  const T eps = T(h.eps);
  // Elementwise, so any split is exact: results are bitwise independent of thread count.
  parallel_blocks(
      n,
      [&](int64_t b, int64_t e, int) {
        adam_block(param, grad, m, v, b, e, b1, omb1, b2, omb2, step_size, inv_sqrt_bc2, eps);
      },
      1 << 15);  // below ~32k values a fork costs more than the loop
}

double exp_decay_lr(double lr0, double lr_end, int64_t step, int64_t total) {
  HCC_REQUIRE(lr0 > 0 && lr_end > 0, "", "learning rate", "lr0 {} lr_end {} (expected > 0)", lr0,
              lr_end);
  if (total <= 0 || step >= total) return lr_end;  // exact end value, no pow rounding
  if (step <= 0) return lr0;
  return lr0 * std::pow(lr_end / lr0, double(step) / double(total));
}

template void adam_step<float>(float*, const float*, float*, float*, int64_t, double, int64_t,
                               const AdamHyper&);
template void adam_step<double>(double*, const double*, double*, double*, int64_t, double,
                                int64_t, const AdamHyper&);

}  // namespace hashcc
