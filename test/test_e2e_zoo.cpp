// The zoo's sweep (issue 49): a capture that walks past its subject, turning to keep it framed
// (LLFF horns). Its cameras' turn and slide move the image alike, and Adam alone barely turns
// them; CamP's preconditioner (--pose-precondition 0.1) is what turns them. Measured at this size
// (64×48, 62 views, 256 rays, 2,500 steps, 1 thread, focal fixed at a 65° prior, Zen 4):
// relative rotation 4.22° / 4.51° with it against 7.98° / 8.07° without (seeds 0 / 1; do-nothing
// 10.0°). At 1 thread a run is bitwise reproducible, so these margins do not flake with load.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "eval/pose_eval.h"
#include "test/fixtures.h"
#include "train/trainer.h"
#include "tools/simulator.h"

namespace fs = std::filesystem;
using namespace hashcc;

namespace {

RelativeRotationError sweep_run(double precondition) {
  const std::string data = (fs::temp_directory_path() / "hashcc_e2e_zoo_sweep").string();
  if (!fs::exists(data + "/poses_bounds.npy")) {
    SimOptions o;  // tools/make_zoo.sh's `sweep`, at 64×48
    o.width = 64;
    o.height = 48;
    o.views = 62;
    o.sweep = true;
    o.sweep_deg = 22;
    o.baseline = 0.5;
    o.rot_jitter_deg = 1.5;
    o.backdrop_depth = 24;
    write_sim_scene(data, o, false);
  }
  TrainConfig c;
  c.data = data;
  c.out = (fs::temp_directory_path() / ("hashcc_e2e_zoo_run_" + std::to_string(precondition))).string();
  fs::remove_all(c.out);
  c.model.field = Field::grid;
  for (const PresetEntry& e : field_defaults("grid")) e.set(c);
  c.model.variant = Variant::sh;
  c.model.gf.density_init = 2;  // the first stage of recipes/fern60.json
  c.lr_pose = 3e-3;
  c.lr_net = 2e-2;
  c.lr_net_end = 1e-3;
  c.pose_precondition = precondition;
  c.focal_fov = 65;
  c.fx_only = true;
  c.fixed_focal = true;
  c.rays = 256;
  c.steps = 2500;
  c.threads = 1;
  c.seed = 0;
  c.progress = false;
  c.checkpoint_minutes = c.preview_minutes = 1e9;
  Trainer t(c);
  REQUIRE(t.run());
  std::vector<Pose34> learned, ref;
  for (size_t i = 0; i < t.scene().train.size(); ++i) {
    const PoseParams<float> p = t.pose_of(int(i));
    Pose34 m;
    m.leftCols<3>() = so3::exp(Vec3<double>(p.r.cast<double>())).cast<double>();
    m.col(3) = p.t.cast<double>();
    learned.push_back(m);
    ref.push_back(t.scene().ref_c2w[t.scene().train[i]]);
  }
  return relative_rotation_error(learned, ref);
}

}  // namespace

TEST_CASE("e2e zoo: the preconditioner turns a sweep's cameras, Adam alone barely does",
          "[e2e][zoo][sweep]") {
  const RelativeRotationError plain = sweep_run(0), pc = sweep_run(0.1);
  WARN("zoo sweep: relative rotation " << plain.mean_deg << " deg without the preconditioner, "
       << pc.mean_deg << " with (do-nothing " << pc.do_nothing_deg << ")");
  CHECK(pc.do_nothing_deg > 8);
  CHECK(pc.mean_deg < 0.7 * plain.mean_deg);    // measured 0.53
  CHECK(pc.mean_deg < 0.6 * pc.do_nothing_deg);  // measured 0.42
}

// ---------------------------------------------------------------------------------------------
// The default command on the zoo (issue 49): `hashcc train --data DIR` with nothing but the
// budget, the batch and the thread count, on scenes that each switch on one capture effect. The
// run's own RUN/camera_error.csv (written against the simulator's reference cameras) gives the
// relative rotation at the start (the do-nothing value: every camera at identity) and at the
// end, and the focal against the reference.

namespace {

// tools/make_zoo.sh's scenes, at 64×48.
SimOptions zoo_options(const std::string& name) {
  SimOptions o;
  o.width = 64;
  o.height = 48;
  if (name == "lookat") {
    o.look_at = true;
    o.baseline = 0.5;
    o.rot_jitter_deg = 2;
  } else if (name == "narrow") {
    o.fov_deg = 40;
    o.rot_jitter_deg = 1.5;
  } else if (name == "wide") {
    o.fov_deg = 90;
  } else if (name == "deep") {
    o.backdrop_depth = 40;
  }
  return o;
}

struct CameraErrorRow {
  double rel_rot_deg = 0, fx = 0, ref_focal = 0;
};

// The first and the last row of a camera_error.csv.
std::pair<CameraErrorRow, CameraErrorRow> camera_error_ends(const std::string& path) {
  std::ifstream in(path);
  REQUIRE(in.good());
  std::string line, first, last;
  std::getline(in, line);  // header: step,seconds,rel_rot_deg,sim3_dR_deg,sim3_dT,fx,fy,ref_focal
  while (std::getline(in, line))
    if (!line.empty()) (first.empty() ? first : last) = line;
  const auto parse = [](const std::string& row) {
    std::vector<std::string> f;
    std::stringstream ss(row);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    REQUIRE(f.size() == 8);
    return CameraErrorRow{std::stod(f[2]), std::stod(f[5]), std::stod(f[7])};
  };
  return {parse(first), parse(last.empty() ? first : last)};
}

}  // namespace

// Measured at this size (64×48, 1,500 steps of 256 rays, 1 thread, seed 0, Zen 4 AVX-512; ~75 s
// a scene): relative rotation against the do-nothing value 1.83 / 7.27° (plain), 3.33 / 6.78°
// (lookat), 1.81 / 7.27° (deep); the focal 3.1%, 3.2%, 3.9% low. The bounds leave a margin
// for another ISA's rounding: a run's path is bitwise fixed at 1 thread on one machine only.
// What the default does not learn yet (2,500 steps, docs/results/scenes): the focal of a lens
// far from its 65° prior (wide 90°: +43%; narrow 40°: −41%) and the zoo's sweep (0.85×).
namespace {

// `hashcc train` with the default command on one zoo scene; its relative rotation must end below
// max_fraction of the do-nothing value, its focal within 5%.
void default_command_on(const std::string& name, double max_fraction) {
  const std::string data = (fs::temp_directory_path() / ("hashcc_e2e_zoo_default_" + name)).string();
  if (!fs::exists(data + "/poses_bounds.npy")) write_sim_scene(data, zoo_options(name), false);
  const std::string out = test::tmp("default_" + name, true);
  REQUIRE(test::cli({"train", "--data", data, "--out", out, "--steps", "1500", "--rays", "256",
                     "--threads", "1", "--seed", "0", "--no-progress"}) == 0);
  // A plan: stage 1 starts from identity, the last stage (RUN itself) ends the run.
  const auto [start, s1_end] = camera_error_ends(out + "/stage1/camera_error.csv");
  const auto [last_start, end] = camera_error_ends(out + "/camera_error.csv");
  const double focal_err = end.fx / end.ref_focal - 1;
  WARN("zoo " << name << ": relative rotation " << end.rel_rot_deg << " deg (do-nothing "
              << start.rel_rot_deg << ", after stage 1 " << s1_end.rel_rot_deg << "), focal "
              << end.fx << " px against " << end.ref_focal << " (" << 100 * focal_err << "%)");
  CHECK(start.rel_rot_deg > 3);  // the cameras had to turn
  CHECK(end.rel_rot_deg < max_fraction * start.rel_rot_deg);
  CHECK(std::abs(focal_err) < 0.05);
}

}  // namespace

// One test case a scene, so that CTest can run them side by side (CMakeLists.txt, e2e_zoo_*).
TEST_CASE("e2e zoo: the default command learns the cameras of the plain scene",
          "[e2e][zoo][plain]") {
  default_command_on("plain", 0.35);
}
TEST_CASE("e2e zoo: the default command learns the cameras of a walk round a near object",
          "[e2e][zoo][lookat]") {
  default_command_on("lookat", 0.6);
}
TEST_CASE("e2e zoo: the default command learns the cameras of a scene with a far backdrop",
          "[e2e][zoo][deep]") {
  default_command_on("deep", 0.35);
}
