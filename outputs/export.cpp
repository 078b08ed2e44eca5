#include "outputs/export.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fmt/format.h>

#include "core/error.h"
#include "core/fileio.h"
#include "core/progress.h"
#include "outputs/paths.h"
#include "model/render_view.h"
#include "train/trainer.h"

namespace hashcc {

using Eigen::Vector3d;

void append_view_points(PointCloud& cloud, const ViewCamera& cam, int stride, const ViewImage& v,
                        double opacity_threshold) {
  const PoseParams<float>& pose = cam.pose;
  const FocalParams<float>& focal = cam.focal;
  const ImageSize size = cam.size;
  const bool ndc = cam.ndc.on;  // the depth map's inverse does not use the box's focal
  const int w = v.width, h = v.height;
  const float *depth = v.depth.data(), *opacity = v.opacity.data(), *rgb = v.rgb.data();
  // Rays in double: the NDC inverse amplifies errors as s̄ → 1 (X_z = 1/(s̄ − 1)).
  const PoseParams<double> pd = pose.cast<double>();
  FocalParams<double> fd;
  fd.a = focal.a; fd.b = focal.b; fd.fx_only = focal.fx_only;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t k = size_t(y) * w + x;
      const double op = opacity[k];
      if (!(op >= opacity_threshold) || !(op > 0)) continue;
      const double s = double(depth[k]) / op;  // s̄ = Σ w s / Σ w
      if (!std::isfinite(s) || s < 0) continue;
      if (ndc && !(s < 1.0 - 1e-4)) continue;  // at infinity
      int px[2] = {x * stride, y * stride};
      double o[3], d[3];
      rays_forward<double>(o, d, px, 1, pd, fd, size);
      cloud.xyz.push_back(ndc_depth_to_world(Vector3d(o[0], o[1], o[2]),
                                             Vector3d(d[0], d[1], d[2]), s, ndc));
      std::array<uint8_t, 3> c;
      for (int j = 0; j < 3; ++j)
        c[j] = uint8_t(std::lround(std::clamp(double(rgb[3 * k + j]), 0.0, 1.0) * 255.0));
      cloud.rgb.push_back(c);
    }
}

PointCloud training_point_cloud(const Trainer& tr, int stride, double opacity_threshold,
                                bool progress) {
  stride = std::max(1, stride);
  const Scene& sc = tr.scene();
  StepWorkspace<float> ws;
  PointCloud cloud;
  ProgressBar bar("points", int64_t(sc.train.size()), progress);
  for (int i = 0; i < int(sc.train.size()); ++i) {
    const PoseParams<float> pose = tr.pose_of(i);
    ViewImage v = render_view(ws, tr.net(), tr.view_camera(pose),
                              {tr.config().samples, stride, tr.config().chunk_rays,
                               tr.render_occupancy()});
    // Colours from the training photo at the same pixels (crisper than the render).
    std::vector<float>& photo = v.rgb;
    const ImageU8& img = sc.images[sc.train[i]];
    for (int y = 0; y < v.height; ++y)
      for (int x = 0; x < v.width; ++x)
        for (int c = 0; c < 3; ++c)
          photo[(size_t(y) * v.width + x) * 3 + c] = img.at(y * stride, x * stride, c);
    append_view_points(cloud, tr.view_camera(pose), stride, v, opacity_threshold);
    bar.update(i + 1, fmt::format("{} points", cloud.size()));
  }
  bar.finish(fmt::format("{} points", cloud.size()));
  return cloud;
}

void write_ply(const std::string& path, const PointCloud& cloud) {
  std::string out = fmt::format(
      "ply\nformat binary_little_endian 1.0\ncomment hashcc export: expected depth of the "
      "training views, learned frame\nelement vertex {}\nproperty float x\nproperty float y\n"
      "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
      "end_header\n",
      cloud.size());
  const size_t head = out.size();
  out.resize(head + cloud.size() * 15);
  char* p = out.data() + head;
  for (size_t i = 0; i < cloud.size(); ++i) {
    float xyz[3] = {float(cloud.xyz[i].x()), float(cloud.xyz[i].y()), float(cloud.xyz[i].z())};
    std::memcpy(p, xyz, 12);  // little-endian hosts (x86-64, arm64)
    std::memcpy(p + 12, cloud.rgb[i].data(), 3);
    p += 15;
  }
  const std::string parent = std::filesystem::path(path).parent_path().string();
  if (!parent.empty()) make_dirs(parent);
  write_file_atomic(path, out);
}

ColmapPose colmap_from_c2w(const Mat34d& c2w) {
  // OpenGL [right up back] → OpenCV [right down forward]: flip the y and z axes.
  const Eigen::Matrix3d R_cv = c2w.leftCols<3>() * Eigen::Vector3d(1, -1, -1).asDiagonal();
  const Eigen::Matrix3d R_w2c = R_cv.transpose();
  ColmapPose p;
  p.q = Eigen::Quaterniond(R_w2c).normalized();
  if (p.q.w() < 0) p.q.coeffs() *= -1;  // same rotation; COLMAP writes q_w ≥ 0
  p.t = -R_w2c * c2w.col(3);
  return p;
}

Mat34d c2w_from_colmap(const ColmapPose& p) {
  const Eigen::Matrix3d R_w2c = p.q.normalized().toRotationMatrix();
  Mat34d m;
  m.leftCols<3>() = R_w2c.transpose() * Eigen::Vector3d(1, -1, -1).asDiagonal();
  m.col(3) = -R_w2c.transpose() * p.t;
  return m;
}

ColmapCamera colmap_camera(const FocalParams<float>& focal, ImageSize size) {
  ColmapCamera c;
  c.width = size.W;
  c.height = size.H;
  c.fx = focal_fx<double>(FocalParams<double>{focal.a, focal.b, focal.fx_only}, size);
  c.fy = focal_fy<double>(FocalParams<double>{focal.a, focal.b, focal.fx_only}, size);
  c.cx = size.W / 2.0 + 0.5;
  c.cy = size.H / 2.0 + 0.5;
  return c;
}

void write_colmap_text(const std::string& dir, const ColmapCamera& cam,
                       const std::vector<Mat34d>& c2w, const std::vector<std::string>& names,
                       const PointCloud* cloud) {
  HCC_ASSERT(c2w.size() == names.size());
  make_dirs(dir);
  write_file_atomic(
      dir + "/cameras.txt",
      fmt::format("# Camera list with one line of data per camera:\n"
                  "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                  "# Number of cameras: 1\n"
                  "1 PINHOLE {} {} {:.17g} {:.17g} {:.17g} {:.17g}\n",
                  cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy));
  std::string im = fmt::format("# Image list with two lines of data per image:\n"
                               "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                               "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
                               "# Number of images: {}, mean observations per image: 0\n",
                               c2w.size());
  for (size_t i = 0; i < c2w.size(); ++i) {
    const ColmapPose p = colmap_from_c2w(c2w[i]);
    im += fmt::format("{} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} 1 {}\n\n",
                      i + 1, p.q.w(), p.q.x(), p.q.y(), p.q.z(), p.t.x(), p.t.y(), p.t.z(),
                      names[i]);
  }
  write_file_atomic(dir + "/images.txt", im);
  const size_t n = cloud ? cloud->size() : 0;
  std::string pts = fmt::format("# 3D point list with one line of data per point:\n"
                                "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as "
                                "(IMAGE_ID, POINT2D_IDX)\n"
                                "# Number of points: {}, mean track length: 0\n",
                                n);
  for (size_t i = 0; i < n; ++i)
    pts += fmt::format("{} {:.9g} {:.9g} {:.9g} {} {} {} 0\n", i + 1, cloud->xyz[i].x(),
                       cloud->xyz[i].y(), cloud->xyz[i].z(), cloud->rgb[i][0], cloud->rgb[i][1],
                       cloud->rgb[i][2]);
  write_file_atomic(dir + "/points3D.txt", pts);
}

}  // namespace hashcc
