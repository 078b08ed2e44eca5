// outputs/export.h — hand-off to other tools: a coloured point cloud from the expected depth of the
// training views (PLY), and the learned cameras as a COLMAP text model. Conventions and
// formulas: docs/render.md. Tests: test/test_render.cpp ("[render]").
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "model/render_view.h"
#include "core/llff.h"

namespace hashcc {

class Trainer;

struct PointCloud {
  std::vector<Eigen::Vector3d> xyz;           // world (learned frame)
  std::vector<std::array<uint8_t, 3>> rgb;    // 0..255
  size_t size() const { return xyz.size(); }
};

// One view's points. v is a render at `stride` of camera cam (v.rgb may be replaced by other
// colours, e.g. the photo's): entry (x, y) is pixel (u, v) = (x·stride, y·stride) of cam.size.
// Keeps pixels with opacity ≥ opacity_threshold; s̄ = depth / opacity (Σ w s / Σ w, the
// expected depth of the visible part); with NDC, s̄ ≥ 1 − 1e-4 (at infinity) is dropped. The
// world point is ndc_depth_to_world(o, d, s̄) of the pixel's world ray (outputs/paths.h).
void append_view_points(PointCloud& cloud, const ViewCamera& cam, int stride, const ViewImage& v,
                        double opacity_threshold);

// Renders every training view of a run at `stride` and collects its points; colours are the
// training photos' pixels. progress: show a bar.
PointCloud training_point_cloud(const Trainer& tr, int stride, double opacity_threshold,
                                bool progress = false);

// Binary little-endian PLY: float x y z, uchar red green blue.
void write_ply(const std::string& path, const PointCloud& cloud);

// ---- COLMAP text model -----------------------------------------------------------------------
// COLMAP's cameras are OpenCV-style (x right, y down, z forward) and images.txt stores
// world-to-camera: R_cv = R_gl·diag(1, −1, −1), R_w2c = R_cvᵀ, t_w2c = −R_w2c·centre,
// q = quaternion(R_w2c) with q_w ≥ 0.
struct ColmapPose {
  Eigen::Quaterniond q;  // world-to-camera rotation
  Eigen::Vector3d t;     // world-to-camera translation
};
ColmapPose colmap_from_c2w(const Mat34d& c2w_gl);
Mat34d c2w_from_colmap(const ColmapPose& p);

// One PINHOLE camera. COLMAP puts the centre of the top-left pixel at (0.5, 0.5), our rays put
// pixel u at u (formulas.md §1, no +0.5), so cx = W/2 + 0.5, cy = H/2 + 0.5.
struct ColmapCamera {
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
};
ColmapCamera colmap_camera(const FocalParams<float>& focal, ImageSize size);

// Writes dir/cameras.txt, dir/images.txt (IDs 1…N, camera 1, empty 2D-point lines) and
// dir/points3D.txt (the cloud, or only the header when cloud is null/empty).
void write_colmap_text(const std::string& dir, const ColmapCamera& cam,
                       const std::vector<Mat34d>& c2w_gl, const std::vector<std::string>& names,
                       const PointCloud* cloud);

}  // namespace hashcc
