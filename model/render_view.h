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
  // Render shortcuts (the grid field without an occupancy grid; other fields ignore them):
  // 0 = off, every sample of every ray (the exact render). When shortcuts is on, a ray marches
  // its samples in blocks of kMarchBlock and stops once its transmittance T < t_min, and a
  // sample whose weight w < w_min gets no colour (its density still counts in T, depth and
  // opacity). The weight left out of a ray's colour is < t_min + S·w_min, so each colour moves
  // by less than that times the largest |colour| left out (docs/render.md, "Render shortcuts").
  bool shortcuts = false;
  double t_min = 0.5e-4;
  double w_min_total = 0.5e-4;  // w_min = w_min_total / S
  // Empty-space skipping (with the shortcuts only; null = off): a sample in a cell this grid
  // marks empty gets σ = 0 without evaluating the field (its density, colour and CC branch).
  // Built from the trained field by empty_space_grid(); not exact: a skipped sample's true σ
  // was below the grid's threshold at the points the grid measured (docs/render.md).
  const OccupancyGrid* skip = nullptr;
};

// The empty-space grid of a trained field for ViewOptions::skip: res³ cells over the NDC box,
// each marked occupied when the largest σ at `passes` jittered points inside it reaches sigma_min
// (then dilated by one cell, render/occupancy.h).
OccupancyGrid empty_space_grid(const NetView<float>& net, int res, double sigma_min, int passes,
                               uint64_t seed = 1);

// The render shortcuts' block of samples a ray marches at a time.
inline constexpr int kMarchBlock = 8;

// What a render evaluated: samples whose density was computed, and whose colour was.
struct RenderStats {
  int64_t samples = 0, density = 0, colour = 0;
};

ViewImage render_view(StepWorkspace<float>& ws, const NetView<float>& net, const ViewCamera& cam,
                      const ViewOptions& opt, RenderStats* stats = nullptr);

// Whether render_view takes the shortcuts for this network and options.
bool render_shortcuts_apply(const ModelConfig& cfg, const ViewOptions& opt);

// The shortcuts' render of R rays (o, d) (R, 3) with the same S sample positions s (S) each
// (no jitter, no occupancy); the grid field only. out as ray_batch_render's (rgb, rgb_cc, depth,
// opacity; each may be null). Rays in blocks over the threads; stats may be null.
void render_rays_marched(const NetView<float>& net, const float* o, const float* d, const float* s,
                         int R, int S, const RayOutputs<float>& out, double t_min, double w_min,
                         RenderStats* stats = nullptr, const OccupancyGrid* skip = nullptr);

}  // namespace hashcc
