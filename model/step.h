// model/step.h — one training step's math, from rays to loss and gradients, no randomness.
//
//   (o, d) per ray ─ sampler ─ x = o + s·d (R·S, 3);  u = normalize(d) (R, 3)
//   model_forward(x, u) ─ σ_raw, c, Δc;  σ = relu(σ_raw);  c_c = c + Δc
//   compositor(σ, c, c_c) ─ p̃, p̃_c;  loss = MSE(p, p̃) [+ MSE(p, p̃_c) for hashcc]
//   backward in reverse order → dL/dparams (+=), dL/do, dL/dd (written) for the camera.
//
// The trainer (random pixels, jitter, camera, Adam) and the golden step (every input from a
// file) both call ray_batch_step, so what is checked is what is trained.
#pragma once
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "model/model.h"

namespace hashcc {

struct StepOptions {
  int chunk_rays = 64;           // rays per forward/backward chunk: bounds activation memory;
                                 // chunks are spread over the threads (data parallel)
  bool data_parallel = true;     // spread chunks over threads (false: chunks in order on one
                                 // workspace, whose cache tests can inspect)
  bool need_ray_grads = true;    // compute dL/do, dL/dd (false when the camera is frozen)
  bool stop_cc_to_camera = false;  // ablation: the second loss reaches σ, c for the networks
                                   // but not the camera
};

template <class T>
struct StepWorkspace {
  ModelCache<T> cache;
  AlignedVec<T> x, u, sigma, color2, d_sigma, d_color, d_color2, d_x, d_u, d_o, d_d, d_x2, d_u2;
  const T* cc_x_fixed = nullptr;  // test hook (R·S, 3), see model_forward
  // Data-parallel steps: one workspace and one parameter-gradient arena per thread.
  std::vector<std::unique_ptr<StepWorkspace<T>>> per_thread;
  std::vector<AlignedVec<T>> thread_grads;
  std::vector<StageTimes> thread_prof;            // per-thread profilers (when cache.prof is set)
  std::vector<std::pair<double, double>> sums;    // per-chunk squared errors (grow-only)
};

template <class T>
struct StepResult {
  double loss = 0, mse = 0, mse_cc = 0;  // mse of p̃ and of p̃_c (mse_cc = mse without CC)
};

// R rays: o, d (R, 3) (NDC when the scene uses it), s (R, S) increasing sample positions,
// target (R, 3). Outputs (each may be null): rgb (R,3) = p̃, rgb_cc (R,3) = p̃_c (= p̃ without
// CC), depth (R). d_params += ; d_o, d_d (R,3) WRITTEN when non-null.
template <class T>
StepResult<T> ray_batch_step(StepWorkspace<T>& ws, const T* params, T* d_params,
                             const ModelConfig& cfg, const ModelLayout& L, const T* o, const T* d,
                             const T* s, const T* target, int R, int S, const StepOptions& opt,
                             T* rgb = nullptr, T* rgb_cc = nullptr, T* depth = nullptr,
                             T* opacity = nullptr, T* d_o = nullptr, T* d_d = nullptr);

// Forward only (rendering): rgb_cc gets c + Δc for hashcc (the colour renders use), rgb gets
// p̃ from c. Any output may be null.
template <class T>
void ray_batch_render(StepWorkspace<T>& ws, const T* params, const ModelConfig& cfg,
                      const ModelLayout& L, const T* o, const T* d, const T* s, int R, int S,
                      int chunk_rays, T* rgb, T* rgb_cc, T* depth, T* opacity);

}  // namespace hashcc
