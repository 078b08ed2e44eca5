// Negative controls for the checkers of test/gradcheck.h (issue 52): every error measure must
// count a NaN or an infinity as an infinite error. std::max(worst, NaN) returns worst, so before
// this a backward writing NaN into some gradient entries passed every finite-difference check
// that did not also REQUIRE finiteness. Each helper is run on a correct input (it must measure
// a small, finite error: the positive control), then with one entry set to NaN and to +inf (it
// must return +inf, which fails any tolerance).
#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cmath>
#include <limits>
#include <vector>

#include "test/gradcheck.h"

using namespace hashcc;
using namespace hashcc::test;

namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

}  // namespace

TEST_CASE("gradcheck: the old maximum was blind to NaN (why the helpers changed)", "[gradcheck][exact]") {
  // The defect itself, kept as a reminder that it is real: a NaN never wins std::max.
  CHECK(std::max(0.0, kNaN) == 0.0);
  double worst = 0;
  keep_worst(worst, kNaN);
  CHECK(worst == kInf);
  keep_worst(worst, 1e-3);  // an infinite error stays infinite
  CHECK(worst == kInf);
  CHECK(as_error(-kInf) == kInf);
  CHECK(as_error(2.5) == 2.5);
  // The must-differ checks: a real difference passes, a NaN or inf (an infinite error) does not.
  CHECK(clearly_differs(0.5, 1e-3));
  CHECK_FALSE(clearly_differs(1e-4, 1e-3));
  CHECK_FALSE(clearly_differs(as_error(kNaN), 1e-3));
  CHECK_FALSE(clearly_differs(kInf, 1e-3));
}

TEST_CASE("gradcheck: every error helper fails a NaN or an inf entry", "[gradcheck][exact]") {
  Rng rng(52);
  // A smooth loss with a known backward: L(θ) = Σ c_i sin(θ_i), dL/dθ_i = c_i cos(θ_i).
  std::vector<double> theta = random_vec(16, rng), c = random_vec(16, rng);
  auto loss = [&] {
    double s = 0;
    for (size_t i = 0; i < theta.size(); ++i) s += c[i] * std::sin(theta[i]);
    return s;
  };
  std::vector<double> grad(theta.size());
  for (size_t i = 0; i < theta.size(); ++i) grad[i] = c[i] * std::cos(theta[i]);
  const std::vector<double> ref = random_vec(16, rng);
  std::vector<float> ref_f(ref.begin(), ref.end());

  // Positive controls: the correct backward and equal vectors pass with small, finite errors.
  CHECK(worst_grad_error(theta, grad, loss) < 1e-6);
  CHECK(worst_rel_diff(ref, ref) == 0);
  CHECK(worst_scaled_diff(ref, ref) == 0);
  CHECK(vec_rel(ref, ref) == 0);
  CHECK(float_vs_double(ref_f, ref) < 1e-7);
  CHECK(rel_err(1.0, 1.0 + 1e-12) < 1e-11);

  for (double bad : {kNaN, kInf}) {
    INFO("one entry set to " << bad);
    std::vector<double> g = grad, v = ref;
    g[5] = bad;
    v[11] = bad;
    std::vector<float> vf(v.begin(), v.end());
    CHECK(rel_err(bad, 1.0) == kInf);
    CHECK(rel_err(1.0, bad) == kInf);
    CHECK(rel_err(bad, bad) == kInf);  // inf vs inf is no agreement either
    CHECK(worst_grad_error(theta, g, loss) == kInf);
    CHECK(worst_rel_diff(v, ref) == kInf);
    CHECK(worst_rel_diff(ref, v) == kInf);
    CHECK(worst_scaled_diff(v, ref) == kInf);
    CHECK(worst_scaled_diff(ref, v) == kInf);
    CHECK(vec_rel(v, ref) == kInf);
    CHECK(vec_rel(ref, v) == kInf);
    CHECK(float_vs_double(vf, ref) == kInf);
    CHECK(float_vs_double(ref_f, v) == kInf);
  }
}

TEST_CASE("gradcheck: max_abs_entry fails a NaN or an inf entry of a matrix", "[gradcheck][exact]") {
  // Geometry checks compare Eigen matrices (rotations, poses); Eigen's maxCoeff() may return or
  // skip a NaN depending on where it sits (its vector max, like maxpd, keeps the other operand).
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity(), b = a;
  b(1, 2) = 1e-9;
  CHECK(max_abs_entry(a - b) == Approx(1e-9).epsilon(1e-12));  // positive control
  for (double bad : {kNaN, kInf}) {
    INFO("one entry set to " << bad);
    Eigen::Matrix3d c = b;
    c(2, 0) = bad;
    CHECK(max_abs_entry(a - c) == kInf);
    CHECK(max_abs_entry(c - a) == kInf);
  }
}
