// model/camera_step.h — the one training step with the camera around it: pixels, poses and
// focal in; loss, network gradients and camera gradients out.
//
//   px (R, 2) ─ camera_rays_forward(pose_j, focal) per view ─ (o, d) [NDC when ndc]
//   ray_batch_step(o, d, s, target) ─ loss, dL/dθ (+=), dL/do, dL/dd         (model/step.h)
//   camera_rays_backward per view ─ dL/d[r t]_j (each view), dL/d[a b] (summed over views)
//
// Trainer::step_once (K training views), the golden step (one view, every input from a file)
// and eval's test-pose refinement (one view, frozen networks) all call camera_step, so what the
// [golden] test checks is what trains. Nothing random happens inside: the caller draws the
// pixels (pick_distinct) and the sample positions (jitter_samples).
#pragma once
#include <cstdint>
#include <vector>

#include "camera/camera.h"
#include "core/parallel.h"
#include "model/step.h"
#include "render/occupancy.h"

namespace hashcc {

// What goes in. The rays are split into `views` equal segments: view j owns rays
// [j·R/views, (j+1)·R/views) and is seen through poses[j]; all views share one focal.
template <class T>
struct CameraBatch {
  const int* px = nullptr;      // (R, 2) full-resolution pixels [u v …], u = column, v = row
  const T* target = nullptr;    // (R, 3) the pixels' colours
  const T* s = nullptr;         // (R, S) increasing sample positions
  int R = 0, S = 0;
  const PoseParams<T>* poses = nullptr;  // (views)
  int views = 1;
  FocalParams<T> focal;
  ImageSize size;
  NdcWarp ndc = true;           // NDC on/off and the focal its box is drawn with (camera.h)
  const T* cc_x = nullptr;      // detached CC input override (RayBatch::cc_x); null = x
  // --occupancy: s is then the uniform jitter that occupancy_samples maps into the occupied
  // stretches of each ray (render/occupancy.h), with their δ. null = s as given.
  const OccupancyGrid* occupancy = nullptr;
};

// What comes out besides the loss. d_params (L.count) += (null: the networks are frozen);
// d_pose (views, 6) = dL/d[r t] of each view and d_focal = dL/d[a b], both WRITTEN.
template <class T>
struct CameraStepGrads {
  T* d_params = nullptr;
  std::vector<T> d_pose;   // grow-only: sized on the first step, reused after
  T d_focal[2] = {0, 0};
};

// Buffers of a camera step, grow-only: the ray step's workspace and the rays with their
// gradients. After a step, o and d hold its (NDC) rays.
template <class T>
struct CameraStepWorkspace {
  StepWorkspace<T> rays;
  std::vector<T> o, d, d_o, d_d;  // (R, 3)
  std::vector<T> s, delta;        // (R, S) occupancy samples and their δ (CameraBatch::occupancy)
};

template <class T>
StepResult<T> camera_step(CameraStepWorkspace<T>& ws, const NetView<T>& net,
                          const CameraBatch<T>& in, const StepOptions& opt,
                          CameraStepGrads<T>& grads, const RayOutputs<T>& out = {});

// The first k entries of idx become k distinct values of [0, n), drawn uniformly (a partial
// Fisher–Yates shuffle; idx is resized to n and reused across steps).
void pick_distinct(Rng& rng, std::vector<int>& idx, int n, int k);

// Jittered samples (formulas.md §3): s_k = (k + U[0, 1))/S, independent per sample; s (R, S).
template <class T>
void jitter_samples(Rng& rng, T* s, int R, int S) {
  for (int r = 0; r < R; ++r)
    for (int k = 0; k < S; ++k) s[int64_t(r) * S + k] = T((k + rng.uniform()) / S);
}

}  // namespace hashcc
