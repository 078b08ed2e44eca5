#include "model/step.h"
#include "model/grid_field.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <omp.h>

#include "core/error.h"
#include "kernels/dense.h"
#include "kernels/sh.h"
#include "render/compositor.h"
#include "render/distortion.h"
#include "render/sampler.h"

namespace hashcc {

namespace {

template <class T>
void prepare(ChunkBuffers<T>& cb, const ModelConfig& cfg, int chunk, int S, bool keep_mlp) {
  int64_t N = int64_t(chunk) * S;
  if (cb.cache.N < N) cb.cache.reserve(cfg, chunk, S);
  // StepOptions::keep_mlp, or the cache's own default (on in double: the gradient checks read them).
  cb.cache.keep_mlp = keep_mlp || std::is_same_v<T, double>;
  ensure(cb.x, N * 3);
  ensure(cb.u, int64_t(chunk) * 3);
  ensure(cb.sigma, N);
  ensure(cb.d_sigma, N);
  ensure(cb.d_color, N * 3);
  ensure(cb.d_color2, N * 3);
  ensure(cb.color2, N * 3);
  ensure(cb.d_x, N * 3);
  ensure(cb.d_u, int64_t(chunk) * 3);
  ensure(cb.d_u2, int64_t(chunk) * 3);
}

// The weights' buffers, only for a step with the distortion loss (and the camera's own pass
// through the compositor, for its detach on the grid field).
template <class T>
void prepare_weights(ChunkBuffers<T>& cb, int chunk, int S) {
  const int64_t N = int64_t(chunk) * S;
  ensure(cb.weights, N);
  ensure(cb.d_weights, N);
  ensure(cb.d_sigma_x, N);
  ensure(cb.d_color_x, N * 3);
  ensure(cb.d_color2_x, N * 3);
}

// Rays [r0, r0 + Rc) of a batch.
template <class T>
RayBatch<T> slice(const RayBatch<T>& in, int r0, int Rc) {
  RayBatch<T> c = in;
  c.o = in.o + 3 * int64_t(r0);
  c.d = in.d + 3 * int64_t(r0);
  c.s = in.s + int64_t(r0) * in.S;
  if (in.target) c.target = in.target + 3 * int64_t(r0);
  if (in.cc_x) c.cc_x = in.cc_x + int64_t(r0) * in.S * 3;
  if (in.delta) c.delta = in.delta + int64_t(r0) * in.S;
  c.R = Rc;
  return c;
}

// Copies a chunk's per-ray values (rows [0, Rc) of `from`) to rows [r0, r0 + Rc) of `to`.
template <class T>
void copy_rows(const RayOutputs<T>& to, const RayOutputs<T>& from, int r0, int Rc) {
  if (to.rgb) std::copy(from.rgb, from.rgb + 3 * Rc, to.rgb + 3 * int64_t(r0));
  if (to.rgb_cc) std::copy(from.rgb_cc, from.rgb_cc + 3 * Rc, to.rgb_cc + 3 * int64_t(r0));
  if (to.depth) std::copy(from.depth, from.depth + Rc, to.depth + r0);
  if (to.opacity) std::copy(from.opacity, from.opacity + Rc, to.opacity + r0);
}

// The compositor's inputs for a chunk: σ, c and (hashcc) c_c.
template <class T>
CompositeIn<T> composite_in(const ChunkBuffers<T>& cb, bool cc, const RayBatch<T>& c) {
  return {cb.sigma.data(), cb.cache.color.data(), cc ? cb.color2.data() : (const T*)nullptr, c.s,
          c.R, c.S, c.delta};
}

// The model's input for chunk c: its samples x, its unit directions u and, detached, the CC
// branch's input (c.cc_x when given, else x itself).
// keep_jac: the backward will ask for d_x (ModelIn::keep_jac).
template <class T>
ModelIn<T> model_in(const ChunkBuffers<T>& cb, const RayBatch<T>& c, bool keep_jac = false) {
  return {cb.x.data(), cb.u.data(), c.cc_x ? c.cc_x : cb.x.data(), c.R, c.S, keep_jac};
}

// Forward of one chunk c (R rays) into cb; the compositor's outputs go to out (all four set);
// weights (R·S): the compositing weights too (null = not needed); keep_jac: a backward to the
// rays follows (ModelIn::keep_jac).
template <class T>
void chunk_forward(ChunkBuffers<T>& cb, const NetView<T>& net, const RayBatch<T>& c,
                   const RayOutputs<T>& out, T* weights = nullptr, bool keep_jac = false) {
  const ModelConfig& cfg = net.cfg;
  const int R = c.R, S = c.S;
  const int64_t N = int64_t(R) * S;
  StageClock clk(cb.cache.prof, kStageRays);
  sample_points_forward(cb.x.data(), c.o, c.d, c.s, R, S);          // x (N, 3)
  normalize3_forward(cb.u.data(), c.d, R);                          // u (R, 3)
  HCC_DEBUG_FINITE(cb.x.data(), N * 3, "sample_points_forward");
  HCC_DEBUG_FINITE(cb.u.data(), int64_t(R) * 3, "normalize3_forward");
  clk.stop();  // model_forward times its own stages
  model_forward(cb.cache, net, model_in(cb, c, keep_jac));
  clk.to(kStageCompositor);
  relu_forward(cb.sigma.data(), cb.cache.sigma_raw.data(), N);      // σ = relu(σ_raw)
  const bool cc = cfg.has_cc();
  if (cc) {
    clk.to(kStageCC);
    T* c2 = cb.color2.data();  // c_c = c + Δc (N, 3)
    const T* col = cb.cache.color.data();
    const T* dc = cb.cache.dcolor.data();
    parallel_for(N * 3, [&](int64_t i) { c2[i] = col[i] + dc[i]; }, 4096);
    clk.to(kStageCompositor);
  }
  composite_forward<T>({out.rgb, cc ? out.rgb_cc : (T*)nullptr, out.depth, out.opacity, weights},
                       composite_in(cb, cc, c));
  if (!cc && out.rgb_cc) std::copy(out.rgb, out.rgb + 3 * R, out.rgb_cc);
  HCC_DEBUG_FINITE(out.rgb, 3 * int64_t(R), "composite_forward (rgb)");
  HCC_DEBUG_FINITE(out.rgb_cc, 3 * int64_t(R), "composite_forward (rgb_cc)");
  HCC_DEBUG_FINITE(out.depth, R, "composite_forward (depth)");
  HCC_DEBUG_FINITE(out.opacity, R, "composite_forward (opacity)");
}

// What every chunk of one step shares.
template <class T>
struct StepArgs {
  const NetView<T>& net;
  const RayBatch<T>& in;
  const RayGrads<T>& grads;  // d_o, d_d; the parameter gradients go to each thread's arena
  const RayOutputs<T>& out;
  const StepOptions& opt;
  double norm;               // dL/dp̃ = norm · (p̃ − p), norm = 2/(3R)
  double dist_scale;         // dL/dL_dist(ray) = λ/R (0: no distortion loss)
};

// c_c = c + Δc: dL/dc gets both losses (fan-in), dL/dΔc = dL/dc_c. N samples.
template <class T>
void add_cc_fan_in(ChunkBuffers<T>& cb, int64_t N) {
  T* dcol = cb.d_color.data();
  const T* dcol2 = cb.d_color2.data();
  for (int64_t i = 0; i < N * 3; ++i) dcol[i] += dcol2[i];
}

// The camera's own losses, when not every loss reaches the camera: the networks learn from all
// of them, the camera from MSE(p, p̃), MSE(p, p̃_c) unless --stop-cc-to-camera (the ablation),
// and the distortion loss only with --distortion-to-camera (render/distortion.h: on fern it pulls
// the cameras off the photos while they learn). On entry cb holds dσ_raw, dc (all losses, the
// CC fan-in done) and dΔc. A first backward sends every loss to the parameters; the compositor
// is then run backward again for the camera's losses alone (d_cam: dL/dp̃, dL/dp̃_c or null,
// dL/dw or null; cam_in: color2 null when p̃_c's loss does not reach the camera), and that
// reaches x, u (d_in.d_x, d_in.d_dir WRITTEN) but not the parameters. The CC branch's input is
// detached (formulas.md §5), so p̃_c's loss reaches x only through c, by the fan-in c_c = c + Δc.
template <class T>
void camera_losses_backward(ChunkBuffers<T>& cb, const NetView<T>& net, const ModelIn<T>& pts,
                            const ModelInGrads<T>& d_in, const CompositeOut<const T>& d_cam,
                            const CompositeIn<T>& cam_in, const CompositeOut<const T>& fwd) {
  const int64_t N = cam_in.R * cam_in.S;
  model_backward<T>({d_in.d_params, nullptr, nullptr},
                    {cb.d_sigma.data(), cb.d_color.data(), cb.d_color2.data()}, cb.cache, net, pts);
  const bool cc = cam_in.color2 != nullptr;
  composite_backward<T>({cb.d_sigma.data(), cb.d_color.data(), cc ? cb.d_color2.data() : nullptr},
                        d_cam, cam_in, fwd);
  relu_backward(cb.d_sigma.data(), cb.d_sigma.data(), cb.sigma.data(), N);
  if (cc) add_cc_fan_in(cb, N);
  model_backward<T>({nullptr, d_in.d_x, d_in.d_dir}, {cb.d_sigma.data(), cb.d_color.data(), nullptr},
                    cb.cache, net, pts);
}

// One chunk of Rc rays starting at ray r0: forward, loss terms, backward. Parameter gradients
// go to d_params (+=); ray gradients to a.grads.d_o, d_d at the chunk's rows. Returns the
// chunk's loss sums.
template <class T>
ChunkSums process_chunk(ChunkBuffers<T>& cb, const StepArgs<T>& a, T* d_params, int r0, int Rc) {
  const ModelConfig& cfg = a.net.cfg;
  const StepOptions& opt = a.opt;
  const bool cc = cfg.has_cc();
  const int S = a.in.S;
  const int64_t N = int64_t(Rc) * S;
  T rgb[3 * kMaxChunkRays], rgb_cc[3 * kMaxChunkRays], depth[kMaxChunkRays],
      opacity[kMaxChunkRays], d_rgb[3 * kMaxChunkRays], d_rgb_cc[3 * kMaxChunkRays];
  const RayBatch<T> c = slice(a.in, r0, Rc);
  const RayOutputs<T> fwd{rgb, rgb_cc, depth, opacity};
  const bool dist = a.dist_scale > 0;
  // The grid field keeps its position Jacobian when the camera learns and it pays (grid_jac_pays).
  const bool keep_jac = opt.need_ray_grads && cfg.field == Field::grid &&
                        (!d_params || grid_jac_pays(cfg.gf));
  chunk_forward(cb, a.net, c, fwd, dist ? cb.weights.data() : (T*)nullptr, keep_jac);
  StageClock clk(cb.cache.prof, kStageCompositor);
  // loss = (1/(3R)) Σ (p̃ − p)² [+ (1/(3R)) Σ (p̃_c − p)²]: dL/dp̃ = 2(p̃ − p)/(3R) = norm·e.
  double se = 0, se_cc = 0;
  for (int i = 0; i < 3 * Rc; ++i) {
    double e = double(rgb[i]) - c.target[i];
    se += e * e;
    d_rgb[i] = T(a.norm * e);
    double ec = double(rgb_cc[i]) - c.target[i];
    se_cc += ec * ec;
    d_rgb_cc[i] = cc ? T(a.norm * ec) : T(0);
  }
  copy_rows(a.out, fwd, r0, Rc);
  // + λ · (1/R) Σ_rays L_dist (render/distortion.h): dL/dw = (λ/R) dL_dist/dw, on the main
  // field's weights (p̃_c shares them: one loss on them, not two).
  double dist_sum = 0;
  if (dist) {
    T ray_dist[kMaxChunkRays], d_ray[kMaxChunkRays];
    distortion_forward(ray_dist, cb.weights.data(), c.s, Rc, S);
    for (int r = 0; r < Rc; ++r) {
      dist_sum += double(ray_dist[r]);
      d_ray[r] = T(a.dist_scale);
    }
    distortion_backward(cb.d_weights.data(), d_ray, cb.weights.data(), c.s, Rc, S);
  }
  const T* d_weights = dist ? cb.d_weights.data() : nullptr;
  if (!d_params && !opt.need_ray_grads) return {se, se_cc, dist_sum};

  // Compositor backward: dσ, dc from both predictions (they share w_i).
  const CompositeIn<T> cin = composite_in(cb, cc, c);
  composite_backward<T>({cb.d_sigma.data(), cb.d_color.data(), cc ? cb.d_color2.data() : (T*)nullptr},
                        {d_rgb, cc ? d_rgb_cc : (T*)nullptr, nullptr, nullptr, d_weights},
                        cin, {rgb, cc ? rgb_cc : (T*)nullptr, depth, opacity});
  // σ = relu(σ_raw): dσ_raw = dσ · [σ_raw > 0]  (relu_backward uses the output σ)
  relu_backward(cb.d_sigma.data(), cb.d_sigma.data(), cb.sigma.data(), N);
  HCC_DEBUG_FINITE(cb.d_sigma.data(), N, "composite_backward (d_sigma) + relu_backward");
  HCC_DEBUG_FINITE(cb.d_color.data(), N * 3, "composite_backward (d_color)");
  if (cc) HCC_DEBUG_FINITE(cb.d_color2.data(), N * 3, "composite_backward (d_color_cc)");
  if (cc) {
    clk.to(kStageCC);
    add_cc_fan_in(cb, N);
  }
  clk.stop();  // model_backward times its own stages (the ablation's 2nd compositor pass: other)
  T* d_x = opt.need_ray_grads ? cb.d_x.data() : nullptr;
  T* d_u = opt.need_ray_grads ? cb.d_u.data() : nullptr;
  const bool cc_to_camera = cc && !opt.stop_cc_to_camera;
  const bool dist_to_camera = dist && opt.distortion_to_camera;
  const bool cc_detached = cc && !cc_to_camera, dist_detached = dist && !dist_to_camera;
  if (opt.need_ray_grads && dist_detached && !cc_detached && cfg.field == Field::grid) {
    // The grid field's detach in one backward: the distortion loss reaches the networks through
    // σ alone, so the camera's losses differ from all of them only in dσ. The compositor runs
    // backward once more for the camera's dσ (colour gradients discarded: the same), and the
    // model sends dσ to the parameters and the camera's dσ to x (ModelOutGrads::d_sigma_raw_x):
    // only the small density MLP runs twice. The general path below runs every network twice.
    clk.to(kStageCompositor);
    composite_backward<T>({cb.d_sigma_x.data(), cb.d_color_x.data(),
                           cc ? cb.d_color2_x.data() : (T*)nullptr},
                          {d_rgb, cc ? d_rgb_cc : (T*)nullptr, nullptr, nullptr, nullptr},
                          cin, {rgb, cc ? rgb_cc : (T*)nullptr, depth, opacity});
    relu_backward(cb.d_sigma_x.data(), cb.d_sigma_x.data(), cb.sigma.data(), N);
    clk.stop();
    model_backward<T>({d_params, d_x, d_u},
                      {cb.d_sigma.data(), cb.d_color.data(), cc ? cb.d_color2.data() : nullptr,
                       cb.d_sigma_x.data()},
                      cb.cache, a.net, model_in(cb, c));
  } else if (opt.need_ray_grads && (cc_detached || dist_detached)) {
    camera_losses_backward<T>(
        cb, a.net, model_in(cb, c), {d_params, d_x, d_u},
        {d_rgb, cc_to_camera ? d_rgb_cc : (T*)nullptr, nullptr, nullptr,
         dist_to_camera ? d_weights : nullptr},
        {cin.sigma, cin.color, cc_to_camera ? cin.color2 : nullptr, cin.s, Rc, S, cin.delta},
        {rgb, cc_to_camera ? rgb_cc : (T*)nullptr, depth, opacity});
  } else {
    model_backward<T>({d_params, d_x, d_u},
                      {cb.d_sigma.data(), cb.d_color.data(), cc ? cb.d_color2.data() : nullptr},
                      cb.cache, a.net, model_in(cb, c));
  }
  if (opt.need_ray_grads && a.grads.d_o && a.grads.d_d) {
    clk.to(kStageRays);
    // x = o + s d → dL/do, dL/dd; u = normalize(d) adds its share to dL/dd (fan-in).
    T* d_oc = a.grads.d_o + 3 * int64_t(r0);
    T* d_dc = a.grads.d_d + 3 * int64_t(r0);
    sample_points_backward(d_oc, d_dc, d_x, c.s, Rc, S);
    normalize3_backward(cb.d_u2.data(), d_u, c.d, Rc);
    for (int i = 0; i < 3 * Rc; ++i) d_dc[i] += cb.d_u2[i];
    HCC_DEBUG_FINITE(d_oc, 3 * int64_t(Rc), "sample_points_backward (d_o)");
    HCC_DEBUG_FINITE(d_dc, 3 * int64_t(Rc), "sample_points_backward + normalize3_backward (d_d)");
  }
  return {se, se_cc, dist_sum};
}

int chunk_size(int chunk_rays, const ModelConfig& cfg, int R, int S) {
  return std::max(1, std::min(resolve_chunk_rays(chunk_rays, cfg, S), R));
}

}  // namespace

int64_t chunk_floats(const ModelConfig& cfg, int R, int S) {
  const int64_t N = int64_t(R) * S;
  // prepare(): x, sigma, d_sigma, d_color, d_color2, color2, d_x a sample; u, d_u, d_u2 a ray.
  return cache_floats(cfg, R, S) + N * (3 + 1 + 1 + 3 + 3 + 3 + 3) + int64_t(R) * 9;
}

int resolve_chunk_rays(int chunk_rays, const ModelConfig& cfg, int S) {
  if (chunk_rays > 0) return std::min(chunk_rays, kMaxChunkRays);
  int rays = 1;
  while (rays < kMaxChunkRays && int64_t(sizeof(float)) * chunk_floats(cfg, 2 * rays, S) <= kAutoChunkBytes)
    rays *= 2;
  return rays;
}

template <class T>
StepResult<T> ray_batch_step(StepWorkspace<T>& ws, const NetView<T>& net, const RayBatch<T>& in,
                             const StepOptions& opt, const RayGrads<T>& grads,
                             const RayOutputs<T>& out) {
  StepResult<T> res;
  const int R = in.R;
  if (R == 0) return res;
  const ModelConfig& cfg = net.cfg;
  const ModelLayout& L = net.L;
  T* d_params = grads.d_params;
  const int chunk = chunk_size(opt.chunk_rays, cfg, R, in.S);
  const int nchunks = (R + chunk - 1) / chunk;
  const StepArgs<T> args{net, in, grads, out, opt, 2.0 / (3.0 * (opt.loss_rays > 0 ? opt.loss_rays : R)),
                         opt.distortion / R};
  if (int(ws.sums.size()) < nchunks) ws.sums.resize(nchunks);  // grow-only: no per-step allocation
  ChunkSums* sums = ws.sums.data();
  StageTimes* prof = ws.chunk.cache.prof;
  const int nt = opt.data_parallel ? std::min(num_threads(), nchunks) : 1;
  if (nt <= 1) {
    // One thread (or one chunk): chunks in order, kernels free to use the threads they have.
    prepare(ws.chunk, cfg, chunk, in.S, opt.keep_mlp);
    if (opt.distortion > 0) prepare_weights(ws.chunk, chunk, in.S);
    for (int c = 0; c < nchunks; ++c)
      sums[c] = process_chunk(ws.chunk, args, d_params, c * chunk, std::min(chunk, R - c * chunk));
  } else {
    // Data parallel over chunks of rays, ONE parallel region per step: thread t runs chunks
    // t, t+nt, … with serial kernels, its own buffers and its own parameter-gradient arena;
    // the arenas are then added to d_params in thread order (thread 0's is d_params itself when
    // it starts at zero: StepOptions::d_params_zero). Deterministic for a given thread
    // count; across thread counts only the rounding of that final sum differs.
    const int first_arena = d_params && opt.d_params_zero ? 1 : 0;
    // StepOptions::level_scatter: the grid table's gradient [tb, te) skips the arenas.
    const bool defer = d_params && opt.level_scatter && cfg.field == Field::grid;
    const HashGridConfig& hg = cfg.gf.grid;
    const int64_t N = int64_t(R) * in.S;
    const int64_t tb = defer ? L.grid_table : 0, te = defer ? L.grid_table + hg.param_count() : 0;
    if (defer) {
      ensure(ws.defer_g, N * hg.out_dim());
      ensure(ws.defer_x, N * 3);
    }
    while (int(ws.per_thread.size()) < nt) ws.per_thread.push_back(std::make_unique<ChunkBuffers<T>>());
    ws.thread_grads.resize(std::max<size_t>(ws.thread_grads.size(), nt));
    ws.thread_prof.resize(std::max<size_t>(ws.thread_prof.size(), nt));
    for (int t = 0; t < nt; ++t) {
      prepare(*ws.per_thread[t], cfg, chunk, in.S, opt.keep_mlp);
      if (opt.distortion > 0) prepare_weights(*ws.per_thread[t], chunk, in.S);
      ws.thread_prof[t].clear();
      ws.per_thread[t]->cache.prof = prof ? &ws.thread_prof[t] : nullptr;
      if (d_params && t >= first_arena) {
        ensure(ws.thread_grads[t], L.count);
        T* a = ws.thread_grads[t].data();
        std::fill(a, a + tb, T(0));  // [tb, te) is never written when deferred
        std::fill(a + te, a + L.count, T(0));
      }
    }
#pragma omp parallel num_threads(nt)
    {
      const int t = omp_get_thread_num();
      T* g = !d_params ? nullptr : t < first_arena ? d_params : ws.thread_grads[t].data();
      ModelCache<T>& mc = ws.per_thread[t]->cache;
      for (int c = t; c < nchunks; c += nt) {
        if (defer) {
          mc.defer_g = ws.defer_g.data();
          mc.defer_x = ws.defer_x.data();
          mc.defer_n = N;
          mc.defer_n0 = int64_t(c) * chunk * in.S;
        }
        sums[c] = process_chunk(*ws.per_thread[t], args, g, c * chunk, std::min(chunk, R - c * chunk));
      }
      mc.defer_g = mc.defer_x = nullptr;
      if (defer) {
        // Every chunk's encoding gradient is in: one level a thread at a time, all points in
        // order, into d_params (whose table part no thread has written this step).
#pragma omp barrier
        StageClock clk(mc.prof, kStageEncode);
#pragma omp for schedule(dynamic, 1)
        for (int l = 0; l < hg.levels; ++l)
          hashgrid_scatter_level(d_params + L.grid_table, ws.defer_g.data() + int64_t(l) * N * hg.features,
                                 ws.defer_x.data(), N, hg, l);
      }
    }
    // Profiler: the threads ran side by side, so their mean is the wall-equivalent.
    if (prof)
      for (int t = 0; t < nt; ++t) prof->add_scaled(ws.thread_prof[t], 1.0 / nt);
    if (d_params) {
      const auto add_arenas = [&](int64_t i) {
        T acc = d_params[i];
        for (int t = first_arena; t < nt; ++t) acc += ws.thread_grads[t][i];
        d_params[i] = acc;
      };
      parallel_for(tb, add_arenas, 4096);
      parallel_for(L.count - te, [&](int64_t i) { add_arenas(te + i); }, 4096);
    }
  }
  HCC_DEBUG_FINITE(d_params, L.count, "ray_batch_step: parameter gradients (all backward kernels)");
  double se = 0, se_cc = 0, dist = 0;
  for (int c = 0; c < nchunks; ++c) {  // fixed order
    se += sums[c].se;
    se_cc += sums[c].se_cc;
    dist += sums[c].dist;
  }
  res.mse = se / (3.0 * R);
  res.mse_cc = se_cc / (3.0 * R);
  res.distortion = dist / R;
  res.loss = (cfg.has_cc() ? res.mse + res.mse_cc : res.mse) + opt.distortion * res.distortion;
  return res;
}

template <class T>
void ray_batch_render(StepWorkspace<T>& ws, const NetView<T>& net, const RayBatch<T>& in,
                      int chunk_rays, const RayOutputs<T>& out) {
  const int R = in.R;
  if (R == 0) return;
  const int chunk = chunk_size(chunk_rays, net.cfg, R, in.S);
  const int nchunks = (R + chunk - 1) / chunk;
  const int nt = std::max(1, std::min(num_threads(), nchunks));
  // One thread renders in buffers that already exist — ws.chunk (1-thread training steps use
  // it) unless the data-parallel steps made per_thread[0] — never new ones: each holds a full
  // set of activations (≤ kAutoChunkBytes at the automatic chunk; ≈ 69 MiB for the paper's
  // network at 64 rays, by the growth law of docs/performance.md).
  ChunkBuffers<T>& single = ws.per_thread.empty() ? ws.chunk : *ws.per_thread[0];
  if (nt <= 1) {
    prepare(single, net.cfg, chunk, in.S, false);  // forward only: nothing to keep
  } else {
    while (int(ws.per_thread.size()) < nt) ws.per_thread.push_back(std::make_unique<ChunkBuffers<T>>());
    for (int t = 0; t < nt; ++t) prepare(*ws.per_thread[t], net.cfg, chunk, in.S, false);
  }
  RayBatch<T> rays = in;
  rays.cc_x = nullptr;
  auto run = [&](int t) {
    ChunkBuffers<T>& cb = nt <= 1 ? single : *ws.per_thread[t];
    T c_rgb[3 * kMaxChunkRays], c_rgb_cc[3 * kMaxChunkRays], c_depth[kMaxChunkRays],
        c_op[kMaxChunkRays];
    const RayOutputs<T> fwd{c_rgb, c_rgb_cc, c_depth, c_op};
    for (int c = t; c < nchunks; c += nt) {
      const int r0 = c * chunk, Rc = std::min(chunk, R - r0);
      chunk_forward(cb, net, slice(rays, r0, Rc), fwd);
      copy_rows(out, fwd, r0, Rc);
    }
  };
  if (nt <= 1) { run(0); return; }
#pragma omp parallel num_threads(nt)
  run(omp_get_thread_num());
}

#define HCC_INST(T)                                                                          \
  template StepResult<T> ray_batch_step<T>(StepWorkspace<T>&, const NetView<T>&,              \
                                           const RayBatch<T>&, const StepOptions&,           \
                                           const RayGrads<T>&, const RayOutputs<T>&);        \
  template void ray_batch_render<T>(StepWorkspace<T>&, const NetView<T>&, const RayBatch<T>&, \
                                    int, const RayOutputs<T>&);
HCC_INST(float)
HCC_INST(double)

}  // namespace hashcc
