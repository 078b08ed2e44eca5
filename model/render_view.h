// model/render_view.h — render a whole view (or every stride-th pixel) of a trained model.
// Samples are s_i = i/S (no jitter, formulas.md §3: final renders); rays go through the same camera
// and NDC code as training. Chunked over rows; every kernel inside runs on all threads.
#pragma once
#include <vector>

#include "camera/camera.h"
#include "model/step.h"

namespace hashcc {

struct ViewImage {
  int width = 0, height = 0;
  std::vector<float> rgb;      // (H, W, 3): p̃_c for hashcc (the corrected colour), else p̃
  std::vector<float> depth;    // (H, W) expected NDC depth Σ w s
  std::vector<float> opacity;  // (H, W) Σ w
};

// One camera as a render sees it: the pose, the shared focal, the image size, NDC on or off.
struct ViewCamera {
  PoseParams<float> pose;
  FocalParams<float> focal;
  ImageSize size;
  bool ndc = true;
};

// How to render: samples per ray, every stride-th pixel in x and y, rays per chunk.
struct ViewOptions {
  int samples = 128;
  int stride = 1;
  int chunk_rays = 1024;
};

ViewImage render_view(StepWorkspace<float>& ws, const NetView<float>& net, const ViewCamera& cam,
                      const ViewOptions& opt);

}  // namespace hashcc
