// The training options beyond the paper, each off by default:
//   --images-per-step K   the K chosen cameras (and only they) get a gradient, which matches
//                         central differences in double; K = 1 is the paper's step, bitwise;
//   --pyramid F           level-s rays are exactly those of a W/s × H/s camera, the filtered
//                         colours are close to the simulator's own coarse render, the filter
//                         keeps constants and mass, and the level schedule is as documented;
//   --camera-start-psnr P, --camera-warmup N
//                         lr 0 before the trigger, the ramp, the end value, and a resume after
//                         the trigger ends bitwise equal to an uninterrupted run.
#include <catch2/catch.hpp>

#include "test/fixtures.h"

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numeric>
#include <set>
#include <sstream>

#include "camera/camera.h"
#include "core/error.h"
#include "kernels/adam.h"
#include "train/pyramid.h"
#include "train/plan.h"
#include "train/trainer.h"
#include "test/gradcheck.h"
#include "tools/simulator.h"

namespace fs = std::filesystem;
using namespace hashcc;
using hashcc::test::rel_err;

using hashcc::test::sim_scene;

namespace {


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
  out.loss = ray_batch_step(ws, NetView<float>{t.state().net.data(), c.model, t.layout()},
                            {o.data(), d.data(), s.data(), target.data(), R, S}, opt,
                            {d_net.data(), d_o.data(), d_d.data()}).loss;
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
  REQUIRE(t.last_images().size() == 4);
  CHECK(t.last_rays().R == 64);
  std::set<int> chosen;
  for (int j = 0; j < 4; ++j) {
    chosen.insert(t.last_images()[j]);
    double norm = 0;
    for (int k = 0; k < 6; ++k) norm += std::abs(t.last_camera_grads().d_pose[6 * j + k]);
    CHECK(norm > 0);
  }
  CHECK(chosen.size() == 4);  // distinct
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
    CHECK(t.last_images()[0] == ref.image);
    CHECK(r.loss == ref.loss);
    for (int j = 0; j < 6; ++j) CHECK(t.last_camera_grads().d_pose[j] == ref.d_pose[j]);
    for (int j = 0; j < 2; ++j) CHECK(t.last_camera_grads().d_focal[j] == ref.d_focal[j]);
  }
  // A config without the new keys (an older config.json) is the same run, bitwise.
  nlohmann::json j = nlohmann::json::parse(train_config_json(c));
  for (const char* key : {"images_per_step", "pyramid", "camera_start_psnr", "camera_warmup"}) {
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
  for (int image : t.last_images())
    for (int k = 0; k < 6; ++k) cam.push_back(before.poses[6 * image + k]);
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
    const double l = ray_batch_step(ws, NetView<double>{p.data(), cfg, L},
                                    {o.data(), d.data(), s.data(), target.data(), R, S}, opt,
                                    {nullptr, d_o.data(), d_d.data()}).loss;
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
  // Central differences, symmetric relative error with floor 1e-7. Poses: h = 1e-7 (test_model.cpp's
  // kHCam: the numbers of a camera move every ray of its image). Focal: h = 1e-5, because its
  // gradient is the sum of the K segments' shares, which nearly cancel (~2e-6 against ~1e-3 for
  // the poses), so the loss's rounding (~1e-17) over 2h = 2e-7 would be a 3e-4 relative error.
  // Tolerance 1e-5 (measured ≤ 1.1e-6). Entries whose ±h flips a ReLU of the tiny network (any
  // of its ~140k) carry an extra O(h) error: test_model.cpp skips them; here, with 6 numbers
  // per camera moving all of its rays at once, they are held to 1e-4 instead (measured: 5 of 26
  // straddle a kink, worst 4.5e-6), so every entry is checked.
  constexpr double h_pose = 1e-7, h_focal = 1e-5, floor = 1e-7, tol = 1e-5, tol_kink = 1e-4;
  loss(cam, nullptr);
  const std::vector<bool> base = test::relu_pattern(ws, cfg);
  double worst = 0, worst_kink = 0;
  int kinks = 0;
  for (size_t i = 0; i < cam.size(); ++i) {
    const double keep = cam[i], h = i < size_t(6 * K) ? h_pose : h_focal;
    cam[i] = keep + h;
    const double lp = loss(cam, nullptr);
    bool same = test::relu_pattern(ws, cfg) == base;
    cam[i] = keep - h;
    const double lm = loss(cam, nullptr);
    same = same && test::relu_pattern(ws, cfg) == base;
    cam[i] = keep;
    const double e = rel_err(g[i], (lp - lm) / (2 * h), floor);
    if (same) {
      hashcc::test::keep_worst(worst, e);
    } else {
      hashcc::test::keep_worst(worst_kink, e);
      ++kinks;
    }
  }
  INFO("worst camera gradient error " << worst << "; " << kinks << " entries straddle a kink, "
       "worst " << worst_kink);
  CHECK(worst < tol);
  CHECK(worst_kink < tol_kink);
  CHECK(kinks < int(cam.size()) / 2);  // most entries are checked at the full tolerance
  // What the trainer applied (float) is this gradient: within float rounding of the largest
  // entry (1e-3, as "model step: float agrees with double").
  double gmax = 0, diff = 0;
  for (int j = 0; j < K; ++j)
    for (int k = 0; k < 6; ++k) {
      gmax = std::max(gmax, std::abs(g[6 * j + k]));
      hashcc::test::keep_worst(diff, std::abs(double(t.last_camera_grads().d_pose[6 * j + k]) - g[6 * j + k]));
    }
  for (int k = 0; k < 2; ++k) {
    gmax = std::max(gmax, std::abs(g[6 * K + k]));
    hashcc::test::keep_worst(diff, std::abs(double(t.last_camera_grads().d_focal[k]) - g[6 * K + k]));
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
  c.images_per_step = -1;
  REQUIRE_THROWS_WITH(validate_train_config(c), Catch::Contains("--images-per-step"));
  c.images_per_step = 0;  // auto (the grid field's default): resolved to min(4, 8) on load
  validate_train_config(c);
  CHECK(Trainer{c}.config().images_per_step == 4);
  c.images_per_step = 16;  // divides 64, but the scene has 8 training images
  validate_train_config(c);
  REQUIRE_THROWS_WITH(Trainer{c}, Catch::Contains("--images-per-step: 16 is more than the 8 "
                                                  "training images"));
}

// ---------------------------------------------------------------- --pyramid F

TEST_CASE("pyramid levels produce consistent rays", "[trainer][pyramid]") {
  // Level s's pixel (u', v') is the full-resolution pixel (s·u', s·v'): its ray must be the ray
  // of a W/s × H/s camera with focal f/s (the same a, b: fx = a²W) at (u', v').
  const ImageSize full{80, 60};
  PoseParams<double> pd;
  pd.r = Vec3<double>(0.03, -0.02, 0.05);
  pd.t = Vec3<double>(0.1, -0.05, 0.02);
  FocalParams<double> fd;
  fd.a = 1.1;
  fd.b = 0.9;
  PoseParams<float> pf;
  pf.r = pd.r.cast<float>();
  pf.t = pd.t.cast<float>();
  FocalParams<float> ff;
  ff.a = 1.1f;
  ff.b = 0.9f;
  for (int s : {2, 4})
    for (bool ndc : {true, false}) {
      const ImageSize low{full.W / s, full.H / s};
      std::vector<int> px_full, px_low;
      for (int v = 0; v < low.H; ++v)
        for (int u = 0; u < low.W; ++u) {
          px_low.insert(px_low.end(), {u, v});
          px_full.insert(px_full.end(), {s * u, s * v});
        }
      const int64_t N = int64_t(px_low.size() / 2);
      std::vector<double> o1(3 * N), d1(3 * N), o2(3 * N), d2(3 * N);
      camera_rays_forward(o1.data(), d1.data(), px_full.data(), N, pd, fd, full, ndc);
      camera_rays_forward(o2.data(), d2.data(), px_low.data(), N, pd, fd, low, ndc);
      std::vector<float> o1f(3 * N), d1f(3 * N), o2f(3 * N), d2f(3 * N);
      camera_rays_forward(o1f.data(), d1f.data(), px_full.data(), N, pf, ff, full, ndc);
      camera_rays_forward(o2f.data(), d2f.data(), px_low.data(), N, pf, ff, low, ndc);
      double worst = 0, worst_f = 0;
      for (int64_t i = 0; i < 3 * N; ++i) {
        for (double e : {std::abs(o1[i] - o2[i]), std::abs(d1[i] - d2[i])}) hashcc::test::keep_worst(worst, e);
        for (double e : {double(std::abs(o1f[i] - o2f[i])), double(std::abs(d1f[i] - d2f[i]))})
          hashcc::test::keep_worst(worst_f, e);
      }
      INFO("s = " << s << (ndc ? " NDC" : " world") << ": double " << worst << ", float " << worst_f);
      // The same ray up to rounding (measured: bitwise, as s = 2, 4 scale exactly).
      CHECK(worst < 1e-12);
      CHECK(worst_f < 1e-6);  // and in the float the trainer uses
    }

  // The colour: the level-s colour of the simulated scene's full-resolution photo (8-bit, as
  // loaded) is close to the simulator's own render at W/s × H/s with focal f/s (each pixel the
  // average of 8 × 8 sub-pixel rays, i.e. the pixel's area). Measured mean abs errors: 0.0067
  // (s = 2) and 0.0039 (s = 4); tolerance 0.03. Nearest-pixel subsampling of the same photo,
  // with no filter, must be worse (measured 0.013 and 0.029): the filter is what makes the
  // coarse colour a coarse pixel's.
  SimOptions so;
  so.views = 3;
  so.width = full.W;
  so.height = full.H;
  const SimScene scene = make_sim_scene(so);
  const std::vector<SimCamera> rig = make_sim_rig(so);
  std::vector<float> rgb, z;
  render_sim_view(scene, rig[1], so, &rgb, &z);
  ImageU8 photo;
  photo.width = full.W;
  photo.height = full.H;
  for (float v : rgb) photo.rgb.push_back(uint8_t(std::lround(std::clamp(v, 0.f, 1.f) * 255)));
  for (int s : {2, 4}) {
    SimOptions lo = so;
    lo.width = full.W / s;
    lo.height = full.H / s;
    lo.supersample = 8;
    std::vector<float> ref;
    render_sim_view(scene, rig[1], lo, &ref, &z);  // same rig: make_sim_rig ignores the size
    const PyramidLevel lvl = make_pyramid_level(photo, s);
    REQUIRE(lvl.width == lo.width);
    REQUIRE(lvl.height == lo.height);
    double err = 0, err_nearest = 0;
    for (int v = 0; v < lo.height; ++v)
      for (int u = 0; u < lo.width; ++u)
        for (int ch = 0; ch < 3; ++ch) {
          const double r = ref[(size_t(v) * lo.width + u) * 3 + ch];
          err += std::abs(lvl.at(v, u, ch) - r);
          err_nearest += std::abs(photo.at(s * v, s * u, ch) - r);
        }
    err /= 3.0 * lo.width * lo.height;
    err_nearest /= 3.0 * lo.width * lo.height;
    INFO("s = " << s << ": mean abs error " << err << " (unfiltered subsampling " << err_nearest << ")");
    CHECK(err < 0.03);
    CHECK(err < err_nearest);
  }
}

TEST_CASE("pyramid filter: weights sum to 1, constants and mass are kept exactly", "[trainer][pyramid]") {
  for (int s : {2, 4, 6, 8}) {
    const std::vector<int> c = box_filter_taps(s);
    REQUIRE(int(c.size()) == s + 1);
    CHECK(std::accumulate(c.begin(), c.end(), 0) == 2 * s);  // weights c_j / (2s) sum to 1
    CHECK(c.front() == 1);
    CHECK(c.back() == 1);
    for (int j = 1; j < s; ++j) CHECK(c[j] == 2);
  }
  CHECK_THROWS_WITH(box_filter_taps(3), Catch::Contains("--pyramid"));
  // A constant image (odd size: the lattice's last row and column clamp at the border).
  for (int p : {0, 1, 128, 255})
    for (int s : {2, 4}) {
      ImageU8 img;
      img.width = 13;
      img.height = 7;
      img.rgb.assign(13 * 7 * 3, uint8_t(p));
      const PyramidLevel L = make_pyramid_level(img, s);
      CHECK(L.width == (13 + s - 1) / s);
      CHECK(L.height == (7 + s - 1) / s);
      for (uint16_t v : L.num) CHECK(v == 4 * s * s * p);
      CHECK(L.at(L.height - 1, L.width - 1, 2) == float(p) / 255.0f);  // exact
    }
  // Mass: an impulse away from the border spreads over the lattice with weights summing to
  // 1/s² (the lattice samples one pixel in s²), here 4 × (1/(2s))² for s = 2 at an odd pixel.
  for (int s : {2, 4}) {
    ImageU8 img;
    img.width = img.height = 16;
    img.rgb.assign(16 * 16 * 3, 0);
    img.rgb[(size_t(7) * 16 + 5) * 3 + 1] = 255;  // row 7, column 5, green
    const PyramidLevel L = make_pyramid_level(img, s);
    int64_t total = 0;
    for (size_t i = 1; i < L.num.size(); i += 3) total += L.num[i];
    CHECK(total * s * s == 4 * s * s * 255);  // Σ at() = 1/s² of the impulse, exactly
  }
}

TEST_CASE("pyramid schedule: level 4, then 2, then full resolution", "[trainer][pyramid]") {
  // F = 0.4 over 100 steps: level 4 for steps 0–19, level 2 for 20–39, then 1.
  CHECK(pyramid_level(0, 100, 0.4) == 4);
  CHECK(pyramid_level(19, 100, 0.4) == 4);
  CHECK(pyramid_level(20, 100, 0.4) == 2);
  CHECK(pyramid_level(39, 100, 0.4) == 2);
  CHECK(pyramid_level(40, 100, 0.4) == 1);
  CHECK(pyramid_level(99, 100, 0.4) == 1);
  CHECK(pyramid_level(0, 100, 0.0) == 1);  // off
  CHECK(pyramid_level(0, 10, 0.1) == 2);   // ⌊0.05·10⌋ = 0 steps at level 4, ⌊0.1·10⌋ = 1 at 2

  // The trainer: rays at level 4 sit on the lattice {0, 4, 8, …} with the level's filtered
  // colours; 40 × 30 images have a 10 × 8 lattice, smaller than the 12 × 12 grid of 144 rays, so
  // the step uses the whole lattice (80 rays). At level 1 the full grid is back.
  const std::string data = eight_train_scene();
  TrainConfig c = test::tiny_train_config(data, "", 20);
  c.rays = 144;
  c.pyramid = 0.4;  // steps 0–3 at level 4, 4–7 at level 2, 8– at full resolution
  Trainer t(c);
  for (int64_t s : {0, 3, 4, 7, 8, 19}) {
    INFO("step " << s);
    CHECK(t.pyramid_level_at(s) == (s < 4 ? 4 : s < 8 ? 2 : 1));
  }
  std::vector<PyramidLevel> lv4, lv2;
  for (int i : t.scene().train) {
    lv4.push_back(make_pyramid_level(t.scene().images[i], 4));
    lv2.push_back(make_pyramid_level(t.scene().images[i], 2));
  }
  for (int step = 0; step < 9; ++step) {
    const int s = t.pyramid_level_at(step);
    t.step_once();
    const Trainer::StepRays r = t.last_rays();
    const int i = t.last_images()[0];
    INFO("step " << step << " level " << s);
    CHECK(r.R == (s == 4 ? 8 * 10 : s == 2 ? 12 * 12 : 12 * 12));
    std::set<std::pair<int, int>> seen;
    bool on_lattice = true, colours = true;
    for (int k = 0; k < r.R; ++k) {
      const int u = r.px[2 * k], v = r.px[2 * k + 1];
      seen.insert({u, v});
      on_lattice = on_lattice && u % s == 0 && v % s == 0 && u < 40 && v < 30;
      for (int ch = 0; ch < 3; ++ch) {
        const float want = s == 4   ? lv4[i].at(v / 4, u / 4, ch)
                           : s == 2 ? lv2[i].at(v / 2, u / 2, ch)
                                    : t.scene().images[t.scene().train[i]].at(v, u, ch);
        colours = colours && r.target[3 * k + ch] == want;
      }
    }
    CHECK(on_lattice);
    CHECK(colours);
    CHECK(int(seen.size()) == r.R);  // distinct pixels
  }
}

// ---------------------------------------------------------------- --camera-start-psnr, --camera-warmup

TEST_CASE("camera warm-up: lr 0 before the trigger, a linear ramp, the end value", "[trainer]") {
  const std::string data = eight_train_scene();
  TrainConfig c = test::tiny_train_config(data, "", 1000);
  c.camera_start_psnr = 20;
  c.camera_warmup = 10;
  Trainer t(c);
  CHECK(t.camera_start_step() == -1);
  for (int64_t s : {0, 1, 500, 999, 1000}) {
    CHECK(t.lr_pose_at(s) == 0.0);
    CHECK(t.lr_focal_at(s) == 0.0);
  }
  // Triggered: the decay runs over [100, 1000], its first 10 steps scaled by 1/10 … 10/10.
  t.mutable_state().camera_start = 100;
  CHECK(t.lr_pose_at(99) == 0.0);
  CHECK(t.lr_pose_at(100) == Approx(1e-3 * 0.1).epsilon(1e-12));
  CHECK(t.lr_pose_at(104) == Approx(exp_decay_lr(1e-3, 1e-8, 4, 900) * 0.5).epsilon(1e-12));
  CHECK(t.lr_pose_at(109) == exp_decay_lr(1e-3, 1e-8, 9, 900));  // ramp done: the schedule
  CHECK(t.lr_pose_at(550) == exp_decay_lr(1e-3, 1e-8, 450, 900));
  CHECK(t.lr_pose_at(1000) == 1e-8);                             // formulas.md §6's end value
  CHECK(t.lr_focal_at(1000) == 1e-8);
  for (int64_t s = 100; s < 109; ++s) CHECK(t.lr_pose_at(s) < t.lr_pose_at(s + 1));  // rising
  // --camera-warmup alone ramps from step 0; the default (both off) is the paper's schedule.
  TrainConfig w = test::tiny_train_config(data, "", 1000);
  w.camera_warmup = 4;
  Trainer tw(w);
  CHECK(tw.lr_pose_at(0) == Approx(1e-3 / 4).epsilon(1e-12));
  CHECK(tw.lr_pose_at(3) == exp_decay_lr(1e-3, 1e-8, 3, 1000));
  Trainer td(test::tiny_train_config(data, "", 1000));
  for (int64_t s : {0, 7, 999}) CHECK(td.lr_pose_at(s) == exp_decay_lr(1e-3, 1e-8, s, 1000));
  // Both ways of choosing the cameras' start at once is an error naming the flag.
  TrainConfig both = c;
  both.camera_delay = 0.2;
  REQUIRE_THROWS_WITH(validate_train_config(both), Catch::Contains("--camera-start-psnr") &&
                                                       Catch::Contains("--camera-delay"));
}

TEST_CASE("--hold-cameras-from and --distortion-from: the cameras stop, the loss starts, at "
          "their fraction of the run", "[trainer]") {
  const std::string data = eight_train_scene();
  TrainConfig c = test::tiny_train_config(data, "", 8);
  c.hold_cameras_from = 0.5;  // steps 4 … 7 held
  c.distortion = 0.5;
  c.distortion_from = 0.25;   // steps 2 … 7 with the loss
  Trainer t(c);
  CHECK_FALSE(t.cameras_held_at(3));
  CHECK(t.cameras_held_at(4));
  CHECK(t.distortion_at(1) == 0.0);
  CHECK(t.distortion_at(2) == 0.5);
  std::vector<float> poses = t.state().poses, focal = t.state().focal;
  for (int s = 0; s < 8; ++s) {
    const StepResult<float> r = t.step_once();
    INFO("step " << s);
    CHECK((r.distortion > 0) == (s >= 2));
    const bool moved = t.state().poses != poses || t.state().focal != focal;
    CHECK(moved == (s < 4));  // learning cameras move every step; held ones never
    if (s >= 4) {
      for (int k = 0; k < 6; ++k) CHECK(t.last_camera_grads().d_pose[k] == 0.f);  // not computed
    }
    poses = t.state().poses;
    focal = t.state().focal;
  }
  // Off (the default) changes nothing: never held, the loss from the start.
  TrainConfig d = test::tiny_train_config(data, "", 8);
  d.distortion = 0.5;
  Trainer td(d);
  CHECK_FALSE(td.cameras_held_at(7));
  CHECK(td.distortion_at(0) == 0.5);
  // The start of a loss that is not there is refused, naming the flag.
  TrainConfig bad = test::tiny_train_config(data, "", 8);
  bad.distortion_from = 0.5;
  CHECK_THROWS_WITH(validate_train_config(bad), Catch::Contains("--distortion-from") &&
                                                    Catch::Contains("without --distortion"));
}

TEST_CASE("camera warm-up: the PSNR trigger is state, and resume after it is bitwise",
          "[trainer]") {
  const std::string data = sim_scene("psnr", 6, 40, 30);
  const std::string a = (fs::temp_directory_path() / "hashcc_opt_psnrA").string();
  const std::string b = (fs::temp_directory_path() / "hashcc_opt_psnrB").string();
  fs::remove_all(a);
  fs::remove_all(b);
  const int threads = num_threads();
  set_num_threads(1);
  // Probe: the running PSNR with the cameras frozen (a threshold never reached), identical to
  // the gated run's until its trigger. The threshold is the probe's running PSNR at the first
  // step s* ≥ 1 where it exceeds every earlier value, so the gated run (the same plan of 20
  // steps: the same schedules) triggers exactly there: its cameras learn from step s* + 1, and
  // it checkpoints 3 steps later. (lr_net 1e-2: the tiny model's PSNR then rises within a few
  // steps; measured s* = 5.)
  const int64_t total = 20;
  TrainConfig base = test::tiny_train_config(data, "", total);
  base.lr_net = 1e-2;
  TrainConfig probe_cfg = base;
  probe_cfg.camera_start_psnr = 100;
  Trainer probe(probe_cfg);
  std::vector<double> ema;
  int64_t s_star = -1;
  for (int k = 0; k < 12 && s_star < 0; ++k) {
    probe.step_once();
    ema.push_back(probe.state().psnr_ema);
    if (k >= 1 && ema[k] > *std::max_element(ema.begin(), ema.begin() + k)) s_star = k;
  }
  REQUIRE(s_star >= 1);
  const double P = ema[size_t(s_star)];
  const int64_t ckpt = s_star + 4;

  TrainConfig c = base;
  c.out = a;
  c.camera_start_psnr = P;
  c.camera_warmup = 3;
  Trainer ta(c);
  REQUIRE(ta.run());
  const int64_t start = ta.state().camera_start;
  INFO("threshold " << P << " dB, cameras start at step " << start);
  REQUIRE(start == s_star + 1);
  CHECK(ta.lr_pose_at(start - 1) == 0.0);
  CHECK(ta.lr_pose_at(start) > 0.0);
  CHECK(ta.lr_pose_at(total) == c.lr_pose_end);
  double moved = 0;
  for (float v : ta.state().poses) moved += std::abs(v);
  CHECK(moved > 0);  // the cameras did learn after the trigger
  // The log's pose lr column shows the trigger: 0 on the rows of steps before it.
  std::ifstream log(a + "/log.csv");
  std::string line;
  std::getline(log, line);
  int rows = 0;
  while (std::getline(log, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    REQUIRE(cells.size() == 10);
    const int64_t step = std::stoll(cells[0]);
    const double lr_pose = std::stod(cells[6]);
    INFO("log row of step " << step);
    CHECK((lr_pose == 0) == (step < start));
    ++rows;
  }
  CHECK(rows == total);

  {
    TrainConfig cb = c;
    cb.out = b;
    Trainer tb(cb);
    for (int k = 0; k < ckpt; ++k) tb.step_once();
    REQUIRE(tb.state().camera_start == start);  // triggered before the checkpoint
    tb.save_checkpoint_now();
  }
  Trainer tb = Trainer::resume(b);
  CHECK(tb.state().step == ckpt);
  CHECK(tb.state().camera_start == start);
  REQUIRE(tb.run());
  set_num_threads(threads);
  CHECK(tb.state().step == total);
  CHECK(ta.state().net == tb.state().net);  // bitwise
  CHECK(ta.state().poses == tb.state().poses);
  CHECK(ta.state().focal == tb.state().focal);
  CHECK(ta.state().poses_m == tb.state().poses_m);
  CHECK(ta.state().psnr_ema == tb.state().psnr_ema);
}

TEST_CASE("train config: the options beyond the paper round-trip through JSON", "[trainer]") {
  TrainConfig c;
  c.images_per_step = 4;
  c.pyramid = 0.3;
  c.camera_start_psnr = 17.5;
  c.camera_warmup = 250;
  c.model.gf.density_init = 2;
  c.bootstrap_lr_pose = 3e-3;
  c.model.field = Field::grid;
  c.restarts = 2;
  c.restart_first = 0.5;
  c.restart_last = 0.25;
  const TrainConfig d = train_config_from_json(train_config_json(c), "config.json");
  CHECK(d.model.gf.density_init == 2);
  CHECK(d.bootstrap_lr_pose == 3e-3);
  CHECK(d.restarts == 2);
  CHECK(d.restart_first == 0.5);
  CHECK(d.restart_last == 0.25);
  CHECK(d.images_per_step == 4);
  CHECK(d.pyramid == 0.3);
  CHECK(d.camera_start_psnr == 17.5);
  CHECK(d.camera_warmup == 250);
  CHECK(train_config_json(d) == train_config_json(c));
  nlohmann::json j = nlohmann::json::parse(train_config_json(c));
  j["images_per_step"] = -1;  // (0 is auto: a plan's record of the run before the scene loads)
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"), Catch::Contains("images_per_step"));
  j = nlohmann::json::parse(train_config_json(c));
  j["pyramid"] = 1.0;  // the run must end at full resolution
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"), Catch::Contains("pyramid"));
  j = nlohmann::json::parse(train_config_json(c));
  j["grid_density_init"] = 11.0;  // σ = e^11 at init: beyond kGridDensityInitMax
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"),
                      Catch::Contains("grid_density_init"));
  j = nlohmann::json::parse(train_config_json(c));
  j["bootstrap_lr_pose"] = -1e-3;
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"),
                      Catch::Contains("bootstrap_lr_pose"));
  j = nlohmann::json::parse(train_config_json(c));
  j["restarts"] = 65;
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"), Catch::Contains("restarts"));
  j = nlohmann::json::parse(train_config_json(c));
  j["restart_first"] = 1.0;  // the later stages would have nothing
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"),
                      Catch::Contains("restart_first"));
  // --restart-steps: round trip, and refused without stages between or beside --restart-last.
  TrainConfig rs;
  rs.model.field = Field::grid;
  rs.restarts = 3;
  rs.restart_first = 0.5;
  rs.restart_steps = 1200;
  CHECK(train_config_from_json(train_config_json(rs), "config.json").restart_steps == 1200);
  j = nlohmann::json::parse(train_config_json(rs));
  j["restart_steps"] = -1;
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"),
                      Catch::Contains("restart_steps"));
  rs.restart_last = 0.2;  // the last stage takes what is left: no share of its own
  CHECK_THROWS_WITH(validate_train_config(rs), Catch::Contains("--restart-last"));
  rs.restart_last = 0;
  rs.restarts = 1;  // no stage between the first and the last
  CHECK_THROWS_WITH(validate_train_config(rs), Catch::Contains("--restarts 1"));
  rs.restarts = 0;
  CHECK_THROWS_WITH(validate_train_config(rs), Catch::Contains("without --restarts"));
  // --last-focal-stages: round trip; refused without --last-focal-hold, and beyond the stages
  // after the first (stage 1 starts from identity with both focals).
  TrainConfig lf = rs;
  lf.restarts = 3;
  lf.last_focal_hold = 0.2;
  lf.last_focal_stages = 3;
  CHECK_NOTHROW(validate_train_config(lf));
  CHECK(train_config_from_json(train_config_json(lf), "config.json").last_focal_stages == 3);
  j = nlohmann::json::parse(train_config_json(lf));
  j["last_focal_stages"] = 0;
  REQUIRE_THROWS_WITH(train_config_from_json(j.dump(), "config.json"),
                      Catch::Contains("last_focal_stages"));
  lf.last_focal_stages = 4;
  CHECK_THROWS_WITH(validate_train_config(lf), Catch::Contains("--restarts 3"));
  lf.last_focal_stages = 2;
  lf.last_focal_hold = 0;
  CHECK_THROWS_WITH(validate_train_config(lf), Catch::Contains("without --last-focal-hold"));
  // --last-grid-log2-table, --last-samples: round trip; refused without --restarts, for the MLP
  // field (a bootstrap keeps only the grid phase's cameras), and at 1.
  TrainConfig ls = rs;
  ls.restarts = 2;
  ls.restart_first = 0;
  ls.restart_steps = 0;
  ls.last_grid_log2_table = 17;
  ls.last_samples = 64;
  CHECK_NOTHROW(validate_train_config(ls));
  const TrainConfig back = train_config_from_json(train_config_json(ls), "config.json");
  CHECK(back.last_grid_log2_table == 17);
  CHECK(back.last_samples == 64);
  ls.last_samples = 1;
  CHECK_THROWS_WITH(validate_train_config(ls), Catch::Contains("--last-samples"));
  ls.last_samples = 0;
  ls.restarts = 0;
  CHECK_THROWS_WITH(validate_train_config(ls),
                    Catch::Contains("--last-grid-log2-table") && Catch::Contains("without --restarts"));
  // --last-lr-net, --last-lr-net-end: round trip; refused without --restarts, for the MLP field,
  // and when the last stage's rate would rise (the MLP field: below).
  TrainConfig lr = ls;
  lr.last_grid_log2_table = 0;
  lr.last_samples = 0;
  lr.restarts = 2;
  lr.last_lr_net = 2e-2;
  lr.last_lr_net_end = 1e-3;
  CHECK_NOTHROW(validate_train_config(lr));
  const TrainConfig lr_back = train_config_from_json(train_config_json(lr), "config.json");
  CHECK(lr_back.last_lr_net == 2e-2);
  CHECK(lr_back.last_lr_net_end == 1e-3);
  {  // --first-focal-hold: round trip; refused without --restarts, beside --focal-delay or
     // --fixed-focal
    TrainConfig f = lr;
    f.first_focal_hold = 0.5;
    CHECK_NOTHROW(validate_train_config(f));
    CHECK(train_config_from_json(train_config_json(f), "config.json").first_focal_hold == 0.5);
    f.focal_delay = 0.2;  // a stage's config (refused on the command by grid_restarts)
    CHECK_NOTHROW(validate_train_config(f));
    f.focal_delay = 0;
    f.fixed_focal = true;
    CHECK_THROWS_WITH(validate_train_config(f),
                      Catch::Contains("--first-focal-hold") && Catch::Contains("--fixed-focal"));
    f.fixed_focal = false;
    f.restarts = 0;
    f.last_lr_net = f.last_lr_net_end = 0;
    CHECK_THROWS_WITH(validate_train_config(f),
                      Catch::Contains("--first-focal-hold") && Catch::Contains("without --restarts"));
  }
  {  // --last-lr-focal-end: round trip; refused when it would make the focal's rate rise
    TrainConfig f = lr;
    f.last_lr_focal_end = f.lr_focal;
    CHECK_NOTHROW(validate_train_config(f));
    CHECK(train_config_from_json(train_config_json(f), "config.json").last_lr_focal_end == f.lr_focal);
    f.last_lr_focal_end = 2 * f.lr_focal;
    CHECK_THROWS_WITH(validate_train_config(f),
                      Catch::Contains("--last-lr-focal-end") && Catch::Contains("rise"));
    f.last_lr_focal_end = f.lr_focal;
    f.restarts = 0;
    f.last_lr_net = f.last_lr_net_end = 0;
    CHECK_THROWS_WITH(validate_train_config(f),
                      Catch::Contains("--last-lr-focal-end") && Catch::Contains("without --restarts"));
  }
  {  // --last-lr-pose-end: round trip; refused when it would make the poses' rate rise
    TrainConfig f = lr;
    f.last_lr_pose_end = f.lr_pose / 10;
    CHECK_NOTHROW(validate_train_config(f));
    CHECK(train_config_from_json(train_config_json(f), "config.json").last_lr_pose_end ==
          f.lr_pose / 10);
    f.last_lr_pose_end = 2 * f.lr_pose;
    CHECK_THROWS_WITH(validate_train_config(f),
                      Catch::Contains("--last-lr-pose-end") && Catch::Contains("rise"));
    f.last_lr_pose_end = f.lr_pose / 10;
    f.restarts = 0;
    f.last_lr_net = f.last_lr_net_end = 0;
    CHECK_THROWS_WITH(validate_train_config(f),
                      Catch::Contains("--last-lr-pose-end") && Catch::Contains("without --restarts"));
  }
  lr.last_distortion = 0.01;  // --last-distortion: round trip, and (below) refused without --restarts
  lr.last_distortion_from = 0.6;
  lr.last_hold_cameras_from = 0.7;
  lr.hold_cameras_from = 0.9;
  lr.distortion = 0.001;
  lr.distortion_from = 0.8;
  {
    const TrainConfig back = train_config_from_json(train_config_json(lr), "config.json");
    CHECK(back.last_distortion == 0.01);
    CHECK(back.last_distortion_from == 0.6);
    CHECK(back.last_hold_cameras_from == 0.7);
    CHECK(back.hold_cameras_from == 0.9);
    CHECK(back.distortion_from == 0.8);
  }
  for (const char* flag : {"--last-distortion-from", "--last-hold-cameras-from"}) {
    TrainConfig no_restarts = lr;
    no_restarts.restarts = 0;
    no_restarts.last_lr_net = no_restarts.last_lr_net_end = no_restarts.last_distortion = 0;
    if (std::string(flag) == "--last-distortion-from") no_restarts.last_hold_cameras_from = 0;
    else no_restarts.last_distortion_from = 0;
    CHECK_THROWS_WITH(validate_train_config(no_restarts),
                      Catch::Contains(flag) && Catch::Contains("without --restarts"));
  }
  lr.last_distortion_from = lr.last_hold_cameras_from = lr.hold_cameras_from = 0;
  lr.distortion = lr.distortion_from = 0;
  {
    TrainConfig no_restarts = lr;
    no_restarts.restarts = 0;
    no_restarts.last_lr_net = no_restarts.last_lr_net_end = 0;
    CHECK_THROWS_WITH(validate_train_config(no_restarts),
                      Catch::Contains("--last-distortion") && Catch::Contains("without --restarts"));
  }
  lr.last_distortion = 0;
  lr.last_lr_net_end = 3e-2;
  CHECK_THROWS_WITH(validate_train_config(lr),
                    Catch::Contains("--last-lr-net-end") && Catch::Contains("rise"));
  lr.last_lr_net = 0;
  lr.last_lr_net_end = 0;
  lr.lr_net_end = lr.lr_net / 10;
  lr.last_lr_net = lr.lr_net_end / 2;  // below the --lr-net-end it keeps
  CHECK_THROWS_WITH(validate_train_config(lr),
                    Catch::Contains("--last-lr-net") && Catch::Contains("rise"));
  lr.last_lr_net = 2e-2;
  lr.restarts = 0;
  CHECK_THROWS_WITH(validate_train_config(lr),
                    Catch::Contains("--last-lr-net") && Catch::Contains("without --restarts"));
  // The last stage's field options are refused for the MLP field: a bootstrap's grid phase hands
  // on only its cameras, so a larger or faster last grid field would be thrown away.
  for (const auto set : {+[](TrainConfig& c) { c.last_samples = 64; },
                         +[](TrainConfig& c) { c.last_grid_log2_table = 17; },
                         +[](TrainConfig& c) { c.last_lr_net_end = 1e-4; }}) {
    TrainConfig lm;
    lm.restarts = 1;
    lm.bootstrap_minutes = 5;
    set(lm);
    CHECK_THROWS_WITH(validate_train_config(lm), Catch::Contains("MLP field"));
  }
  TrainConfig rf;
  rf.restart_first = 0.5;  // without --restarts: no stages to share the budget
  CHECK_THROWS_WITH(validate_train_config(rf), Catch::Contains("--restart-first"));
  rf.restart_first = 0;
  rf.restart_last = 0.5;
  CHECK_THROWS_WITH(validate_train_config(rf), Catch::Contains("--restart-last"));
  // --restarts restarts the grid field: refused for the MLP field unless a bootstrap's grid phase
  // takes it, and with --init-poses (a restart starts from the cameras the stage before learned).
  TrainConfig m;
  m.restarts = 1;
  CHECK_THROWS_WITH(validate_train_config(m), Catch::Contains("--restarts"));
  m.bootstrap_minutes = 5;
  CHECK_NOTHROW(validate_train_config(m));
  TrainConfig ip = c;
  ip.init_poses = "poses_bounds.npy";
  CHECK_THROWS_WITH(validate_train_config(ip), Catch::Contains("--restarts"));
}

TEST_CASE("preset: paper sets nothing, laptop fills only the flags not given", "[trainer][preset][plan]") {
  const auto none = [](const std::string&) { return false; };
  TrainConfig def;
  // --preset laptop is the recipe recipes/laptop.json: one stage, a base of three values.
  const TrainPlan laptop = load_plan("laptop");
  REQUIRE(laptop.stages.size() == 1);
  TrainConfig lap;
  const std::vector<std::string> applied = apply_plan_base(lap, laptop, none);
  CHECK(applied.size() == laptop.base.size());
  CHECK(lap.lr_pose_end == 1e-4);
  CHECK(lap.lr_focal_end == 1e-4);
  CHECK(lap.images_per_step == 4);
  CHECK(train_config_json(lap) != train_config_json(def));
  for (const std::string& key : applied) {
    // An explicit flag wins over the recipe's value.
    TrainConfig mine;
    mine.lr_pose_end = 0.123;
    mine.lr_focal_end = 0.123;
    const auto given = [&](const std::string& k) { return k == key; };
    CHECK(apply_plan_base(mine, laptop, given).size() == applied.size() - 1);
    if (key == "lr_pose_end") CHECK(mine.lr_pose_end == 0.123);
    if (key == "lr_focal_end") CHECK(mine.lr_focal_end == 0.123);
  }
  // A --set value wins over the flag.
  TrainPlan forced = laptop;
  set_plan_value(forced, "lr_pose_end=2e-4");
  TrainConfig f2;
  apply_plan_base(f2, forced, [](const std::string&) { return true; });
  CHECK(f2.lr_pose_end == 2e-4);
  CHECK(f2.lr_focal_end == def.lr_focal_end);
  // The preset's name is part of the run's config and round-trips; a bad name is a clear error.
  lap.preset = "laptop";
  TrainConfig back = train_config_from_json(train_config_json(lap), "config.json");
  CHECK(back.preset == "laptop");
  CHECK(back.lr_pose_end == lap.lr_pose_end);
  CHECK_THROWS_WITH(load_plan("fast"), Catch::Contains("neither a recipe nor a file"));
  CHECK(preset_names_text().find("paper, ") == 0);
  // fern60: a whole recipe for the grid field; every value says why, and it resolves as it is.
  const auto& names = recipe_names();
  REQUIRE(std::find(names.begin(), names.end(), "fern60") != names.end());
  TrainConfig fern;
  fern.minutes = 60;
  const TrainPlan fp = load_plan("fern60");
  apply_plan_base(fern, fp, none);
  CHECK(fern.model.field == Field::grid);
  CHECK(fp.stages.size() == 5);
  CHECK_NOTHROW(resolve_plan(fp, fern));
  std::string bad = train_config_json(lap);
  bad.replace(bad.find("\"laptop\""), 8, "\"turbo\"");
  CHECK_THROWS_AS(train_config_from_json(bad, "config.json"), Error);
}

// --focal-guard G (train/trainer.cpp, guard_focal): a focal pushed out of [start/G, start·G] is
// put back to exactly where it started and held there for the rest of the run; with the guard
// off (0) the same run leaves the band. The focal is pushed by an absurd focal rate.
TEST_CASE("focal guard: a focal leaving its band is put back and held; off, it is not",
          "[trainer][focal]") {
  const std::string data = test::sim_scene("focal_guard", 6, 48, 36);
  const auto run = [&](double guard) {
    TrainConfig c = test::tiny_train_config(data, "", 40);
    c.lr_focal = c.lr_focal_end = 0.05;  // ~10% of the focal a step: it must leave any band
    c.focal_guard = guard;
    c.threads = 1;
    Trainer t(c);
    REQUIRE(t.run());
    return std::pair{t.state().focal_guarded, t.state().focal};
  };
  const auto [fired, focal] = run(1.1);
  const auto [never, loose] = run(0);
  INFO("guarded: fired at step " << fired << ", a = " << focal[0] << ", b = " << focal[1]
       << "; unguarded: a = " << loose[0] << ", b = " << loose[1]);
  CHECK(fired >= 0);
  CHECK(fired < 40);
  CHECK(focal[0] == 1.f);  // fx = W, fy = H: the paper's start, bit for bit
  CHECK(focal[1] == 1.f);
  CHECK(never == -1);
  const double fx_ratio = double(loose[0]) * loose[0];  // fx / fx_start
  CHECK((fx_ratio > 1.1 || fx_ratio < 1 / 1.1 || double(loose[1]) * loose[1] > 1.1 ||
         double(loose[1]) * loose[1] < 1 / 1.1));
}

// --ndc-fixed-focal (Trainer::ndc_warp, camera.h's NdcWarp): the NDC box is drawn with the focal
// the run started from, whatever the focal learns; a resumed run (and so eval and render of a
// finished one) draws the same box. Without the flag the box follows the learned focal.
TEST_CASE("ndc fixed focal: the box keeps the starting focal while the focal learns, across resume",
          "[trainer][focal][ndc]") {
  const std::string data = test::sim_scene("ndc_fixed", 6, 48, 36);
  const std::string out = (fs::temp_directory_path() / "hashcc_opt_ndc_fixed").string();
  fs::remove_all(out);
  TrainConfig c = test::tiny_train_config(data, out, 30);
  c.focal_fov = 65;                     // a start that is not fx = W: the box's focal is visible
  c.fx_only = true;
  c.lr_focal = c.lr_focal_end = 1e-2;   // the focal must move within 30 steps
  c.focal_guard = 0;
  c.threads = 1;
  c.ndc_fixed_focal = true;
  const double f0 = focal_for_fov(48, 65);
  NdcWarp before, after;
  double fx_learned = 0;
  {
    Trainer t(c);
    before = t.ndc_warp();
    REQUIRE(t.run());
    after = t.ndc_warp();
    fx_learned = focal_fx(t.focal(), t.image_size());
  }
  INFO("box fx " << after.fx << " fy " << after.fy << ", start " << f0 << ", learned fx " << fx_learned);
  REQUIRE(before.fixed());
  CHECK(before.fx == Approx(f0).epsilon(1e-5));
  CHECK(before.fy == Approx(f0).epsilon(1e-5));  // one focal: fy = fx
  CHECK(after.fx == before.fx);
  CHECK(after.fy == before.fy);
  CHECK(std::abs(fx_learned / f0 - 1) > 1e-3);   // the focal learned, the box did not follow
  const Trainer back = Trainer::resume(out);
  CHECK(back.ndc_warp().fx == before.fx);
  CHECK(back.ndc_warp().fy == before.fy);
  // --ndc-box-scale: the held box at 0.8x the start (a wider box), saved in config.json, so the
  // resumed run draws it too.
  fs::remove_all(out);
  c.ndc_box_scale = 0.8;
  {
    Trainer t(c);
    CHECK(t.ndc_warp().fx == Approx(0.8 * f0).epsilon(1e-5));
    REQUIRE(t.run());
  }
  CHECK(Trainer::resume(out).ndc_warp().fx == Approx(0.8 * f0).epsilon(1e-5));
  c.ndc_box_scale = 1;
  // The paper's box: follows the learned focal (no fixed focal); NDC off: off.
  c.ndc_fixed_focal = false;
  c.out.clear();
  const NdcWarp learned = Trainer(c).ndc_warp();  // one scene load for both checks
  CHECK_FALSE(learned.fixed());
  CHECK(learned.on);
  c.ndc = false;
  c.pose_precondition = 0;
  CHECK_FALSE(Trainer(c).ndc_warp().on);
  c.ndc_fixed_focal = true;  // and the flag without NDC is refused by name
  CHECK_THROWS_WITH(validate_train_config(c), Catch::Contains("--ndc-fixed-focal"));
  c.ndc = true;  // a box scale without the held box is refused by name
  c.ndc_fixed_focal = false;
  c.ndc_box_scale = 0.8;
  CHECK_THROWS_WITH(validate_train_config(c), Catch::Contains("--ndc-box-scale"));
  fs::remove_all(out);
}
