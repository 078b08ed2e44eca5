// kernels/adam.h — Adam with bias correction over a flat group, and lr schedules.
//
// Buffers: param, grad, m, v all (n,) flat over one parameter group (design practice 3: one
// arena per group, so one call per group per step). param, m, v are updated in place; grad is
// read only (the trainer zeroes it once per step; kernels accumulate into it with +=).
// Semantics are PyTorch's torch.optim.Adam (no weight decay, no amsgrad); derivation and the
// tests that prove it: docs/math/adam.md.
#pragma once
#include <cstdint>
namespace hashcc {

struct AdamHyper { double beta1 = 0.9, beta2 = 0.999, eps = 1e-8; };

// One Adam update of n parameters. t is the 1-based step count of this group (bias correction).
template <class T>
void adam_step(T* param, const T* grad, T* m, T* v, int64_t n, double lr, int64_t t,
               const AdamHyper& h = {});

// Exponential decay from lr0 (step 0) to lr_end (step == total): lr0·(lr_end/lr0)^(step/total).
// Exact at both ends; step is clamped to [0, total] (a run that overshoots its plan stays at
// lr_end); total ≤ 0 returns lr_end.
double exp_decay_lr(double lr0, double lr_end, int64_t step, int64_t total);

}  // namespace hashcc
