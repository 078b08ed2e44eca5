// eval/pose_eval.cpp — Sim(3) alignment and pose errors (see pose_eval.h).
#include "eval/pose_eval.h"

#include <cmath>

#include "core/error.h"

namespace hashcc {
namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

}  // namespace

double rotation_angle(const Eigen::Matrix3d& R) {
  const Eigen::Vector3d v(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));
  return std::atan2(0.5 * v.norm(), 0.5 * (R.trace() - 1.0));
}

double rotation_angle_deg(const Eigen::Matrix3d& R) { return rotation_angle(R) * kRadToDeg; }

PoseErrors align_and_score(const std::vector<Pose34>& learned, const std::vector<Pose34>& reference,
                           Alignment how) {
  HCC_REQUIRE(learned.size() == reference.size(), "", "pose alignment",
              "{} learned vs {} reference poses (expected equal counts)", learned.size(),
              reference.size());
  for (size_t i = 0; i < learned.size(); ++i)
    HCC_REQUIRE(learned[i].allFinite() && reference[i].allFinite(), "", "pose alignment",
                "pose {} is not finite", i);
  std::vector<Eigen::Vector3d> src, dst;
  for (size_t i = 0; i < learned.size(); ++i) {
    src.push_back(learned[i].col(3));
    dst.push_back(reference[i].col(3));
  }
  PoseErrors e;
  if (how == Alignment::kCentres) {
    e.sim = umeyama_sim3(src, dst);
  } else {
    std::vector<Eigen::Matrix3d> src_R, dst_R;
    for (size_t i = 0; i < learned.size(); ++i) {
      src_R.push_back(learned[i].leftCols<3>());
      dst_R.push_back(reference[i].leftCols<3>());
    }
    e.sim = rotation_sim3(src_R, src, dst_R, dst);
  }
  const size_t n = learned.size();
  for (size_t i = 0; i < n; ++i) {
    // formulas.md §7: R' = R_a R, t' = s R_a t + t_a.
    const Eigen::Matrix3d R_aligned = e.sim.R * learned[i].leftCols<3>();
    const Eigen::Vector3d t_aligned = e.sim.apply(src[i]);
    e.dR_deg.push_back(rotation_angle_deg(R_aligned * reference[i].leftCols<3>().transpose()));
    e.dT.push_back((dst[i] - t_aligned).norm());
    e.mean_dR_deg += e.dR_deg.back() / double(n);
    e.mean_dT += e.dT.back() / double(n);
  }
  return e;
}

RelativeRotationError relative_rotation_error(const std::vector<Pose34>& learned,
                                              const std::vector<Pose34>& reference) {
  HCC_REQUIRE(learned.size() == reference.size(), "", "relative rotation error",
              "{} learned vs {} reference poses (expected equal counts)", learned.size(),
              reference.size());
  HCC_REQUIRE(learned.size() >= 2, "", "relative rotation error",
              "{} poses (expected at least 2: the error is over pairs)", learned.size());
  for (size_t i = 0; i < learned.size(); ++i)
    HCC_REQUIRE(learned[i].allFinite() && reference[i].allFinite(), "", "relative rotation error",
                "pose {} is not finite", i);
  RelativeRotationError r;
  const size_t n = learned.size();
  double sum = 0, sum0 = 0;
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 1; j < n; ++j) {
      const Eigen::Matrix3d rel_l = learned[i].leftCols<3>().transpose() * learned[j].leftCols<3>();
      const Eigen::Matrix3d rel_r = reference[i].leftCols<3>().transpose() * reference[j].leftCols<3>();
      sum += rotation_angle_deg(rel_l * rel_r.transpose());
      sum0 += rotation_angle_deg(rel_r);  // learned rel = I when all learned rotations are equal
      ++r.pairs;
    }
  r.mean_deg = sum / r.pairs;
  r.do_nothing_deg = sum0 / r.pairs;
  return r;
}

}  // namespace hashcc
