#include "model/step.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <omp.h>

#include "core/error.h"
#include "kernels/dense.h"
#include "kernels/sh.h"
#include "render/compositor.h"
#include "render/sampler.h"

namespace hashcc {

namespace {

template <class T>
void prepare(StepWorkspace<T>& ws, const ModelConfig& cfg, int chunk, int S) {
  int64_t N = int64_t(chunk) * S;
  if (ws.cache.N < N) ws.cache.reserve(cfg, chunk, S);
  ensure(ws.x, N * 3);
  ensure(ws.u, int64_t(chunk) * 3);
  ensure(ws.sigma, N);
  ensure(ws.d_sigma, N);
  ensure(ws.d_color, N * 3);
  ensure(ws.d_color2, N * 3);
  ensure(ws.color2, N * 3);
  ensure(ws.d_x, N * 3);
  ensure(ws.d_u, int64_t(chunk) * 3);
  ensure(ws.d_x2, N * 3);
  ensure(ws.d_u2, int64_t(chunk) * 3);
}

// Forward of one chunk into the workspace; outputs of the compositor for the chunk.
template <class T>
void chunk_forward(StepWorkspace<T>& ws, const T* params, const ModelConfig& cfg,
                   const ModelLayout& L, const T* o, const T* d, const T* s, int R, int S,
                   T* rgb, T* rgb_cc, T* depth, T* opacity, const T* cc_x_fixed = nullptr) {
  const int64_t N = int64_t(R) * S;
  StageClock clk(ws.cache.prof, kStageRays);
  sample_points_forward(ws.x.data(), o, d, s, R, S);                 // x (N, 3)
  normalize3_forward(ws.u.data(), d, R);                             // u (R, 3)
  HCC_DEBUG_FINITE(ws.x.data(), N * 3, "sample_points_forward");
  HCC_DEBUG_FINITE(ws.u.data(), int64_t(R) * 3, "normalize3_forward");
  clk.stop();  // model_forward times its own stages
  model_forward(ws.cache, params, cfg, L, ws.x.data(), ws.u.data(), R, S, cc_x_fixed);
  clk.to(kStageCompositor);
  relu_forward(ws.sigma.data(), ws.cache.sigma_raw.data(), N);       // σ = relu(σ_raw)
  const T* color2 = nullptr;
  if (cfg.has_cc()) {
    clk.to(kStageCC);
    T* c2 = ws.color2.data();  // c_c = c + Δc (N, 3)
    const T* c = ws.cache.color.data();
    const T* dc = ws.cache.dcolor.data();
    parallel_for(N * 3, [&](int64_t i) { c2[i] = c[i] + dc[i]; }, 4096);
    color2 = c2;
    clk.to(kStageCompositor);
  }
  composite_forward(rgb, color2 ? rgb_cc : (T*)nullptr, depth, opacity, ws.sigma.data(),
                    ws.cache.color.data(), color2, s, R, S);
  if (!color2 && rgb_cc) std::copy(rgb, rgb + 3 * R, rgb_cc);
  HCC_DEBUG_FINITE(rgb, 3 * int64_t(R), "composite_forward (rgb)");
  HCC_DEBUG_FINITE(rgb_cc, 3 * int64_t(R), "composite_forward (rgb_cc)");
  HCC_DEBUG_FINITE(depth, R, "composite_forward (depth)");
  HCC_DEBUG_FINITE(opacity, R, "composite_forward (opacity)");
}

}  // namespace

namespace {

// One chunk of Rc rays starting at ray r0: forward, loss terms, backward. Parameter gradients
// go to d_params (+=); ray gradients to d_o, d_d at the chunk's rows. Returns Σ squared errors
// of p̃ and of p̃_c.
template <class T>
std::pair<double, double> process_chunk(StepWorkspace<T>& ws, const T* params, T* d_params,
                                        const ModelConfig& cfg, const ModelLayout& L,
                                        const T* o, const T* d, const T* s, const T* target,
                                        int r0, int Rc, int S, double norm,
                                        const StepOptions& opt, T* rgb_out, T* rgb_cc_out,
                                        T* depth_out, T* opacity_out, T* d_o, T* d_d) {
  const bool cc = cfg.has_cc();
  const int64_t N = int64_t(Rc) * S;
  T rgb[3 * 1024], rgb_cc[3 * 1024], depth[1024], opacity[1024], d_rgb[3 * 1024], d_rgb_cc[3 * 1024];
  const T* oc = o + 3 * int64_t(r0);
  const T* dc = d + 3 * int64_t(r0);
  const T* sc = s + int64_t(r0) * S;
  const T* tc = target + 3 * int64_t(r0);
  chunk_forward(ws, params, cfg, L, oc, dc, sc, Rc, S, rgb, rgb_cc, depth, opacity,
                ws.cc_x_fixed ? ws.cc_x_fixed + int64_t(r0) * S * 3 : (const T*)nullptr);
  StageClock clk(ws.cache.prof, kStageCompositor);
  // loss = (1/(3R)) Σ (p̃ − p)² [+ (1/(3R)) Σ (p̃_c − p)²]: dL/dp̃ = 2(p̃ − p)/(3R) = norm·e.
  double se = 0, se_cc = 0;
  for (int i = 0; i < 3 * Rc; ++i) {
    double e = double(rgb[i]) - tc[i];
    se += e * e;
    d_rgb[i] = T(norm * e);
    double ec = double(rgb_cc[i]) - tc[i];
    se_cc += ec * ec;
    d_rgb_cc[i] = cc ? T(norm * ec) : T(0);
  }
  if (rgb_out) std::copy(rgb, rgb + 3 * Rc, rgb_out + 3 * int64_t(r0));
  if (rgb_cc_out) std::copy(rgb_cc, rgb_cc + 3 * Rc, rgb_cc_out + 3 * int64_t(r0));
  if (depth_out) std::copy(depth, depth + Rc, depth_out + r0);
  if (opacity_out) std::copy(opacity, opacity + Rc, opacity_out + r0);
  if (!d_params && !opt.need_ray_grads) return {se, se_cc};

  // Compositor backward: dσ, dc from both predictions (they share w_i).
  composite_backward(ws.d_sigma.data(), ws.d_color.data(), cc ? ws.d_color2.data() : (T*)nullptr,
                     d_rgb, cc ? d_rgb_cc : (T*)nullptr, (T*)nullptr, (T*)nullptr,
                     ws.sigma.data(), ws.cache.color.data(), cc ? ws.color2.data() : (T*)nullptr,
                     sc, rgb, cc ? rgb_cc : (T*)nullptr, depth, opacity, Rc, S);
  // σ = relu(σ_raw): dσ_raw = dσ · [σ_raw > 0]  (relu_backward uses the output σ)
  relu_backward(ws.d_sigma.data(), ws.d_sigma.data(), ws.sigma.data(), N);
  HCC_DEBUG_FINITE(ws.d_sigma.data(), N, "composite_backward (d_sigma) + relu_backward");
  HCC_DEBUG_FINITE(ws.d_color.data(), N * 3, "composite_backward (d_color)");
  if (cc) HCC_DEBUG_FINITE(ws.d_color2.data(), N * 3, "composite_backward (d_color_cc)");
  if (cc) {
    clk.to(kStageCC);
    // c_c = c + Δc: dL/dc gets both losses (fan-in), dL/dΔc = dL/dc_c.
    T* dcol = ws.d_color.data();
    const T* dcol2 = ws.d_color2.data();
    for (int64_t i = 0; i < N * 3; ++i) dcol[i] += dcol2[i];
  }
  clk.stop();  // model_backward times its own stages (the ablation's 2nd compositor pass: other)
  T* d_x = opt.need_ray_grads ? ws.d_x.data() : nullptr;
  T* d_u = opt.need_ray_grads ? ws.d_u.data() : nullptr;
  if (cc && opt.stop_cc_to_camera && opt.need_ray_grads) {
    // Ablation: networks learn from both losses; the camera only from MSE(p, p̃).
    model_backward(d_params, (T*)nullptr, (T*)nullptr, ws.cache, params, cfg, L, ws.x.data(),
                   ws.u.data(), ws.d_sigma.data(), ws.d_color.data(), ws.d_color2.data());
    composite_backward(ws.d_sigma.data(), ws.d_color.data(), (T*)nullptr, d_rgb, (T*)nullptr,
                       (T*)nullptr, (T*)nullptr, ws.sigma.data(), ws.cache.color.data(),
                       (T*)nullptr, sc, rgb, (T*)nullptr, depth, opacity, Rc, S);
    relu_backward(ws.d_sigma.data(), ws.d_sigma.data(), ws.sigma.data(), N);
    model_backward((T*)nullptr, d_x, d_u, ws.cache, params, cfg, L, ws.x.data(), ws.u.data(),
                   ws.d_sigma.data(), ws.d_color.data(), (T*)nullptr);
  } else {
    model_backward(d_params, d_x, d_u, ws.cache, params, cfg, L, ws.x.data(), ws.u.data(),
                   ws.d_sigma.data(), ws.d_color.data(), cc ? ws.d_color2.data() : (T*)nullptr);
  }
  if (opt.need_ray_grads && d_o && d_d) {
    clk.to(kStageRays);
    // x = o + s d → dL/do, dL/dd; u = normalize(d) adds its share to dL/dd (fan-in).
    T* d_oc = d_o + 3 * int64_t(r0);
    T* d_dc = d_d + 3 * int64_t(r0);
    sample_points_backward(d_oc, d_dc, d_x, sc, Rc, S);
    normalize3_backward(ws.d_u2.data(), d_u, dc, Rc);
    for (int i = 0; i < 3 * Rc; ++i) d_dc[i] += ws.d_u2[i];
    HCC_DEBUG_FINITE(d_oc, 3 * int64_t(Rc), "sample_points_backward (d_o)");
    HCC_DEBUG_FINITE(d_dc, 3 * int64_t(Rc), "sample_points_backward + normalize3_backward (d_d)");
  }
  return {se, se_cc};
}

}  // namespace

template <class T>
StepResult<T> ray_batch_step(StepWorkspace<T>& ws, const T* params, T* d_params,
                             const ModelConfig& cfg, const ModelLayout& L, const T* o,
                             const T* d, const T* s, const T* target, int R, int S,
                             const StepOptions& opt, T* rgb_out, T* rgb_cc_out, T* depth_out,
                             T* opacity_out, T* d_o, T* d_d) {
  StepResult<T> res;
  if (R == 0) return res;
  const int chunk = std::max(1, std::min({opt.chunk_rays, R, 1024}));
  const int nchunks = (R + chunk - 1) / chunk;
  const double norm = 2.0 / (3.0 * R);
  if (int(ws.sums.size()) < nchunks) ws.sums.resize(nchunks);  // grow-only: no per-step allocation
  std::pair<double, double>* sums = ws.sums.data();
  StageTimes* prof = ws.cache.prof;
  const int nt = opt.data_parallel ? std::min(num_threads(), nchunks) : 1;
  if (nt <= 1) {
    // One thread (or one chunk): chunks in order, kernels free to use the threads they have.
    prepare(ws, cfg, chunk, S);
    for (int c = 0; c < nchunks; ++c)
      sums[c] = process_chunk(ws, params, d_params, cfg, L, o, d, s, target, c * chunk,
                              std::min(chunk, R - c * chunk), S, norm, opt, rgb_out, rgb_cc_out,
                              depth_out, opacity_out, d_o, d_d);
  } else {
    // Data parallel over chunks of rays, ONE parallel region per step: thread t runs chunks
    // t, t+nt, … with serial kernels, its own workspace and its own parameter-gradient arena;
    // the arenas are then added to d_params in thread order. Deterministic for a given thread
    // count; across thread counts only the rounding of that final sum differs.
    while (int(ws.per_thread.size()) < nt) ws.per_thread.push_back(std::make_unique<StepWorkspace<T>>());
    ws.thread_grads.resize(std::max<size_t>(ws.thread_grads.size(), nt));
    ws.thread_prof.resize(std::max<size_t>(ws.thread_prof.size(), nt));
    for (int t = 0; t < nt; ++t) {
      prepare(*ws.per_thread[t], cfg, chunk, S);
      ws.per_thread[t]->cc_x_fixed = ws.cc_x_fixed;
      ws.thread_prof[t].clear();
      ws.per_thread[t]->cache.prof = prof ? &ws.thread_prof[t] : nullptr;
      if (d_params) {
        ensure(ws.thread_grads[t], L.count);
        std::fill(ws.thread_grads[t].begin(), ws.thread_grads[t].begin() + L.count, T(0));
      }
    }
#pragma omp parallel num_threads(nt)
    {
      const int t = omp_get_thread_num();
      T* g = d_params ? ws.thread_grads[t].data() : nullptr;
      for (int c = t; c < nchunks; c += nt)
        sums[c] = process_chunk(*ws.per_thread[t], params, g, cfg, L, o, d, s, target, c * chunk,
                                std::min(chunk, R - c * chunk), S, norm, opt, rgb_out, rgb_cc_out,
                                depth_out, opacity_out, d_o, d_d);
    }
    // Profiler: the threads ran side by side, so their mean is the wall-equivalent.
    if (prof)
      for (int t = 0; t < nt; ++t) prof->add_scaled(ws.thread_prof[t], 1.0 / nt);
    if (d_params)
      parallel_for(L.count, [&](int64_t i) {
        T acc = d_params[i];
        for (int t = 0; t < nt; ++t) acc += ws.thread_grads[t][i];
        d_params[i] = acc;
      }, 4096);
  }
  HCC_DEBUG_FINITE(d_params, L.count, "ray_batch_step: parameter gradients (all backward kernels)");
  double se = 0, se_cc = 0;
  for (int c = 0; c < nchunks; ++c) { se += sums[c].first; se_cc += sums[c].second; }  // fixed order
  res.mse = se / (3.0 * R);
  res.mse_cc = se_cc / (3.0 * R);
  res.loss = cfg.has_cc() ? res.mse + res.mse_cc : res.mse;
  return res;
}

template <class T>
void ray_batch_render(StepWorkspace<T>& ws, const T* params, const ModelConfig& cfg,
                      const ModelLayout& L, const T* o, const T* d, const T* s, int R, int S,
                      int chunk_rays, T* rgb, T* rgb_cc, T* depth, T* opacity) {
  if (R == 0) return;
  const int chunk = std::max(1, std::min({chunk_rays, R, 1024}));
  const int nchunks = (R + chunk - 1) / chunk;
  const int nt = std::max(1, std::min(num_threads(), nchunks));
  // One thread renders in a workspace that already exists — ws itself (1-thread training
  // steps use it) unless the data-parallel steps made per_thread[0] — never a new one: each
  // holds a full set of activations (~145 MB at the default chunk; measured, README "Memory").
  StepWorkspace<T>& single = ws.per_thread.empty() ? ws : *ws.per_thread[0];
  if (nt <= 1) {
    prepare(single, cfg, chunk, S);
  } else {
    while (int(ws.per_thread.size()) < nt) ws.per_thread.push_back(std::make_unique<StepWorkspace<T>>());
    for (int t = 0; t < nt; ++t) prepare(*ws.per_thread[t], cfg, chunk, S);
  }
  auto run = [&](int t) {
    StepWorkspace<T>& w = nt <= 1 ? single : *ws.per_thread[t];
    T c_rgb[3 * 1024], c_rgb_cc[3 * 1024], c_depth[1024], c_op[1024];
    for (int c = t; c < nchunks; c += nt) {
      const int r0 = c * chunk, Rc = std::min(chunk, R - r0);
      chunk_forward(w, params, cfg, L, o + 3 * int64_t(r0), d + 3 * int64_t(r0),
                    s + int64_t(r0) * S, Rc, S, c_rgb, c_rgb_cc, c_depth, c_op);
      if (rgb) std::copy(c_rgb, c_rgb + 3 * Rc, rgb + 3 * int64_t(r0));
      if (rgb_cc) std::copy(c_rgb_cc, c_rgb_cc + 3 * Rc, rgb_cc + 3 * int64_t(r0));
      if (depth) std::copy(c_depth, c_depth + Rc, depth + r0);
      if (opacity) std::copy(c_op, c_op + Rc, opacity + r0);
    }
  };
  if (nt <= 1) { run(0); return; }
#pragma omp parallel num_threads(nt)
  run(omp_get_thread_num());
}

#define HCC_INST(T)                                                                          \
  template StepResult<T> ray_batch_step<T>(StepWorkspace<T>&, const T*, T*, const ModelConfig&, \
                                           const ModelLayout&, const T*, const T*, const T*,    \
                                           const T*, int, int, const StepOptions&, T*, T*, T*,  \
                                           T*, T*, T*);                                         \
  template void ray_batch_render<T>(StepWorkspace<T>&, const T*, const ModelConfig&,            \
                                    const ModelLayout&, const T*, const T*, const T*, int, int, \
                                    int, T*, T*, T*, T*);
HCC_INST(float)
HCC_INST(double)

}  // namespace hashcc
