// core/stats.h — small statistics helpers shared by the loaders and the render paths.
#pragma once
#include <algorithm>
#include <cmath>
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

}  // namespace hashcc
