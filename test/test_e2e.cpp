// End-to-end: from identity cameras, a short run on the built-in simulated scene must learn the
// images (train PSNR up by ≥ 5 dB over every training view, rendered without jitter) AND the
// cameras: the alignment-free relative rotation error (formulas.md §7: the measure for short runs,
// where a Sim(3) fit on nearly coincident centres is ill-conditioned) must fall well below its
// do-nothing value. Tagged [e2e]: CTest runs it once, at 2 threads.
//
// One departure from the paper's recipe, and why (measured): the cameras' learning
// rate ends at 1e-4 instead of 1e-8. Each camera gets a gradient once per epoch (one image
// per step), so with Adam it moves about a quarter of its lr per step; the paper's decay
// over 1,200 steps lets it travel ≈ 0.24 · Σ lr ≈ 0.025 rad ≈ 1.4° in all — less than the
// scene's 3° hand-held rotations. The paper spreads the same decay over 10,000 epochs
// (170,000 steps), where the travel is never the limit. Measured on the default scene
// (1,200 steps, 1 thread): cameras' lr ending at 1e-8 → relative rotation error ≈ do-nothing;
// ending at 1e-4 → 2.9° against 7.3° for doing nothing.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>

#include "camera/camera.h"
#include "eval/pose_eval.h"
#include "model/render_view.h"
#include "train/trainer.h"
#include "tools/simulator.h"

namespace fs = std::filesystem;
using namespace hashcc;

namespace {

// Mean PSNR of every training view rendered at stride 2 against its ground truth.
double train_psnr(Trainer& t) {
  StepWorkspace<float> ws;
  double sum = 0;
  const Scene& sc = t.scene();
  for (size_t i = 0; i < sc.train.size(); ++i) {
    ViewImage v = render_view(ws, t.net(), t.view_camera(t.pose_of(int(i))), {t.config().samples, 2});
    const ImageU8& gt = sc.images[sc.train[i]];
    double se = 0;
    for (int y = 0; y < v.height; ++y)
      for (int x = 0; x < v.width; ++x)
        for (int c = 0; c < 3; ++c) {
          double e = v.rgb[(size_t(y) * v.width + x) * 3 + c] - gt.at(2 * y, 2 * x, c);
          se += e * e;
        }
    sum += -10 * std::log10(se / (3.0 * v.width * v.height));
  }
  return sum / double(sc.train.size());
}

std::vector<Pose34> learned_poses(const Trainer& t) {
  std::vector<Pose34> out;
  for (size_t i = 0; i < t.scene().train.size(); ++i) {
    PoseParams<float> p = t.pose_of(int(i));
    Pose34 m;
    m.leftCols<3>() = so3::exp(Vec3<double>(p.r.cast<double>())).cast<double>();
    m.col(3) = p.t.cast<double>();
    out.push_back(m);
  }
  return out;
}

// The default simulated scene (20 views, 128×96, hand-held rig) written afresh, and a run of
// 1,200 steps on it (a deterministic length) with no progress bar and final checkpoint only.
TrainConfig e2e_config(const std::string& name) {
  TrainConfig c;
  c.data = (fs::temp_directory_path() / ("hashcc_e2e_sim_" + name)).string();
  fs::remove_all(c.data);
  write_sim_scene(c.data, SimOptions{}, false);
  c.out = (fs::temp_directory_path() / ("hashcc_e2e_run_" + name)).string();
  fs::remove_all(c.out);
  c.steps = 1200;
  c.progress = false;
  c.checkpoint_minutes = 1e9;
  c.preview_minutes = 1e9;
  return c;
}

}  // namespace

TEST_CASE("e2e: learns the simulated scene and its cameras from identity", "[e2e]") {
  TrainConfig c = e2e_config("mlp");
  c.model.width = 64;
  c.model.rgb_width = 32;
  c.samples = 32;
  c.rays = 1024;           // 1,200 steps: ≈ 1.5 min on 2 quiet cores
  c.lr_pose_end = 1e-4;   // see the top of this file: the travel budget of a short run
  c.lr_focal_end = 1e-4;
  Trainer t(c);
  const double psnr0 = train_psnr(t);
  std::vector<Pose34> ref;
  for (int i : t.scene().train) ref.push_back(t.scene().ref_c2w[i]);
  REQUIRE(t.run());
  const double psnr1 = train_psnr(t);
  RelativeRotationError rel = relative_rotation_error(learned_poses(t), ref);
  PoseErrors sim3 = align_and_score(learned_poses(t), ref);
  WARN("e2e: " << t.state().step << " steps in " << t.state().elapsed << " s; train PSNR "
               << psnr0 << " -> " << psnr1 << " dB; relative rotation error " << rel.mean_deg
               << " deg (do-nothing " << rel.do_nothing_deg << "); Sim(3) dR " << sim3.mean_dR_deg
               << " deg, dT " << sim3.mean_dT << "; fx " << focal_fx(t.focal(), t.image_size())
               << " (reference " << t.scene().ref_focal << ")");
  CHECK(psnr1 >= psnr0 + 5.0);
  // The cameras learned: the relative rotations are much closer to the truth than doing
  // nothing (measured 0.40× on this scene; 0.7× leaves room for another CPU's rounding).
  CHECK(rel.do_nothing_deg > 5.0);  // the scene really has rotations to learn
  CHECK(rel.mean_deg < 0.7 * rel.do_nothing_deg);
  // The cameras learned something finite: every pose moved, the focal left its start and
  // stayed in a sane range.
  double moved = 1e9;
  for (size_t i = 0; i < t.scene().train.size(); ++i) {
    PoseParams<float> p = t.pose_of(int(i));
    REQUIRE(p.r.allFinite());
    REQUIRE(p.t.allFinite());
    moved = std::min<double>(moved, p.r.norm() + p.t.norm());
  }
  CHECK(moved > 0);
  const double fx = focal_fx(t.focal(), t.image_size());
  CHECK(fx != 128.0);
  CHECK(fx > 0.5 * 128);
  CHECK(fx < 2.0 * 128);
}

// The grid field (--field grid with its defaults, model/grid_field.h): the same scene and
// step count, and the cameras must land much closer: relative rotation error < 0.3× doing
// nothing (measured 0.19×: 1.36° against 7.27°, test PSNR 26.7 dB, 1,200 steps at the former
// 64 samples, docs/results/grid/; 0.20×, 1.44°, train PSNR 27.5 dB at the default 32), the quick
// start's promise.
TEST_CASE("e2e: the grid field learns the simulated scene's cameras from identity", "[e2e]") {
  TrainConfig c = e2e_config("grid");
  c.model.field = Field::grid;
  for (const PresetEntry& e : field_defaults("grid")) e.set(c);
  Trainer t(c);
  const double psnr0 = train_psnr(t);
  std::vector<Pose34> ref;
  for (int i : t.scene().train) ref.push_back(t.scene().ref_c2w[i]);
  REQUIRE(t.run());
  const double psnr1 = train_psnr(t);
  RelativeRotationError rel = relative_rotation_error(learned_poses(t), ref);
  WARN("e2e grid: " << t.state().step << " steps in " << t.state().elapsed << " s; train PSNR "
                    << psnr0 << " -> " << psnr1 << " dB; relative rotation error " << rel.mean_deg
                    << " deg (do-nothing " << rel.do_nothing_deg << "); fx "
                    << focal_fx(t.focal(), t.image_size()) << " (reference "
                    << t.scene().ref_focal << ")");
  CHECK(psnr1 >= 25.0);
  CHECK(rel.do_nothing_deg > 5.0);
  CHECK(rel.mean_deg < 0.3 * rel.do_nothing_deg);
}
