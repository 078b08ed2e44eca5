// core/stats.h — small statistics helpers shared by the loaders and the render paths.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "core/error.h"

namespace hashcc {

// numpy.percentile with linear interpolation, p in [0, 100] (clamped). v must be non-empty.
inline double percentile(std::vector<double> v, double p) {
  HCC_ASSERT(!v.empty());
  std::sort(v.begin(), v.end());
  const double pos = std::clamp(p, 0.0, 100.0) / 100.0 * double(v.size() - 1);
  const size_t i = size_t(std::floor(pos));
  if (i + 1 >= v.size()) return v.back();
  return v[i] + (pos - double(i)) * (v[i + 1] - v[i]);
}

// Whether every float of p[0, n) is finite: the exponent bits all ones is an Inf or a NaN. Blocks
// of 4,096 with a branch-free OR inside (the compiler vectorises it; a loop that stops at the
// first bad value does not), an early exit between them. The trainer's guard reads every
// gradient a step with it: 1M+ floats for the grid field, where a scalar std::isfinite loop
// cost more than a millisecond of serial time a step.
inline bool all_finite(const float* p, int64_t n) {
  constexpr int64_t kBlockFloats = 4096;
  for (int64_t b = 0; b < n; b += kBlockFloats) {
    const int64_t e = std::min(n, b + kBlockFloats);
    uint32_t bad = 0;
    for (int64_t i = b; i < e; ++i) {
      uint32_t u;
      std::memcpy(&u, p + i, sizeof u);
      bad |= uint32_t((u & 0x7f800000u) == 0x7f800000u);
    }
    if (bad) return false;
  }
  return true;
}

}  // namespace hashcc
