// model/render_view.h — render a whole view (or every stride-th pixel) of a trained model.
// Samples are s_i = i/S (no jitter, formulas.md §3: final renders); rays go through the same camera
// and NDC code as training. Chunked over rows; every kernel inside runs on all threads.
#pragma once
#include <vector>

#include "camera/camera.h"
#include "model/step.h"
#include "render/occupancy.h"

namespace hashcc {

struct ViewImage {
  int width = 0, height = 0;
  std::vector<float> rgb;      // (H, W, 3): p̃_c for hashcc (the corrected colour), else p̃
  std::vector<float> depth;    // (H, W) expected NDC depth Σ w s
  std::vector<float> opacity;  // (H, W) Σ w
};

// One camera as a render sees it: the pose, the shared focal, the image size, the NDC warp (on or
// off, and the focal its box is drawn with: camera.h's NdcWarp).
struct ViewCamera {
  PoseParams<float> pose;
  FocalParams<float> focal;
  ImageSize size;
  NdcWarp ndc = true;
};

// How to render: samples per ray, every stride-th pixel in x and y, rays per chunk (0 = auto,
// resolve_chunk_rays), and (runs trained with --occupancy on) the occupancy grid: the samples
// then go where it says, at the strata's centres s_in = (k + ½)/S (render/occupancy.h).
struct ViewOptions {
  int samples = 128;
  int stride = 1;
  int chunk_rays = 1024;
  const OccupancyGrid* occupancy = nullptr;
};

ViewImage render_view(StepWorkspace<float>& ws, const NetView<float>& net, const ViewCamera& cam,
                      const ViewOptions& opt);

}  // namespace hashcc
