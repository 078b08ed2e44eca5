// outputs/paths.h — camera paths for novel views (hashcc render) and the NDC-depth geometry they
// need. Formulas and conventions: docs/render.md. Tests: test/test_render.cpp ("[render]").
//
// Every pose here is an OpenGL camera-to-world 3×4 matrix [right up back | centre] in the
// LEARNED frame (the frame of the training cameras, as in cameras.json), double precision.
#pragma once
#include "core/stats.h"
#include <Eigen/Core>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "core/llff.h"

namespace hashcc {

class Trainer;

// c2w → the renderer's pose parameters: r = Log(R) (|r| ≤ π), t = centre, no P0. (The other
// way is world_from_camera(p.cast<double>()), camera/camera.h.)
PoseParams<float> pose_params_from_c2w(const Mat34d& c2w);


// ---- the NDC depth ↔ world point inverse (formulas.md §2; derivation in docs/render.md) ----------
// (o, d): the WORLD ray of a pixel before NDC (rays_forward). s: position along the NDC ray
// x = o' + s·d' (s = 0 on the near plane z = −1, s → 1 at z → −∞). Returns the world point
//   p = o + t_n·d,  t_n = −(1 + o_z)/d_z        (the ray moved to the near plane)
//   X = p + τ·d,    τ = s / ((s − 1)·d_z)         (so that X_z = 1/(s − 1))
// Without NDC (ndc = false) the sampler's x = o + s·d is already the world point.
Eigen::Vector3d ndc_depth_to_world(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double s,
                                   bool ndc = true);
// The forward map for points on that ray: s = 1 + 1/X_z (NDC), or the ray parameter (no NDC).
double world_to_ndc_depth(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                          const Eigen::Vector3d& X, bool ndc = true);

// ---- LLFF's spiral (render_path_spiral of LLFF / NeRF's load_llff.py) ---------------------
struct SpiralOptions {
  int frames = 120;          // LLFF's N_views
  double rotations = 2;      // N_rots
  double zrate = 0.5;        // z oscillation: −sin(θ·zrate)
  double radius_percentile = 90;
  double dt = 0.75;          // focus = 1 / ((1 − dt)/close + dt/inf)
};
struct SpiralInfo {
  Mat34d average;                     // LLFF poses_avg of the cameras
  Eigen::Vector3d radii;              // per axis of the average pose
  double close_depth = 0, inf_depth = 0, focus = 0;
};
// close_depth, inf_depth: LLFF's bds.min()·0.9 and bds.max()·5 (metric, in learned units along
// each camera's −z), here taken from the percentiles of the rendered depth (docs/render.md).
std::vector<Mat34d> spiral_path(const std::vector<Mat34d>& c2w, double close_depth,
                                double inf_depth, const SpiralOptions& opt,
                                SpiralInfo* info = nullptr);

// Metric z-depths (along each camera's −z, learned units) of the expected surface seen by the
// training views: render every training view at ≤ max_pixels rays, keep pixels with opacity
// ≥ opacity_threshold, s̄ = Σ w s / Σ w, X = ndc_depth_to_world(o, d, s̄). Also returns the
// 1st/99th-percentile range of s̄ (for colour-mapping depth images) when s_range is non-null.
std::vector<double> training_view_depths(const Trainer& tr, int max_pixels = 4096,
                                         double opacity_threshold = 0.5,
                                         double* s_range = nullptr);

// The learned training cameras, in training order.
std::vector<Mat34d> training_c2w(const Trainer& tr);
// The test images' reference cameras moved into the learned frame: the Umeyama Sim(3) that maps
// the reference training centres onto the learned ones, applied to whole poses
// (R = R_a·R_ref, c = s·R_a·c_ref + t_a). Falls back to formulas.md §7's initialisation (reference
// pose, translation scaled by the ratio of spreads) when the fit is degenerate (early runs).
// Throws hashcc::Error naming the scene when it has no reference cameras or no test images.
std::vector<Mat34d> test_c2w_in_learned_frame(const Trainer& tr, std::string* method = nullptr);

}  // namespace hashcc
