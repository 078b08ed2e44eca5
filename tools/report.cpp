#include "tools/report.h"

#include <cmath>
#include <fmt/core.h>

#include "eval/evaluate.h"

namespace hashcc {

// Fast by design (no rendering, no test-pose refinement): pose error of the training cameras
// against the reference and the focal. `hashcc eval` does the rest.
void print_train_report(Trainer& tr) {
  const TrainPoseReport p = train_pose_report(tr);
  if (!p.has_reference) {
    fmt::print("pose error: {}\n", p.note);
    return;
  }
  if (p.sim3)
    fmt::print("pose error (train cameras, Sim(3)-aligned, formulas.md §7): ΔR {:.3f}°  ΔT {:.5f}\n",
               p.sim3->mean_dR_deg, p.sim3->mean_dT);
  if (p.relative)
    fmt::print("relative rotation error: {:.3f}° (do-nothing {:.3f}°)\n", p.relative->mean_deg,
               p.relative->do_nothing_deg);
  if (!p.note.empty()) fmt::print("{}\n", p.note);
  fmt::print("focal: learned fx {:.2f} fy {:.2f}, reference {:.2f} px\n", p.fx, p.fy, p.ref_focal);
  fmt::print("test views: hashcc eval --run {}\n", tr.config().out);
}

}  // namespace hashcc
