#include "model/render_view.h"

#include <algorithm>

#include "core/parallel.h"

namespace hashcc {

ViewImage render_view(StepWorkspace<float>& ws, const NetView<float>& net, const ViewCamera& cam,
                      const ViewOptions& opt) {
  const PoseParams<float>& pose = cam.pose;
  const FocalParams<float>& focal = cam.focal;
  const ImageSize size = cam.size;
  const NdcWarp ndc = cam.ndc;
  const int S = opt.samples, stride = std::max(1, opt.stride);
  const int chunk_rays = resolve_chunk_rays(opt.chunk_rays, net.cfg, S);
  ViewImage img;
  img.width = (size.W + stride - 1) / stride;
  img.height = (size.H + stride - 1) / stride;
  const int64_t total = int64_t(img.width) * img.height;
  img.rgb.resize(total * 3);
  img.depth.resize(total);
  img.opacity.resize(total);
  // One chunk a thread per call: ray_batch_render then runs the chunks side by side, each thread
  // with serial kernels, as a training step does (one chunk a call would fork every kernel).
  const int block = std::min(kMaxChunkRays, chunk_rays * std::max(1, num_threads()));
  std::vector<int> px(2 * block);
  std::vector<float> o(3 * block), d(3 * block), s(int64_t(block) * S), rgb(3 * block);
  // formulas.md §3: s_i = i/S for final renders; with an occupancy grid, the strata's centres
  // (k + ½)/S, which occupancy_samples moves into each ray's occupied stretches (s_occ, delta).
  for (int i = 0; i < S; ++i) s[i] = opt.occupancy ? (i + 0.5f) / S : float(i) / S;
  for (int r = 1; r < block; ++r) std::copy(s.begin(), s.begin() + S, s.begin() + int64_t(r) * S);
  std::vector<float> s_occ, delta;
  if (opt.occupancy) {
    s_occ.resize(s.size());
    delta.resize(s.size());
  }
  for (int64_t r0 = 0; r0 < total; r0 += block) {
    const int R = int(std::min<int64_t>(block, total - r0));
    for (int r = 0; r < R; ++r) {
      int64_t k = r0 + r;
      px[2 * r] = int(k % img.width) * stride;      // u (column)
      px[2 * r + 1] = int(k / img.width) * stride;  // v (row)
    }
    camera_rays_forward(o.data(), d.data(), px.data(), R, pose, focal, size, ndc);
    RayBatch<float> rays{o.data(), d.data(), s.data(), nullptr, R, S};
    if (opt.occupancy) {
      occupancy_samples(s_occ.data(), delta.data(), *opt.occupancy, o.data(), d.data(), s.data(),
                        R, S);
      rays.s = s_occ.data();
      rays.delta = delta.data();
    }
    ray_batch_render(ws, net, rays,
                     chunk_rays, {nullptr, img.rgb.data() + 3 * r0, img.depth.data() + r0,
                                  img.opacity.data() + r0});
  }
  return img;
}

}  // namespace hashcc
