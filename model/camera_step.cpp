#include "model/camera_step.h"

#include <algorithm>

#include "core/error.h"

namespace hashcc {

template <class T>
StepResult<T> camera_step(CameraStepWorkspace<T>& ws, const NetView<T>& net,
                          const CameraBatch<T>& in, const StepOptions& opt,
                          CameraStepGrads<T>& grads, const RayOutputs<T>& out) {
  const int R = in.R, V = in.views;
  HCC_ASSERT(V >= 1 && R % V == 0);
  const int Rv = R / V;  // rays per view
  const size_t n3 = 3 * size_t(R);
  for (std::vector<T>* v : {&ws.o, &ws.d, &ws.d_o, &ws.d_d})
    if (v->size() < n3) v->resize(n3);
  if (grads.d_pose.size() < 6 * size_t(V)) grads.d_pose.resize(6 * size_t(V));
  StageClock clk(ws.rays.chunk.cache.prof, kStageRays);
  // Camera: pixels → rays → NDC, each view's segment with its own pose (one shared focal).
  for (int j = 0; j < V; ++j) {
    const int64_t off = int64_t(j) * Rv;
    camera_rays_forward(ws.o.data() + 3 * off, ws.d.data() + 3 * off, in.px + 2 * off, Rv,
                        in.poses[j], in.focal, in.size, in.ndc);
  }
  // Occupancy sampling: the same jitter, moved into the occupied stretches of each ray.
  RayBatch<T> rays{ws.o.data(), ws.d.data(), in.s, in.target, R, in.S, in.cc_x};
  if (in.occupancy) {
    const size_t ns = size_t(R) * in.S;
    if (ws.s.size() < ns) ws.s.resize(ns);
    if (ws.delta.size() < ns) ws.delta.resize(ns);
    occupancy_samples(ws.s.data(), ws.delta.data(), *in.occupancy, ws.o.data(), ws.d.data(), in.s,
                      R, in.S);
    rays.s = ws.s.data();
    rays.delta = ws.delta.data();
  }
  clk.stop();  // ray_batch_step times its own stages
  // The model, the loss (the mean over all R rays, whichever view they came from) and every
  // gradient of the rays.
  const StepResult<T> res =
      ray_batch_step(ws.rays, net, rays, opt, {grads.d_params, ws.d_o.data(), ws.d_d.data()}, out);
  clk.to(kStageRays);
  // Camera backward per view: each view's rays give its own [dr dt]; every view adds its share
  // to the one focal gradient. Cameras that do not learn (need_ray_grads off) get zeros.
  std::fill(grads.d_focal, grads.d_focal + 2, T(0));
  if (!opt.need_ray_grads) {
    std::fill(grads.d_pose.begin(), grads.d_pose.begin() + 6 * V, T(0));
    return res;
  }
  for (int j = 0; j < V; ++j) {
    const int64_t off = int64_t(j) * Rv;
    T* d_pose = grads.d_pose.data() + 6 * j;
    std::fill(d_pose, d_pose + 6, T(0));
    camera_rays_backward(d_pose, grads.d_focal, ws.d_o.data() + 3 * off, ws.d_d.data() + 3 * off,
                         in.px + 2 * off, Rv, in.poses[j], in.focal, in.size, in.ndc);
  }
  return res;
}

void pick_distinct(Rng& rng, std::vector<int>& idx, int n, int k) {
  idx.resize(n);
  for (int j = 0; j < n; ++j) idx[j] = j;
  for (int j = 0; j < k; ++j) std::swap(idx[j], idx[j + rng.below(uint32_t(n - j))]);
}

#define HCC_INST(T)                                                                          \
  template StepResult<T> camera_step<T>(CameraStepWorkspace<T>&, const NetView<T>&,        \
                                        const CameraBatch<T>&, const StepOptions&,         \
                                        CameraStepGrads<T>&, const RayOutputs<T>&);
HCC_INST(float)
HCC_INST(double)

}  // namespace hashcc
