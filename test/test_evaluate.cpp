// Evaluation pipeline tests (eval/evaluate.h, `hashcc eval`): metrics.json and the images on a
// tiny run, exact pose errors for hand-set poses, the two test-pose initialisations, refinement
// mechanics (only the test deltas move, bounded by Adam's step, deterministic), and the
// no-reference path.
#include <catch2/catch.hpp>

#include "test/fixtures.h"

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fileio.h"
#include "core/image.h"
#include "core/parallel.h"
#include "eval/evaluate.h"
#include "train/trainer.h"
#include "tools/cli.h"
#include "tools/simulator.h"

namespace fs = std::filesystem;
using namespace hashcc;
using nlohmann::json;
using hashcc::test::cli;
using hashcc::test::tmp;

namespace {

TrainConfig tiny_config(const std::string& data, const std::string& out) {
  return test::tiny_train_config(data, out, 10);
}

// Puts the exact reference poses into the learned train poses: r = Log(R_ref), t = centre.
void set_poses_to_reference(Trainer& t) {
  const Scene& sc = t.scene();
  auto& p = t.mutable_state().poses;
  for (size_t i = 0; i < sc.train.size(); ++i) {
    const Mat34d& c2w = sc.ref_c2w[size_t(sc.train[i])];
    const Vec3<double> r = so3::log(Mat3<double>(c2w.leftCols<3>()));
    for (int j = 0; j < 3; ++j) {
      p[6 * i + j] = float(r[j]);
      p[6 * i + 3 + j] = float(c2w(j, 3));
    }
  }
}

double rot_deg(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B) {
  return rotation_angle_deg(A * B.transpose());
}

}  // namespace

TEST_CASE("evaluate: refinement lr schedule read literally", "[evalcmd]") {
  CHECK(refine_lr(0) == Approx(5e-4));    // first halving at epoch 0
  CHECK(refine_lr(199) == Approx(5e-4));
  CHECK(refine_lr(200) == Approx(2.5e-4));
  CHECK(refine_lr(999) == Approx(3.125e-5));
  CHECK(parse_test_init("scale") == TestInit::kScale);
  CHECK(parse_test_init("sim3") == TestInit::kSim3);
  CHECK_THROWS_AS(parse_test_init("colmap"), hashcc::Error);
}

TEST_CASE("evaluate: hashcc eval writes metrics.json and the images", "[evalcmd]") {
  const std::string data = test::sim_scene("cli", 10, 40, 30, 1);  // test images 0, 8; 8 train
  const std::string run = tmp("cli_run");
  fs::remove_all(run);
  {
    Trainer t(tiny_config(data, run));
    REQUIRE(t.run());
  }
  REQUIRE(cli({"eval", "--run", run, "--refine-epochs", "2", "--no-progress"}) == 0);
  const json j = json::parse(read_file_bytes(run + "/eval/metrics.json", 1 << 24));
  CHECK(j["mode"] == "test_views");
  for (const char* k : {"psnr", "ssim", "seconds", "rel_rot_err_deg", "rel_rot_do_nothing_deg"})
    CHECK(j.at(k).is_number());
  for (const char* k : {"rot_err_deg", "trans_err"})  // null only for a degenerate alignment
    CHECK((j.at(k).is_number() || (j.at(k).is_null() && !j["pose_note"].get<std::string>().empty())));
  CHECK(j.at("lpips").is_null());
  CHECK(j["lpips_note"] == "LPIPS: not computed (no weights)");
  CHECK(j["refine_epochs"] == 2);
  CHECK(j.at("refine_seconds").is_number());
  CHECK(j.at("render_seconds").is_number());
  // The trajectory: a header, one row an epoch (epoch, lr, loss, 6 deltas a test camera).
  {
    const std::string csv = read_file_bytes(run + "/eval/refine.csv", 1 << 20);
    std::vector<std::string> lines;
    size_t a = 0;
    for (size_t b; (b = csv.find('\n', a)) != std::string::npos; a = b + 1) lines.push_back(csv.substr(a, b - a));
    REQUIRE(lines.size() == 3);
    CHECK(lines[0].rfind("epoch,lr,loss,", 0) == 0);
    CHECK(std::count(lines[0].begin(), lines[0].end(), ',') == 2 + 6 * 2);
    CHECK(lines[2].rfind("1,0.0005,", 0) == 0);
    CHECK(std::count(lines[2].begin(), lines[2].end(), ',') == 2 + 6 * 2);
  }
  CHECK(j["focal"]["fx"].is_number());
  CHECK(j["focal"]["fy"].is_number());
  CHECK(j["focal"]["reference"].get<double>() == Approx(0.8 * 40));  // SimOptions focal_ratio
  REQUIRE(j["per_image"].size() == 2);
  for (const auto& im : j["per_image"]) {
    const std::string name = im.at("name");
    CHECK(im.at("psnr").is_number());
    CHECK(im.at("ssim").is_number());
    CHECK(im.at("lpips").is_null());
    for (const char* sub : {"renders", "gt", "error"}) {
      int w = 0, h = 0;
      image_size(run + "/eval/" + sub + "/" + name + ".png", &w, &h);
      CHECK(w == 40);
      CHECK(h == 30);
    }
  }
  int w = 0, h = 0;
  image_size(run + "/eval/contact_sheet.png", &w, &h);
  CHECK(w == 3 * 40);
  CHECK(h == 2 * 30);
  // The ground truth written is the scene image itself.
  const ImageU8 gt = read_image(run + "/eval/gt/" + j["per_image"][0]["name"].get<std::string>() + ".png");
  const ImageU8 src = read_image(data + "/images/" + j["per_image"][0]["name"].get<std::string>() + ".png");
  CHECK(gt.rgb == src.rgb);

  // Bad input: one line, exit 2. An incomplete LPIPS folder: null and the reason.
  CHECK(cli({"eval", "--run", tmp("no_such_run")}) == 2);
  CHECK(cli({"eval", "--run", run, "--lpips-weights", tmp("no_such_dir")}) == 2);
  CHECK(cli({"eval", "--run", run, "--refine-epochs", "-1"}) == 2);
  const std::string partial = tmp("lpips_partial");
  fs::create_directories(partial);
  REQUIRE(cli({"eval", "--run", run, "--refine-epochs", "0", "--lpips-weights", partial,
               "--no-progress", "--test-init", "sim3"}) == 0);
  const json j2 = json::parse(read_file_bytes(run + "/eval/metrics.json", 1 << 24));
  CHECK(j2["lpips"].is_null());
  CHECK(j2["lpips_note"].get<std::string>().find("lacks features.0.weight.npy") != std::string::npos);
  CHECK(j2["refine_epochs"] == 0);
  CHECK(j2["test_init"] == "sim3");
}

TEST_CASE("evaluate: learned poses equal to the reference give zero pose error", "[evalcmd]") {
  const std::string data = test::sim_scene("exact", 10, 40, 30, 1);
  Trainer t(tiny_config(data, ""));
  set_poses_to_reference(t);
  const TrainPoseReport p = train_pose_report(t);
  REQUIRE(p.sim3.has_value());
  REQUIRE(p.relative.has_value());
  CHECK(p.sim3->mean_dR_deg < 1e-3);  // float storage of r, t
  CHECK(p.sim3->mean_dT < 1e-5);
  CHECK(p.sim3->sim.s == Approx(1).epsilon(1e-5));
  CHECK(p.relative->mean_deg < 1e-3);
  CHECK(p.relative->do_nothing_deg > 0.1);
  CHECK(p.note.empty());
  CHECK(learned_to_reference_distance_ratio(t) == Approx(1).epsilon(1e-5));
  // Both initialisations give the reference test poses back.
  const Scene& sc = t.scene();
  for (TestInit mode : {TestInit::kScale, TestInit::kSim3}) {
    const auto P0 = test_pose_init(t, mode, &p.sim3->sim);
    REQUIRE(P0.size() == sc.test.size());
    for (size_t k = 0; k < P0.size(); ++k) {
      const Mat34d& ref = sc.ref_c2w[size_t(sc.test[k])];
      CHECK(rot_deg(P0[k].leftCols<3>(), ref.leftCols<3>()) < 1e-3);
      CHECK((P0[k].col(3) - ref.col(3)).norm() < 1e-5);
    }
  }
}

TEST_CASE("evaluate: sim3 test init maps reference poses into the learned frame", "[evalcmd]") {
  const std::string data = test::sim_scene("exact", 10, 40, 30, 1);
  Trainer t(tiny_config(data, ""));
  const Scene& sc = t.scene();
  // The learned frame = the reference frame moved by a known similarity: x_l = (R_aᵀ(x_ref − t_a))/s.
  const Eigen::Matrix3d Ra = so3::exp(Vec3<double>(0.3, -0.5, 0.2));
  const Eigen::Vector3d ta(0.4, -0.1, 0.7);
  const double s = 0.25;
  auto to_learned = [&](const Mat34d& ref) {
    Mat34d q;
    q.leftCols<3>() = Ra.transpose() * ref.leftCols<3>();
    q.col(3) = Ra.transpose() * (ref.col(3) - ta) / s;
    return q;
  };
  auto& poses = t.mutable_state().poses;
  for (size_t i = 0; i < sc.train.size(); ++i) {
    const Mat34d q = to_learned(sc.ref_c2w[size_t(sc.train[i])]);
    const Vec3<double> r = so3::log(Mat3<double>(q.leftCols<3>()));
    for (int j = 0; j < 3; ++j) {
      poses[6 * i + j] = float(r[j]);
      poses[6 * i + 3 + j] = float(q(j, 3));
    }
  }
  const TrainPoseReport p = train_pose_report(t);
  REQUIRE(p.sim3.has_value());
  CHECK(p.sim3->sim.s == Approx(s).epsilon(1e-4));  // x_ref = s R_a x_l + t_a
  CHECK(p.sim3->mean_dR_deg < 1e-3);
  CHECK(p.sim3->mean_dT < 1e-4);
  const auto P0 = test_pose_init(t, TestInit::kSim3, &p.sim3->sim);
  for (size_t k = 0; k < P0.size(); ++k) {
    const Mat34d want = to_learned(sc.ref_c2w[size_t(sc.test[k])]);
    CHECK(rot_deg(P0[k].leftCols<3>(), want.leftCols<3>()) < 1e-3);
    CHECK((P0[k].col(3) - want.col(3)).norm() < 1e-4);
  }
  // The scale init keeps the reference rotation and scales the centre by the distance ratio.
  const double ratio = learned_to_reference_distance_ratio(t);
  CHECK(ratio == Approx(1 / s).epsilon(1e-4));  // learned / reference distances
  const auto P0s = test_pose_init(t, TestInit::kScale, nullptr);
  for (size_t k = 0; k < P0s.size(); ++k) {
    const Mat34d& ref = sc.ref_c2w[size_t(sc.test[k])];
    CHECK(P0s[k].leftCols<3>().isApprox(ref.leftCols<3>()));
    CHECK(P0s[k].col(3).isApprox(ref.col(3) * ratio));
  }
}

TEST_CASE("evaluate: refinement moves only the test deltas", "[evalcmd]") {
  const std::string data = test::sim_scene("exact", 10, 40, 30, 1);
  Trainer t(tiny_config(data, ""));
  for (int i = 0; i < 10; ++i) t.step_once();
  const TrainState before = t.state();
  const std::vector<PoseParams<float>> init = test_pose_params(t, TestInit::kScale, nullptr);
  const int epochs = 6;
  const RefineResult a = refine_test_poses(t, init, t.scene().test, epochs);
  CHECK(t.state().net == before.net);  // bitwise
  CHECK(t.state().focal == before.focal);
  CHECK(t.state().poses == before.poses);
  CHECK(t.state().net_m == before.net_m);
  REQUIRE(a.poses.size() == init.size());
  REQUIRE(int(a.epoch_loss.size()) == epochs);
  double moved = 0, biggest = 0;
  for (size_t k = 0; k < init.size(); ++k) {
    CHECK(a.poses[k].has_P0);
    CHECK(a.poses[k].P0 == init[k].P0);
    for (int j = 0; j < 3; ++j) {
      REQUIRE(std::isfinite(a.poses[k].r[j]));
      REQUIRE(std::isfinite(a.poses[k].t[j]));
      moved += std::abs(a.poses[k].r[j]) + std::abs(a.poses[k].t[j]);
      biggest = std::max({biggest, double(std::abs(a.poses[k].r[j])), double(std::abs(a.poses[k].t[j]))});
    }
  }
  CHECK(moved > 0);
  // Adam moves a parameter by at most ~lr per step: epochs × images steps at 5e-4.
  CHECK(biggest <= 1.05 * epochs * init.size() * 5e-4);
  // Deterministic.
  const RefineResult b = refine_test_poses(t, init, t.scene().test, epochs);
  for (size_t k = 0; k < init.size(); ++k) {
    CHECK(a.poses[k].r == b.poses[k].r);
    CHECK(a.poses[k].t == b.poses[k].t);
  }
}

TEST_CASE("evaluate: a run without reference poses scores the training views", "[evalcmd]") {
  // A bare photo folder: the simulated images without poses_bounds.npy.
  const std::string src = test::sim_scene("exact", 10, 40, 30, 1);
  const std::string bare = tmp("bare");
  fs::remove_all(bare);
  fs::create_directories(bare + "/images");
  for (auto& e : fs::directory_iterator(src + "/images"))
    fs::copy_file(e.path(), bare + "/images/" + e.path().filename().string());
  const std::string run = tmp("bare_run");
  fs::remove_all(run);
  {
    Trainer t(tiny_config(bare, run));
    REQUIRE(t.run());
  }
  REQUIRE(cli({"eval", "--run", run, "--no-progress"}) == 0);
  const json j = json::parse(read_file_bytes(run + "/eval/metrics.json", 1 << 24));
  CHECK(j["mode"] == "train_views");
  CHECK(j["note"].get<std::string>().find("training-view reconstruction only") != std::string::npos);
  CHECK(j["per_image"].size() == 8);
  CHECK(j["psnr"].is_number());
  CHECK(j["rot_err_deg"].is_null());
  CHECK(j["rel_rot_err_deg"].is_null());
  CHECK(j["focal"]["reference"].is_null());
  CHECK(j["refine_epochs"] == 0);
  CHECK(fs::exists(run + "/eval/contact_sheet.png"));
}

TEST_CASE("evaluate: pose error composes the learned delta with --init-poses' P0", "[evalcmd][initposes]") {
  // Cameras given exactly (the scene's own poses_bounds.npy) and frozen: the pose error of the
  // composed cameras [Exp(r)|t]·P0 must be zero. (Reading only the deltas would score identity
  // cameras instead: ~170° here, the bug this guards against.)
  const std::string data = test::sim_scene("p0", 10, 40, 30, 1);
  TrainConfig c = tiny_config(data, "");
  c.steps = 3;
  c.init_poses = data + "/poses_bounds.npy";
  c.refine_poses = false;
  Trainer t(c);
  for (int k = 0; k < 3; ++k) t.step_once();
  TrainPoseReport r = train_pose_report(t);
  REQUIRE(r.sim3.has_value());
  REQUIRE(r.relative.has_value());
  CHECK(r.sim3->mean_dR_deg < 1e-3);
  CHECK(r.relative->mean_deg < 1e-3);
  CHECK(r.relative->do_nothing_deg > 0.5);
}
