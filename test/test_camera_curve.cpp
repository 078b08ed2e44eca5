// RUN/camera_error.csv (eval/camera_curve): rows at the stated steps, values equal to the
// end-of-run pose report, a resume that keeps exactly the rows up to its checkpoint, and no
// file for a scene without reference cameras. Also --focal / --fixed-focal.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "eval/camera_curve.h"
#include "eval/evaluate.h"
#include "test/fixtures.h"
#include "train/trainer.h"

namespace fs = std::filesystem;
using namespace hashcc;

namespace {
std::vector<std::vector<std::string>> read_csv(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::vector<std::string>> rows;
  for (std::string line; std::getline(in, line);) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    rows.push_back(cells);
  }
  return rows;
}
std::vector<int> steps_of(const std::vector<std::vector<std::string>>& rows) {
  std::vector<int> s;
  for (size_t i = 1; i < rows.size(); ++i) s.push_back(std::stoi(rows[i][0]));
  return s;
}
}  // namespace

TEST_CASE("camera curve: rows every k steps, last row = the pose report, resume keeps its rows",
          "[trainer][curve]") {
  const std::string data = test::sim_scene("curve", 6, 40, 30);
  const std::string out = (fs::temp_directory_path() / "hashcc_curve_run").string();
  fs::remove_all(out);
  const std::string csv = out + "/camera_error.csv";
  {
    Trainer t(test::tiny_train_config(data, out, 12));
    CameraCurve curve(t, csv, 2);
    REQUIRE(curve.active());
    for (int i = 0; i < 5; ++i) { t.step_once(); curve(t); }
    t.save_checkpoint_now();                              // step 5
    for (int i = 0; i < 2; ++i) { t.step_once(); curve(t); }  // rows past the checkpoint: a crash
  }
  CHECK(steps_of(read_csv(csv)) == std::vector<int>{0, 2, 4, 6});
  Trainer t = Trainer::resume(out);
  REQUIRE(t.state().step == 5);
  CameraCurve curve(t, csv, 2);
  REQUIRE(t.run(nullptr, [&curve](const Trainer& tr) { curve(tr); }));
  const auto rows = read_csv(csv);
  REQUIRE(rows.at(0).size() == 8);
  CHECK(rows[0][0] == "step");
  CHECK(rows[0][2] == "rel_rot_deg");
  // 12 is the last step (planned_total), written though 12 % 2 == 0 anyway; 7 and 9 are not.
  CHECK(steps_of(rows) == std::vector<int>{0, 2, 4, 6, 8, 10, 12});
  const TrainPoseReport r = train_pose_report(t);
  REQUIRE(r.relative.has_value());
  REQUIRE(r.sim3.has_value());
  CHECK(std::stod(rows.back()[2]) == Approx(r.relative->mean_deg).margin(1e-4));
  CHECK(std::stod(rows.back()[3]) == Approx(r.sim3->mean_dR_deg).margin(1e-4));
  CHECK(std::stod(rows.back()[5]) == Approx(r.fx).margin(1e-3));
  CHECK(std::stod(rows.back()[7]) == Approx(t.scene().ref_focal).margin(1e-3));
  // Identity cameras at step 0: the do-nothing error, and the cameras moved since.
  CHECK(std::stod(rows[1][2]) == Approx(r.relative->do_nothing_deg).margin(1e-3));
  CHECK(std::stod(rows.back()[2]) != std::stod(rows[1][2]));
}

TEST_CASE("camera curve: no reference cameras, no file", "[trainer][curve]") {
  const std::string src = test::sim_scene("curve", 6, 40, 30);
  const std::string bare = (fs::temp_directory_path() / "hashcc_curve_bare").string();
  fs::remove_all(bare);
  fs::create_directories(bare + "/images");
  for (auto& e : fs::directory_iterator(src + "/images"))
    fs::copy_file(e.path(), bare + "/images/" + e.path().filename().string());
  const std::string out = (fs::temp_directory_path() / "hashcc_curve_bare_run").string();
  fs::remove_all(out);
  Trainer t(test::tiny_train_config(bare, out, 2));
  CameraCurve curve(t, out + "/camera_error.csv");
  CHECK_FALSE(curve.active());
  REQUIRE(t.run(nullptr, [&curve](const Trainer& tr) { curve(tr); }));
  CHECK_FALSE(fs::exists(out + "/camera_error.csv"));
}

TEST_CASE("--focal starts from a given focal; --fixed-focal keeps it", "[trainer][curve]") {
  const std::string data = test::sim_scene("curve", 6, 40, 30);
  TrainConfig c = test::tiny_train_config(data, "", 6);
  c.focal_fx = 33.0;
  c.focal_fy = 31.0;
  {
    Trainer t(c);
    CHECK(focal_fx(t.focal(), t.image_size()) == Approx(33.0).epsilon(1e-6));
    CHECK(focal_fy(t.focal(), t.image_size()) == Approx(31.0).epsilon(1e-6));
    REQUIRE(t.run());
    CHECK(focal_fx(t.focal(), t.image_size()) != Approx(33.0).epsilon(1e-6));  // learned
  }
  c.fixed_focal = true;
  Trainer t(c);
  const std::vector<float> before = t.state().focal;
  const std::vector<float> poses0 = t.state().poses;
  REQUIRE(t.run());
  CHECK(t.state().focal == before);      // bitwise: not learned
  CHECK(t.state().poses != poses0);      // the poses still learn
  // One of fx, fy alone, and a focal with --init-poses' own, are refused.
  TrainConfig bad = c;
  bad.focal_fy = 0;
  CHECK_THROWS_AS(validate_train_config(bad), Error);
  bad = c;
  bad.init_poses = data + "/poses_bounds.npy";
  CHECK_THROWS_AS(validate_train_config(bad), Error);
}
