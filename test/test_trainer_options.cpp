// The training options beyond the paper (issue 13), each off by default:
//   --images-per-step K   the K chosen cameras (and only they) get a gradient, which matches
//                         central differences in double; K = 1 is the paper's step, bitwise.
#include <catch2/catch.hpp>

#include "test/fixtures.h"

#include <filesystem>
#include <nlohmann/json.hpp>
#include <numeric>
#include <set>

#include "camera/camera.h"
#include "core/error.h"
#include "model/trainer.h"
#include "test/gradcheck.h"
#include "tools/simulator.h"

namespace fs = std::filesystem;
using namespace hashcc;
using hashcc::test::rel_err;

namespace {

std::string sim_scene(const std::string& name, int views, int w, int h) {
  std::string d = (fs::temp_directory_path() / ("hashcc_opt_" + name)).string();
  if (fs::exists(d + "/poses_bounds.npy")) return d;
  SimOptions o;
  o.views = views;
  o.width = w;
  o.height = h;
  write_sim_scene(d, o, false);
  return d;
}

// 10 views: 8 training images (0 and 8 are held out), 40 × 30.
std::string eight_train_scene() { return sim_scene("k8", 10, 40, 30); }

// The paper's step as it was written before the options (one image, its 32 × 32-style grid,
// then the jitter), spelled out independently of Trainer::step_once: loss, camera gradient and
// image of the step the trainer is about to take.
struct PaperStep {
  double loss = 0;
  float d_pose[6] = {0}, d_focal[2] = {0};
  int image = -1;
};
PaperStep paper_step(const Trainer& t) {
  const TrainConfig& c = t.config();
  const Scene& sc = t.scene();
  const int64_t step = t.state().step;
  const int n = int(sc.train.size());
  std::vector<int> perm(n);
  std::iota(perm.begin(), perm.end(), 0);
  Rng prng(c.seed, 0x100000000ULL + uint64_t(step / n));
  for (int i = n - 1; i > 0; --i) std::swap(perm[i], perm[prng.below(uint32_t(i + 1))]);
  PaperStep out;
  out.image = perm[step % n];
  const ImageU8& img = sc.images[sc.train[out.image]];
  const int rows = c.grid_rows(), cols = c.grid_cols(), R = rows * cols, S = c.samples;
  Rng rng(c.seed ^ 0x9E3779B97F4A7C15ULL, uint64_t(step));
  auto pick = [&](int N, int K) {
    std::vector<int> idx(N);
    std::iota(idx.begin(), idx.end(), 0);
    for (int j = 0; j < K; ++j) std::swap(idx[j], idx[j + rng.below(uint32_t(N - j))]);
    return idx;
  };
  const std::vector<int> rsel = pick(sc.height, rows), csel = pick(sc.width, cols);
  std::vector<int> px(2 * R);
  std::vector<float> target(3 * R), o(3 * R), d(3 * R), s(int64_t(R) * S), d_o(3 * R), d_d(3 * R);
  for (int a = 0; a < rows; ++a)
    for (int b = 0; b < cols; ++b) {
      const int k = a * cols + b;
      px[2 * k] = csel[b];
      px[2 * k + 1] = rsel[a];
      for (int ch = 0; ch < 3; ++ch) target[3 * k + ch] = img.at(rsel[a], csel[b], ch);
    }
  const PoseParams<float> pose = t.pose_of(out.image);
  camera_rays_forward(o.data(), d.data(), px.data(), R, pose, t.focal(), t.image_size(), c.ndc);
  for (int r = 0; r < R; ++r)
    for (int k = 0; k < S; ++k) s[int64_t(r) * S + k] = float((k + rng.uniform()) / S);
  StepWorkspace<float> ws;
  std::vector<float> d_net(t.layout().count, 0.f);
  StepOptions opt;
  opt.chunk_rays = c.chunk_rays;
  out.loss = ray_batch_step(ws, t.state().net.data(), d_net.data(), c.model, t.layout(), o.data(),
                            d.data(), s.data(), target.data(), R, S, opt, (float*)nullptr,
                            (float*)nullptr, (float*)nullptr, (float*)nullptr, d_o.data(),
                            d_d.data()).loss;
  camera_rays_backward(out.d_pose, out.d_focal, d_o.data(), d_d.data(), px.data(), R, pose,
                       t.focal(), t.image_size(), c.ndc);
  return out;
}

}  // namespace

// ---------------------------------------------------------------- --images-per-step K

TEST_CASE("images per step: exactly the K chosen cameras get a pose gradient", "[trainer]") {
  const std::string data = eight_train_scene();
  TrainConfig c = test::tiny_train_config(data, "", 4);
  c.images_per_step = 4;  // 64 rays: a 4 × 4 grid on each of 4 images
  Trainer t(c);
  REQUIRE(t.scene().train.size() == 8);
  CHECK(t.steps_per_epoch() == 2);
  t.step_once();
  REQUIRE(t.last_cameras.size() == 4);
  CHECK(t.last_rays().R == 64);
  std::set<int> chosen;
  for (const auto& g : t.last_cameras) {
    chosen.insert(g.image);
    double norm = 0;
    for (float v : g.d_pose) norm += std::abs(v);
    CHECK(norm > 0);
  }
  CHECK(chosen.size() == 4);  // distinct
  CHECK(t.last_image == t.last_cameras[0].image);
  // The assembled gradient of the pose group: Adam's first step from zero moments moves exactly
  // the cameras whose gradient is non-zero, and leaves every other one bitwise at 0.
  const TrainState& st = t.state();
  for (int i = 0; i < 8; ++i) {
    double moved = 0, moments = 0;
    for (int k = 0; k < 6; ++k) {
      moved += std::abs(st.poses[6 * i + k]);
      moments += std::abs(st.poses_m[6 * i + k]) + std::abs(st.poses_v[6 * i + k]);
    }
    INFO("training image " << i);
    if (chosen.count(i)) {
      CHECK(moved > 0);
    } else {
      CHECK(moved == 0);
      CHECK(moments == 0);
    }
  }
  // An epoch (2 steps) visits every training image once.
  std::set<int> epoch;
  int imgs[4];
  for (int64_t s = 0; s < 2; ++s) {
    t.images_for_step(s, imgs);
    epoch.insert(imgs, imgs + 4);
  }
  CHECK(epoch.size() == 8);
  // K = 3 does not divide 8: an epoch is 3 steps, the last wraps to the permutation's head
  // (positions 6, 7, 0), still distinct images, and the epoch still covers all 8.
  TrainConfig c3 = test::tiny_train_config(data, "", 4);
  c3.rays = 48;
  c3.images_per_step = 3;
  Trainer t3(c3);
  CHECK(t3.steps_per_epoch() == 3);
  std::set<int> epoch3;
  int first[3];
  t3.images_for_step(0, first);
  for (int64_t s = 0; s < 3; ++s) {
    t3.images_for_step(s, imgs);
    CHECK(std::set<int>(imgs, imgs + 3).size() == 3);
    epoch3.insert(imgs, imgs + 3);
  }
  CHECK(epoch3.size() == 8);
  CHECK(imgs[2] == first[0]);  // step 2's third image is position 0 again
}

TEST_CASE("images per step: K = 1 is the paper's step, bitwise", "[trainer]") {
  const std::string data = eight_train_scene();
  TrainConfig c = test::tiny_train_config(data, "", 6);
  c.images_per_step = 1;
  Trainer t(c);
  for (int k = 0; k < 4; ++k) {
    const PaperStep ref = paper_step(t);
    const StepResult<float> r = t.step_once();
    INFO("step " << k);
    CHECK(t.last_image == ref.image);
    CHECK(r.loss == ref.loss);
    for (int j = 0; j < 6; ++j) CHECK(t.last_d_pose[j] == ref.d_pose[j]);
    for (int j = 0; j < 2; ++j) CHECK(t.last_d_focal[j] == ref.d_focal[j]);
  }
  // A config without the new keys (an older config.json) is the same run, bitwise.
  nlohmann::json j = nlohmann::json::parse(train_config_json(c));
  for (const char* key : {"images_per_step"}) {
    REQUIRE(j.contains(key));
    j.erase(key);
  }
  Trainer old(train_config_from_json(j.dump(), "old.json"));
  for (int k = 0; k < 4; ++k) old.step_once();
  CHECK(old.state().net == t.state().net);
  CHECK(old.state().poses == t.state().poses);
  CHECK(old.state().focal == t.state().focal);
}

TEST_CASE("images per step: the K camera gradients match central differences (double)",
          "[trainer][grad]") {
  // The trainer's float step on K = 4 images, then the same rays (its pixels, targets, jitter
  // and parameters) through the camera → model chain in double, as the whole-step camera check
  // of test_model.cpp: dL/d[r t] of each of the 4 cameras and dL/d[a b] (summed over the
  // segments) against central differences of the mean loss over all 64 rays. Model sh (the
  // camera check of hashcc needs the CC input held fixed; test_model.cpp covers that).
  const std::string data = eight_train_scene();
  TrainConfig c = test::tiny_train_config(data, "", 8);
  c.images_per_step = 4;
  c.model.variant = Variant::sh;
  Trainer t(c);
  for (int k = 0; k < 2; ++k) t.step_once();  // cameras off the identity
  const TrainState before = t.state();
  t.step_once();
  const Trainer::StepRays rays = t.last_rays();
  const int K = 4, R = rays.R, Rk = R / K, S = c.samples;
  REQUIRE(R == 64);
  const ModelConfig& cfg = t.config().model;
  const ModelLayout& L = t.layout();
  const std::vector<double> p(before.net.begin(), before.net.end());
  const std::vector<double> s(rays.s, rays.s + int64_t(R) * S),
      target(rays.target, rays.target + 3 * R);
  // cam = [r t of camera 0, …, r t of camera 3, a, b] at the parameters the step used.
  std::vector<double> cam;
  for (const auto& g : t.last_cameras)
    for (int k = 0; k < 6; ++k) cam.push_back(before.poses[6 * g.image + k]);
  cam.push_back(before.focal[0]);
  cam.push_back(before.focal[1]);
  StepWorkspace<double> ws;
  auto loss = [&](const std::vector<double>& th, std::vector<double>* grad) {
    FocalParams<double> f;
    f.a = th[6 * K];
    f.b = th[6 * K + 1];
    std::vector<double> o(3 * R), d(3 * R), d_o(3 * R), d_d(3 * R);
    auto pose = [&](int j) {
      PoseParams<double> q;
      q.r = Vec3<double>(th[6 * j], th[6 * j + 1], th[6 * j + 2]);
      q.t = Vec3<double>(th[6 * j + 3], th[6 * j + 4], th[6 * j + 5]);
      return q;
    };
    for (int j = 0; j < K; ++j)
      camera_rays_forward(o.data() + 3 * j * Rk, d.data() + 3 * j * Rk, rays.px + 2 * j * Rk, Rk,
                          pose(j), f, t.image_size(), true);
    StepOptions opt;
    opt.chunk_rays = 1024;
    opt.data_parallel = false;  // one chunk on ws: the kink detector reads its cache
    const double l = ray_batch_step(ws, p.data(), (double*)nullptr, cfg, L, o.data(), d.data(),
                                    s.data(), target.data(), R, S, opt, (double*)nullptr,
                                    (double*)nullptr, (double*)nullptr, (double*)nullptr,
                                    d_o.data(), d_d.data()).loss;
    if (grad) {
      grad->assign(6 * K + 2, 0.0);
      for (int j = 0; j < K; ++j)
        camera_rays_backward(grad->data() + 6 * j, grad->data() + 6 * K, d_o.data() + 3 * j * Rk,
                             d_d.data() + 3 * j * Rk, rays.px + 2 * j * Rk, Rk, pose(j), f,
                             t.image_size(), true);
    }
    return l;
  };
  std::vector<double> g;
  loss(cam, &g);
  // Central differences, symmetric relative error with floor 1e-7, tolerance 1e-5; entries whose
  // ±h flips a ReLU are skipped (at most 2 of 26). Poses: h = 1e-7 (test_model.cpp's kHCam: the
  // numbers of a camera move every ray of its image). Focal: h = 1e-5, because its gradient is
  // the sum of the K segments' shares, which nearly cancel (here ~6e-6 and ~1.5e-7 against
  // ~1e-3 for the poses), so the loss's rounding (~1e-17) over 2h = 2e-7 would be a 3e-4
  // relative error of the smaller one; measured at h = 1e-5: 1.7e-6 (poses: < 1e-6).
  constexpr double h_pose = 1e-7, h_focal = 1e-5, floor = 1e-7, tol = 1e-5;
  loss(cam, nullptr);
  const std::vector<bool> base = test::relu_pattern(ws, cfg);
  double worst = 0;
  int skipped = 0;
  for (size_t i = 0; i < cam.size(); ++i) {
    const double keep = cam[i], h = i < size_t(6 * K) ? h_pose : h_focal;
    cam[i] = keep + h;
    const double lp = loss(cam, nullptr);
    bool same = test::relu_pattern(ws, cfg) == base;
    cam[i] = keep - h;
    const double lm = loss(cam, nullptr);
    same = same && test::relu_pattern(ws, cfg) == base;
    cam[i] = keep;
    if (!same) { ++skipped; continue; }
    worst = std::max(worst, rel_err(g[i], (lp - lm) / (2 * h), floor));
  }
  INFO("worst camera gradient error " << worst << ", skipped " << skipped);
  CHECK(worst < tol);
  CHECK(skipped <= 2);
  // What the trainer applied (float) is this gradient: within float rounding of the largest
  // entry (1e-3, as "model step: float agrees with double").
  double gmax = 0, diff = 0;
  for (int j = 0; j < K; ++j)
    for (int k = 0; k < 6; ++k) {
      gmax = std::max(gmax, std::abs(g[6 * j + k]));
      diff = std::max(diff, std::abs(double(t.last_cameras[j].d_pose[k]) - g[6 * j + k]));
    }
  for (int k = 0; k < 2; ++k) {
    gmax = std::max(gmax, std::abs(g[6 * K + k]));
    diff = std::max(diff, std::abs(double(t.last_d_focal[k]) - g[6 * K + k]));
  }
  INFO("max |g_float − g_double| " << diff << " of max |g| " << gmax);
  CHECK(gmax > 1e-6);
  CHECK(diff < 1e-3 * gmax);
}

TEST_CASE("images per step: bad K is a clear error naming the flag", "[trainer]") {
  const std::string data = eight_train_scene();
  TrainConfig c = test::tiny_train_config(data, "", 4);
  c.images_per_step = 3;  // 64 rays
  REQUIRE_THROWS_WITH(validate_train_config(c), Catch::Contains("--images-per-step") &&
                                                    Catch::Contains("does not divide --rays 64"));
  c.images_per_step = 0;
  REQUIRE_THROWS_WITH(validate_train_config(c), Catch::Contains("--images-per-step"));
  c.images_per_step = 16;  // divides 64, but the scene has 8 training images
  validate_train_config(c);
  REQUIRE_THROWS_WITH(Trainer{c}, Catch::Contains("--images-per-step: 16 is more than the 8 "
                                                  "training images"));
}

TEST_CASE("train config: the options beyond the paper round-trip through JSON", "[trainer]") {
  TrainConfig c;
  c.images_per_step = 4;
  const TrainConfig d = train_config_from_json(train_config_json(c), "config.json");
  CHECK(d.images_per_step == 4);
  CHECK(train_config_json(d) == train_config_json(c));
  nlohmann::json j = nlohmann::json::parse(train_config_json(c));
  j["images_per_step"] = 0;
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"), Catch::Contains("images_per_step"));
}
