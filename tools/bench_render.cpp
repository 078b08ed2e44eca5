// tools/bench_render.cpp — `hashcc bench --render`: one 504×378 frame of a grid-field run (or of
// a freshly initialised grid field), at 32 and 64 samples and each thread count, with the render
// shortcuts and without, against the training step's samples per second (docs/render.md,
// "Render shortcuts"; docs/performance.md). Timings and the shortcuts' difference only:
// nothing here is asserted.
#include <algorithm>
#include <cmath>
#include <fstream>

#include <fmt/core.h>

#include "core/error.h"
#include "core/isa.h"
#include "core/parallel.h"
#include "model/camera_step.h"
#include "model/render_view.h"
#include "tools/bench.h"
#include "train/trainer.h"

namespace hashcc {

namespace {

// The frame's colour clamped to [0,1], as eval and the PNGs see it.
double psnr_between(const std::vector<float>& a, const std::vector<float>& b, double* max_abs) {
  double se = 0, m = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const double x = std::clamp(a[i], 0.f, 1.f), y = std::clamp(b[i], 0.f, 1.f);
    se += (x - y) * (x - y);
    m = std::max(m, std::abs(double(a[i]) - double(b[i])));
  }
  *max_abs = m;
  const double mse = se / double(std::max<size_t>(1, a.size()));
  return mse > 0 ? -10 * std::log10(mse) : INFINITY;
}

// What a field and camera to render: a run's (its first training camera) or a fresh grid field's.
struct Subject {
  ModelConfig cfg;
  ModelLayout L;
  std::vector<float> params;
  ViewCamera cam;
  std::string what;
};

Subject subject_of(const BenchRenderOptions& o) {
  Subject s;
  if (!o.run.empty()) {
    Trainer tr = Trainer::open(o.run);
    HCC_REQUIRE(tr.config().model.field == Field::grid, "--run", o.run,
                "a {} field run", field_name(tr.config().model.field), "a grid-field run");
    s.cfg = tr.config().model;
    s.L = make_layout(s.cfg);
    s.params.assign(tr.state().net.data(), tr.state().net.data() + s.L.count);
    s.cam = tr.view_camera(tr.pose_of(0));
    s.what = fmt::format("the run {} (its first training camera, {}x{}, {} variant, 2^{} table)",
                         o.run, s.cam.size.W, s.cam.size.H, variant_name(s.cfg.variant),
                         s.cfg.gf.grid.log2_table);
    return s;
  }
  s.cfg.variant = Variant::hashcc;
  s.cfg.field = Field::grid;
  s.cfg.gf.grid.log2_table = 17;  // the forward recipe's last stage
  s.cfg.gf.density_init = 2;
  s.L = make_layout(s.cfg);
  s.params.assign(s.L.count, 0.f);
  Rng rng(1);
  init_params(s.params.data(), s.cfg, s.L, rng);
  s.cam.size = {504, 378};
  const double a = std::sqrt(focal_for_fov(504, 65) / 504);
  s.cam.focal = {float(a), float(a), true};
  s.cam.ndc = true;
  s.what = "a freshly initialised grid field (hashcc, 2^17 table, density init 2: no run given), "
           "identity camera, 504x378, 65 deg";
  return s;
}

}  // namespace

void run_bench_render(const BenchRenderOptions& o) {
  Subject sub = subject_of(o);
  const NetView<float> net{sub.params.data(), sub.cfg, sub.L};
  const std::vector<int> threads = o.threads.empty() ? std::vector<int>{1, 2} : o.threads;
  const int pixels = sub.cam.size.W * sub.cam.size.H;
  fmt::print("render bench: {}\nCPU: {} (compiled {}; {} logical CPUs)\n", sub.what, cpu_model(),
             compiled_isa().name, omp_get_num_procs());
  // Empty-space grids (--skip-sigma): built once each, at the first thread count, and timed.
  std::vector<OccupancyGrid> grids;
  set_num_threads(threads.front());
  for (double sm : o.skip_sigmas) {
    const double w0 = bench_wall_s();
    grids.push_back(empty_space_grid(net, o.skip_res, sm, o.skip_passes));
    const double built = bench_wall_s() - w0;
    std::vector<float> cs = grids.back().cell_sigma();  // each cell's largest sampled σ
    std::sort(cs.begin(), cs.end());
    auto pct = [&](double q) { return cs[size_t(q * double(cs.size() - 1))]; };
    fmt::print("empty-space grid sigma >= {:g}: {}^3 cells, {} jittered points a cell, {:.1f}% "
               "occupied (after a one-cell dilation), built in {:.2f} s at {} thread(s); the "
               "cells' sigma: 1% {:.3g}, 10% {:.3g}, 50% {:.3g}, 90% {:.3g}\n",
               sm, o.skip_res, o.skip_passes, 100.0 * grids.back().occupied_fraction(), built,
               threads.front(), pct(0.01), pct(0.1), pct(0.5), pct(0.9));
  }
  fmt::print("{:>7} {:>7} {:>9} {:>10} {:>10} {:>10} {:>9} {:>12} {:>12} {:>10} {:>9}\n", "samples",
             "threads", "mode", "s/frame", "cpu s", "Msamp/s", "density%", "colour%", "step Msamp/s",
             "PSNR vs exact", "max|diff|");
  for (int S : o.samples) {
    // The training step's rate on this field: 1,024 rays × S samples of the camera's view,
    // forward and backward with parameter and ray gradients (what a training step computes).
    std::vector<float> d_params(sub.L.count, 0.f);
    for (int T : threads) {
      set_num_threads(T);
      // Training step.
      double step_rate = 0;
      {
        CameraStepWorkspace<float> ws;
        CameraStepGrads<float> g;
        g.d_params = d_params.data();
        const int R = 1024;
        std::vector<int> px(2 * R);
        std::vector<float> s(int64_t(R) * S), target(3 * R, 0.5f);
        Rng rng(7);
        std::vector<int> rs, cs;
        pick_distinct(rng, rs, sub.cam.size.H, 32);
        pick_distinct(rng, cs, sub.cam.size.W, 32);
        for (int a = 0; a < 32; ++a)
          for (int b = 0; b < 32; ++b) {
            px[2 * (a * 32 + b)] = cs[b];
            px[2 * (a * 32 + b) + 1] = rs[a];
          }
        jitter_samples(rng, s.data(), R, S);
        CameraBatch<float> cb;
        cb.px = px.data();
        cb.target = target.data();
        cb.s = s.data();
        cb.R = R;
        cb.S = S;
        cb.poses = &sub.cam.pose;
        cb.focal = sub.cam.focal;
        cb.size = sub.cam.size;
        cb.ndc = sub.cam.ndc;
        StepOptions so;
        camera_step(ws, net, cb, so, g);  // warm-up
        const int reps = 5;
        const double w0 = bench_wall_s();
        for (int i = 0; i < reps; ++i) camera_step(ws, net, cb, so, g);
        step_rate = double(R) * S * reps / (bench_wall_s() - w0) * 1e-6;
      }
      std::vector<float> exact_rgb;
      // mode 0: exact; 1: the shortcuts; 2…: the shortcuts with each empty-space grid.
      for (int mode = 0; mode < 2 + int(grids.size()); ++mode) {
        const bool shortcuts = mode >= 1;
        StepWorkspace<float> ws;
        ViewOptions vo;
        vo.samples = S;
        vo.chunk_rays = 0;
        vo.shortcuts = shortcuts;
        if (mode >= 2) vo.skip = &grids[mode - 2];
        ViewImage img = render_view(ws, net, sub.cam, vo);  // warm-up (and the compared frame)
        std::vector<double> walls, cpus;
        RenderStats st;
        for (int f = 0; f < o.frames; ++f) {
          RenderStats sf;
          const double w0 = bench_wall_s(), c0 = bench_cpu_s();
          img = render_view(ws, net, sub.cam, vo, &sf);
          walls.push_back(bench_wall_s() - w0);
          cpus.push_back(bench_cpu_s() - c0);
          st = sf;
        }
        std::sort(walls.begin(), walls.end());
        std::sort(cpus.begin(), cpus.end());
        const double wall = walls[walls.size() / 2], cpu = cpus[cpus.size() / 2];
        std::string cmp = "-", mad = "-";
        if (!shortcuts) {
          exact_rgb = img.rgb;
        } else {
          double m = 0;
          const double p = psnr_between(img.rgb, exact_rgb, &m);
          cmp = std::isfinite(p) ? fmt::format("{:.2f} dB", p) : "identical";
          mad = fmt::format("{:.2e}", m);
        }
        fmt::print("{:>7} {:>7} {:>9} {:>10.3f} {:>10.3f} {:>10.2f} {:>9.1f} {:>12.1f} {:>12.2f} {:>10} {:>9}\n",
                   S, T, mode == 0 ? std::string("exact") : mode == 1 ? std::string("shortcuts")
                                   : fmt::format("skip>={:g}", o.skip_sigmas[mode - 2]), wall, cpu,
                   double(pixels) * S / wall * 1e-6, 100.0 * st.density / std::max<int64_t>(1, st.samples),
                   100.0 * st.colour / std::max<int64_t>(1, st.samples), step_rate, cmp, mad);
      }
    }
  }
  fmt::print("s/frame and cpu s: the median of {} frames after one warm-up; Msamp/s: the frame's "
             "W·H·S samples a wall second (shortcuts: the samples it stands for); density%, "
             "colour%: the samples whose density, colour were computed; step: one training step "
             "(1,024 rays × S, forward and backward with parameter gradients) a wall second; "
             "skip>=X: the shortcuts with the empty-space grid of sigma >= X (docs/render.md)\n",
             o.frames);
}

}  // namespace hashcc
