#include "outputs/paths.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "camera/sim3.h"
#include "model/render_view.h"
#include "train/trainer.h"

namespace hashcc {

using Eigen::Vector3d;

PoseParams<float> pose_params_from_c2w(const Mat34d& c2w) {
  PoseParams<float> p;
  Mat3<double> R = c2w.leftCols<3>();
  p.r = so3::log<double>(R).cast<float>();
  p.t = c2w.col(3).cast<float>();
  return p;
}



Vector3d ndc_depth_to_world(const Vector3d& o, const Vector3d& d, double s, bool ndc) {
  if (!ndc) return o + s * d;
  // formulas.md §2: the ray is first moved to the near plane (p_z = −1); NDC z of a world point is
  // 1 + 2/X_z and along the NDC ray z = −1 + 2s, so X_z = 1/(s − 1) = −1 + τ d_z.
  const double t_n = -(1.0 + o.z()) / d.z();
  const Vector3d p = o + t_n * d;
  const double tau = s / ((s - 1.0) * d.z());
  return p + tau * d;
}

double world_to_ndc_depth(const Vector3d& o, const Vector3d& d, const Vector3d& X, bool ndc) {
  if (!ndc) return (X - o).dot(d) / d.squaredNorm();
  return 1.0 + 1.0 / X.z();
}

std::vector<Mat34d> spiral_path(const std::vector<Mat34d>& c2w, double close_depth,
                                double inf_depth, const SpiralOptions& opt, SpiralInfo* info) {
  HCC_REQUIRE(c2w.size() >= 2, "--path spiral", "", "{} cameras (expected at least 2)", c2w.size());
  HCC_REQUIRE(opt.frames >= 1, "--frames", "", "{} (expected ≥ 1)", opt.frames);
  HCC_REQUIRE(close_depth > 0 && inf_depth > close_depth, "--path spiral", "depth",
              "close {} inf {} (expected 0 < close < inf)", close_depth, inf_depth);
  const Mat34d avg = average_pose(c2w);
  const Eigen::Matrix3d Ra = avg.leftCols<3>();
  const Vector3d ca = avg.col(3);
  // LLFF: up = normalize(Σ up); rads = 90th percentile of |centre| per axis of the recentred
  // poses, i.e. of Raᵀ(c − c_avg).
  const Vector3d up = [&] {
    Vector3d u = Vector3d::Zero();
    for (auto& p : c2w) u += p.col(1);
    return u.normalized();
  }();
  Vector3d rads;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> a;
    for (auto& p : c2w) a.push_back(std::abs((Ra.transpose() * (p.col(3) - ca))[k]));
    rads[k] = percentile(a, opt.radius_percentile);
  }
  const double focus = 1.0 / ((1.0 - opt.dt) / close_depth + opt.dt / inf_depth);
  std::vector<Mat34d> path;
  const double two_pi = 2.0 * M_PI;
  for (int i = 0; i < opt.frames; ++i) {
    // np.linspace(0, 2π·rots, N + 1)[:-1]
    const double th = two_pi * opt.rotations * double(i) / double(opt.frames);
    const Vector3d local(std::cos(th) * rads[0], -std::sin(th) * rads[1],
                         -std::sin(th * opt.zrate) * rads[2]);
    const Vector3d c = Ra * local + ca;
    const Vector3d target = ca + Ra * Vector3d(0, 0, -focus);  // c2w · (0, 0, −focus, 1)
    const Vector3d z = (c - target).normalized();                // back axis
    const Vector3d x = up.cross(z).normalized();
    const Vector3d y = z.cross(x).normalized();
    Mat34d m;
    m << x, y, z, c;
    path.push_back(m);
  }
  if (info) {
    info->average = avg;
    info->radii = rads;
    info->close_depth = close_depth;
    info->inf_depth = inf_depth;
    info->focus = focus;
  }
  return path;
}

std::vector<Mat34d> training_c2w(const Trainer& tr) {
  std::vector<Mat34d> out;
  for (int i = 0; i < int(tr.scene().train.size()); ++i)
    out.push_back(world_from_camera(tr.pose_of(i).cast<double>()));
  return out;
}

std::vector<double> training_view_depths(const Trainer& tr, int max_pixels,
                                         double opacity_threshold, double* s_range) {
  const ImageSize sz = tr.image_size();
  int stride = 1;
  while (int64_t((sz.W + stride - 1) / stride) * ((sz.H + stride - 1) / stride) > max_pixels) ++stride;
  const FocalParams<float> f = tr.focal();
  FocalParams<double> fd;
  fd.a = f.a; fd.b = f.b; fd.fx_only = f.fx_only;
  StepWorkspace<float> ws;
  std::vector<double> z, svals;
  for (int i = 0; i < int(tr.scene().train.size()); ++i) {
    const PoseParams<float> pose = tr.pose_of(i);
    ViewImage v = render_view(ws, tr.net(), tr.view_camera(pose),
                              {tr.config().samples, stride, tr.config().chunk_rays,
                               tr.render_occupancy()});
    const PoseParams<double> pd = pose.cast<double>();  // with P0 (--init-poses), as rendered
    const Mat34d c2w = world_from_camera(pd);
    for (int y = 0; y < v.height; ++y)
      for (int x = 0; x < v.width; ++x) {
        const size_t k = size_t(y) * v.width + x;
        if (!(v.opacity[k] >= opacity_threshold)) continue;
        const double s = double(v.depth[k]) / double(v.opacity[k]);
        if (tr.config().ndc && !(s < 1.0 - 1e-4)) continue;  // at infinity
        int px[2] = {x * stride, y * stride};
        double o[3], d[3];
        rays_forward<double>(o, d, px, 1, pd, fd, sz);
        const Vector3d X = ndc_depth_to_world(Vector3d(o[0], o[1], o[2]), Vector3d(d[0], d[1], d[2]),
                                              s, tr.config().ndc);
        // depth along the camera's −z axis
        z.push_back(-(c2w.leftCols<3>().transpose() * (X - c2w.col(3))).z());
        svals.push_back(s);
      }
  }
  HCC_REQUIRE(!z.empty(), tr.config().out, "depth",
              "no training pixel has opacity ≥ {} (an untrained run?)", opacity_threshold);
  if (s_range) {
    s_range[0] = percentile(svals, 1);
    s_range[1] = percentile(svals, 99);
  }
  return z;
}

std::vector<Mat34d> test_c2w_in_learned_frame(const Trainer& tr, std::string* method) {
  const Scene& sc = tr.scene();
  HCC_REQUIRE(sc.has_reference, sc.dir, "poses_bounds.npy",
              "no reference cameras, so the test images have no poses to render from (use "
              "--path spiral or --path train)");
  HCC_REQUIRE(!sc.test.empty(), sc.dir, "", "no test images (every 8th image is one)");
  const std::vector<Mat34d> learned = training_c2w(tr);
  std::vector<Vector3d> ref_c, lrn_c;
  for (size_t i = 0; i < sc.train.size(); ++i) {
    ref_c.push_back(sc.ref_c2w[sc.train[i]].col(3));
    lrn_c.push_back(learned[i].col(3));
  }
  std::vector<Mat34d> out;
  try {
    const Sim3 a = umeyama_sim3(ref_c, lrn_c);  // reference → learned
    for (int j : sc.test) {
      Mat34d m;
      m.leftCols<3>() = a.R * sc.ref_c2w[j].leftCols<3>();
      m.col(3) = a.apply(sc.ref_c2w[j].col(3));
      out.push_back(m);
    }
    if (method) *method = fmt::format("Sim(3) fit of the reference onto the learned training "
                                      "cameras (scale {:.4g})", a.s);
  } catch (const Error&) {
    // formulas.md §7's initialisation: reference pose, translation scaled by the ratio of the largest
    // distance from the first training centre (learned / reference).
    double dl = 0, dr = 0;
    for (size_t i = 0; i < ref_c.size(); ++i) {
      dl = std::max(dl, (lrn_c[i] - lrn_c[0]).norm());
      dr = std::max(dr, (ref_c[i] - ref_c[0]).norm());
    }
    const double k = dr > 0 ? dl / dr : 1.0;
    for (int j : sc.test) {
      Mat34d m = sc.ref_c2w[j];
      m.col(3) *= k;
      out.push_back(m);
    }
    if (method) *method = fmt::format("reference poses, translation × {:.4g} (formulas.md §7 init; "
                                      "the Sim(3) fit is degenerate)", k);
  }
  return out;
}

}  // namespace hashcc
