// test/test_render.cpp — hashcc render / export: the COLMAP convention round trip, the NDC-depth
// inverse, scaled renders, the spiral path, and the point cloud against the simulator's analytic
// surfaces. Formulas: docs/render.md.
#include <catch2/catch.hpp>

#include "test/fixtures.h"

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <fmt/format.h>

#include "core/image.h"
#include "core/llff.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "outputs/export.h"
#include "outputs/paths.h"
#include "train/trainer.h"
#include "tools/cli.h"
#include "tools/simulator.h"
#include "test/gradcheck.h"

namespace fs = std::filesystem;
using namespace hashcc;
using Eigen::Vector3d;

using hashcc::test::cli;
using hashcc::test::sim_scene;
using hashcc::test::tmp;

namespace {


// A test-side COLMAP reader, written from COLMAP's documentation (not from outputs/export.cpp):
// images.txt lines "ID QW QX QY QZ TX TY TZ CAM NAME" then a 2D-points line; '#' comments.
struct ParsedImage { int id, cam; double q[4], t[3]; std::string name; };
std::vector<ParsedImage> parse_images_txt(const std::string& path, int* lines_after = nullptr) {
  std::ifstream f(path);
  std::vector<ParsedImage> out;
  std::string line;
  bool expect_points = false;
  int points_lines = 0;
  while (std::getline(f, line)) {
    if (!line.empty() && line[0] == '#') continue;
    if (expect_points) { ++points_lines; expect_points = false; REQUIRE(line.empty()); continue; }
    if (line.empty()) continue;
    std::istringstream s(line);
    ParsedImage im;
    s >> im.id >> im.q[0] >> im.q[1] >> im.q[2] >> im.q[3] >> im.t[0] >> im.t[1] >> im.t[2] >>
        im.cam >> im.name;
    REQUIRE(!s.fail());
    out.push_back(im);
    expect_points = true;
  }
  if (lines_after) *lines_after = points_lines;
  return out;
}

// OpenGL camera-to-world from a COLMAP (OpenCV world-to-camera) pose, by hand.
Mat34d c2w_gl_from_parsed(const ParsedImage& im) {
  const double w = im.q[0], x = im.q[1], y = im.q[2], z = im.q[3];
  Eigen::Matrix3d R;  // unit quaternion → rotation (Hamilton, as COLMAP)
  R << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
       2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
       2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  Eigen::Matrix3d Rc2w_cv = R.transpose();
  Vector3d centre = -Rc2w_cv * Vector3d(im.t[0], im.t[1], im.t[2]);
  Mat34d m;
  m.col(0) = Rc2w_cv.col(0);    // right
  m.col(1) = -Rc2w_cv.col(1);   // up = −down
  m.col(2) = -Rc2w_cv.col(2);   // back = −forward
  m.col(3) = centre;
  return m;
}

}  // namespace

TEST_CASE("export: COLMAP text model of known cameras reads back to the same poses", "[render]") {
  SimOptions so;
  std::vector<Mat34d> poses;
  std::vector<std::string> names;
  for (auto& c : make_sim_rig(so)) {
    poses.push_back(c.c2w);
    names.push_back(fmt::format("image{:03d}.png", names.size()));
  }
  // Also a few arbitrary poses, including ones turned by ~π (q_w ≈ 0: quaternion sign cases).
  Rng rng(5, 1);
  for (int k = 0; k < 6; ++k) {
    Vector3d r(rng.normal(), rng.normal(), rng.normal());
    if (k < 2) r = r.normalized() * (M_PI - 1e-9 * k);
    Mat34d m;
    m.leftCols<3>() = so3::exp<double>(r);
    m.col(3) = Vector3d(rng.normal(), rng.normal(), rng.normal()) * 3;
    poses.push_back(m);
    names.push_back(fmt::format("extra{}.jpg", k));
  }
  const ImageSize sz{128, 96};
  FocalParams<float> f;
  f.a = 0.9f; f.b = 1.1f;
  const std::string dir = tmp("colmap", true);
  write_colmap_text(dir, colmap_camera(f, sz), poses, names, nullptr);

  int points_lines = 0;
  auto parsed = parse_images_txt(dir + "/images.txt", &points_lines);
  REQUIRE(parsed.size() == poses.size());
  CHECK(points_lines == int(poses.size()));
  double worst = 0;
  for (size_t i = 0; i < poses.size(); ++i) {
    CHECK(parsed[i].id == int(i + 1));
    CHECK(parsed[i].cam == 1);
    CHECK(parsed[i].name == names[i]);
    CHECK(parsed[i].q[0] >= 0);
    hashcc::test::keep_worst(worst, hashcc::test::max_abs_entry(c2w_gl_from_parsed(parsed[i]) - poses[i]));
    // Convention, independently: a point 2 units in front of the camera and 1 to its right and
    // 1 above has COLMAP camera coordinates (x > 0, y < 0, z = 2).
    const Mat34d& P = poses[i];
    Vector3d X = P.col(3) - 2 * P.col(2) + P.col(0) + P.col(1);
    Eigen::Quaterniond q(parsed[i].q[0], parsed[i].q[1], parsed[i].q[2], parsed[i].q[3]);
    Vector3d xc = q.toRotationMatrix() * X + Vector3d(parsed[i].t[0], parsed[i].t[1], parsed[i].t[2]);
    CHECK(std::abs(xc.x() - 1) < 1e-9);
    CHECK(std::abs(xc.y() + 1) < 1e-9);
    CHECK(std::abs(xc.z() - 2) < 1e-9);
  }
  INFO("worst |c2w − read back| = " << worst);
  CHECK(worst < 1e-9);
  // The library's own inverse agrees too.
  for (auto& P : poses) CHECK(hashcc::test::max_abs_entry(c2w_from_colmap(colmap_from_c2w(P)) - P) < 1e-12);

  // cameras.txt: one PINHOLE camera, fx = a²W, fy = b²H, principal point W/2 + 0.5 (COLMAP's
  // pixel centres are at +0.5, ours at integers).
  std::ifstream cf(dir + "/cameras.txt");
  std::string line, model;
  int ncam = 0, id, W, H;
  double fx, fy, cx, cy;
  while (std::getline(cf, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    s >> id >> model >> W >> H >> fx >> fy >> cx >> cy;
    ++ncam;
  }
  CHECK(ncam == 1);
  CHECK(model == "PINHOLE");
  CHECK(W == 128);
  CHECK(H == 96);
  CHECK(fx == Approx(double(0.9f) * double(0.9f) * 128).epsilon(1e-12));
  CHECK(fy == Approx(double(1.1f) * double(1.1f) * 96).epsilon(1e-12));
  CHECK(cx == 64.5);
  CHECK(cy == 48.5);
  // points3D.txt: header only.
  std::ifstream pf(dir + "/points3D.txt");
  int data_lines = 0;
  while (std::getline(pf, line)) if (!line.empty() && line[0] != '#') ++data_lines;
  CHECK(data_lines == 0);
}

TEST_CASE("NDC depth → world point inverts formulas.md §2's forward map", "[render]") {
  Rng rng(11, 2);
  const ImageSize sz{100, 80};
  const double fx = 93.0, fy = 71.0;
  const double sx = fx / (sz.W / 2.0), sy = fy / (sz.H / 2.0);
  double worst = 0, worst_line = 0;
  for (int k = 0; k < 200; ++k) {
    Vector3d o(0.3 * rng.normal(), 0.3 * rng.normal(), 0.2 * rng.uniform(-1, 1));
    Vector3d d(0.4 * rng.normal(), 0.4 * rng.normal(), -1);
    d *= rng.uniform(0.5, 2.0);  // unnormalised, as rays_forward gives
    // A world point on the ray beyond the near plane: X_z ∈ (−1, −60).
    const double Xz = -1.0 - rng.uniform(1e-3, 60);
    const Vector3d X = o + ((Xz - o.z()) / d.z()) * d;
    // Forward: the ray's NDC (o', d') and the NDC projection of X.
    double on[3], dn[3];
    ndc_forward<double>(on, dn, o.data(), d.data(), 1, fx, fy, sz);
    const Vector3d op(on[0], on[1], on[2]), dp(dn[0], dn[1], dn[2]);
    const Vector3d x_ndc(-sx * X.x() / X.z(), -sy * X.y() / X.z(), 1 + 2 / X.z());
    const double s = (x_ndc.z() - op.z()) / dp.z();
    hashcc::test::keep_worst(worst_line, (op + s * dp - x_ndc).norm());  // X's image is on the NDC ray
    CHECK(std::abs(world_to_ndc_depth(o, d, X) - s) < 1e-12);
    const Vector3d back = ndc_depth_to_world(o, d, s);
    hashcc::test::keep_worst(worst, (back - X).norm() / std::max(1.0, X.norm()));
  }
  INFO("worst relative |X − inverse(forward(X))| = " << worst << ", NDC line " << worst_line);
  CHECK(worst < 1e-9);
  CHECK(worst_line < 1e-9);
  // s = 0 is the near plane, s = 1/2 is z = −2.
  CHECK(ndc_depth_to_world(Vector3d(0, 0, 0), Vector3d(0.1, 0.2, -1), 0.0).z() == Approx(-1).margin(1e-15));
  CHECK(ndc_depth_to_world(Vector3d(0, 0, 0), Vector3d(0.1, 0.2, -1), 0.5).z() == Approx(-2).margin(1e-15));
  // Without NDC, s is the ray parameter.
  CHECK((ndc_depth_to_world(Vector3d(1, 2, 3), Vector3d(0, 0, -1), 0.25, false) - Vector3d(1, 2, 2.75)).norm() < 1e-15);
}

TEST_CASE("render: a scaled image keeps the intrinsics (pixel u of scale s ≡ u/s at full size)", "[render]") {
  // ImageSize{W·s, H·s} with the same a, b: fx' = a²W·s, cx' = W·s/2.
  PoseParams<double> pose;
  pose.r = Vector3d(0.05, -0.1, 0.02);
  pose.t = Vector3d(0.1, 0.0, -0.05);
  FocalParams<double> f;
  f.a = 0.93; f.b = 1.07;
  const ImageSize full{120, 90}, half{60, 45};
  double worst = 0;
  for (bool ndc : {false, true})
    for (int v = 0; v < half.H; v += 7)
      for (int u = 0; u < half.W; u += 5) {
        int ph[2] = {u, v}, pf[2] = {2 * u, 2 * v};
        double oh[3], dh[3], of[3], df[3];
        camera_rays_forward<double>(oh, dh, ph, 1, pose, f, half, ndc);
        camera_rays_forward<double>(of, df, pf, 1, pose, f, full, ndc);
        for (int k = 0; k < 3; ++k)
          for (double e : {std::abs(oh[k] - of[k]), std::abs(dh[k] - df[k])}) hashcc::test::keep_worst(worst, e);
      }
  CHECK(worst < 1e-12);
}

TEST_CASE("render/export CLI: half-size frames, poses.json, COLMAP and PLY from a run", "[render]") {
  const std::string data = sim_scene("cli", 6, 40, 30);
  const std::string run = tmp("cli_run", true);
  {
    TrainConfig c = test::tiny_train_config(data, run, 3);
    Trainer t(c);
    REQUIRE(t.run());
  }
  const std::string out = tmp("cli_frames", true);
  REQUIRE(cli({"render", "--run", run, "--out", out, "--path", "train", "--frames", "2", "--scale",
               "0.5", "--no-progress"}) == 0);
  for (int i = 0; i < 2; ++i)
    for (auto suffix : {"_rgb.png", "_depth.png", "_opacity.png"}) {
      int w = 0, h = 0;
      image_size(fmt::format("{}/{:04d}{}", out, i, suffix), &w, &h);
      CHECK(w == 20);
      CHECK(h == 15);
    }
  CHECK(fs::exists(out + "/0000_depth.exr"));
  CHECK_FALSE(fs::exists(out + "/0002_rgb.png"));
  CHECK(fs::exists(out + "/contact_sheet.png"));
  CHECK(fs::exists(out + "/poses.json"));
  // test path: the simulated scene has reference cameras for its test images (0 of 6).
  REQUIRE(cli({"render", "--run", run, "--out", out + "_test", "--path", "test", "--no-progress"}) == 0);
  CHECK(fs::exists(out + "_test/0000_rgb.png"));
  // Export: every pixel (threshold 0) of every training view, and the COLMAP model.
  const std::string col = tmp("cli_colmap", true);
  REQUIRE(cli({"export", "--run", run, "--colmap", col, "--ply", col + "/cloud.ply",
               "--opacity-threshold", "0", "--stride", "5", "--no-progress"}) == 0);
  auto parsed = parse_images_txt(col + "/images.txt");
  CHECK(parsed.size() == 5);  // 6 images, image 0 is the test image
  std::ifstream ply(col + "/cloud.ply", std::ios::binary);
  std::string l1, l2, l3;
  std::getline(ply, l1);
  std::getline(ply, l2);
  std::getline(ply, l3);
  std::getline(ply, l3);
  CHECK(l1 == "ply");
  CHECK(l2 == "format binary_little_endian 1.0");
  CHECK(l3 == fmt::format("element vertex {}", 5 * 8 * 6));  // ⌈40/5⌉ × ⌈30/5⌉ per view
  // No run folder: a clear error (exit 2).
  CHECK(cli({"export", "--run", tmp("nonexistent", true), "--ply", "x.ply"}) == 2);
}

TEST_CASE("spiral: N orthonormal poses around the average camera, each looking at the focus", "[render]") {
  const std::string data = sim_scene("cli", 6, 40, 30);
  Scene sc = load_scene(data, {"", false});
  SpiralOptions so;
  so.frames = 40;
  SpiralInfo info;
  auto path = spiral_path(sc.ref_c2w, 1.2, 30.0, so, &info);
  REQUIRE(path.size() == 40);
  CHECK(info.focus == Approx(1.0 / (0.25 / 1.2 + 0.75 / 30.0)));
  const Eigen::Matrix3d Ra = info.average.leftCols<3>();
  const Vector3d focus_pt = info.average.col(3) - info.focus * Ra.col(2);
  double worst_ortho = 0, worst_angle = 0;
  for (auto& P : path) {
    const Eigen::Matrix3d R = P.leftCols<3>();
    hashcc::test::keep_worst(worst_ortho, hashcc::test::max_abs_entry(R.transpose() * R - Eigen::Matrix3d::Identity()));
    CHECK(R.determinant() == Approx(1).margin(1e-12));
    const Vector3d to_focus = (focus_pt - P.col(3)).normalized();
    hashcc::test::keep_worst(worst_angle, std::atan2(to_focus.cross(-R.col(2)).norm(), to_focus.dot(-R.col(2))));
    // The centre stays inside the box of radii around the average pose.
    const Vector3d local = Ra.transpose() * (P.col(3) - info.average.col(3));
    for (int k = 0; k < 3; ++k) CHECK(std::abs(local[k]) <= info.radii[k] + 1e-12);
  }
  CHECK(worst_ortho < 1e-12);
  CHECK(worst_angle < 1e-9);
  // Two rotations: frame N/2 is back at θ = 2π (same x, y offset as frame 0).
  const Vector3d l0 = Ra.transpose() * (path[0].col(3) - info.average.col(3));
  const Vector3d l20 = Ra.transpose() * (path[20].col(3) - info.average.col(3));
  CHECK(std::abs(l0.x() - l20.x()) < 1e-12);
  CHECK(std::abs(l0.y() - l20.y()) < 1e-12);
  CHECK(info.radii.minCoeff() > 0);
}

namespace {

// Simulated scene + a Trainer whose cameras are set to the TRUE cameras in the learned frame
// (the loader's centred, scaled reference poses) and whose focal is the true focal.
struct TrueCamRig {
  SimOptions so;
  SimScene scene;
  Eigen::Matrix4d A;  // scaled world from learned (centred) frame: the average pose
  double scale = 1;
  // learned-frame point → original simulator world
  Vector3d to_sim(const Vector3d& X) const { return (A.topLeftCorner<3, 3>() * X + A.topRightCorner<3, 1>()) / scale; }
};

TrueCamRig set_true_cameras(Trainer& t, const SimOptions& so) {
  const Scene& sc = t.scene();
  TrueCamRig rig;
  rig.so = so;
  rig.scene = make_sim_scene(so);
  std::vector<Mat34d> scaled = sc.ref_c2w_raw;
  for (auto& p : scaled) p.col(3) *= sc.scale;
  rig.A = to4(average_pose(scaled));
  rig.scale = sc.scale;
  for (size_t i = 0; i < sc.train.size(); ++i) {
    PoseParams<float> p = pose_params_from_c2w(sc.ref_c2w[sc.train[i]]);
    float* v = t.mutable_state().poses.data() + 6 * i;
    for (int k = 0; k < 3; ++k) { v[k] = p.r[k]; v[3 + k] = p.t[k]; }
  }
  t.mutable_state().focal[0] = float(std::sqrt(sc.ref_focal / sc.width));
  t.mutable_state().focal[1] = float(std::sqrt(sc.ref_focal / sc.height));
  return rig;
}

TrainConfig small_config(const std::string& data) {
  return test::tiny_train_config(data, "", 10);
}

}  // namespace

TEST_CASE("point cloud: true NDC depth of the simulated scene lands on its surfaces", "[render]") {
  const std::string data = sim_scene("cloud", 9, 64, 48);
  SimOptions so;
  so.views = 9; so.width = 64; so.height = 48;
  Trainer t(small_config(data));
  TrueCamRig rig = set_true_cameras(t, so);
  const ImageSize sz = t.image_size();
  const Eigen::Matrix3d RA = rig.A.topLeftCorner<3, 3>();
  PointCloud cloud;
  int64_t pixels = 0, hits = 0;
  for (size_t i = 0; i < t.scene().train.size(); ++i) {
    const PoseParams<float> pose = t.pose_of(int(i));
    // The true expected NDC depth per pixel, by exact ray tracing; opacity 1 on hits, 0 on misses,
    // and 0.7 with depth 0.7·s on every third pixel (partial opacity: s̄ = depth/opacity).
    std::vector<float> depth(sz.W * sz.H), opacity(sz.W * sz.H), rgb(sz.W * sz.H * 3, 0.5f);
    PoseParams<double> pd;
    pd.r = pose.r.cast<double>();
    pd.t = pose.t.cast<double>();
    FocalParams<double> fd;
    fd.a = t.focal().a; fd.b = t.focal().b;
    for (int v = 0; v < sz.H; ++v)
      for (int u = 0; u < sz.W; ++u) {
        int px[2] = {u, v};
        double o[3], d[3];
        rays_forward<double>(o, d, px, 1, pd, fd, sz);
        const Vector3d O(o[0], o[1], o[2]), D(d[0], d[1], d[2]);
        const double tt = rig.scene.trace(rig.to_sim(O), RA * D / rig.scale, nullptr);
        const size_t k = size_t(v) * sz.W + u;
        ++pixels;
        if (tt <= 0) continue;
        ++hits;
        const double s = world_to_ndc_depth(O, D, O + tt * D);
        const float op = (k % 3 == 0) ? 0.7f : 1.0f;
        opacity[k] = op;
        depth[k] = float(op * s);
      }
    ViewImage view;
    view.width = sz.W;
    view.height = sz.H;
    view.depth = depth;
    view.opacity = opacity;
    view.rgb = rgb;
    append_view_points(cloud, {pose, t.focal(), sz, true}, 1, view, 0.5);
  }
  REQUIRE(hits > pixels / 2);
  CHECK(int64_t(cloud.size()) == hits);
  double sum = 0, worst = 0;
  for (auto& X : cloud.xyz) {
    const double e = rig.scene.surface_distance(rig.to_sim(X));
    sum += e;
    hashcc::test::keep_worst(worst, e);
  }
  const double mean = sum / double(cloud.size());
  INFO("points " << cloud.size() << ", mean distance " << mean << ", worst " << worst
                 << " (scene depth 2..8 units)");
  // Float depth (24-bit mantissa) through X_z = 1/(s − 1): errors ~1e-6 of the depth.
  CHECK(mean < 1e-4);
  CHECK(worst < 1e-3);
}

// No [e2e] point-cloud test of a trained network: on the 2 shared cores a ≤ 60 s run reaches a
// few hundred small steps, whose density has not formed yet (rays end on the last sample, far
// behind the scene: mean distance 10-20 units after 13-400 steps); docs/render.md.

TEST_CASE("training-view depths: a camera split into P0 and a delta gives the same depths",
          "[render][initposes]") {
  // Run A starts from the scene's own cameras as fixed P0 (--init-poses, delta 0); run B holds
  // the same cameras in its learned parameters (r = log R, t = centre). Same seed, same fresh
  // networks: the rendered depths must agree. (Before the fix, P0 was dropped when a depth
  // was taken back to the camera frame, so A's depths were measured from the wrong camera.)
  const std::string data = sim_scene("cli", 6, 40, 30);
  TrainConfig ca = test::tiny_train_config(data, "", 1);
  ca.init_poses = data + "/poses_bounds.npy";
  ca.refine_poses = false;
  Trainer a(ca);
  TrainConfig cb = test::tiny_train_config(data, "", 1);
  Trainer b(cb);
  REQUIRE(a.state().net == b.state().net);
  TrainState& sb = b.mutable_state();
  for (int i = 0; i < int(a.scene().train.size()); ++i) {
    const Mat34<double> c2w = world_from_camera(a.pose_of(i).cast<double>());
    const Mat3<double> R = c2w.leftCols<3>();
    const Vec3<double> r = so3::log<double>(R);
    for (int k = 0; k < 3; ++k) {
      sb.poses[6 * i + k] = float(r[k]);
      sb.poses[6 * i + 3 + k] = float(c2w(k, 3));
    }
  }
  sb.focal = a.state().focal;
  const std::vector<double> za = training_view_depths(a, 4096, 1e-3, nullptr);
  const std::vector<double> zb = training_view_depths(b, 4096, 1e-3, nullptr);
  REQUIRE(za.size() == zb.size());
  REQUIRE(za.size() > 100);
  double worst = 0;
  for (size_t k = 0; k < za.size(); ++k)
    hashcc::test::keep_worst(worst, std::abs(za[k] - zb[k]) / std::max(1e-6, std::abs(zb[k])));
  CHECK(worst < 1e-3);
}
