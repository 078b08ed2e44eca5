// model/step.h — one training step's math, from rays to loss and gradients, no randomness.
//
//   (o, d) per ray ─ sampler ─ x = o + s·d (R·S, 3);  u = normalize(d) (R, 3)
//   model_forward(x, cc_x = detach(x), u) ─ σ_raw, c, Δc;  σ = relu(σ_raw);  c_c = c + Δc
//   compositor(σ, c, c_c) ─ p̃, p̃_c, w;  loss = MSE(p, p̃) [+ MSE(p, p̃_c) for hashcc]
//                                        [+ λ · mean distortion(w), --distortion λ]
//   backward in reverse order → dL/dparams (+=), dL/do, dL/dd (written) for the camera.
//
// model/camera_step.h puts the camera around this (pixels in, camera gradients out); the
// trainer, the golden step and the test-pose refinement all call that.
#pragma once
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "model/model.h"

namespace hashcc {

// Rays per chunk, at most: bounds the per-chunk stack arrays of per-ray values (and, through
// StepOptions::chunk_rays, the activation memory of one chunk).
inline constexpr int kMaxChunkRays = 1024;

// The automatic chunk (chunk_rays = 0): the largest power of two of rays whose buffers (the
// model's cache and the step's own, in float) fit in this many bytes. The fields keep very
// different bytes a sample, so a good chunk in rays differs 16× between them: the paper's network
// ~8.7 KB a sample (16 rays of 128 samples: ~17 MiB), the grid field's ~2.2 KB (256 rays of 32
// samples: ~17 MiB). Measured on a Zen 4 (32 MiB of L3, 2 threads, paired rounds): the paper's
// step at 16 rays against its old default of 64, and the grid field's at 256 against 64
// (docs/performance.md, "The automatic chunk").
inline constexpr int64_t kAutoChunkBytes = int64_t(24) << 20;

// The floats one chunk of R rays × S samples holds: ModelCache::reserve's and the step's own
// per-chunk buffers (without the distortion loss's, which only a run with --distortion has).
int64_t chunk_floats(const ModelConfig& cfg, int R, int S);

// Rays per chunk: chunk_rays if > 0, else the automatic chunk; always in [1, kMaxChunkRays].
int resolve_chunk_rays(int chunk_rays, const ModelConfig& cfg, int S);

struct StepOptions {
  int chunk_rays = 0;            // rays per forward/backward chunk (≤ kMaxChunkRays; 0 = auto,
                                 // resolve_chunk_rays): bounds activation memory; chunks are
                                 // spread over the threads
  bool data_parallel = true;     // spread chunks over threads (false: chunks in order on one
                                 // workspace, whose cache tests can inspect)
  bool need_ray_grads = true;    // compute dL/do, dL/dd (false when the camera is frozen)
  bool stop_cc_to_camera = false;  // ablation: the second loss reaches σ, c for the networks
                                   // but not the camera (stop_cc_to_camera_backward)
  double distortion = 0;           // --distortion λ: adds λ · mean over rays of the distortion
                                   // loss of the main field's weights (render/distortion.h);
                                   // 0 = off, and nothing of it is computed. It reaches the
                                   // networks, not the camera (camera_losses_backward) unless:
  bool distortion_to_camera = false;  // ablation: the distortion loss reaches the camera too
  // The caller's d_params is all +0 on entry (the trainer zeroes it before every step): the
  // data-parallel step's first thread then adds its chunks' gradients into d_params itself
  // instead of into an arena of its own, one parameter-sized buffer less (16 MiB for a 2^17
  // grid). The same bits: its arena would have started at +0 too, and d_params + arena_0 was
  // arena_0 (a sum that starts at +0 never becomes −0).
  bool d_params_zero = false;
  // The grid field's table gradient in the data-parallel step: split over levels (true) — each
  // thread's chunks leave their encoding gradients, then each level is scattered by one thread
  // over all the batch's points in order (hashgrid_scatter_level), straight into d_params: no
  // per-thread table arena to zero and add up, and the table gradient the same bit for bit at
  // any thread count (the 1-thread step's). false: each thread scatters its chunks into its own
  // arena, added up afterwards (the step before session 28; kept for the test that compares).
  bool level_scatter = true;
  // Keep the small MLPs' activations from the forward for the backward (ModelCache::keep_mlp)
  // instead of recomputing them there. The same values either way. Off for training (its
  // backward forms weight gradients, where recomputing in L1/L2 was measured faster); on for
  // eval's test-pose refinement, whose backward is input gradients only (docs/performance.md).
  bool keep_mlp = false;
  int loss_rays = 0;  // > 0: the MSE's gradient is that of a mean over this many rays instead of
                      // R (eval's test-pose refinement batches several views, each its own loss
                      // over its own rays: eval/evaluate.cpp). StepResult still divides by R.
};

// R rays of S samples (NDC when the scene uses it).
template <class T>
struct RayBatch {
  const T* o = nullptr;       // (R, 3)
  const T* d = nullptr;       // (R, 3)
  const T* s = nullptr;       // (R, S) increasing sample positions
  const T* target = nullptr;  // (R, 3) the pixels' colours p (the step; unused by render)
  int R = 0, S = 0;
  // The CC branch's input (R·S, 3), detached: no gradient flows back through it (docs/formulas.md
  // §5). null = the step's own samples x. A finite difference over the camera passes a fixed x
  // here, so that the CC branch does not move with the camera.
  const T* cc_x = nullptr;
  // (R, S) each sample's δ for the compositor (CompositeIn::delta); null = the gaps of s.
  const T* delta = nullptr;
};

// Per-ray outputs of a step or a render, each (R, 3) or (R) and each may be null: rgb = p̃,
// rgb_cc = p̃_c (= p̃ without CC), depth, opacity.
template <class T>
struct RayOutputs {
  T* rgb = nullptr;
  T* rgb_cc = nullptr;
  T* depth = nullptr;
  T* opacity = nullptr;
};

// Gradients of a step. d_params (L.count) += (null: the networks are frozen); d_o, d_d (R, 3)
// WRITTEN when non-null (the camera's inputs).
template <class T>
struct RayGrads {
  T* d_params = nullptr;
  T* d_o = nullptr;
  T* d_d = nullptr;
};

// The buffers of one chunk of rays: the model's activations and the step's own per-sample
// values and gradients. Grow-only (sized for the largest chunk seen).
template <class T>
struct ChunkBuffers {
  ModelCache<T> cache;
  AlignedVec<T> x, u, sigma, color2, d_sigma, d_color, d_color2, d_x, d_u, d_u2;
  AlignedVec<T> weights, d_weights;  // (R·S) the compositing weights and their gradient
                                     // (only with StepOptions::distortion)
  AlignedVec<T> d_sigma_x, d_color_x, d_color2_x;  // the camera's losses alone through the
                                     // compositor (the grid field's detached distortion)
};

// One chunk's loss sums: squared errors of p̃ and of p̃_c, and the distortion losses of its rays.
struct ChunkSums {
  double se = 0, se_cc = 0, dist = 0;
};

// A step's scratch: the chunk buffers (one thread, chunks in order) and the multi-thread state
// of data-parallel steps (one ChunkBuffers and one parameter-gradient arena per thread).
template <class T>
struct StepWorkspace {
  ChunkBuffers<T> chunk;
  std::vector<std::unique_ptr<ChunkBuffers<T>>> per_thread;
  std::vector<AlignedVec<T>> thread_grads;
  std::vector<StageTimes> thread_prof;            // per-thread profilers (when chunk.cache.prof)
  std::vector<ChunkSums> sums;                    // per-chunk loss sums (grow-only)
  AlignedVec<T> defer_g, defer_x;  // StepOptions::level_scatter: the batch's (L, N, F), (N, 3)
};

template <class T>
struct StepResult {
  double loss = 0, mse = 0, mse_cc = 0;  // mse of p̃ and of p̃_c (mse_cc = mse without CC)
  double distortion = 0;                 // mean distortion loss over the rays (0 when off);
                                         // loss = mse [+ mse_cc] + λ · distortion
};

// Forward, loss and backward of a batch of rays.
template <class T>
StepResult<T> ray_batch_step(StepWorkspace<T>& ws, const NetView<T>& net, const RayBatch<T>& in,
                             const StepOptions& opt, const RayGrads<T>& grads,
                             const RayOutputs<T>& out = {});

// Forward only (rendering): out.rgb_cc gets c + Δc for hashcc (the colour renders use), out.rgb
// gets p̃ from c. in.target is unused.
template <class T>
void ray_batch_render(StepWorkspace<T>& ws, const NetView<T>& net, const RayBatch<T>& in,
                      int chunk_rays, const RayOutputs<T>& out);

}  // namespace hashcc
