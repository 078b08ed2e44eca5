// test/gradcheck.h — shared helpers for central-difference gradient checks (design.md §8).
//
// Recipe: loss L = ⟨g, y(θ)⟩ with a random projection g (not sum(y), which hides sign errors);
// analytic dL/dθ from the kernel's backward; numeric (L(θ+h) − L(θ−h)) / 2h in double;
// compared with the symmetric relative error |a − n| / max(|a| + |n|, floor).
#pragma once
#include <catch2/catch.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <limits>
#include <vector>
#include "core/parallel.h"

namespace hashcc::test {

// The one switch for test output: HASHCC_TEST_VERBOSE=1 (any value) makes the checks print
// what they measured (worst errors against their tolerances); unset, a passing run prints only
// Catch2's summary. HCC_TEST_PRINTF takes printf arguments.
inline bool verbose() {
  static const bool v = std::getenv("HASHCC_TEST_VERBOSE") != nullptr;
  return v;
}
#define HCC_TEST_PRINTF(...)                                   \
  do {                                                         \
    if (::hashcc::test::verbose()) std::printf(__VA_ARGS__);   \
  } while (0)

// Every error measure below treats a non-finite value as an INFINITE error (issue 52):
// std::max(worst, NaN) returns worst, so a backward writing NaN into some entries would
// otherwise pass every check; ±inf in a gradient gives inf − inf = NaN in many formulas. The
// negative controls in test/test_gradcheck.cpp show each helper failing a NaN and a +inf entry.
inline double as_error(double e) {
  return std::isfinite(e) ? e : std::numeric_limits<double>::infinity();
}
// worst = max(worst, e), with a non-finite e counted as +inf (which then stays).
inline void keep_worst(double& worst, double e) { worst = std::max(worst, as_error(e)); }
// max |entry| of an Eigen matrix expression, +inf if any entry is not finite (Eigen's maxCoeff
// makes no promise about NaN: depending on where it sits it may be returned or skipped).
template <class M>
double max_abs_entry(const M& m) {
  return m.allFinite() ? double(m.cwiseAbs().maxCoeff()) : std::numeric_limits<double>::infinity();
}
// For the checks that two results MUST differ (a detach is real, a gradient is not zero): an
// error above `by` and finite. A NaN or inf, now an infinite error, is not a real difference.
inline bool clearly_differs(double e, double by) { return e > by && std::isfinite(e); }

// max|a − b| / max(max|b|, tiny): a whole-vector relative error.
template <class A, class B>
double vec_rel(const std::vector<A>& a, const std::vector<B>& b) {
  REQUIRE(a.size() == b.size());
  double num = 0, den = 1e-300;
  for (size_t i = 0; i < a.size(); ++i) {
    keep_worst(num, std::abs(double(a[i]) - double(b[i])));
    den = std::max(den, std::abs(double(b[i])));
  }
  return as_error(num / den);
}

// The vector in another element type (float ↔ double).
template <class To, class From>
std::vector<To> cast(const std::vector<From>& v) { return std::vector<To>(v.begin(), v.end()); }

// Symmetric relative error; +inf when a or n is not finite (inf/inf would be NaN).
inline double rel_err(double a, double n, double floor = 1e-8) {
  if (!std::isfinite(a) || !std::isfinite(n)) return std::numeric_limits<double>::infinity();
  return as_error(std::abs(a - n) / std::max(std::abs(a) + std::abs(n), floor));
}

inline std::vector<double> random_vec(size_t n, Rng& rng, double lo = -1, double hi = 1) {
  std::vector<double> v(n);
  for (auto& x : v) x = rng.uniform(lo, hi);
  return v;
}

// Accumulated in long double: in L(θ+h) − L(θ−h) the unperturbed terms then cancel to far
// below the double roundoff that would otherwise dominate the central difference of a long sum.
inline long double dot_ld(const std::vector<double>& a, const std::vector<double>& b) {
  long double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += (long double)a[i] * b[i];
  return s;
}
inline double dot(const std::vector<double>& a, const std::vector<double>& b) {
  return double(dot_ld(a, b));
}

// Loss ⟨g, y⟩ measured from its value at the unperturbed point, L(θ) − L(θ₀), formed in long
// double before rounding: rounding a large L to double would otherwise put ulp(L)/2h into
// every central difference. Set the origin once (from y at θ₀), then call with each y.
struct CenteredLoss {
  std::vector<double> g;
  long double L0 = 0;
  explicit CenteredLoss(std::vector<double> g_) : g(std::move(g_)) {}
  void set_origin(const std::vector<double>& y0) { L0 = dot_ld(g, y0); }
  double operator()(const std::vector<double>& y) const { return double(dot_ld(g, y) - L0); }
};

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
    keep_worst(worst, rel_err(grad[i], (lp - lm) / (2 * h), floor));
  }
  return worst;
}

// Worst symmetric relative error between two results of the same computation (e.g. an optimised
// kernel and its _naive reference), element-wise, with an absolute floor for values near 0.
inline double worst_rel_diff(const std::vector<double>& a, const std::vector<double>& b,
                             double floor = 1e-12) {
  double worst = 0;
  for (size_t i = 0; i < a.size(); ++i) keep_worst(worst, rel_err(a[i], b[i], floor));
  return worst;
}

// Worst |a − b| relative to the largest |b|: for comparing an optimised kernel with its _naive
// reference when entries are sums whose cancellation makes per-entry relative error meaningless.
inline double worst_scaled_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double scale = 0, worst = 0;
  for (double v : b) scale = std::max(scale, std::abs(v));
  for (size_t i = 0; i < a.size(); ++i) keep_worst(worst, std::abs(a[i] - b[i]));
  return as_error(scale > 0 ? worst / scale : worst);
}

// Float build against the double build: worst |f − d| relative to the largest |d| of the result
// (float rounding scales with the magnitude of the whole array, not of each tiny entry).
template <class F>
inline double float_vs_double(const std::vector<F>& f, const std::vector<double>& d) {
  double scale = 0, worst = 0;
  for (double v : d) scale = std::max(scale, std::abs(v));
  for (size_t i = 0; i < d.size(); ++i) keep_worst(worst, std::abs(double(f[i]) - d[i]));
  return as_error(scale > 0 ? worst / scale : worst);
}

inline std::vector<float> to_float(const std::vector<double>& v) {
  return std::vector<float>(v.begin(), v.end());
}

// Prints "name: measured (tolerance)" when HASHCC_VERBOSE is set, so reports can quote the
// measured errors; returns the error for REQUIRE(check(...) < tol) style use.
inline double report(const char* name, double err, double tol) {
  if (std::getenv("HASHCC_VERBOSE")) std::printf("  %-48s %.3e  (tol %.0e)\n", name, err, tol);
  return err;
}

}  // namespace hashcc::test
