// camera/precondition.cpp — see precondition.h and docs/math/precondition.md.
#include "camera/precondition.h"

#include <Eigen/Eigenvalues>
#include <cmath>

namespace hashcc {

namespace {

// Pixel (u, v) of world point X seen by the camera at `pose` (formulas.md §1 inverted:
// u = W/2 + fx·x/(−z), v = H/2 − fy·y/(−z), x, y, z in the camera frame, looking down −z).
Eigen::Vector2d project(const Mat34<double>& c2w, const Vec3<double>& X, double fx, double fy,
                        ImageSize size) {
  const Mat3<double> R = c2w.leftCols<3>();
  const Vec3<double> xc = R.transpose() * (X - c2w.col(3));
  return {0.5 * size.W + fx * xc.x() / -xc.z(), 0.5 * size.H - fy * xc.y() / -xc.z()};
}

}  // namespace

Eigen::MatrixXd pose_projection_jacobian(const PoseParams<double>& pose,
                                         const FocalParams<double>& focal, ImageSize size,
                                         const PreconditionOptions& opt, int focal_params) {
  const int G = opt.lattice, D = opt.disparities;
  const double fx = focal_fx(focal, size), fy = focal_fy(focal, size);
  const Mat34<double> c2w = world_from_camera(pose);
  // The points, in the world: pixel centres of a G × G lattice at D disparities.
  std::vector<Vec3<double>> X;
  X.reserve(size_t(G) * G * D);
  for (int a = 0; a < G; ++a)
    for (int b = 0; b < G; ++b) {
      const double u = (b + 0.5) * size.W / G, v = (a + 0.5) * size.H / G;
      const Vec3<double> dc((u - 0.5 * size.W) / fx, -(v - 0.5 * size.H) / fy, -1.0);
      for (int k = 0; k < D; ++k) {
        const double depth = 1.0 / ((k + 0.5) / D);
        X.push_back(c2w.leftCols<3>() * (depth * dc) + c2w.col(3));
      }
    }
  // Central differences in double: the projection is smooth and h = 1e-6 leaves ~1e-9 of
  // relative error (test/test_precondition.cpp checks entries against their closed forms).
  const double h = 1e-6;
  Eigen::MatrixXd J(2 * X.size(), 6 + focal_params);
  for (int p = 0; p < 6 + focal_params; ++p) {
    if (p >= 6) {  // the focal: the points stay, their pixels move
      FocalParams<double> fp = focal, fm = focal;
      (p == 6 ? fp.a : fp.b) += h;
      (p == 6 ? fm.a : fm.b) -= h;
      for (size_t i = 0; i < X.size(); ++i)
        J.block<2, 1>(2 * i, p) =
            (project(c2w, X[i], focal_fx(fp, size), focal_fy(fp, size), size) -
             project(c2w, X[i], focal_fx(fm, size), focal_fy(fm, size), size)) / (2 * h);
      continue;
    }
    PoseParams<double> plus = pose, minus = pose;
    (p < 3 ? plus.r(p) : plus.t(p - 3)) += h;
    (p < 3 ? minus.r(p) : minus.t(p - 3)) -= h;
    const Mat34<double> cp = world_from_camera(plus), cm = world_from_camera(minus);
    for (size_t i = 0; i < X.size(); ++i)
      J.block<2, 1>(2 * i, p) =
          (project(cp, X[i], fx, fy, size) - project(cm, X[i], fx, fy, size)) / (2 * h);
  }
  return J;
}

namespace {

// c · (Σ + λ diag Σ)^(−1/2) with det = 1, for a symmetric positive semi-definite Σ.
Eigen::MatrixXd whitening(Eigen::MatrixXd S, double damping) {
  S.diagonal() *= 1.0 + damping;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(S);
  const Eigen::VectorXd log_lam = es.eigenvalues().array().log();
  // det P = 1: log c = Σ log λ_i / (2D), in logs (the λ_i span decades).
  const double log_c = log_lam.sum() / (2.0 * double(S.rows()));
  const Eigen::VectorXd scale = (log_c - 0.5 * log_lam.array()).exp().matrix();
  return es.eigenvectors() * scale.asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace

Eigen::MatrixXd camera_preconditioner(const std::vector<PoseParams<double>>& poses,
                                      const FocalParams<double>& focal, ImageSize size,
                                      int focal_params, const PreconditionOptions& opt) {
  const int n = int(poses.size()), m = focal_params, D = 6 * n + m;
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(D, D);
  for (int i = 0; i < n; ++i) {
    const Eigen::MatrixXd J = pose_projection_jacobian(poses[i], focal, size, opt, m);
    const Eigen::MatrixXd Si = (J.transpose() * J) / double(J.rows() / 2);
    S.block(6 * i, 6 * i, 6, 6) += Si.topLeftCorner(6, 6);
    if (m == 0) continue;
    S.block(6 * i, 6 * n, 6, m) += Si.topRightCorner(6, m);
    S.block(6 * n, 6 * i, m, 6) += Si.bottomLeftCorner(m, 6);
    S.block(6 * n, 6 * n, m, m) += Si.bottomRightCorner(m, m);
  }
  return whitening(S, opt.damping);
}

Mat6d pose_preconditioner(const PoseParams<double>& pose, const FocalParams<double>& focal,
                          ImageSize size, const PreconditionOptions& opt) {
  const Eigen::MatrixXd J = pose_projection_jacobian(pose, focal, size, opt);
  return whitening((J.transpose() * J) / double(J.rows() / 2), opt.damping);
}

}  // namespace hashcc
