#include "tools/simulator.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "camera/camera.h"
#include "core/error.h"
#include "core/fileio.h"
#include "core/image.h"
#include "core/npy.h"
#include "core/parallel.h"
#include "core/progress.h"

namespace hashcc {

using Eigen::Vector3d;

namespace {

double smoothstep(double e0, double e1, double x) {
  double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

// Procedural textures on (u, v) surface coordinates. Soft edges keep them band-limited, so
// a small network can fit them at CI resolution; distinct patterns per object give parallax cues.
Vector3d texture(int id, double u, double v) {
  auto soft_checker = [](double u, double v, double period) {
    double su = std::sin(2 * M_PI * u / period), sv = std::sin(2 * M_PI * v / period);
    return smoothstep(-0.35, 0.35, su * sv);
  };
  switch (id) {
    case 0: {  // backdrop: large warm/cool blobs and a grid
      double a = 0.5 + 0.5 * std::sin(0.9 * u + 0.3) * std::cos(0.7 * v - 0.2);
      double g = soft_checker(u, v, 1.6);
      return Vector3d(0.25 + 0.5 * a, 0.3 + 0.25 * g, 0.55 - 0.3 * a) ;
    }
    case 1: {  // red/yellow checker
      double c = soft_checker(u, v, 0.5);
      return Vector3d(0.85, 0.25 + 0.6 * c, 0.15);
    }
    case 2: {  // blue stripes
      double s = smoothstep(-0.3, 0.3, std::sin(2 * M_PI * (u + 0.5 * v) / 0.35));
      return Vector3d(0.1 + 0.2 * s, 0.3 + 0.3 * s, 0.8);
    }
    case 3: {  // green spots
      double s = smoothstep(0.2, 0.6, std::sin(2 * M_PI * u / 0.3) + std::sin(2 * M_PI * v / 0.3));
      return Vector3d(0.2 + 0.6 * s, 0.75, 0.25);
    }
    default: {  // white/purple rings
      double r = std::sqrt(u * u + v * v);
      double s = smoothstep(-0.3, 0.3, std::sin(2 * M_PI * r / 0.3));
      return Vector3d(0.9, 0.6 + 0.35 * s, 0.95);
    }
  }
}

}  // namespace

SimScene make_sim_scene(const SimOptions& opt) {
  SimScene s;
  s.specular = opt.specular;
  s.light_dir = Vector3d(0.4, 0.6, 0.7).normalized();
  // Camera rig sits near the origin looking down −z; surfaces between z = −2 and z = −8.
  const double wall = opt.backdrop_depth / 8;  // 1 for the built-in scene
  s.planes.push_back({Vector3d(0, 0, -opt.backdrop_depth), Vector3d(0, 0, 1), Vector3d(1, 0, 0),
                      Vector3d(0, 1, 0), 20 * wall, 20 * wall, 0});
  s.planes.push_back({Vector3d(-1.6, 0.6, -5.0), Vector3d(0.2, 0, 1).normalized(),
                      Vector3d(1, 0, -0.2).normalized(), Vector3d(0, 1, 0), 1.1, 0.9, 1});
  s.planes.push_back({Vector3d(1.7, -0.8, -4.2), Vector3d(-0.25, 0.1, 1).normalized(),
                      Vector3d(1, 0, 0.25).normalized(), Vector3d(0, 1, -0.1).normalized(),
                      0.9, 0.7, 2});
  s.spheres.push_back({Vector3d(0.3, 0.2, -3.3), 0.55, 3});
  s.spheres.push_back({Vector3d(-0.9, -0.9, -2.6), 0.35, 4});
  s.spheres.push_back({Vector3d(1.2, 1.0, -6.0), 0.8, 2});
  return s;
}

double SimScene::trace(const Vector3d& o, const Vector3d& d, Vector3d* rgb) const {
  double best = -1;
  Vector3d n, albedo;
  bool is_sphere = false;
  for (auto& p : planes) {
    double dn = d.dot(p.normal);
    if (std::abs(dn) < 1e-12) continue;
    double t = (p.centre - o).dot(p.normal) / dn;
    if (t <= 1e-9 || (best > 0 && t >= best)) continue;
    Vector3d q = o + t * d - p.centre;
    double u = q.dot(p.u_axis), v = q.dot(p.v_axis);
    if (std::abs(u) > p.half_u || std::abs(v) > p.half_v) continue;
    best = t;
    n = dn < 0 ? p.normal : Vector3d(-p.normal);
    albedo = texture(p.texture, u, v);
    is_sphere = false;
  }
  for (auto& sp : spheres) {
    Vector3d oc = o - sp.centre;
    double a = d.squaredNorm(), b = oc.dot(d), c = oc.squaredNorm() - sp.radius * sp.radius;
    double disc = b * b - a * c;
    if (disc < 0) continue;
    double t = (-b - std::sqrt(disc)) / a;
    if (t <= 1e-9 || (best > 0 && t >= best)) continue;
    best = t;
    n = (o + t * d - sp.centre) / sp.radius;
    double u = std::atan2(n.x(), n.z()) * sp.radius, v = std::asin(std::clamp(n.y(), -1.0, 1.0)) * sp.radius;
    albedo = texture(sp.texture, 2 * u, 2 * v);
    is_sphere = true;
  }
  if (best > 0 && rgb) {
    double diffuse = std::max(0.0, n.dot(light_dir));
    Vector3d c = albedo * (0.45 + 0.55 * diffuse);
    if (specular && is_sphere) {
      // Blinn–Phong highlight: the only view-dependent effect, on only when asked.
      Vector3d h = (light_dir - d.normalized()).normalized();
      c += Vector3d::Constant(0.6 * std::pow(std::max(0.0, n.dot(h)), 40.0));
    }
    *rgb = c.cwiseMin(1.0).cwiseMax(0.0);
  }
  return best;
}

double SimScene::surface_distance(const Vector3d& p) const {
  double best = 1e300;
  for (auto& pl : planes) {
    // The patch is what trace() hits: in-plane points x with |x·u_axis| ≤ half_u and
    // |x·v_axis| ≤ half_v. The axes need not be orthogonal (a plane's v axis may be tilted), so
    // the patch is a parallelogram: clamping the two dot products does not give the closest point.
    const Vector3d q = p - pl.centre;
    const double h = q.dot(pl.normal);
    const Vector3d qp = q - h * pl.normal;  // projection onto the plane
    if (std::abs(qp.dot(pl.u_axis)) <= pl.half_u && std::abs(qp.dot(pl.v_axis)) <= pl.half_v) {
      best = std::min(best, std::abs(h));
      continue;
    }
    // Outside: nearest point on the boundary. Corners solve x·u = ±half_u, x·v = ±half_v in the
    // plane (x = α u + β v with the Gram matrix of the axes).
    const double uv = pl.u_axis.dot(pl.v_axis), det = 1 - uv * uv;
    auto corner = [&](double cu, double cv) {
      const double a = (cu - uv * cv) / det, b = (cv - uv * cu) / det;
      return Vector3d(pl.centre + a * pl.u_axis + b * pl.v_axis);
    };
    const Vector3d c[4] = {corner(-pl.half_u, -pl.half_v), corner(pl.half_u, -pl.half_v),
                           corner(pl.half_u, pl.half_v), corner(-pl.half_u, pl.half_v)};
    for (int k = 0; k < 4; ++k) {
      const Vector3d a = c[k], e = c[(k + 1) % 4] - a;
      const double t = std::clamp((p - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
      best = std::min(best, (p - (a + t * e)).norm());
    }
  }
  for (auto& sp : spheres) best = std::min(best, std::abs((p - sp.centre).norm() - sp.radius));
  return best;
}

double SimOptions::focal_px() const {
  return fov_deg > 0 ? focal_for_fov(width, fov_deg) : focal_ratio * width;
}

namespace {
// The camera at `centre` looking at `focus` (or down −z with no focus), rolled by `roll`
// radians about its viewing axis: OpenGL axes [right up back].
Eigen::Matrix3d look_rotation(const Vector3d& centre, const Vector3d* focus, double roll) {
  Vector3d back = focus ? Vector3d((centre - *focus).normalized()) : Vector3d(0, 0, 1);
  Vector3d up0(std::sin(roll), std::cos(roll), 0);
  Vector3d right = up0.cross(back).normalized();
  Vector3d up = back.cross(right).normalized();
  Eigen::Matrix3d R;
  R << right, up, back;
  return R;
}
}  // namespace

std::vector<SimCamera> make_sim_rig(const SimOptions& opt) {
  // Cameras on a jittered golden-angle spiral in the plane z ≈ 0, looking down −z (or at a
  // focus point 5 units ahead), with a small random roll, then the hand-held rotation.
  Rng rng(opt.seed, 7);
  std::vector<SimCamera> rig;
  const Vector3d focus(0, 0, -opt.focus_depth);
  for (int i = 0; i < opt.views; ++i) {
    Vector3d centre;
    if (opt.sweep) {
      // Left to right along the arc of radius focus_depth round the focus, in view order, with
      // the vertical wander of a hand that walks (±baseline) and a little jitter along the arc.
      const double u = opt.views > 1 ? double(i) / (opt.views - 1) - 0.5 : 0.0;
      const double phi = (u * opt.sweep_deg + 0.5 * rng.normal()) * M_PI / 180;
      centre = focus + opt.focus_depth * Vector3d(std::sin(phi), 0, std::cos(phi)) +
               Vector3d(0, opt.baseline * rng.uniform(-1, 1), 0.03 * rng.normal());
    } else {
      double a = 2.399963 * i;  // golden angle spiral
      double r = opt.baseline * std::sqrt((i + 0.5) / opt.views);
      centre = Vector3d(r * std::cos(a) + 0.03 * rng.normal(),
                        0.75 * r * std::sin(a) + 0.03 * rng.normal(), 0.1 * rng.uniform(-1, 1));
    }
    const bool turns = opt.look_at || opt.sweep;
    double roll = 0.03 * rng.normal();
    SimCamera c;
    c.c2w << look_rotation(centre, turns ? &focus : nullptr, roll), centre;
    if (opt.rot_jitter_deg > 0) {  // hand-held: an extra rotation about the camera's own axes
      const double sd = opt.rot_jitter_deg * M_PI / 180;
      Vector3d w(sd * rng.normal(), sd * rng.normal(), sd * rng.normal());
      Eigen::Matrix3d J = Eigen::AngleAxisd(w.norm(), w.norm() > 0 ? Vector3d(w.normalized())
                                                                    : Vector3d::UnitZ())
                              .toRotationMatrix();
      c.c2w.leftCols<3>() = c.c2w.leftCols<3>() * J;
    }
    rig.push_back(c);
  }
  return rig;
}

void render_sim_view(const SimScene& scene, const SimCamera& cam, const SimOptions& opt,
                     std::vector<float>* rgb, std::vector<float>* zdepth) {
  const int W = opt.width, H = opt.height, ss = std::max(1, opt.supersample);
  const double f = opt.focal_px();
  rgb->assign(size_t(W) * H * 3, 0.f);
  zdepth->assign(size_t(W) * H, 0.f);
  Eigen::Matrix3d R = cam.c2w.leftCols<3>();
  Vector3d o = cam.c2w.col(3);
  parallel_for(H, [&](int64_t v) {
    for (int u = 0; u < W; ++u) {
      Vector3d acc = Vector3d::Zero();
      double zsum = 0;
      int nhit = 0;
      for (int sy = 0; sy < ss; ++sy)
        for (int sx = 0; sx < ss; ++sx) {
          // Sub-pixel offsets symmetric around the integer pixel position.
          double du = (sx + 0.5) / ss - 0.5, dv = (sy + 0.5) / ss - 0.5;
          Vector3d dc((u + du - W / 2.0) / f, -(v + dv - H / 2.0) / f, -1.0);  // formulas.md §1
          Vector3d d = R * dc;
          Vector3d c;
          double t = scene.trace(o, d, &c);
          if (t > 0) { acc += c; zsum += t; ++nhit; }  // d_c has z = −1: t is the z-depth
        }
      size_t i = size_t(v) * W + u;
      for (int k = 0; k < 3; ++k) (*rgb)[3 * i + k] = float(acc[k] / (ss * ss));
      (*zdepth)[i] = nhit ? float(zsum / nhit) : 0.f;
    }
  });
}

// One view as a phone's JPEG (SimOptions::jpeg): 8-bit pixels rounded as write_png_float
// rounds them, an EXIF block with the 35 mm equivalent focal (f35 = focal / long side · 36 mm,
// exif_focal_px's convention), image 1 stored turned 90° anticlockwise with orientation 6, so
// that turning it clockwise (what 6 asks of the reader) shows it upright.
static void write_sim_jpeg(const std::string& dir, int i, const std::vector<float>& rgb,
                           const SimOptions& opt) {
  ImageU8 img;
  img.width = opt.width;
  img.height = opt.height;
  img.rgb.resize(rgb.size());
  for (size_t k = 0; k < rgb.size(); ++k)
    img.rgb[k] = uint8_t(std::lround(std::clamp(std::isnan(rgb[k]) ? 0.f : rgb[k], 0.f, 1.f) * 255.f));
  int orientation = 1;
  if (i == 1) {
    img = apply_orientation(img, 8);  // the inverse of 6
    orientation = 6;
  }
  const int f35 = int(std::lround(opt.focal_px() / std::max(opt.width, opt.height) * 36.0));
  const std::string tiff = make_exif_tiff(i % 2 == 0, orientation, f35);  // both byte orders
  write_file_atomic(fmt::format("{}/images/image{:03d}.jpg", dir, i),
                    jpeg_with_exif(encode_jpeg(img.rgb.data(), img.width, img.height, 92), tiff));
}

std::vector<SimCamera> write_sim_scene(const std::string& dir, const SimOptions& opt,
                                       bool progress) {
  HCC_REQUIRE(opt.views >= 2 && opt.views <= 10000, "--views", "", "{} views", opt.views,
              "2 to 10000");
  HCC_REQUIRE(opt.width >= 8 && opt.height >= 8 && opt.width <= 8192 && opt.height <= 8192,
              "--width/--height", "", "{}x{}", opt.width, opt.height, "8 to 8192 pixels");
  HCC_REQUIRE(opt.fov_deg == 0 || (opt.fov_deg >= 10 && opt.fov_deg <= 150), "--fov", "",
              "{} degrees", opt.fov_deg, "10 to 150 (0 = the built-in focal, 0.8 × width)");
  HCC_REQUIRE(opt.sweep_deg > 0 && opt.sweep_deg <= 120, "--sweep", "", "{} degrees",
              opt.sweep_deg, "above 0 and at most 120");
  HCC_REQUIRE(opt.backdrop_depth >= 7 && opt.backdrop_depth <= 1000, "--backdrop-depth", "",
              "{}", opt.backdrop_depth, "7 to 1000 (the objects stand at depths 2.6 to 6)");
  HCC_REQUIRE(opt.focus_depth >= 1 && opt.focus_depth <= 100, "--focus-depth", "", "{}",
              opt.focus_depth, "1 to 100");
  make_dirs(dir + "/images");
  SimScene scene = make_sim_scene(opt);
  auto rig = make_sim_rig(opt);
  std::vector<double> rows(rig.size() * 17);
  ProgressBar bar("simulate", int64_t(rig.size()), progress);
  for (size_t i = 0; i < rig.size(); ++i) {
    std::vector<float> rgb, z;
    render_sim_view(scene, rig[i], opt, &rgb, &z);
    if (opt.jpeg) write_sim_jpeg(dir, int(i), rgb, opt);
    else
      write_png_float(fmt::format("{}/images/image{:03d}.png", dir, i), rgb.data(), opt.width,
                      opt.height);
    float zmin = 1e30f, zmax = 0;
    for (float v : z)
      if (v > 0) { zmin = std::min(zmin, v); zmax = std::max(zmax, v); }
    // Bounds like COLMAP's: a margin around the depths actually seen.
    c2w_to_llff_row(rig[i].c2w, opt.height, opt.width, opt.focal_px(), 0.9 * zmin,
                    1.1 * zmax, rows.data() + 17 * i);
    bar.update(int64_t(i + 1));
  }
  bar.finish();
  write_npy(dir + "/poses_bounds.npy", rows.data(), {int64_t(rig.size()), 17});
  nlohmann::json j = {{"generator", "hashcc simulate"},
                      {"version", HASHCC_VERSION},
                      {"views", opt.views},
                      {"width", opt.width},
                      {"height", opt.height},
                      {"seed", opt.seed},
                      {"specular", opt.specular},
                      {"focal_px", opt.focal_px()},
                      {"supersample", opt.supersample},
                      {"rig", opt.sweep ? "sweep" : opt.look_at ? "lookat" : "parallel"},
                      {"baseline", opt.baseline},
                      {"rot_jitter_deg", opt.rot_jitter_deg},
                      {"sweep_deg", opt.sweep ? opt.sweep_deg : 0.0},
                      {"focus_depth", opt.focus_depth},
                      {"backdrop_depth", opt.backdrop_depth}};
  if (opt.jpeg) j["format"] = "jpeg+exif";
  write_file_atomic(dir + "/scene.json", j.dump(2) + "\n");
  return rig;
}

}  // namespace hashcc
