// camera/sim3.cpp — Umeyama similarity alignment (see sim3.h).
#include "camera/sim3.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>

#include "core/error.h"

namespace hashcc {
namespace {

// Rejects sets whose centres coincide or lie on one line: returns the centred points' singular
// values s0 ≥ s1 ≥ s2 (of the n×3 matrix; their ratios are accurate to ~1e-16, unlike the
// eigenvalues of the scatter matrix, which square them).
void require_spread(const std::vector<Eigen::Vector3d>& pts, const char* which) {
  const int n = int(pts.size());
  Eigen::Vector3d mu = Eigen::Vector3d::Zero();
  double scale = 1.0;
  for (const auto& p : pts) {
    HCC_REQUIRE(p.allFinite(), "", "pose alignment", "{} camera centre is not finite", which);
    mu += p;
    scale = std::max(scale, p.norm());
  }
  mu /= n;
  Eigen::MatrixXd X(n, 3);
  for (int i = 0; i < n; ++i) X.row(i) = (pts[i] - mu).transpose();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(X);
  const Eigen::Vector3d s = svd.singularValues();
  HCC_REQUIRE(s(0) > 1e-12 * scale * std::sqrt(double(n)), "", "pose alignment",
              "all {} {} camera centres coincide (spread {:.3g}); a Sim(3) alignment is undefined",
              n, which, s(0) / std::sqrt(double(n)));
  HCC_REQUIRE(s(1) > 1e-10 * s(0), "", "pose alignment",
              "the {} {} camera centres are collinear (singular values {:.3g}, {:.3g}); the "
              "rotation about that line is undefined",
              n, which, s(0), s(1));
}

// The reflection fix of Umeyama (eq. 39/43) for the SVD M = U D Vᵀ of a 3×3 cross-covariance:
// S = diag(1, 1, ±1) flips the weakest direction when det(U)det(V) < 0, so R = U S Vᵀ is the
// proper rotation nearest M.
Eigen::Vector3d reflection_fix(const Eigen::Matrix3d& U, const Eigen::Matrix3d& V) {
  return {1, 1, (U.determinant() * V.determinant() < 0) ? -1.0 : 1.0};
}

}  // namespace

Sim3 umeyama_sim3(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst) {
  const int n = int(src.size());
  HCC_REQUIRE(src.size() == dst.size(), "", "pose alignment",
              "{} learned vs {} reference cameras (expected equal counts)", src.size(), dst.size());
  HCC_REQUIRE(n >= 3, "", "pose alignment",
              "{} cameras: a Sim(3) alignment needs at least 3 with non-collinear centres", n);
  require_spread(src, "learned");
  require_spread(dst, "reference");

  Eigen::Vector3d mu_s = Eigen::Vector3d::Zero(), mu_d = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) { mu_s += src[i]; mu_d += dst[i]; }
  mu_s /= n; mu_d /= n;
  double var_s = 0;
  Eigen::Matrix3d Sigma = Eigen::Matrix3d::Zero();  // (1/n) Σ (d − μ_d)(s − μ_s)ᵀ
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d a = src[i] - mu_s, b = dst[i] - mu_d;
    var_s += a.squaredNorm();
    Sigma += b * a.transpose();
  }
  var_s /= n;
  Sigma /= n;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(Sigma, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d D = svd.singularValues();
  HCC_REQUIRE(D(1) > 1e-10 * D(0), "", "pose alignment",
              "learned and reference centres are not correlated in two directions (singular "
              "values {:.3g}, {:.3g}, {:.3g}); the rotation is undefined",
              D(0), D(1), D(2));
  const Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  const Eigen::Vector3d S = reflection_fix(U, V);
  Sim3 out;
  out.R = U * S.asDiagonal() * V.transpose();
  out.s = D.dot(S) / var_s;
  out.t = mu_d - out.s * out.R * mu_s;
  HCC_REQUIRE(out.R.allFinite() && out.t.allFinite() && std::isfinite(out.s) && out.s > 0, "",
              "pose alignment", "alignment is not finite or has scale {} (expected > 0)", out.s);
  return out;
}

Sim3 rotation_sim3(const std::vector<Eigen::Matrix3d>& src_R, const std::vector<Eigen::Vector3d>& src_c,
                   const std::vector<Eigen::Matrix3d>& dst_R, const std::vector<Eigen::Vector3d>& dst_c) {
  const size_t n = src_R.size();
  HCC_REQUIRE(src_c.size() == n && dst_R.size() == n && dst_c.size() == n, "", "pose alignment",
              "{} learned vs {} reference cameras (expected equal counts)", n, dst_R.size());
  HCC_REQUIRE(n >= 2, "", "pose alignment", "{} cameras: a scale needs at least 2", n);
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  Eigen::Vector3d mu_s = Eigen::Vector3d::Zero(), mu_d = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    HCC_REQUIRE(src_R[i].allFinite() && dst_R[i].allFinite() && src_c[i].allFinite() &&
                    dst_c[i].allFinite(),
                "", "pose alignment", "camera {} is not finite", i);
    M += dst_R[i] * src_R[i].transpose();
    mu_s += src_c[i];
    mu_d += dst_c[i];
  }
  mu_s /= double(n);
  mu_d /= double(n);
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  Sim3 out;
  out.R = U * reflection_fix(U, V).asDiagonal() * V.transpose();  // the chordal mean
  double num = 0, den = 0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d a = out.R * (src_c[i] - mu_s), b = dst_c[i] - mu_d;
    num += b.dot(a);
    den += a.squaredNorm();
  }
  HCC_REQUIRE(den > 0, "", "pose alignment",
              "all {} learned camera centres coincide; a scale is undefined", n);
  out.s = num / den;
  HCC_REQUIRE(std::isfinite(out.s) && out.s > 0, "", "pose alignment",
              "the centres give scale {:.3g} once the rotations are aligned (expected > 0: the "
              "learned rig runs against the reference)", out.s);
  out.t = mu_d - out.s * out.R * mu_s;
  return out;
}

}  // namespace hashcc
