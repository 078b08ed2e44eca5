// eval/camera_curve.h — the camera error as training goes: RUN/camera_error.csv, one row every
// `every` steps, for scenes with reference cameras (poses_bounds.npy).
//
// Columns: step, seconds (training time), rel_rot_deg (formulas.md §7 relative rotation error,
// alignment-free), sim3_dR_deg and sim3_dT (Umeyama-aligned, §7), fx, fy (learned) and
// ref_focal. This is the "accuracy against time" curve of a run: the study plots it, and a user
// sees whether the cameras are still moving. The trainer calls it through Trainer::run's
// after_step hook, so train/ does not depend on eval/.
#pragma once
#include <cstdint>
#include <fstream>
#include <string>

namespace hashcc {

class Trainer;

class CameraCurve {
 public:
  // path: the csv. A resumed run keeps the rows up to its checkpoint step and appends; a fresh
  // run (step 0) starts the file anew. Does nothing (active() false) without reference cameras.
  CameraCurve(const Trainer& tr, const std::string& path, int64_t every = 25);
  void operator()(const Trainer& tr);  // writes a row when step % every == 0 or at the last step
  bool active() const { return active_; }

 private:
  std::ofstream out_;
  int64_t every_;
  bool active_ = false;
};

}  // namespace hashcc
