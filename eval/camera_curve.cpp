// eval/camera_curve.cpp — see camera_curve.h.
#include "eval/camera_curve.h"

#include <fmt/format.h>

#include <filesystem>
#include <sstream>

#include "core/fileio.h"
#include "eval/evaluate.h"
#include "train/trainer.h"

namespace hashcc {

namespace {
constexpr const char* kHeader = "step,seconds,rel_rot_deg,sim3_dR_deg,sim3_dT,fx,fy,ref_focal\n";

// The rows of an earlier session up to `step` (a crash after the checkpoint leaves later rows).
std::string kept_rows(const std::string& path, int64_t step) {
  std::string kept = kHeader;
  if (!std::filesystem::exists(path)) return kept;
  std::istringstream in(read_file_bytes(path, int64_t(1) << 30));
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    try {
      if (std::stoll(line.substr(0, line.find(','))) > step) break;
    } catch (const std::exception&) {
      break;  // a torn last line
    }
    kept += line + "\n";
  }
  return kept;
}
}  // namespace

CameraCurve::CameraCurve(const Trainer& tr, const std::string& path, int64_t every)
    : every_(std::max<int64_t>(1, every)) {
  if (!tr.scene().has_reference || tr.scene().train.size() < 3 || path.empty()) return;
  const int64_t step = tr.state().step;
  write_file_atomic(path, step == 0 ? std::string(kHeader) : kept_rows(path, step));
  out_.open(path, std::ios::app);
  active_ = out_.is_open();
  if (active_ && step == 0) (*this)(tr);  // the starting point of the curve
}

void CameraCurve::operator()(const Trainer& tr) {
  if (!active_) return;
  const int64_t step = tr.state().step;
  if (step % every_ != 0 && step != tr.planned_total()) return;
  const TrainPoseReport r = train_pose_report(tr);
  const auto num = [](bool ok, double v) { return ok ? fmt::format("{:.4f}", v) : std::string(); };
  out_ << fmt::format("{},{:.3f},{},{},{},{:.3f},{:.3f},{:.3f}\n", step, tr.state().elapsed,
                      num(r.relative.has_value(), r.relative ? r.relative->mean_deg : 0),
                      num(r.sim3.has_value(), r.sim3 ? r.sim3->mean_dR_deg : 0),
                      num(r.sim3.has_value(), r.sim3 ? r.sim3->mean_dT : 0), r.fx, r.fy,
                      r.ref_focal);
  out_.flush();
}

}  // namespace hashcc
