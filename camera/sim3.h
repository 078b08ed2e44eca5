// camera/sim3.h — the similarity (scale, rotation, translation) that best maps one set of
// camera centres onto another: pose evaluation aligns learned cameras onto reference ones with
// it, and the render paths map reference poses into a run's learned frame.
#pragma once
#include <Eigen/Core>
#include <vector>

namespace hashcc {

// dst ≈ s·R·src + t.
struct Sim3 {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double s = 1.0;
  Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return s * (R * x) + t; }
};

// Umeyama (1991) least-squares similarity: minimises Σ‖dst_i − (s R src_i + t)‖², with the
// reflection fix (R = U S Vᵀ, S = diag(1, 1, det(U)det(V))) so R is always a proper rotation.
// Requires n ≥ 3 points, not all coincident and not collinear (either set), otherwise
// hashcc::Error (the rotation about the line would be arbitrary). Coplanar sets are fine.
Sim3 umeyama_sim3(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst);

}  // namespace hashcc
