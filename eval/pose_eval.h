// eval/pose_eval.h — camera pose errors of formulas.md §7: Umeyama Sim(3) alignment + ΔR/ΔT, and the
// alignment-free relative rotation error.
//
// Poses are camera-to-world 3×4 matrices [R | t] (columns right, up, back, centre; OpenGL
// frame as in formulas.md §1). Everything is double. Degenerate inputs (size mismatch, fewer than 3
// cameras, coincident or collinear centres, non-finite values) throw hashcc::Error: these
// functions never return NaN.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "camera/sim3.h"

namespace hashcc {

using Pose34 = Eigen::Matrix<double, 3, 4>;

// Rotation angle of R in radians, atan2(‖vee(R − Rᵀ)‖/2, (tr R − 1)/2): accurate near 0 and
// near π (acos of the trace loses half the digits near 0).
double rotation_angle(const Eigen::Matrix3d& R);
double rotation_angle_deg(const Eigen::Matrix3d& R);

struct PoseErrors {
  Sim3 sim;                    // learned centres → reference centres
  std::vector<double> dR_deg;  // per image: angle of R' R_refᵀ, R' = R_a R, degrees
  std::vector<double> dT;      // per image: ‖t_ref − (s R_a t + t_a)‖ (reference units)
  double mean_dR_deg = 0, mean_dT = 0;
};

// How the learned cameras are put in the reference frame before they are scored.
enum class Alignment {
  kCentres,    // formulas.md §7 (the papers' figure): Umeyama Sim(3) on the camera centres
  kRotations,  // rotation_sim3 (camera/sim3.h): the frame from the rotations, scale and shift
               // from the centres; immune to a rig's depth tilt (issue 49), so its ΔR is the
               // rotations' own error and its ΔT shows where the centres are off
};

// formulas.md §7: align learned cameras onto the reference ones (by default Umeyama Sim(3) on
// the centres), apply the similarity to whole poses, and score each image.
PoseErrors align_and_score(const std::vector<Pose34>& learned, const std::vector<Pose34>& reference,
                           Alignment how = Alignment::kCentres);

struct RelativeRotationError {
  double mean_deg = 0;        // mean over i<j of angle((R_iᵀR_j)_learned ((R_iᵀR_j)_ref)ᵀ)
  double do_nothing_deg = 0;  // the same with all learned rotations equal: mean angle(R_iᵀR_j ref)
  int pairs = 0;
};

// formulas.md §7 alignment-free relative rotation error (needs n ≥ 2 poses of equal count). Invariant
// to any global rotation of either set (left multiplication), so it needs no alignment.
RelativeRotationError relative_rotation_error(const std::vector<Pose34>& learned,
                                              const std::vector<Pose34>& reference);

}  // namespace hashcc
