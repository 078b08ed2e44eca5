// test/gradcheck.h — shared helpers for central-difference gradient checks (design.md §8).
//
// Recipe: loss L = ⟨g, y(θ)⟩ with a random projection g (not sum(y), which hides sign errors);
// analytic dL/dθ from the kernel's backward; numeric (L(θ+h) − L(θ−h)) / 2h in double;
// compared with the symmetric relative error |a − n| / max(|a| + |n|, floor).
#pragma once
#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>
#include "core/parallel.h"

namespace hashcc::test {

inline double rel_err(double a, double n, double floor = 1e-8) {
  return std::abs(a - n) / std::max(std::abs(a) + std::abs(n), floor);
}

inline std::vector<double> random_vec(size_t n, Rng& rng, double lo = -1, double hi = 1) {
  std::vector<double> v(n);
  for (auto& x : v) x = rng.uniform(lo, hi);
  return v;
}

inline double dot(const std::vector<double>& a, const std::vector<double>& b) {
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
  return s;
}

// Worst symmetric relative error between analytic gradient `grad` of L w.r.t. `theta` and the
// central difference of `loss()` (which reads theta) over the indices `idx` (all when empty).
inline double worst_grad_error(std::vector<double>& theta, const std::vector<double>& grad,
                               const std::function<double()>& loss, double h = 1e-6,
                               std::vector<size_t> idx = {}, double floor = 1e-8) {
  if (idx.empty()) for (size_t i = 0; i < theta.size(); ++i) idx.push_back(i);
  double worst = 0;
  for (size_t i : idx) {
    double keep = theta[i];
    theta[i] = keep + h; double lp = loss();
    theta[i] = keep - h; double lm = loss();
    theta[i] = keep;
    worst = std::max(worst, rel_err(grad[i], (lp - lm) / (2 * h), floor));
  }
  return worst;
}

}  // namespace hashcc::test
