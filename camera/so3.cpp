// camera/so3.cpp — SO(3) exponential, its derivative, logarithm and angle.
// Derivations and branch thresholds: docs/math/camera.md §1–§3. Tests: test/test_camera.cpp
// ("so3 exp derivative …", "[hard]" round trips).
//
// Scalar coefficients are computed in double for both instantiations (one rotation per image,
// so the cost is nil and the float build gets correctly rounded coefficients).
#include <cmath>
#include "camera/camera.h"

namespace hashcc {
namespace so3 {
namespace {

// R = I + A K + B K², K = [r]×, θ = |r| (formulas.md §1), and for the derivative
// C = A'(θ)/θ, D = B'(θ)/θ:
//   A = sinθ/θ, B = (1 − cosθ)/θ² = 2 sin²(θ/2)/θ²,
//   C = (θ cosθ − sinθ)/θ³, D = (θ sinθ − 2(1 − cosθ))/θ⁴.
struct RodriguesCoeffs { double A, B, C, D; };

// A and B in the half-angle form have no cancellation: only θ² that could underflow needs the
// series (θ² < 1e-16, where 1 − θ²/6 is already exact to rounding).
constexpr double kMapTaylorTheta2 = 1e-16;
// C and D cancel like θ³ and θ⁴ (relative error ≈ 3ε/θ² in the closed form): use the series
// (5 terms, truncation < 1e-20 relative) below θ = 0.1; above it the closed form is within
// 3.3e-14 relative, and C, D are multiplied by r_k K, r_k K² = O(θ²) anyway.
constexpr double kJacTaylorTheta2 = 1e-2;

RodriguesCoeffs coeffs(double th2, bool need_derivative) {
  RodriguesCoeffs c{};
  if (th2 < kMapTaylorTheta2) {
    c.A = 1.0 - th2 / 6.0;
    c.B = 0.5 - th2 / 24.0;
  } else {
    double th = std::sqrt(th2), s = std::sin(th), sh = std::sin(0.5 * th);
    c.A = s / th;
    c.B = 2.0 * sh * sh / th2;
  }
  if (!need_derivative) return c;
  if (th2 < kJacTaylorTheta2) {
    double t2 = th2, t4 = t2 * t2, t6 = t4 * t2, t8 = t4 * t4;
    c.C = -1.0 / 3.0 + t2 / 30.0 - t4 / 840.0 + t6 / 45360.0 - t8 / 3991680.0;
    c.D = -1.0 / 12.0 + t2 / 180.0 - t4 / 6720.0 + t6 / 453600.0 - t8 / 47900160.0;
  } else {
    double th = std::sqrt(th2), s = std::sin(th), co = std::cos(th), sh = std::sin(0.5 * th);
    double one_minus_cos = 2.0 * sh * sh;
    c.C = (th * co - s) / (th2 * th);
    c.D = (th * s - 2.0 * one_minus_cos) / (th2 * th2);
  }
  return c;
}

}  // namespace

template <class T> Mat3<T> hat(const Vec3<T>& r) {
  Mat3<T> K;
  K << T(0), -r.z(), r.y(),
       r.z(), T(0), -r.x(),
       -r.y(), r.x(), T(0);
  return K;
}

template <class T> Mat3<T> exp(const Vec3<T>& r) {
  Eigen::Vector3d rd = r.template cast<double>();
  RodriguesCoeffs c = coeffs(rd.squaredNorm(), false);
  Eigen::Matrix3d K = hat<double>(rd);
  // formulas.md §1: R = I + (sinθ/θ)[r]× + ((1−cosθ)/θ²)[r]×²
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity() + c.A * K + c.B * (K * K);
  return R.cast<T>();
}

template <class T> void exp_derivative(const Vec3<T>& r, Mat3<T> dR_dr[3]) {
  Eigen::Vector3d rd = r.template cast<double>();
  RodriguesCoeffs c = coeffs(rd.squaredNorm(), true);
  Eigen::Matrix3d K = hat<double>(rd), K2 = K * K;
  Eigen::Matrix3d common = c.C * K + c.D * K2;  // (A'/θ) K + (B'/θ) K², times ∂θ/∂r_k·θ = r_k
  for (int k = 0; k < 3; ++k) {
    Eigen::Matrix3d E = hat<double>(Eigen::Vector3d::Unit(k));  // ∂K/∂r_k
    // ∂R/∂r_k = r_k (C K + D K²) + A E_k + B (E_k K + K E_k)
    Eigen::Matrix3d dR = rd[k] * common + c.A * E + c.B * (E * K + K * E);
    dR_dr[k] = dR.cast<T>();
  }
}

template <class T> Vec3<T> log(const Mat3<T>& R_in) {
  // Quaternion route (Shepperd: divide by the largest of 4w², 4x², 4y², 4z²), then
  // θ = 2 atan2(|v|, w) with w ≥ 0, so |r| ≤ π and θ → π stays well conditioned.
  Eigen::Matrix3d R = R_in.template cast<double>();
  double tr = R.trace(), w, x, y, z;
  if (tr >= R(0, 0) && tr >= R(1, 1) && tr >= R(2, 2)) {
    double s = 2.0 * std::sqrt(std::max(1.0 + tr, 0.0));  // 4w
    w = 0.25 * s; x = (R(2, 1) - R(1, 2)) / s; y = (R(0, 2) - R(2, 0)) / s; z = (R(1, 0) - R(0, 1)) / s;
  } else if (R(0, 0) >= R(1, 1) && R(0, 0) >= R(2, 2)) {
    double s = 2.0 * std::sqrt(std::max(1.0 + R(0, 0) - R(1, 1) - R(2, 2), 0.0));  // 4x
    w = (R(2, 1) - R(1, 2)) / s; x = 0.25 * s; y = (R(0, 1) + R(1, 0)) / s; z = (R(0, 2) + R(2, 0)) / s;
  } else if (R(1, 1) >= R(2, 2)) {
    double s = 2.0 * std::sqrt(std::max(1.0 + R(1, 1) - R(0, 0) - R(2, 2), 0.0));  // 4y
    w = (R(0, 2) - R(2, 0)) / s; x = (R(0, 1) + R(1, 0)) / s; y = 0.25 * s; z = (R(1, 2) + R(2, 1)) / s;
  } else {
    double s = 2.0 * std::sqrt(std::max(1.0 + R(2, 2) - R(0, 0) - R(1, 1), 0.0));  // 4z
    w = (R(1, 0) - R(0, 1)) / s; x = (R(0, 2) + R(2, 0)) / s; y = (R(1, 2) + R(2, 1)) / s; z = 0.25 * s;
  }
  if (w < 0) { w = -w; x = -x; y = -y; z = -z; }  // q and −q are the same rotation; pick θ ≤ π
  Eigen::Vector3d v(x, y, z);
  double n = v.norm();
  double scale;  // r = scale · v
  if (n < 1e-8) {
    // 2 atan2(n, w)/n = (2/w)(1 − n²/(3w²) + …); here w ≈ 1 (|q| ≈ 1), next term n⁴ < 1e-32.
    scale = 2.0 / w * (1.0 - n * n / (3.0 * w * w));
  } else {
    scale = 2.0 * std::atan2(n, w) / n;
  }
  return (scale * v).cast<T>();
}

template <class T> T angle(const Mat3<T>& R_in) {
  Eigen::Matrix3d R = R_in.template cast<double>();
  Eigen::Vector3d skew(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));  // 2 sinθ · axis
  return T(std::atan2(0.5 * skew.norm(), 0.5 * (R.trace() - 1.0)));
}

#define HCC_SO3_INSTANTIATE(T)                                   \
  template Mat3<T> hat<T>(const Vec3<T>&);                       \
  template Mat3<T> exp<T>(const Vec3<T>&);                       \
  template void exp_derivative<T>(const Vec3<T>&, Mat3<T>[3]);   \
  template Vec3<T> log<T>(const Mat3<T>&);                       \
  template T angle<T>(const Mat3<T>&);
HCC_SO3_INSTANTIATE(float)
HCC_SO3_INSTANTIATE(double)
#undef HCC_SO3_INSTANTIATE

}  // namespace so3
}  // namespace hashcc
