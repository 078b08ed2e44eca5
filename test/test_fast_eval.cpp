// Issue 53, where the user waits: the test-pose refinement's batched step (all test views in one
// camera_step) gives the one-view-a-step refinement's numbers bit for bit; the fast refinement
// (fewer rays a view, the same Adam schedule) recovers a known pose offset as well as the spec's;
// the render shortcuts (early ray termination, no colour for weightless samples) stay within
// their stated bound of the exact render, and with both thresholds at 0 equal it.
#include <catch2/catch.hpp>

#include "test/fixtures.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include "camera/camera.h"
#include "core/error.h"
#include "core/image.h"
#include "core/parallel.h"
#include "eval/evaluate.h"
#include "model/render_view.h"
#include "train/trainer.h"

using namespace hashcc;

namespace {

// A tiny HashCC grid field trained `steps` steps on the simulated scene (cameras learning), so
// that it has structure to align against.
TrainConfig grid_config(const std::string& data, int64_t steps) {
  TrainConfig c = test::tiny_train_config(data, "", steps);
  c.model.field = Field::grid;
  c.model.variant = Variant::hashcc;
  c.model.gf.grid.log2_table = 12;
  c.model.gf.grid.levels = 8;
  c.model.gf.grid.max_res = 128;
  c.model.gf.hidden = 16;
  c.model.gf.rgb_hidden = 16;
  c.model.gf.density_init = 2;
  c.lr_net = 0.02;
  c.lr_net_end = 0.005;
  c.samples = 32;
  c.rays = 256;
  return c;
}

// grid_config's field trained 300 steps on the 64×48 simulated scene (a fresh trainer each call).
std::unique_ptr<Trainer> trained_grid() {
  const std::string data = test::sim_scene("exact", 17, 64, 48, 1);
  auto t = std::make_unique<Trainer>(grid_config(data, 300));
  for (int i = 0; i < 300; ++i) t->step_once();
  return t;
}

std::vector<PoseParams<float>> test_init(const Trainer& t) {
  return test_pose_params(t, TestInit::kScale, nullptr);
}

// The exact render of `pose` as an 8-bit image (a target the field can match exactly, up to
// rounding).
ImageU8 render_target(const Trainer& t, const PoseParams<float>& pose) {
  StepWorkspace<float> ws;
  const ViewImage v = render_view(ws, t.net(), t.view_camera(pose), {t.config().samples, 1, 0, nullptr});
  ImageU8 im;
  im.width = v.width;
  im.height = v.height;
  im.rgb.resize(v.rgb.size());
  for (size_t i = 0; i < v.rgb.size(); ++i)
    im.rgb[i] = uint8_t(std::lround(std::clamp(v.rgb[i], 0.f, 1.f) * 255.f));
  return im;
}

// How far a refined pose is from the true one: |Δr| (rad) + |Δt| of the composed c2w.
double pose_distance(const PoseParams<float>& a, const PoseParams<float>& b) {
  const Mat34<double> A = world_from_camera(a.cast<double>()), B = world_from_camera(b.cast<double>());
  const Mat3<double> dR = A.leftCols<3>() * B.leftCols<3>().transpose();
  return so3::angle(dR) + (A.col(3) - B.col(3)).norm();
}

}  // namespace

TEST_CASE("refine: all test views in one step follow the one-view-a-step poses; the spec's mode "
          "keeps one step a view", "[evalcmd][refine]") {
  const std::string data = test::sim_scene("exact", 17, 40, 30, 1);  // 3 test views
  for (Field f : {Field::mlp, Field::grid}) {
    CAPTURE(field_name(f));
    TrainConfig c = f == Field::grid ? grid_config(data, 10) : test::tiny_train_config(data, "", 10);
    c.chunk_rays = 16;  // 4 chunks a view: views and chunks line up
    Trainer t(c);
    for (int i = 0; i < 10; ++i) t.step_once();
    const std::vector<PoseParams<float>> init = test_init(t);
    REQUIRE(init.size() == 3);
    // The spec's mode: one step a view (the published numbers' code path), the run's grid.
    EvalOptions eo;
    CHECK(eo.refine_mode == RefineMode::kFast);  // the default since session 27
    eo.refine_epochs = 7;
    eo.refine_mode = RefineMode::kAdam;
    const RefineOptions spec = refine_options(t, eo);
    CHECK_FALSE(spec.batched);
    CHECK(spec.rows * spec.cols == c.rays);
    eo.refine_mode = RefineMode::kFast;
    const RefineOptions fast = refine_options(t, eo);
    CHECK(fast.batched);
    CHECK(fast.rows == 8);
    CHECK(fast.cols == 16);
    CHECK(fast.full_epochs == kFastRefineFullEpochs);  // the run's grid while lr is 5e-4
    CHECK(spec.full_epochs == 0);
    std::vector<const ImageU8*> targets;
    for (int i : t.scene().test) targets.push_back(&t.scene().images[size_t(i)]);
    for (int threads : {1, 2}) {
      set_num_threads(threads);
      RefineOptions one = spec;
      RefineOptions all = one;
      all.batched = true;
      const RefineResult a = refine_poses(t, init, targets, one);
      const RefineResult b = refine_poses(t, init, targets, all);
      CHECK_FALSE(a.batched);
      CHECK(b.batched);
      REQUIRE(a.epoch_loss.size() == b.epoch_loss.size());
      // The same steps: the losses agree to float rounding (measured ~1e-8 relative; a wrong
      // Adam order or ray split would move them by far more).
      for (size_t e = 0; e < a.epoch_loss.size(); ++e)
        CHECK(b.epoch_loss[e] == Approx(a.epoch_loss[e]).epsilon(1e-6));
      double moved = 0, diff = 0;
      for (size_t k = 0; k < init.size(); ++k) {
        moved += (a.poses[k].r.norm() + a.poses[k].t.norm());
        diff += (a.poses[k].r - b.poses[k].r).norm() + (a.poses[k].t - b.poses[k].t).norm();
      }
      INFO("moved " << moved << ", batched differs by " << diff);
      CHECK(moved > 1e-3);          // the poses moved: not a comparison of two zero vectors
      CHECK(diff < 1e-3 * moved);   // and the batched ones moved with them
      // Deterministic: the spec's mode twice gives the same bits.
      const RefineResult a2 = refine_poses(t, init, targets, one);
      CHECK(a2.epoch_deltas == a.epoch_deltas);
    }
    set_num_threads(2);
  }
}

TEST_CASE("refine: the fast mode returns the mean of its iterates over the last two lr levels "
          "after the full-grid epochs; the spec's mode the last iterate", "[evalcmd][refine]") {
  CHECK(fast_refine_average_from(1000) == 600);  // lr 6.25e-5 and 3.125e-5: epochs 600–999
  CHECK(fast_refine_average_from(1200) == 800);
  CHECK(fast_refine_average_from(1001) == 800);  // a 6th level of one epoch: levels 5 and 6
  CHECK(fast_refine_average_from(400) == 200);   // never inside the full-grid epochs
  CHECK(fast_refine_average_from(300) == 200);
  CHECK(fast_refine_average_from(200) == -1);    // all on the run's grid: nothing to average
  CHECK(fast_refine_average_from(100) == -1);
  CHECK(fast_refine_average_from(0) == -1);
  const std::string data = test::sim_scene("exact", 17, 40, 30, 1);
  TrainConfig c = grid_config(data, 10);
  Trainer t(c);
  for (int i = 0; i < 10; ++i) t.step_once();
  EvalOptions eo;
  eo.refine_epochs = 1000;
  eo.refine_mode = RefineMode::kAdam;
  CHECK(refine_options(t, eo).average_from == -1);
  eo.refine_mode = RefineMode::kFast;
  CHECK(refine_options(t, eo).average_from == 600);
  const std::vector<PoseParams<float>> init = test_init(t);
  std::vector<const ImageU8*> targets;
  for (int i : t.scene().test) targets.push_back(&t.scene().images[size_t(i)]);
  RefineOptions ro;
  ro.epochs = 12;
  const RefineResult last = refine_poses(t, init, targets, ro);
  ro.average_from = 8;
  const RefineResult avg = refine_poses(t, init, targets, ro);
  CHECK(last.average_from == -1);
  CHECK(avg.average_from == 8);
  REQUIRE(avg.epoch_deltas.size() == 12);
  CHECK(avg.epoch_deltas == last.epoch_deltas);  // the same iterates; only the answer differs
  REQUIRE(avg.averaged.size() == init.size());
  double diff = 0;
  for (size_t k = 0; k < init.size(); ++k) {
    const WindowEstimate w = refine_window_estimate(avg.epoch_deltas, 8, int(k));
    CHECK(avg.averaged[k] == w.averaged);
    for (int j = 0; j < 6; ++j) {
      const float got = j < 3 ? avg.poses[k].r[j] : avg.poses[k].t[j - 3];
      const float it = last.epoch_deltas.back()[6 * k + size_t(j)];
      CHECK(got == w.p[j]);
      CHECK((j < 3 ? last.poses[k].r[j] : last.poses[k].t[j - 3]) == it);
      diff += std::abs(double(got) - double(it));
    }
  }
  CHECK(diff > 0);  // the iterates moved over the window: the answer is not the last one
  // The estimator on made-up iterates (two views, 400 epochs from 600): view 0 settled, jitter
  // ±0.01 about 0.3 (alternating, so its half-means agree): the mean, 0.3 to float rounding;
  // view 1 travelling, 0.001 an epoch with the same jitter: the trend line's value at epoch 999,
  // not the mean (0.2 behind) nor the last iterate (0.01 off).
  std::vector<std::vector<float>> its(1000, std::vector<float>(12, 0.f));
  for (int e = 600; e < 1000; ++e) {
    const float jit = (e % 2 ? 0.01f : -0.01f);
    its[size_t(e)][0] = 0.3f + jit;
    its[size_t(e)][6 + 4] = 0.001f * float(e - 600) + jit;
  }
  const WindowEstimate s0 = refine_window_estimate(its, 600, 0), s1 = refine_window_estimate(its, 600, 1);
  CHECK(s0.averaged);
  CHECK(s0.p[0] == Approx(0.3).margin(1e-6));
  CHECK_FALSE(s1.averaged);
  CHECK(s1.p[4] == Approx(0.399).margin(1e-4));  // 0.001·399, the jitter fitted out
  CHECK(std::abs(s1.p[4] - its[999][10]) > 0.005);
  // No movement at all: the mean, exactly.
  std::vector<std::vector<float>> flat(10, std::vector<float>(6, 0.25f));
  CHECK(refine_window_estimate(flat, 2, 0).averaged);
  CHECK(refine_window_estimate(flat, 2, 0).p[0] == 0.25f);
}

TEST_CASE("refine: the fast mode recovers a known test-pose offset as well as the spec's Adam",
          "[evalcmd][refine]") {
  const std::unique_ptr<Trainer> tp = trained_grid();
  Trainer& t = *tp;
  const std::vector<PoseParams<float>> truth = test_init(t);
  // Targets: the field's own exact renders at the true poses; starts: those poses turned by
  // ~1.1° and shifted by 0.01 (known offsets, different per view).
  std::vector<ImageU8> imgs;
  for (const auto& p : truth) imgs.push_back(render_target(t, p));
  std::vector<const ImageU8*> targets;
  for (const auto& im : imgs) targets.push_back(&im);
  std::vector<PoseParams<float>> start = truth;
  for (size_t k = 0; k < start.size(); ++k) {
    const float sg = k % 2 ? -1.f : 1.f;
    start[k].r = Vec3<float>(0.012f * sg, -0.015f, 0.008f);
    start[k].t = Vec3<float>(0.01f, 0.006f * sg, -0.008f);
  }
  double d0 = 0;
  for (size_t k = 0; k < start.size(); ++k) d0 += pose_distance(start[k], truth[k]);
  RefineOptions spec;
  spec.epochs = 200;  // the spec's 8×8 rays a view (the run's grid)
  RefineOptions fast = spec;
  fast.rows = 4;  // a quarter of the rays, the fast mode's ratio (128 of 1,024 is an eighth)
  fast.cols = 4;
  fast.split_chunks = true;
  RefineOptions fast2 = fast;  // the fast mode's schedule: the run's grid first, then fewer
  fast2.full_epochs = 50;
  RefineOptions fast3 = fast2;  // … and the mean of the iterates after epoch 150
  fast3.average_from = 150;
  const RefineResult a = refine_poses(t, start, targets, spec);
  const RefineResult b = refine_poses(t, start, targets, fast);
  const RefineResult b2 = refine_poses(t, start, targets, fast2);
  const RefineResult b3 = refine_poses(t, start, targets, fast3);
  CHECK(b.rays_per_view == 16);
  CHECK(b2.full_epochs == 50);
  double da = 0, db = 0, db2 = 0, db3 = 0;
  for (size_t k = 0; k < start.size(); ++k) {
    da += pose_distance(a.poses[k], truth[k]);
    db += pose_distance(b.poses[k], truth[k]);
    db2 += pose_distance(b2.poses[k], truth[k]);
    db3 += pose_distance(b3.poses[k], truth[k]);
  }
  INFO("offset: start " << d0 << ", spec Adam " << da << ", fast " << db << ", fast after 50 full epochs " << db2
       << ", and averaged over epochs 150-199 " << db3);
  CHECK(db3 < 0.25 * d0);
  CHECK(db3 < 1.5 * da + 0.02 * d0);
  CHECK(db2 < 0.25 * d0);
  CHECK(db2 < 1.5 * da + 0.02 * d0);
  CHECK(da < 0.25 * d0);  // the spec's refinement recovers most of the offset
  CHECK(db < 0.25 * d0);  // so does the fast one
  CHECK(db < 1.5 * da + 0.02 * d0);
}

TEST_CASE("render shortcuts: within their bound of the exact render; with zero thresholds equal to it",
          "[render][shortcuts]") {
  const std::unique_ptr<Trainer> tp = trained_grid();
  Trainer& t = *tp;
  const ViewCamera cam = t.view_camera(t.pose_of(0));
  StepWorkspace<float> ws;
  ViewOptions exact{64, 1, 0, nullptr};
  RenderStats se, sc, s0;
  const ViewImage a = render_view(ws, t.net(), cam, exact, &se);
  ViewOptions fast = exact;
  fast.shortcuts = true;
  REQUIRE(render_shortcuts_apply(t.config().model, fast));
  const ViewImage b = render_view(ws, t.net(), cam, fast, &sc);
  ViewOptions zero = fast;
  zero.t_min = 0;
  zero.w_min_total = 0;
  const ViewImage c = render_view(ws, t.net(), cam, zero, &s0);
  // The exact render evaluates every sample; the shortcuts fewer.
  CHECK(se.density == se.samples);
  CHECK(sc.samples == se.samples);
  CHECK(sc.density < se.samples);
  CHECK(sc.colour < sc.density);
  INFO("density " << sc.density << " colour " << sc.colour << " of " << sc.samples);
  // Zero thresholds: every sample, the same numbers (the same kernels, the same order).
  CHECK(s0.density == s0.samples);
  double d0 = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) d0 = std::max(d0, double(std::abs(a.rgb[i] - c.rgb[i])));
  for (size_t i = 0; i < a.depth.size(); ++i)
    d0 = std::max({d0, double(std::abs(a.depth[i] - c.depth[i])),
                   double(std::abs(a.opacity[i] - c.opacity[i]))});
  CHECK(d0 <= 1e-6);
  // The bound: the weight left out of a colour is < t_min + S·w_min = 1e-4, times the largest
  // |colour| (c + Δc; ≤ 1.5 here), plus float rounding.
  double dc = 0, dd = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) dc = std::max(dc, double(std::abs(a.rgb[i] - b.rgb[i])));
  for (size_t i = 0; i < a.depth.size(); ++i)
    dd = std::max({dd, double(std::abs(a.depth[i] - b.depth[i])),
                   double(std::abs(a.opacity[i] - b.opacity[i]))});
  INFO("max |Δ colour| " << dc << ", max |Δ depth or opacity| " << dd);
  CHECK(dc < 1.5e-4 + 1e-6);
  CHECK(dd < 1e-4 + 1e-6);
}

TEST_CASE("render shortcuts with an empty-space grid: all occupied = the shortcuts' frame; empty "
          "cells skip their samples (σ = 0, nothing evaluated)", "[render][shortcuts]") {
  const std::unique_ptr<Trainer> tp = trained_grid();
  Trainer& t = *tp;
  const ViewCamera cam = t.view_camera(t.pose_of(0));
  StepWorkspace<float> ws;
  ViewOptions fast{64, 1, 0, nullptr};
  fast.shortcuts = true;
  RenderStats sf, sa, se;
  const ViewImage a = render_view(ws, t.net(), cam, fast, &sf);
  // A grid whose every cell holds σ above its threshold: every sample is evaluated as before.
  OccupancyGrid all = empty_space_grid(t.net(), 16, 1e-30, 1);
  REQUIRE(all.occupied_fraction() == 1.0);
  ViewOptions with_all = fast;
  with_all.skip = &all;
  const ViewImage b = render_view(ws, t.net(), cam, with_all, &sa);
  CHECK(sa.density == sf.density);
  CHECK(sa.colour == sf.colour);
  CHECK(b.rgb == a.rgb);
  CHECK(b.depth == a.depth);
  // The far half of the box (NDC z > 0) marked empty: those samples get σ = 0, so fewer are
  // evaluated, and a ray's opacity can only drop (its σ there is now 0).
  OccupancyGrid half = all;
  const int G = half.options().res;
  for (int64_t c = 0; c < int64_t(G) * G * G; ++c)
    if (c / (int64_t(G) * G) >= G / 2 + 1) half.cell_sigma()[c] = 0.f;  // beyond the dilation
  half.rebuild();
  REQUIRE(half.occupied_fraction() == 10.0 / 16);  // layers z ≥ 9 emptied, z = 9 kept by the dilation
  ViewOptions with_half = fast;
  with_half.skip = &half;
  const ViewImage c = render_view(ws, t.net(), cam, with_half, &se);
  CHECK(se.density < sf.density);
  double max_up = 0, max_change = 0;
  for (size_t i = 0; i < a.opacity.size(); ++i) {
    max_up = std::max(max_up, double(c.opacity[i]) - double(a.opacity[i]));
    max_change = std::max(max_change, std::abs(double(c.opacity[i]) - double(a.opacity[i])));
  }
  INFO("evaluated " << se.density << " of " << sf.density << "; largest opacity change " << max_change);
  CHECK(max_up <= 1e-6);
  CHECK(max_change > 0);  // the skip reaches the picture (the field has density back there)
}

TEST_CASE("refine: a view mask refines those views alone, to the bits a run over every view gives "
          "them; the others come back as they went in", "[evalcmd][refine]") {
  const std::string data = test::sim_scene("exact", 17, 40, 30, 1);  // 3 test views
  TrainConfig c = grid_config(data, 10);
  Trainer t(c);
  for (int i = 0; i < 10; ++i) t.step_once();
  const std::vector<PoseParams<float>> init = test_init(t);
  REQUIRE(init.size() == 3);
  std::vector<const ImageU8*> targets;
  for (int i : t.scene().test) targets.push_back(&t.scene().images[size_t(i)]);
  EvalOptions eo;
  eo.refine_epochs = 9;
  eo.refine_mode = RefineMode::kAdam;
  RefineOptions all = refine_options(t, eo);
  const RefineResult a = refine_poses(t, init, targets, all);
  for (const std::vector<bool>& mask : {std::vector<bool>{false, true, false},
                                        std::vector<bool>{true, false, true}}) {
    RefineOptions some = all;
    some.views = mask;
    const RefineResult b = refine_poses(t, init, targets, some);
    for (size_t k = 0; k < 3; ++k) {
      CAPTURE(k, mask[k]);
      const PoseParams<float>& want = mask[k] ? a.poses[k] : init[k];
      CHECK(b.poses[k].r == want.r);  // bit for bit: the zero-gradient steps of the views left
      CHECK(b.poses[k].t == want.t);  // out keep Adam's step count and the moments' decay
      if (mask[k]) CHECK((a.poses[k].r - init[k].r).norm() > 0);  // and it did move
    }
  }
  RefineOptions bad = all;
  bad.views = {true, false};  // a mask of the wrong length
  CHECK_THROWS_AS(refine_poses(t, init, targets, bad), Error);
  bad.views = {true, false, true};
  bad.batched = true;  // the batched step has no masked views
  CHECK_THROWS_AS(refine_poses(t, init, targets, bad), Error);
}

TEST_CASE("eval, fast mode: a test camera still moving at the end is refined again in the spec's "
          "mode and keeps the spec's pose; the settled ones keep their mean", "[evalcmd][refine]") {
  const std::string data = test::sim_scene("exact", 17, 40, 30, 1);  // 3 test views
  TrainConfig c = grid_config(data, 10);
  c.rays = 64;  // small steps: the test's cost is two evals of 240 epochs
  c.samples = 16;
  Trainer t(c);
  for (int i = 0; i < 10; ++i) t.step_once();  // a young run: its test views start far off
  EvalOptions eo;
  eo.refine_epochs = 240;  // the fast mode's window: epochs 200–239, where these still travel
  eo.refine_rays = 16;
  eo.progress = false;
  const EvalResult fast = evaluate(t, eo);
  REQUIRE(fast.refine_averaged.size() == 3);  // false: still moving, refined again as the spec's
  eo.refine_mode = RefineMode::kAdam;
  eo.refine_rays = 0;  // the spec's: the run's grid (the second pass's, whatever --refine-rays says)
  const EvalResult spec = evaluate(t, eo);
  CHECK(spec.refine_averaged.empty());
  int again = 0;
  for (size_t k = 0; k < 3; ++k) {
    CAPTURE(k);
    if (!fast.refine_averaged[k]) {
      ++again;  // the spec's pose: the same distance moved, to the digit
      CHECK(fast.images[k].refine_rot_deg == spec.images[k].refine_rot_deg);
      CHECK(fast.images[k].refine_trans == spec.images[k].refine_trans);
    }
  }
  INFO("views refined again: " << again);
  CHECK(again > 0);  // the case this test is for happened
  const std::string js = eval_metrics_json(fast);
  CHECK(js.find("\"refine_estimate\": \"spec\"") != std::string::npos);
  CHECK(eval_summary(fast).find("refined again in the spec's mode") != std::string::npos);
}

TEST_CASE("eval's report of the fast mode's answer: metrics.json says mean or spec per view; the "
          "summary says how many views were refined again in the spec's mode",
          "[evalcmd][refine]") {
  EvalResult r;
  r.refine_mode = RefineMode::kFast;
  r.refine_epochs = 1000;
  r.refine_rays = 128;
  r.refine_full_epochs = 200;
  r.refine_average_from = 600;
  r.refine_loss = {0.1, 0.01};
  r.images.resize(2);
  r.images[0].name = "a";
  r.images[1].name = "b";
  r.refine_averaged = {true, true};
  const std::string quiet = eval_summary(r);
  CHECK(quiet.find("poses from epochs 600–999: their mean, for 2 of 2 views") != std::string::npos);
  CHECK(quiet.find("(fast, 128 rays a view a step after 200 epochs on the run's grid)") != std::string::npos);
  {  // a short refinement (the quick start's 5 epochs) never reaches the 128 rays
    EvalResult q = r;
    q.refine_epochs = 5;
    q.refine_full_epochs = 5;
    q.refine_average_from = -1;
    q.refine_averaged.clear();
    CHECK(eval_summary(q).find("(fast, the run's ray grid every epoch)") != std::string::npos);
  }
  CHECK(quiet.find("still moving") == std::string::npos);
  r.refine_averaged = {true, false};  // evaluate()'s answer to a moving view: refined again
  const std::string again = eval_summary(r);
  CHECK(again.find("their mean, for 1 of 2 views") != std::string::npos);
  CHECK(again.find("1 of 2 test cameras were still moving over the last epochs: refined again") != std::string::npos);
  CHECK(again.find("--refine-mode adam refines") == std::string::npos);
  const std::string js = eval_metrics_json(r);
  CHECK(js.find("\"refine_average_from\": 600") != std::string::npos);
  CHECK(js.find("\"refine_estimate\": \"mean\"") != std::string::npos);
  CHECK(js.find("\"refine_estimate\": \"spec\"") != std::string::npos);
  CHECK(js.find("trend") == std::string::npos);  // no view keeps a trend line any more
  r.refine_averaged.clear();  // the spec's mode: no such keys
  r.refine_average_from = -1;
  const std::string spec = eval_metrics_json(r);
  CHECK(spec.find("refine_estimate") == std::string::npos);
  CHECK(spec.find("refine_average_from") == std::string::npos);
}
