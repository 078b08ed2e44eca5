// Whole-model tests: the composed step (sampler → networks → compositor → loss) and its
// backward against central differences in double, the camera chain through it, and the
// CC detach rule of formulas.md §5.
#include <catch2/catch.hpp>

#include <cstring>
#include <limits>

#include "camera/camera.h"
#include "model/model.h"
#include "model/render_view.h"
#include "core/parallel.h"
#include "model/camera_step.h"
#include "test/fixtures.h"
#include "test/gradcheck.h"
#include "test/tolerance_table.h"

using namespace hashcc;
using hashcc::test::rel_err;

namespace {

// Whole-step checks. The loss (~0.1) is a sum of thousands of terms: its rounding (~1e-17
// absolute) over 2h gives ~1e-13 of noise at h = 1e-4, while the O(h²) truncation stays ~1e-8
// relative. Many parameter gradients of a small random network are tiny (1e-10..1e-7), so the
// symmetric relative error uses a floor of 1e-7: relative above it, 1e-7-scaled absolute below.
// Entries whose ±h straddle a ReLU kink are detected and skipped. Tolerance: 1e-5.
// Camera and ray inputs move every sample of a ray (or of the image) at once, so they use
// h = 1e-6 to keep kink crossings rare; their gradients are large enough for that noise.
// The 8 camera numbers move every ray of the image: h = 1e-7 (camera gradients are ~1e-2).
constexpr double kH = 1e-4, kHRay = 1e-6, kHCam = 1e-7, kFloor = 1e-7, kTol = 1e-5;

using test::relu_pattern;

// Worst symmetric relative error over idx, skipping entries whose ±h straddle a kink.
// loss() must run the whole batch in one chunk (so the cache holds every ray).
template <class LossFn, class PatternFn>
double worst_smooth_error(std::vector<double>& theta, const std::vector<double>& grad,
                          LossFn loss, PatternFn pattern, std::vector<size_t> idx, int* skipped,
                          double h = kH) {
  if (idx.empty()) for (size_t i = 0; i < theta.size(); ++i) idx.push_back(i);
  loss();
  const auto base = pattern();
  double worst = 0;
  for (size_t i : idx) {
    double keep = theta[i];
    theta[i] = keep + h; double lp = loss(); bool same = pattern() == base;
    theta[i] = keep - h; double lm = loss(); same = same && pattern() == base;
    theta[i] = keep;
    if (!same) { ++*skipped; continue; }
    test::keep_worst(worst, rel_err(grad[i], (lp - lm) / (2 * h), kFloor));  // NaN/inf: +inf
  }
  return worst;
}

ModelConfig small_config(Variant v) { return tiny_model_config(v); }

struct Rays {
  int R, S;
  std::vector<double> o, d, s, target;
  RayBatch<double> batch(const double* cc_x = nullptr) const {
    return {o.data(), d.data(), s.data(), target.data(), R, S, cc_x};
  }
};

// Rays in NDC-like ranges: origins near z = −1, directions mostly +z in NDC... any smooth
// values work for the model; s increasing in [0, 1).
Rays make_rays(int R, int S, Rng& rng) {
  Rays r{R, S, {}, {}, {}, {}};
  for (int i = 0; i < R; ++i) {
    r.o.insert(r.o.end(), {rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), -1.0});
    r.d.insert(r.d.end(), {rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), 2.0});
    for (int k = 0; k < S; ++k) r.s.push_back((k + rng.uniform(0.1, 0.9)) / S);
    r.target.insert(r.target.end(), {rng.uniform(), rng.uniform(), rng.uniform()});
  }
  return r;
}

// Float copies of double-initialised parameters and of make_rays' batch: what the float step
// tests feed ray_batch_step. Draws from rng in that order (parameters, then rays).
struct FloatStepInputs {
  std::vector<float> p, o, d, s, t;
  int R = 0, S = 0;
  RayBatch<float> batch() const { return {o.data(), d.data(), s.data(), t.data(), R, S}; }
};

FloatStepInputs float_step_inputs(const ModelConfig& cfg, const ModelLayout& L, Rng& rng, int R,
                                  int S) {
  std::vector<double> pd(L.count);
  init_params(pd.data(), cfg, L, rng);
  const Rays r = make_rays(R, S, rng);
  return {std::vector<float>(pd.begin(), pd.end()), std::vector<float>(r.o.begin(), r.o.end()),
          std::vector<float>(r.d.begin(), r.d.end()), std::vector<float>(r.s.begin(), r.s.end()),
          std::vector<float>(r.target.begin(), r.target.end()), r.R, r.S};
}

}  // namespace

TEST_CASE("model step: the whole-step checker fails a NaN or an inf gradient entry", "[model][gradcheck]") {
  // Negative control (issue 52) for worst_smooth_error, the checker of the cases below: on a
  // smooth loss with a known gradient, L = Σ c_i sin θ_i (no kinks: the pattern never changes),
  // the correct gradient passes; one entry set to NaN or +inf must give an infinite error.
  Rng rng(52);
  std::vector<double> theta = test::random_vec(10, rng), c = test::random_vec(10, rng);
  auto loss = [&] {
    double s = 0;
    for (size_t i = 0; i < theta.size(); ++i) s += c[i] * std::sin(theta[i]);
    return s;
  };
  auto pattern = [] { return 0; };
  std::vector<double> grad(theta.size());
  for (size_t i = 0; i < theta.size(); ++i) grad[i] = c[i] * std::cos(theta[i]);
  int skipped = 0;
  CHECK(worst_smooth_error(theta, grad, loss, pattern, {}, &skipped) < kTol);
  for (double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    INFO("entry 7 set to " << bad);
    std::vector<double> g = grad;
    g[7] = bad;
    CHECK(worst_smooth_error(theta, g, loss, pattern, {}, &skipped) == std::numeric_limits<double>::infinity());
  }
  CHECK(skipped == 0);
}

TEST_CASE("model step: parameter and ray gradients match central differences", "[model][grad]") {
  // λ: --distortion (render/distortion.h), its gradient through the compositor's weights. A
  // random network's weights are small (the MLP's: L_dist ~ 1e-9), so λ is scaled to make the
  // term k.lam times the colour loss: a check that cannot miss it (0.2: the hashcc/MLP case is
  // within 1e-5 by 10% in a build without FMA, as it is without the term; at 0.5 it was 1.07e-5).
  struct Case { Variant v; double lam; };
  for (Field f : {Field::mlp, Field::grid})
  for (Case k : {Case{Variant::nerfmm, 0}, Case{Variant::sh, 0}, Case{Variant::hashcc, 0},
                 Case{Variant::sh, 0.2}, Case{Variant::hashcc, 0.2}}) {
    const Variant v = k.v;
    DYNAMIC_SECTION("variant " << variant_name(v) << ", field " << field_name(f)
                    << ", distortion " << k.lam) {
      ModelConfig cfg = tiny_model_config(v, f);
      ModelLayout L = make_layout(cfg);
      Rng rng(11, 3);
      std::vector<double> p(L.count);
      init_params(p.data(), cfg, L, rng);
      // Larger table values than the ±1e-4 init so the grid and CC paths matter in the check.
      if (cfg.has_cc())
        for (int64_t i = 0; i < cfg.cc.param_count(); ++i) p[L.cc_table + i] = rng.uniform(-0.5, 0.5);
      if (f == Field::grid)
        for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) p[L.grid_table + i] = rng.uniform(-0.5, 0.5);
      Rays r = make_rays(5, 12, rng);
      StepWorkspace<double> ws;
      StepOptions opt;
      opt.chunk_rays = 2;  // chunking must not change anything
      std::vector<double> grad(L.count, 0.0), d_o(3 * r.R), d_d(3 * r.R);
      const NetView<double> net{p.data(), cfg, L};
      if (k.lam > 0) {
        StepOptions probe = opt;
        probe.distortion = 1;
        const auto r0 = ray_batch_step(ws, net, r.batch(), probe, {});
        REQUIRE(r0.distortion > 0);
        opt.distortion = k.lam * r0.mse / r0.distortion;
        // The central differences below see the whole loss, so the ray gradients are checked with
        // the distortion reaching the camera (the ablation); the default detach is checked after.
        opt.distortion_to_camera = true;
      }
      const double* cc_x = nullptr;  // the detached CC input (null: the step's own x)
  bool frozen = false;  // networks frozen (eval's test-pose refinement): d_params = null
      auto res = ray_batch_step(ws, net, r.batch(), opt, {grad.data(), d_o.data(), d_d.data()});
      REQUIRE(std::isfinite(res.loss));
      if (k.lam > 0) {  // the term is really there, and of a size the check can see
        CHECK(opt.distortion * res.distortion == Approx(k.lam * res.mse));
      } else {
        CHECK(res.distortion == 0);
      }
      auto loss = [&] {
        StepOptions o2 = opt;
        o2.need_ray_grads = false;
        o2.chunk_rays = 1024;
        o2.data_parallel = false;  // the kink detector reads ws's own cache
        return double(ray_batch_step(ws, net, r.batch(cc_x), o2, {}).loss);
      };
      // Every tensor: a random subset of entries (all of the small ones).
      double worst = 0;
      std::string worst_name;
      int skipped = 0, checked = 0;
      auto pattern = [&] { return relu_pattern(ws, cfg); };
      for (auto& t : L.tensors) {
        std::vector<size_t> idx;
        int64_t n = t.size();
        for (int k = 0; k < std::min<int64_t>(n, 12); ++k)
          idx.push_back(size_t(t.offset + (n <= 12 ? k : rng.below(uint32_t(n)))));
        double e = worst_smooth_error(p, grad, loss, pattern, idx, &skipped);
        checked += int(idx.size());
        if (!(e <= worst)) { worst = e; worst_name = t.name; }  // NaN wins
      }
      INFO("worst parameter gradient error " << worst << " in " << worst_name);
      CHECK(worst < kTol);
      CHECK(skipped < checked / 10);  // kinks are rare: most entries are really checked
      // The ray gradient excludes the CC branch's input path (detached): hold it fixed.
      loss();
      const std::vector<double> x0(ws.chunk.x.begin(), ws.chunk.x.begin() + 3 * int64_t(r.R) * r.S);
      cc_x = cfg.has_cc() ? x0.data() : nullptr;
      int skipped_ray = 0;
      double e_o = worst_smooth_error(r.o, d_o, loss, pattern, {}, &skipped_ray, kHRay);
      double e_d = worst_smooth_error(r.d, d_d, loss, pattern, {}, &skipped_ray, kHRay);
      CHECK(skipped_ray <= 3);
      cc_x = nullptr;
      INFO("skipped " << skipped << " of " << checked + 6 * r.R << " entries at kinks");
      INFO("ray origin error " << e_o << ", direction error " << e_d);
      CHECK(e_o < kTol);
      CHECK(e_d < kTol);
      if (k.lam > 0) {
        // The default: the distortion loss reaches the networks, not the camera. The parameter
        // gradient is the one just checked; the ray gradients are those of the colour loss
        // alone (λ = 0), and differ from the ablation's by the distortion's share.
        StepOptions det = opt, none = opt;
        det.distortion_to_camera = false;
        none.distortion = 0;
        std::vector<double> g1(L.count, 0.0), o1(3 * r.R), d1(3 * r.R), g0(L.count, 0.0),
            o0(3 * r.R), d0(3 * r.R);
        ray_batch_step(ws, net, r.batch(), det, {g1.data(), o1.data(), d1.data()});
        ray_batch_step(ws, net, r.batch(), none, {g0.data(), o0.data(), d0.data()});
        CHECK(test::worst_scaled_diff(g1, grad) < 1e-13);
        CHECK(test::worst_scaled_diff(o1, o0) < 1e-12);
        CHECK(test::worst_scaled_diff(d1, d0) < 1e-12);
        CHECK(test::clearly_differs(test::worst_scaled_diff(o1, d_o), 1e-4));  // the detach is real
      }
    }
  }
}

TEST_CASE("model step: float agrees with double", "[model][float]") {
  ModelConfig cfg = small_config(Variant::hashcc);
  ModelLayout L = make_layout(cfg);
  Rng rng(5, 5);
  std::vector<double> p(L.count);
  init_params(p.data(), cfg, L, rng);
  std::vector<float> pf(p.begin(), p.end());
  Rays r = make_rays(7, 16, rng);
  std::vector<float> of(r.o.begin(), r.o.end()), df(r.d.begin(), r.d.end()),
      sf(r.s.begin(), r.s.end()), tf(r.target.begin(), r.target.end());
  StepWorkspace<double> wsd;
  StepWorkspace<float> wsf;
  std::vector<double> gd(L.count, 0.0), dod(3 * r.R), ddd(3 * r.R);
  std::vector<float> gf(L.count, 0.f), dof(3 * r.R), ddf(3 * r.R);
  StepOptions opt;
  auto rd = ray_batch_step(wsd, NetView<double>{p.data(), cfg, L}, r.batch(), opt,
                           {gd.data(), dod.data(), ddd.data()});
  auto rf = ray_batch_step(wsf, NetView<float>{pf.data(), cfg, L},
                           RayBatch<float>{of.data(), df.data(), sf.data(), tf.data(), r.R, r.S},
                           opt, {gf.data(), dof.data(), ddf.data()});
  CHECK(rel_err(rd.loss, rf.loss) < 1e-5);
  double gmax = 0, diff = 0;
  for (int64_t i = 0; i < L.count; ++i) {
    gmax = std::max(gmax, std::abs(gd[i]));
    test::keep_worst(diff, std::abs(gd[i] - gf[i]));  // a NaN in either is an infinite difference
  }
  INFO("max |g_double − g_float| = " << diff << " of max |g| " << gmax);
  CHECK(diff < 1e-3 * gmax);
  for (int i = 0; i < 3 * r.R; ++i) CHECK(std::abs(ddd[i] - ddf[i]) < 1e-3 * (std::abs(ddd[i]) + 1e-3));
}

namespace {

// The full camera → model chain in double: loss as a function of the 6 pose numbers and the
// 2 focal numbers, with the CC input either moving with the camera or held fixed.
struct CameraChain {
  ModelConfig cfg;
  ModelLayout L;
  std::vector<double> p;
  std::vector<int> px;
  std::vector<double> s, target;
  int R, S = 16;
  ImageSize size{40, 30};
  CameraStepWorkspace<double> ws;
  const double* cc_x = nullptr;  // the detached CC input (null: the step's own x)
  bool frozen = false;  // networks frozen (eval's test-pose refinement): d_params = null

  explicit CameraChain(Variant v, Field f = Field::mlp) : cfg(tiny_model_config(v, f)) {
    L = make_layout(cfg);
    Rng rng(23, 9);
    p.resize(L.count);
    init_params(p.data(), cfg, L, rng);
    if (cfg.has_cc())
      for (int64_t i = 0; i < cfg.cc.param_count(); ++i) p[L.cc_table + i] = rng.uniform(-0.5, 0.5);
    if (f == Field::grid)
      for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) p[L.grid_table + i] = rng.uniform(-0.5, 0.5);
    for (int v2 : {3, 11, 25})
      for (int u : {4, 17, 33}) px.insert(px.end(), {u, v2});
    R = int(px.size() / 2);
    for (int r = 0; r < R; ++r) {
      for (int k = 0; k < S; ++k) s.push_back((k + rng.uniform(0.1, 0.9)) / S);
      target.insert(target.end(), {rng.uniform(), rng.uniform(), rng.uniform()});
    }
  }
  // cam = [r0 r1 r2 t0 t1 t2 a b]
  double loss(const std::vector<double>& cam, StepOptions opt, std::vector<double>* grad) {
    opt.data_parallel = false;  // positions() and the kink detector read ws's own cache
    PoseParams<double> pose;
    pose.r = Vec3<double>(cam[0], cam[1], cam[2]);
    pose.t = Vec3<double>(cam[3], cam[4], cam[5]);
    CameraBatch<double> in;
    in.px = px.data();
    in.target = target.data();
    in.s = s.data();
    in.R = R;
    in.S = S;
    in.poses = &pose;
    in.focal.a = cam[6];
    in.focal.b = cam[7];
    in.size = size;
    in.ndc = true;
    in.cc_x = cc_x;
    std::vector<double> dp(L.count, 0.0);
    CameraStepGrads<double> g;
    g.d_params = grad && !frozen ? dp.data() : nullptr;
    auto res = camera_step(ws, NetView<double>{p.data(), cfg, L}, in, opt, g);
    if (grad) {
      last_d_params = dp;
      grad->assign(g.d_pose.begin(), g.d_pose.begin() + 6);
      grad->insert(grad->end(), g.d_focal, g.d_focal + 2);
    }
    return res.loss;
  }
  std::vector<double> last_d_params;  // the parameter gradient of the last loss(…, grad)
  // Sample positions of the step at cam (for holding the CC input fixed).
  std::vector<double> positions(const std::vector<double>& cam) {
    StepOptions opt;
    opt.chunk_rays = 1024;
    loss(cam, opt, nullptr);
    return std::vector<double>(ws.rays.chunk.x.begin(), ws.rays.chunk.x.begin() + 3 * int64_t(R) * S);
  }
};

const std::vector<double> kCam = {0.03, -0.02, 0.01, 0.05, -0.04, 0.02, 1.02, 0.97};

}  // namespace

TEST_CASE("camera gradient through the whole step matches central differences", "[model][camera][grad]") {
  for (Field f : {Field::mlp, Field::grid})
  for (Variant v : {Variant::nerfmm, Variant::sh}) {
    CameraChain ch(v, f);
    StepOptions opt;
    opt.chunk_rays = 1024;
    std::vector<double> g;
    ch.loss(kCam, opt, &g);
    std::vector<double> cam = kCam;
    int skipped = 0;
    double e = worst_smooth_error(cam, g, [&] { return ch.loss(cam, opt, nullptr); },
                                  [&] { return relu_pattern(ch.ws, ch.cfg); }, {}, &skipped, kHCam);
    CHECK(skipped <= 2);
    INFO(variant_name(v) << ", field " << field_name(f) << ": worst camera gradient error " << e);
    CHECK(e < kTol);
  }
}

TEST_CASE("hashcc: the camera gradient excludes the CC input path (detach, formulas.md §5)", "[model][camera][grad]") {
  const Field f = GENERATE(Field::mlp, Field::grid);
  INFO("field " << field_name(f));
  CameraChain ch(Variant::hashcc, f);
  StepOptions opt;
  opt.chunk_rays = 1024;
  std::vector<double> g;
  ch.loss(kCam, opt, &g);
  std::vector<double> cam = kCam;
  // Finite differences with the CC input held at the unperturbed positions agree ...
  std::vector<double> x0 = ch.positions(kCam);
  ch.cc_x = x0.data();
  int skipped = 0;
  auto pattern = [&] { return relu_pattern(ch.ws, ch.cfg); };
  double e_fixed = worst_smooth_error(cam, g, [&] { return ch.loss(cam, opt, nullptr); }, pattern, {}, &skipped, kHCam);
  CHECK(skipped <= 2);
  ch.cc_x = nullptr;
  INFO("CC input held fixed: worst error " << e_fixed);
  CHECK(e_fixed < kTol);
  // ... while letting the CC input move measures something else (the detached path matters).
  int skipped_moving = 0;
  double e_moving = worst_smooth_error(cam, g, [&] { return ch.loss(cam, opt, nullptr); }, pattern, {}, &skipped_moving, kHCam);
  CHECK(skipped_moving <= 2);
  INFO("CC input moving: worst error " << e_moving);
  CHECK(e_moving > 1e-3);
}

TEST_CASE("frozen networks (d_params null, eval's test-pose refinement): the camera gradient "
          "matches central differences and the training step's", "[model][camera][grad]") {
  // With d_params null the step skips every parameter gradient and the whole CC backward
  // (model_backward: the CC branch only has parameter gradients), and the grid field's hash
  // backward runs positions only. The camera gradient must not notice.
  for (Field f : {Field::mlp, Field::grid})
    for (Variant v : {Variant::sh, Variant::hashcc}) {
      INFO(variant_name(v) << ", field " << field_name(f));
      CameraChain ch(v, f);
      StepOptions opt;
      opt.chunk_rays = 1024;
      std::vector<double> g_train, g_frozen;
      const double l_train = ch.loss(kCam, opt, &g_train);
      ch.frozen = true;
      const double l_frozen = ch.loss(kCam, opt, &g_frozen);
      CHECK(l_frozen == l_train);
      for (int k = 0; k < 8; ++k) CHECK(g_frozen[k] == Approx(g_train[k]).epsilon(1e-12).margin(1e-15));
      // Central differences, the CC input held where the step put it (its input is detached).
      std::vector<double> x0 = ch.positions(kCam);
      if (ch.cfg.has_cc()) ch.cc_x = x0.data();
      std::vector<double> cam = kCam;
      int skipped = 0;
      const double e = worst_smooth_error(cam, g_frozen, [&] { return ch.loss(cam, opt, nullptr); },
                                          [&] { return relu_pattern(ch.ws, ch.cfg); }, {}, &skipped,
                                          kHCam);
      CHECK(skipped <= 2);
      INFO("worst camera gradient error " << e);
      CHECK(e < kTol);
      double mag = 0;
      for (double x : g_frozen) mag = std::max(mag, std::abs(x));
      CHECK(mag > 1e-6);
    }
}

TEST_CASE("hashcc ablation: with stop-cc-to-camera the camera gradient equals the model without CC", "[model][camera]") {
  CameraChain hc(Variant::hashcc);
  CameraChain sh(Variant::sh);
  // Same main network: the hashcc layout is the sh layout plus the CC tensors at the end.
  std::copy(hc.p.begin(), hc.p.begin() + sh.L.count, sh.p.begin());
  sh.s = hc.s;
  sh.target = hc.target;
  StepOptions on;
  on.stop_cc_to_camera = true;
  std::vector<double> g_hc, g_sh, g_default;
  hc.loss(kCam, on, &g_hc);
  sh.loss(kCam, StepOptions{}, &g_sh);
  for (int k = 0; k < 8; ++k) CHECK(g_hc[k] == Approx(g_sh[k]).epsilon(1e-10).margin(1e-14));
  // Without the flag the second loss reaches the camera through σ and c: they differ.
  hc.loss(kCam, StepOptions{}, &g_default);
  double diff = 0;
  for (int k = 0; k < 8; ++k) hashcc::test::keep_worst(diff, std::abs(g_default[k] - g_sh[k]));
  CHECK(hashcc::test::clearly_differs(diff, 1e-6));  // a NaN is no real difference
}

TEST_CASE("held cameras (need_ray_grads off): the same loss and parameter gradient, bitwise; "
          "a zero camera gradient", "[model][camera]") {
  // --refine-poses off skips every ray gradient (the first layer's input gradient, the detached
  // second backward of CC and distortion, the camera backward): it must change nothing else.
  for (Field f : {Field::mlp, Field::grid})
    for (Variant v : {Variant::sh, Variant::hashcc}) {
      INFO(variant_name(v) << ", field " << field_name(f));
      CameraChain ch(v, f);
      StepOptions opt;
      opt.chunk_rays = 4;  // several chunks
      opt.distortion = 0.1;
      std::vector<double> g_on, g_off;
      const double l_on = ch.loss(kCam, opt, &g_on);
      const std::vector<double> dp_on = ch.last_d_params;
      opt.need_ray_grads = false;
      const double l_off = ch.loss(kCam, opt, &g_off);
      CHECK(l_off == l_on);
      CHECK(ch.last_d_params == dp_on);
      double on = 0;
      for (int k = 0; k < 8; ++k) {
        CHECK(g_off[k] == 0.0);
        on += std::abs(g_on[k]);
      }
      CHECK(on > 0);
    }
}

TEST_CASE("model: empty batch and one ray", "[model][hard]") {
  ModelConfig cfg = small_config(Variant::hashcc);
  ModelLayout L = make_layout(cfg);
  Rng rng(1, 1);
  std::vector<double> p(L.count), g(L.count, 0.0);
  init_params(p.data(), cfg, L, rng);
  Rays r = make_rays(1, 4, rng);
  StepWorkspace<double> ws;
  const NetView<double> net{p.data(), cfg, L};
  RayBatch<double> b = r.batch();
  b.R = 0;
  auto res0 = ray_batch_step(ws, net, b, StepOptions{}, {g.data()});
  CHECK(res0.loss == 0);
  for (double v : g) CHECK(v == 0);
  std::vector<double> rgb(3), d_o(3), d_d(3);
  b.R = 1;
  auto res1 = ray_batch_step(ws, net, b, StepOptions{}, {g.data(), d_o.data(), d_d.data()},
                             {rgb.data()});
  CHECK(std::isfinite(res1.loss));
  for (double v : rgb) CHECK((v >= 0 && v <= 1.0 + 1e-9));
}

TEST_CASE("data-parallel step: with d_params_zero the first thread adds into d_params, no arena "
          "of its own; the same loss and gradients, bitwise", "[model][exact]") {
  // The trainer zeroes its gradient before every step and says so (StepOptions::d_params_zero):
  // a parameter-sized buffer less a step (16 MiB for the forward recipe's 2^17 grid).
  const test::ThreadGuard two(2);
  for (Field f : {Field::mlp, Field::grid}) {
    INFO("field " << field_name(f));
    const ModelConfig cfg = tiny_model_config(Variant::hashcc, f);
    const ModelLayout L = make_layout(cfg);
    Rng rng(3, 1);
    const FloatStepInputs r = float_step_inputs(cfg, L, rng, 40, 8);
    const RayBatch<float> b = r.batch();
    const NetView<float> net{r.p.data(), cfg, L};
    StepOptions opt;
    opt.chunk_rays = 4;  // ten chunks over the two threads
    opt.distortion = 0.1;
    std::vector<float> g_arena(L.count, 0.f), g_direct(L.count, 0.f), do_a(3 * r.R), dd_a(3 * r.R),
        do_d(3 * r.R), dd_d(3 * r.R);
    StepWorkspace<float> ws_a, ws_d;
    const auto ra = ray_batch_step(ws_a, net, b, opt, {g_arena.data(), do_a.data(), dd_a.data()});
    opt.d_params_zero = true;
    const auto rd = ray_batch_step(ws_d, net, b, opt, {g_direct.data(), do_d.data(), dd_d.data()});
    CHECK(rd.loss == ra.loss);
    CHECK(std::memcmp(g_direct.data(), g_arena.data(), sizeof(float) * L.count) == 0);
    CHECK(do_d == do_a);
    CHECK(dd_d == dd_a);
    REQUIRE(ws_a.thread_grads.size() == 2);
    REQUIRE(ws_d.thread_grads.size() == 2);
    CHECK(ws_a.thread_grads[0].size() >= size_t(L.count));
    CHECK(ws_d.thread_grads[0].empty());  // thread 0 used d_params itself
    CHECK(ws_d.thread_grads[1].size() >= size_t(L.count));
  }
}

TEST_CASE("data-parallel step, grid field: the table gradient scattered a level a thread is the "
          "1-thread step's, bit for bit; every other gradient the arenas' step's", "[model][exact]") {
  // StepOptions::level_scatter (model/step.cpp): the threads' chunks leave their encoding
  // gradients, then each level is scattered by one thread over all the batch's points in order.
  // The grid table's gradient is then independent of the thread count; the networks' (and the
  // CC branch's table) still come from the arenas, as with level_scatter off.
  for (Variant v : {Variant::sh, Variant::hashcc})
    for (double dist : {0.0, 0.1}) {
      INFO(variant_name(v) << ", distortion " << dist);
      const ModelConfig cfg = tiny_model_config(v, Field::grid);
      const ModelLayout L = make_layout(cfg);
      const int64_t tb = L.grid_table, te = tb + cfg.gf.grid.param_count();
      REQUIRE(tb >= 0);
      Rng rng(5, 2);
      const FloatStepInputs r = float_step_inputs(cfg, L, rng, 40, 8);
      const RayBatch<float> b = r.batch();
      const NetView<float> net{r.p.data(), cfg, L};
      struct Out { std::vector<float> g, d_o, d_d; double loss; };
      const auto step = [&](int threads, bool split) {
        const test::ThreadGuard th(threads);
        StepOptions opt;
        opt.chunk_rays = 4;  // ten chunks
        opt.distortion = dist;
        opt.d_params_zero = true;
        opt.level_scatter = split;
        Out out{std::vector<float>(L.count, 0.f), std::vector<float>(3 * r.R), std::vector<float>(3 * r.R), 0};
        StepWorkspace<float> ws;
        out.loss = ray_batch_step(ws, net, b, opt, {out.g.data(), out.d_o.data(), out.d_d.data()}).loss;
        return out;
      };
      const Out one = step(1, true), split = step(2, true), arenas = step(2, false);
      const auto bytes = [](const std::vector<float>& a, int64_t i0, int64_t i1) {
        return std::vector<char>((const char*)(a.data() + i0), (const char*)(a.data() + i1));
      };
      // The table: the 1-thread step's bits at 2 threads.
      CHECK(bytes(split.g, tb, te) == bytes(one.g, tb, te));
      // Everything else: exactly the arenas' step (the same chunks, threads and sums).
      CHECK(bytes(split.g, 0, tb) == bytes(arenas.g, 0, tb));
      CHECK(bytes(split.g, te, L.count) == bytes(arenas.g, te, L.count));
      CHECK(split.loss == arenas.loss);
      CHECK(split.d_o == arenas.d_o);
      CHECK(split.d_d == arenas.d_d);
      // The arenas' table gradient: the same sums in another order (float rounding only).
      std::vector<float> ta(arenas.g.begin() + tb, arenas.g.begin() + te),
          t1(one.g.begin() + tb, one.g.begin() + te);
      const double e = test::vec_rel(ta, t1);
      INFO("arenas vs 1 thread, table: rel " << e);
      CHECK(e < 1e-5);
      CHECK(test::clearly_differs(test::vec_rel(t1, std::vector<float>(t1.size(), 0.f)), 1e-3));
    }
}

TEST_CASE("cache_floats counts what ModelCache::reserve allocates, every field and model",
          "[model][exact]") {
  // The automatic chunk sizes a chunk by cache_floats without allocating; it must be the real
  // cache's size, or the chunk is sized on a wrong figure. Odd widths and sample counts too.
  for (Field f : {Field::mlp, Field::grid})
    for (Variant v : {Variant::nerfmm, Variant::sh, Variant::hashcc})
      for (int width : {128, 37})
        for (auto [R, S] : {std::pair{3, 5}, std::pair{16, 128}}) {
          ModelConfig cfg;
          cfg.variant = v;
          cfg.field = f;
          cfg.width = width;
          INFO(variant_name(v) << ", field " << field_name(f) << ", width " << width << ", R " << R << ", S " << S);
          ModelCache<float> c;
          c.reserve(cfg, R, S);
          CHECK(c.floats() == cache_floats(cfg, R, S));
        }
}

TEST_CASE("the automatic chunk: the largest power of two of rays within kAutoChunkBytes; the "
          "same step as that chunk set by hand", "[model][exact]") {
  ModelConfig paper;  // the paper's hashcc network, width 128
  paper.variant = Variant::hashcc;
  ModelConfig grid = paper;
  grid.field = Field::grid;
  // The fields' per-sample memory differs ~4×, so do their chunks at their sample counts.
  CHECK(resolve_chunk_rays(0, paper, 128) == 16);
  CHECK(resolve_chunk_rays(0, grid, 32) == 256);
  for (const ModelConfig* cfg : {&paper, &grid})
    for (int S : {2, 7, 32, 128, 1000}) {
      INFO("field " << field_name(cfg->field) << ", S " << S);
      const int rays = resolve_chunk_rays(0, *cfg, S);
      CHECK((rays & (rays - 1)) == 0);  // a power of two
      CHECK(rays >= 1);
      CHECK(rays <= kMaxChunkRays);
      if (rays > 1) CHECK(4 * chunk_floats(*cfg, rays, S) <= kAutoChunkBytes);
      if (rays < kMaxChunkRays) CHECK(4 * chunk_floats(*cfg, 2 * rays, S) > kAutoChunkBytes);
    }
  CHECK(resolve_chunk_rays(0, paper, 1 << 16) == 1);      // one ray is over the budget: still 1
  CHECK(resolve_chunk_rays(7, paper, 128) == 7);          // set by hand: as given
  CHECK(resolve_chunk_rays(5000, paper, 128) == kMaxChunkRays);

  // A step with the automatic chunk is the step with that chunk set by hand, bitwise (the same
  // chunks, so the same order of sums). The test's small network and S samples a ray give 4 rays
  // a chunk, so 9 rays make 3 chunks of which the last is short.
  ModelConfig cfg = small_config(Variant::hashcc);
  ModelLayout L = make_layout(cfg);
  Rng rng(3, 1);
  std::vector<double> p(L.count);
  init_params(p.data(), cfg, L, rng);
  int S = 2;
  while (resolve_chunk_rays(0, cfg, S) > 4) S += S / 2;
  REQUIRE(resolve_chunk_rays(0, cfg, S) == 4);
  Rays r = make_rays(9, S, rng);
  const NetView<double> net{p.data(), cfg, L};
  auto run = [&](int chunk_rays, std::vector<double>& g, std::vector<double>& d_o) {
    StepWorkspace<double> ws;
    StepOptions opt;
    opt.chunk_rays = chunk_rays;
    g.assign(L.count, 0.0);
    d_o.assign(3 * r.R, 0.0);
    std::vector<double> d_d(3 * r.R);
    return ray_batch_step(ws, net, r.batch(), opt, {g.data(), d_o.data(), d_d.data()}).loss;
  };
  std::vector<double> g_auto, o_auto, g_four, o_four, g_all, o_all;
  const double l_auto = run(0, g_auto, o_auto), l_four = run(4, g_four, o_four), l_all = run(9, g_all, o_all);
  CHECK(l_auto == l_four);
  CHECK(g_auto == g_four);
  CHECK(o_auto == o_four);
  // ...and the comparison can fail: one chunk of all 9 rays sums in another order.
  CHECK(l_all == Approx(l_auto).epsilon(1e-12));
  CHECK(g_all != g_auto);
}

TEST_CASE("render_view: the same image at any chunk and thread count, bitwise", "[model][exact]") {
  // render_view hands ray_batch_render one chunk a thread per call; the chunks run side by side
  // with serial kernels, or one at a time with threaded kernels. A pixel's value may not depend
  // on which: every kernel of the forward computes a sample's row the same way in either.
  for (Field f : {Field::mlp, Field::grid}) {
    INFO("field " << field_name(f));
    ModelConfig cfg = small_config(Variant::hashcc);
    cfg.field = f;
    ModelLayout L = make_layout(cfg);
    Rng rng(5, 1);
    std::vector<float> p(L.count);
    init_params(p.data(), cfg, L, rng);
    if (f == Field::grid)  // table values that matter (the init is ±1e-4)
      for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) p[L.grid_table + i] = float(rng.uniform(-0.5, 0.5));
    for (int64_t i = 0; i < cfg.cc.param_count(); ++i) p[L.cc_table + i] = float(rng.uniform(-0.5, 0.5));
    const NetView<float> net{p.data(), cfg, L};
    ViewCamera cam;
    cam.pose.r = Vec3<float>(0.02f, -0.03f, 0.01f);
    cam.size = {23, 17};  // 391 pixels: ragged last blocks and chunks
    auto render = [&](int chunk, int threads) {
      const int keep = num_threads();
      set_num_threads(threads);
      StepWorkspace<float> ws;
      ViewImage v = render_view(ws, net, cam, {16, 1, chunk, nullptr});
      set_num_threads(keep);
      return v;
    };
    const ViewImage ref = render(1024, 1);  // one chunk a call
    double sum = 0;
    for (float v : ref.rgb) sum += v;
    CHECK(sum > 0);
    for (auto [chunk, threads] : {std::pair{3, 2}, std::pair{7, 1}, std::pair{0, 2}, std::pair{64, 2}}) {
      INFO("chunk " << chunk << ", threads " << threads);
      const ViewImage v = render(chunk, threads);
      CHECK(v.rgb == ref.rgb);
      CHECK(v.depth == ref.depth);
      CHECK(v.opacity == ref.opacity);
    }
  }
}

TEST_CASE("coarse-to-fine band weights follow BARF's cosine ramp at several alpha", "[model][exact]") {
  // BARF (Lin et al. 2021): w_k(α) = (1 − cos(π·clamp(α − k, 0, 1)))/2. w(2.5) = 0.5 alone
  // cannot tell this ramp from a linear one; a quarter and three quarters into a band can:
  // (1 − cos(π/4))/2 = (2 − √2)/4 = 0.14644660940672624, (2 + √2)/4 = 0.85355339059327373
  // (a linear ramp gives 0.25 and 0.75).
  double w[10];
  c2f_band_weights(w, 10, -1.0);
  for (double v : w) CHECK(v == 1.0);   // α < 0: off, every band at 1
  c2f_band_weights(w, 10, 0.0);
  for (double v : w) CHECK(v == 0.0);
  c2f_band_weights(w, 10, 0.25);
  CHECK(w[0] == Approx(0.14644660940672624).epsilon(1e-15));
  for (int k = 1; k < 10; ++k) CHECK(w[k] == 0.0);
  c2f_band_weights(w, 10, 3.75);
  for (int k = 0; k < 3; ++k) CHECK(w[k] == 1.0);
  CHECK(w[3] == Approx(0.85355339059327373).epsilon(1e-15));
  for (int k = 4; k < 10; ++k) CHECK(w[k] == 0.0);
  c2f_band_weights(w, 10, 2.5);
  CHECK(w[2] == Approx(0.5).epsilon(1e-15));
  c2f_band_weights(w, 10, 10.0);
  for (double v : w) CHECK(v == 1.0);
  // A sweep against the closed form written here, and its shape: flat (zero slope) at both
  // ends of a band's ramp, as a cosine is and a linear ramp is not.
  for (double a = 0; a <= 11; a += 0.0625) {
    c2f_band_weights(w, 10, a);
    for (int k = 0; k < 10; ++k) {
      const double t = std::clamp(a - k, 0.0, 1.0);
      CHECK(w[k] == Approx((1 - std::cos(M_PI * t)) / 2).epsilon(1e-15).margin(1e-300));
    }
  }
  double lo[10], hi[10];
  c2f_band_weights(lo, 10, 4.001);
  c2f_band_weights(hi, 10, 4.999);
  CHECK(lo[4] < 1e-5);        // ≈ (π·0.001)²/4 = 2.5e-6; linear: 1e-3
  CHECK(1 - hi[4] < 1e-5);
}

TEST_CASE("coarse-to-fine: the step's parameter, origin and direction gradients, every variant",
          "[model][grad]") {
  // The whole step with α = 3.3 (bands 0–2 on, band 3 at 0.39, the rest off): parameter and
  // both ray gradients match central differences for nerfmm, sh and hashcc (its CC input held
  // fixed for the ray gradients, formulas.md §5).
  for (Variant v : {Variant::nerfmm, Variant::sh, Variant::hashcc}) {
    DYNAMIC_SECTION("variant " << variant_name(v)) {
      ModelConfig cfg = small_config(v);
      cfg.pos_c2f_alpha = 3.3;
      ModelLayout L = make_layout(cfg);
      Rng rng(31, 3);
      std::vector<double> p(L.count);
      init_params(p.data(), cfg, L, rng);
      p[L.density.b] = 2.0;  // density everywhere, so every path carries gradient
      if (cfg.has_cc())
        for (int64_t i = 0; i < cfg.cc.param_count(); ++i) p[L.cc_table + i] = rng.uniform(-0.5, 0.5);
      Rays r = make_rays(4, 10, rng);
      StepWorkspace<double> ws;
      StepOptions opt;
      opt.chunk_rays = 1024;
      opt.data_parallel = false;
      std::vector<double> grad(L.count, 0.0), d_o(3 * r.R), d_d(3 * r.R);
      const NetView<double> net{p.data(), cfg, L};
      ray_batch_step(ws, net, r.batch(), opt, {grad.data(), d_o.data(), d_d.data()});
      const double* cc_x = nullptr;
      auto loss = [&] {
        StepOptions o2 = opt;
        o2.need_ray_grads = false;
        return double(ray_batch_step(ws, net, r.batch(cc_x), o2, {}).loss);
      };
      auto pattern = [&] { return relu_pattern(ws, cfg); };
      int skipped = 0;
      std::vector<size_t> idx;
      for (int k = 0; k < 24; ++k) idx.push_back(size_t(L.trunk[0].w) + rng.below(uint32_t(L.trunk[0].in * L.trunk[0].out)));
      double e_w = worst_smooth_error(p, grad, loss, pattern, idx, &skipped);
      loss();
      const std::vector<double> x0(ws.chunk.x.begin(), ws.chunk.x.begin() + 3 * int64_t(r.R) * r.S);
      cc_x = cfg.has_cc() ? x0.data() : nullptr;
      // h = 1e-5 for the rays: with α = 3.3 no band above 2³ is on, so the 3-point truncation
      // (h·2³)²/6 ≈ 1e-9 is far below the tolerance, while rounding (~1e-16/h) stays 10× below
      // the 1e-6 of kHRay (at 1e-6 a small origin entry of nerfmm measured 1.1e-5: rounding).
      const double h_ray = 1e-5;
      double e_o = worst_smooth_error(r.o, d_o, loss, pattern, {}, &skipped, h_ray);
      double e_d = worst_smooth_error(r.d, d_d, loss, pattern, {}, &skipped, h_ray);
      cc_x = nullptr;
      INFO("first-layer weights " << e_w << ", ray origins " << e_o << ", directions " << e_d
                                  << ", skipped " << skipped);
      CHECK(e_w < kTol);
      CHECK(e_o < kTol);
      CHECK(e_d < kTol);
      CHECK(skipped <= 4);
      // Non-trivial: the checked gradients are not all zero (a zero field would pass vacuously),
      // and the first layer's columns of fully-off bands (k ≥ 4) get exactly zero gradient.
      double gmax = 0, omax = 0, dmax = 0;
      for (size_t i : idx) gmax = std::max(gmax, std::abs(grad[i]));
      for (double x : d_o) omax = std::max(omax, std::abs(x));
      for (double x : d_d) dmax = std::max(dmax, std::abs(x));
      CHECK(gmax > 1e-8);
      CHECK(omax > 1e-8);
      CHECK(dmax > 1e-8);
      const LayerView& l0 = L.trunk[0];
      for (int o = 0; o < l0.out; ++o)
        for (int k = 4; k < cfg.pos_bands; ++k)
          for (int j = 0; j < 6; ++j) CHECK(grad[l0.w + int64_t(o) * l0.in + 3 + 6 * k + j] == 0.0);
    }
  }
}

TEST_CASE("coarse-to-fine on the grid field: table, network and ray gradients with a level partly on, "
          "at every level boundary", "[model][grad][c2f]") {
  // The level curriculum w_l(α) = (1 − cos(π·clamp(α − l, 0, 1)))/2 (docs/math/grid_field.md)
  // scales level l of the encoding and of its gradient (model/grid_field.cpp, scale_levels).
  // The trainer raises α from --grid-c2f-start (2) to L = 4 here, crossing levels 2 and 3; each
  // α below puts one level l = ⌊α⌋ partly on (0 < w_l < 1), for every level 0…3, so every
  // boundary the curriculum can cross is covered. For each: the 4 largest table entries of every
  // level (the partly-on one among them; a level off has only zeros, and its difference must be
  // 0 too), 4 random entries of every other tensor, and every ray origin and direction entry
  // (CC input held, formulas.md §5), against central differences (worst_smooth_error: h = 1e-4,
  // kinks skipped, floor 1e-7, tolerance kTol = 1e-5 as the other [model][grad] cases). hashcc:
  // the CC branch rides on top. The exact position gradient (grid_smooth false, the tiny config).
  for (double alpha : {0.4, 1.5, 2.3, 3.7}) {
    DYNAMIC_SECTION("alpha " << alpha) {
      ModelConfig cfg = tiny_model_config(Variant::hashcc, Field::grid);
      cfg.pos_c2f_alpha = alpha;
      const int partly = int(std::floor(alpha));
      double w[4];
      c2f_band_weights(w, 4, alpha);
      REQUIRE(w[partly] > 0.05);
      REQUIRE(w[partly] < 0.95);
      ModelLayout L = make_layout(cfg);
      Rng rng(41, uint64_t(alpha * 10));
      std::vector<double> p(L.count);
      init_params(p.data(), cfg, L, rng);
      for (int64_t i = 0; i < cfg.cc.param_count(); ++i) p[L.cc_table + i] = rng.uniform(-0.5, 0.5);
      for (int64_t i = 0; i < cfg.gf.grid.param_count(); ++i) p[L.grid_table + i] = rng.uniform(-0.5, 0.5);
      Rays r = make_rays(4, 10, rng);
      StepWorkspace<double> ws;
      StepOptions opt;
      opt.chunk_rays = 1024;
      opt.data_parallel = false;
      std::vector<double> grad(L.count, 0.0), d_o(3 * r.R), d_d(3 * r.R);
      const NetView<double> net{p.data(), cfg, L};
      ray_batch_step(ws, net, r.batch(), opt, {grad.data(), d_o.data(), d_d.data()});
      const double* cc_x = nullptr;
      auto loss = [&] {
        StepOptions o2 = opt;
        o2.need_ray_grads = false;
        return double(ray_batch_step(ws, net, r.batch(cc_x), o2, {}).loss);
      };
      auto pattern = [&] { return relu_pattern(ws, cfg); };
      const int64_t per = cfg.gf.grid.table_size() * cfg.gf.grid.features;
      std::vector<size_t> idx;
      for (int l = 0; l < 4; ++l) {
        std::vector<size_t> lv(per);
        for (int64_t j = 0; j < per; ++j) lv[j] = size_t(L.grid_table + l * per + j);
        std::stable_sort(lv.begin(), lv.end(), [&](size_t a, size_t b) { return std::abs(grad[a]) > std::abs(grad[b]); });
        idx.insert(idx.end(), lv.begin(), lv.begin() + 4);
      }
      for (const auto& t : L.tensors)
        if (t.name != "grid.table")
          for (int k = 0; k < 4; ++k) idx.push_back(size_t(t.offset + rng.below(uint32_t(t.size()))));
      int skipped = 0;
      const double e_p = worst_smooth_error(p, grad, loss, pattern, idx, &skipped);
      loss();
      const std::vector<double> x0(ws.chunk.x.begin(), ws.chunk.x.begin() + 3 * int64_t(r.R) * r.S);
      cc_x = x0.data();
      // h = 1e-6 for the rays (kHRay): they move every sample of the ray through the grid's
      // cells, and the finest level (scale 31) puts a face every 1/31: a smaller step keeps the
      // crossings (skipped) rare.
      const double e_o = worst_smooth_error(r.o, d_o, loss, pattern, {}, &skipped, kHRay);
      const double e_d = worst_smooth_error(r.d, d_d, loss, pattern, {}, &skipped, kHRay);
      cc_x = nullptr;
      // The levels: above the partly-on one, no gradient at all; the partly-on one has some.
      double part = 0, off = 0;
      for (int64_t i = 0; i < per; ++i) part = std::max(part, std::abs(grad[L.grid_table + partly * per + i]));
      for (int64_t i = (partly + 1) * per; i < 4 * per; ++i) off = std::max(off, std::abs(grad[L.grid_table + i]));
      INFO("alpha " << alpha << ": w = " << w[partly] << ", parameters " << e_p << ", ray origins "
                    << e_o << ", directions " << e_d << ", skipped " << skipped << " of "
                    << idx.size() + 6 * r.R << "; level " << partly << "'s largest table gradient " << part);
      test::record_tolerance("[model][grad][c2f] grid field, parameters",
                             fmt::format("alpha {} (level {} at w = {:.3f})", alpha, partly, w[partly]), e_p, kTol);
      test::record_tolerance("[model][grad][c2f] grid field, ray origins and directions",
                             fmt::format("alpha {}", alpha), std::max(e_o, e_d), kTol);
      CHECK(e_p < kTol);
      CHECK(e_o < kTol);
      CHECK(e_d < kTol);
      CHECK(skipped <= 4);
      CHECK(part > 1e-6);  // measured 5e-5…: far above the differences' noise (~1e-13)
      CHECK(off == 0);
    }
  }
}
