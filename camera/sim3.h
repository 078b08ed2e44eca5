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

// The similarity whose rotation comes from the cameras' rotations, and only its scale and shift
// from their centres:
//     R = the rotation nearest Σ_i R_dst,i R_src,iᵀ (the chordal mean; SVD, det +1),
//     s, t = argmin Σ‖c_dst,i − (s R c_src,i + t)‖² with R fixed:
//     s = Σ (c_dst,i − μ_dst)·R (c_src,i − μ_src) / Σ‖c_src,i − μ_src‖²,  t = μ_dst − s R μ_src.
// Why: a forward-facing rig's centres spread little along the viewing axis (LLFF horns: 0.18×
// its sideways spread), so Umeyama's rotation, fitted to the centres, tilts by tens of degrees
// when a learned rig's centres are off in depth, even when every camera turns right. The
// rotations pin the frame without that lever. Requires n ≥ 2 cameras whose centres do not all
// coincide (either set), and a positive scale; otherwise hashcc::Error.
Sim3 rotation_sim3(const std::vector<Eigen::Matrix3d>& src_R, const std::vector<Eigen::Vector3d>& src_c,
                   const std::vector<Eigen::Matrix3d>& dst_R, const std::vector<Eigen::Vector3d>& dst_c);

}  // namespace hashcc
