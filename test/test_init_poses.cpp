// --init-poses: readers (COLMAP text, poses_bounds.npy, cameras.json), their conventions and
// the formulas.md §7 centring/scaling (round trips to 1e-9), malformed input naming file and line,
// and the trainer with fixed initial poses P0 (frozen: bitwise fixed; refined: gradients reach
// the deltas and a short run on the simulated scene reduces a perturbation's pose error).
#include <catch2/catch.hpp>

#include <Eigen/Geometry>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/camera_models.h"
#include "core/error.h"
#include "core/fileio.h"
#include "core/parallel.h"
#include "eval/pose_eval.h"
#include "train/trainer.h"
#include "test/fixtures.h"
#include "tools/simulator.h"
#include "test/gradcheck.h"

namespace fs = std::filesystem;
using namespace hashcc;
using hashcc::test::tmp;

namespace {

double max_diff(const std::vector<Mat34d>& a, const std::vector<Mat34d>& b) {
  REQUIRE(a.size() == b.size());
  double m = 0;
  for (size_t i = 0; i < a.size(); ++i) hashcc::test::keep_worst(m, hashcc::test::max_abs_entry(a[i] - b[i]));
  return m;
}

// The scene's sizes and names only (no pixels): what init_poses_for_scene needs.
Scene names_scene(const std::vector<std::string>& names, int W, int H) {
  Scene s;
  s.names = names;
  s.width = W;
  s.height = H;
  s.image_dir = "scene";
  return s;
}

std::vector<Mat34d> rig_c2w(const SimOptions& o) {
  std::vector<Mat34d> v;
  for (auto& c : make_sim_rig(o)) v.push_back(c.c2w);
  return v;
}

std::vector<std::string> sim_names(int n) {
  std::vector<std::string> v;
  for (int i = 0; i < n; ++i) v.push_back(fmt::format("image{:03d}.png", i));
  return v;
}

// recenter(scale · poses): the formulas.md §7 frame for a known scale.
std::vector<Mat34d> spec7(std::vector<Mat34d> p, double scale) {
  for (auto& m : p) m.col(3) *= scale;
  return recenter_poses(p);
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

// Catches the hashcc::Error thrown by f and returns it.
template <class F> Error error_of(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e;
  }
  FAIL("no hashcc::Error thrown");
  return Error("", "", "");
}

}  // namespace

TEST_CASE("init poses: COLMAP convention round trip", "[initposes]") {
  SimOptions o;
  o.views = 8;
  const auto rig = rig_c2w(o);
  for (const auto& c2w : rig) {
    Eigen::Vector4d q;
    Eigen::Vector3d t;
    colmap_from_c2w(c2w, &q, &t);
    CHECK(hashcc::test::max_abs_entry(c2w_from_colmap(q, t) - c2w) < 1e-12);
    // Independently: COLMAP's x_cam = R x_world + t maps the camera centre to 0 and a point
    // in front of an OpenGL camera (−z) to +z (OpenCV looks down +z).
    const Eigen::Matrix3d R = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).toRotationMatrix();
    CHECK((R * c2w.col(3) + t).norm() < 1e-12);
    const Eigen::Vector3d ahead = c2w.col(3) - 2.0 * c2w.col(2) + 0.5 * c2w.col(1);
    const Eigen::Vector3d cv = R * ahead + t;
    CHECK(cv.z() == Approx(2.0).margin(1e-12));
    CHECK(cv.y() == Approx(-0.5).margin(1e-12));  // up in OpenGL is −y in OpenCV
  }
}

TEST_CASE("init poses: COLMAP text, poses_bounds.npy and cameras.json read back the same cameras",
          "[initposes]") {
  SimOptions o;
  o.views = 8;
  o.width = 64;
  o.height = 48;
  const std::string dir = tmp("rt_scene");
  if (!fs::exists(dir + "/poses_bounds.npy")) write_sim_scene(dir, o, false);
  const Scene scene = load_scene(dir, {"", false});
  REQUIRE(scene.names == sim_names(8));
  const auto rig = rig_c2w(o);
  const double f = o.focal_ratio * o.width;

  SECTION("poses_bounds.npy: exactly the loader's reference frame and focal") {
    const CameraModel m = read_camera_model(dir + "/poses_bounds.npy");
    CHECK(m.format == "llff");
    CHECK(max_diff(m.c2w, rig) < 1e-9);  // conversion from LLFF's [down, right, back]
    const InitPoses ip = init_poses_for_scene(m, scene);
    CHECK(max_diff(ip.c2w, scene.ref_c2w) < 1e-9);
    CHECK(ip.scale == Approx(scene.scale).epsilon(1e-12));
    CHECK(ip.fx == Approx(scene.ref_focal).epsilon(1e-12));
    CHECK(ip.fy == Approx(scene.ref_focal).epsilon(1e-12));
  }

  SECTION("COLMAP text with sparse points: near from the depth percentile") {
    const std::string col = tmp("rt_colmap");
    fs::remove_all(col);
    write_colmap_text(col, scene.names, rig, f, f, o.width, o.height);
    // Ten points in front of each camera, seen by it alone, at depths 2.0, 2.1, … 2.9 (camera
    // i: + 0.05·i). numpy.percentile(·, 0.1) of these = 2.0009 (+ 0.05·i); near = camera 0's.
    std::string pts = "# 3D point list\n";
    int id = 1;
    for (int i = 0; i < 8; ++i)
      for (int k = 0; k < 10; ++k) {
        const double depth = 2.0 + 0.1 * k + 0.05 * i;
        const Eigen::Vector3d X = rig[i].col(3) - depth * rig[i].col(2) + 0.1 * k * rig[i].col(0);
        pts += fmt::format("{} {:.17g} {:.17g} {:.17g} 128 128 128 0.5 {} {}\n", id++, X[0], X[1],
                           X[2], i + 1, k);
      }
    write_text(col + "/points3D.txt", pts);
    const CameraModel m = read_camera_model(col);
    CHECK(m.format == "colmap");
    CHECK(m.names == scene.names);
    CHECK(max_diff(m.c2w, rig) < 1e-9);
    REQUIRE(m.near.size() == 8);
    CHECK(m.near[0] == Approx(2.0009).epsilon(1e-12));
    const InitPoses ip = init_poses_for_scene(m, scene);
    CHECK(ip.scale == Approx(1.0 / (0.75 * 2.0009)).epsilon(1e-12));
    CHECK(max_diff(ip.c2w, spec7(rig, 1.0 / (0.75 * 2.0009))) < 1e-9);
    CHECK(ip.fx == Approx(f).epsilon(1e-12));
    CHECK(ip.fy == Approx(f).epsilon(1e-12));
    // With the simulator's own bounds the COLMAP cameras land exactly on the reference frame.
    CameraModel with_bounds = m;
    with_bounds.near = read_camera_model(dir + "/poses_bounds.npy").near;
    CHECK(max_diff(init_poses_for_scene(with_bounds, scene).c2w, scene.ref_c2w) < 1e-9);
  }

  SECTION("cameras.json (transforms.json convention) = COLMAP without points") {
    const std::string col = tmp("rt_colmap_nopts");
    fs::remove_all(col);
    write_colmap_text(col, scene.names, rig, f, 1.01 * f, o.width, o.height);
    const std::string js = tmp("rt_cameras.json");
    write_cameras_json_file(js, scene.names, rig, f, 1.01 * f, o.width, o.height);
    const CameraModel mc = read_camera_model(col), mj = read_camera_model(js);
    CHECK(mj.format == "json");
    CHECK(max_diff(mj.c2w, rig) < 1e-9);
    CHECK(mc.near.empty());
    const InitPoses a = init_poses_for_scene(mc, scene), b = init_poses_for_scene(mj, scene);
    CHECK(max_diff(a.c2w, b.c2w) < 1e-9);
    // Fallback scale: the camera spread becomes kTypicalSpread.
    CHECK(max_diff(a.c2w, spec7(rig, a.scale)) < 1e-9);
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (auto& p : a.c2w) mean += p.col(3) / 8.0;
    double ss = 0;
    for (auto& p : a.c2w) ss += (p.col(3) - mean).squaredNorm() / 8.0;
    CHECK(std::sqrt(ss) == Approx(kTypicalSpread).epsilon(1e-9));
    CHECK(b.fy == Approx(1.01 * f).epsilon(1e-12));
    // A cameras.json written by hashcc ("ndc" key) is already in the frame: scale 1.
    auto j = nlohmann::json::parse(read_file_bytes(js, 1 << 20));
    j["ndc"] = true;
    write_text(js, j.dump());
    const InitPoses c = init_poses_for_scene(read_camera_model(js), scene);
    CHECK(c.scale == 1.0);
    CHECK(max_diff(c.c2w, recenter_poses(rig)) < 1e-9);
  }

  SECTION("matching by name: missing images start at the mean pose, other extensions match") {
    const std::string col = tmp("rt_colmap_missing");
    fs::remove_all(col);
    std::vector<std::string> names;
    std::vector<Mat34d> some;
    for (int i = 0; i < 8; ++i)
      if (i != 3 && i != 5) {
        names.push_back(fmt::format("images/image{:03d}.JPG", i));  // full-res names
        some.push_back(rig[i]);
      }
    write_colmap_text(col, names, some, f, f, 2 * o.width, 2 * o.height);
    const InitPoses ip = init_poses_for_scene(read_camera_model(col), scene);
    CHECK(ip.from_model == std::vector<bool>{true, true, true, false, true, false, true, true});
    CHECK(hashcc::test::max_abs_entry(ip.c2w[3] - Mat34d::Identity()) < 1e-12);
    CHECK(hashcc::test::max_abs_entry(ip.c2w[5] - Mat34d::Identity()) < 1e-12);
    CHECK(ip.fx == Approx(f / 2).epsilon(1e-12));  // focal rescaled to the loaded size
    bool reported = false;
    for (auto& n : ip.notes) reported = reported || n.find("image003.png, image005.png") != std::string::npos;
    CHECK(reported);
  }
}

TEST_CASE("init poses: malformed input names the file and the line", "[initposes]") {
  const std::string col = tmp("bad_colmap");
  fs::remove_all(col);
  SimOptions o;
  o.views = 3;
  write_colmap_text(col, sim_names(3), rig_c2w(o), 50, 50, 64, 48);
  const std::string good_images = read_file_bytes(col + "/images.txt", 1 << 20);
  const std::string cams = col + "/cameras.txt", imgs = col + "/images.txt";

  write_text(cams, "# c\n# c\n1 PINHOLE 64 48 50 50 32 24\n2 PINHOLE 64 48 5O 50 32 24\n");
  Error e = error_of([&] { read_camera_model(col); });
  CHECK(e.file == cams);
  CHECK(e.field == "line 4");
  CHECK_THAT(e.what(), Catch::Contains("5O"));

  write_text(cams, "1 OPENCV 64 48 50 50 32 24 0 0 0 0\n");
  e = error_of([&] { read_camera_model(col); });
  CHECK(e.field == "line 1");
  CHECK_THAT(e.what(), Catch::Contains("unsupported camera model OPENCV"));

  write_text(cams, "1 SIMPLE_PINHOLE 64 48 50 32\n");
  e = error_of([&] { read_camera_model(col); });
  CHECK(e.field == "line 1");
  CHECK_THAT(e.what(), Catch::Contains("2 parameters"));

  // Radial models are read; their distortion is reported as ignored.
  write_text(cams, "1 SIMPLE_RADIAL 64 48 50 32 24 0.01\n2 RADIAL 64 48 50 32 24 0.01 0.001\n"
                   "3 SIMPLE_PINHOLE 64 48 50 32 24\n");
  const CameraModel m = read_camera_model(col);
  CHECK(m.c2w.size() == 3);
  REQUIRE_FALSE(m.notes.empty());
  CHECK_THAT(m.notes[0], Catch::Contains("radial distortion terms ignored"));

  // images.txt: line 4 is image 1, line 5 its (empty) points, line 6 image 2.
  std::string bad = good_images;
  bad.replace(bad.find("\n2 ") + 3, 1, "x");
  write_text(imgs, bad);
  e = error_of([&] { read_camera_model(col); });
  CHECK(e.file == imgs);
  CHECK(e.field == "line 6");
  write_text(imgs, good_images + "4 1 0 0 0 0 0 0 9 image003.png\n\n");
  e = error_of([&] { read_camera_model(col); });
  CHECK(e.field == "line 10");
  CHECK_THAT(e.what(), Catch::Contains("camera 9 is not in cameras.txt"));
  write_text(imgs, good_images + "4 1 0 0 0 0 0 0 1 image003.png\n1 2\n");
  e = error_of([&] { read_camera_model(col); });
  CHECK(e.field == "line 11");
  write_text(imgs, good_images);

  write_text(col + "/points3D.txt", "1 0 0 -3 1 2 3 0.5 1 0\n2 0 0 -3 1 2 3 0.5 1\n");
  e = error_of([&] { read_camera_model(col); });
  CHECK(e.file == col + "/points3D.txt");
  CHECK(e.field == "line 2");
  fs::remove(col + "/points3D.txt");

  // No image in common.
  e = error_of([&] { init_poses_for_scene(read_camera_model(col), names_scene({"a.png", "b.png"}, 64, 48)); });
  CHECK(e.file == col);
  CHECK_THAT(e.what(), Catch::Contains("no image in common"));

  // cameras.json: the parser's line, and the frame at fault.
  const std::string js = tmp("bad.json");
  write_text(js, "{\n \"frames\": [\n  {\"file_path\": \"a.png\",,}\n ]\n}\n");
  e = error_of([&] { read_camera_model(js); });
  CHECK_THAT(e.what(), Catch::Contains("line 3"));
  write_text(js, "{\"frames\": [{\"file_path\": \"a.png\", \"transform_matrix\": "
                 "[[1,0,0,0],[0,1,0,0],[0,0,1,\"x\"],[0,0,0,1]]}]}");
  e = error_of([&] { read_camera_model(js); });
  CHECK(e.field == "frames[0].transform_matrix[2][3]");
  e = error_of([&] { read_camera_model(tmp("nothing_here")); });
  CHECK_THAT(e.what(), Catch::Contains("no such file"));
}

namespace {

std::string train_scene() {
  SimOptions o;
  o.views = 8;
  o.width = 64;
  o.height = 48;
  const std::string d = tmp("train_scene");
  if (!fs::exists(d + "/poses_bounds.npy")) write_sim_scene(d, o, false);
  return d;
}

TrainConfig tiny(const std::string& data, const std::string& init) {
  TrainConfig c = test::tiny_train_config(data, "", 8);
  c.init_poses = init;
  return c;
}

std::vector<Mat34d> learned(const Trainer& t) {
  std::vector<Mat34d> v;
  for (int i = 0; i < int(t.scene().train.size()); ++i)
    v.push_back(world_from_camera(t.pose_of(i)).cast<double>());
  return v;
}

// Ground-truth cameras of the simulated scene, each perturbed by `deg` degrees about a random
// axis and `frac` of the camera spread in a random direction (deterministic).
std::vector<Mat34d> perturbed(const std::vector<Mat34d>& gt, double deg, double frac) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (auto& p : gt) mean += p.col(3) / double(gt.size());
  double spread = 0;
  for (auto& p : gt) spread = std::max(spread, (p.col(3) - mean).norm());
  Rng rng(7, 3);
  std::vector<Mat34d> out = gt;
  for (auto& p : out) {
    Eigen::Vector3d axis(rng.normal(), rng.normal(), rng.normal()), dir(rng.normal(), rng.normal(), rng.normal());
    const Eigen::Matrix3d R = Eigen::AngleAxisd(deg * M_PI / 180, axis.normalized()).toRotationMatrix();
    p.leftCols<3>() = R * p.leftCols<3>();
    p.col(3) += frac * spread * dir.normalized();
  }
  return out;
}

}  // namespace

TEST_CASE("init poses: the trainer starts at P0; frozen poses stay bitwise fixed; gradients reach "
          "the deltas", "[initposes]") {
  const std::string data = train_scene();
  const std::string out = tmp("frozen_run");
  fs::remove_all(out);
  const std::string js = data + "/poses_bounds.npy";

  TrainConfig c = tiny(data, js);
  c.out = out;
  c.refine_poses = false;
  Trainer t(c);
  const Scene& sc = t.scene();
  const std::vector<Mat34d> start = learned(t);
  for (size_t i = 0; i < sc.train.size(); ++i)  // P0 = the reference pose (float)
    CHECK(hashcc::test::max_abs_entry(start[i] - sc.ref_c2w[sc.train[i]]) < 1e-6);
  CHECK(focal_fx(t.focal(), t.image_size()) == Approx(sc.ref_focal).epsilon(1e-6));
  const std::vector<float> P0 = t.state().poses_P0, focal0 = t.state().focal;
  REQUIRE(t.run());
  CHECK(t.state().step == 8);
  for (float v : t.state().poses) CHECK(v == 0.f);  // bitwise: deltas never updated
  CHECK(t.state().poses_P0 == P0);
  CHECK(t.state().focal == focal0);                 // the model's focal is frozen too
  CHECK(learned(t) == start);
  // Held cameras cost nothing: no ray gradient is computed, the camera's gradient is zero.
  for (int k = 0; k < 6; ++k) CHECK(t.last_camera_grads().d_pose[k] == 0.f);
  CHECK(t.last_camera_grads().d_focal[0] == 0.f);
  // cameras.json composes [Exp(r)|t]·P0; a resumed run keeps P0 (checkpoint "poses.P0").
  auto cams = nlohmann::json::parse(read_file_bytes(out + "/cameras.json", 1 << 20));
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 4; ++k)
      CHECK(cams["frames"][1]["transform_matrix"][r][k].get<double>() == Approx(start[1](r, k)).margin(1e-6));
  Trainer back = Trainer::resume(out);
  CHECK(back.state().poses_P0 == P0);
  CHECK(learned(back) == start);
  // Its cameras.json, read back as --init-poses, gives the same cameras (already in the frame).
  Trainer again(tiny(data, out + "/cameras.json"));
  const auto s2 = learned(again);
  // recentred on the train cameras' average: compare relative poses.
  const Eigen::Matrix4d A = to4(start[0]) * to4(s2[0]).inverse();
  for (size_t i = 0; i < s2.size(); ++i)
    CHECK(hashcc::test::max_abs_entry((A * to4(s2[i])).topRows<3>() - start[i]) < 1e-5);

  // Refined: the same step moves the deltas.
  TrainConfig cr = tiny(data, js);
  Trainer tr(cr);
  tr.step_once();
  double moved = 0;
  for (float v : tr.state().poses) moved += std::abs(v);
  CHECK(moved > 0);
}

// Judged by the formulas.md §7 relative rotation error (alignment-free; the Sim(3) fit on 7 nearby
// centres is ill-conditioned in a short run, and the centres themselves — weakly constrained in
// NDC — drift by about the perturbation). Tagged [e2e]: CTest runs it once, at 2 threads.
TEST_CASE("init poses: refining perturbed ground-truth cameras reduces their error",
          "[initposes][e2e]") {
  const std::string data = train_scene();
  const Scene ref = load_scene(data, {"", false});
  const std::vector<Mat34d> pert = perturbed(ref.ref_c2w, 3.0, 0.05);
  const std::string js = tmp("perturbed_cameras.json");
  // Written with the "ndc" key: already in the formulas.md §7 frame, as a hashcc run writes them.
  write_cameras_json_file(js, ref.names, pert, ref.ref_focal, ref.ref_focal, ref.width, ref.height);
  auto j = nlohmann::json::parse(read_file_bytes(js, 1 << 20));
  j["ndc"] = true;
  write_text(js, j.dump());

  TrainConfig c = tiny(data, js);
  c.model.width = 64;
  c.model.rgb_width = 32;
  c.rays = 256;
  c.samples = 32;
  c.steps = 700;  // ~15 s unloaded, ~40 s on 2 shared cores
  c.lr_pose = 1e-3;
  c.lr_pose_end = 1e-6;
  Trainer t(c);
  std::vector<Mat34d> gt;
  for (int i : t.scene().train) gt.push_back(ref.ref_c2w[i]);
  const double before = relative_rotation_error(learned(t), gt).mean_deg;
  const PoseErrors pe_before = align_and_score(learned(t), gt);
  REQUIRE(t.run());
  const double after = relative_rotation_error(learned(t), gt).mean_deg;
  const PoseErrors pe_after = align_and_score(learned(t), gt);
  WARN(fmt::format("relative rotation error {:.3f}° → {:.3f}°; Sim(3) ΔR {:.3f}° → {:.3f}°, "
                   "ΔT {:.4f} → {:.4f}", before, after, pe_before.mean_dR_deg,
                   pe_after.mean_dR_deg, pe_before.mean_dT, pe_after.mean_dT));
  // Refinement must remove at least half of the relative rotation error it removed when
  // measured (Release, AVX-512, Zen 4: 4.343° → 3.169° at 2 threads, → 3.216° at 1 thread, a
  // 26–27% gain): after < (1 − 0.26/2)·before. The former bound, 5%, passed a refinement that
  // barely moved the cameras.
  CHECK(after < (1 - 0.26 / 2) * before);
}
