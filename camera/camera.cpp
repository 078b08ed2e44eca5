// camera/camera.cpp — pose composition, ray generation, NDC and the fused camera chain, each
// with its backward. Derivations: docs/math/camera.md §4–§6. Tests: test/test_camera.cpp.
//
// Reductions (d_pose, d_focal, d_fx, d_fy) use one partial sum per thread block, in double,
// added in block order, so results depend on the thread count only through rounding.
#include <cmath>
#include <vector>
#include <utility>
#include "camera/camera.h"
#include "core/parallel.h"

namespace hashcc {
namespace {

constexpr int64_t kMinRaysPerThread = 512;

// Per-image constants of ray generation.
template <class T>
struct RayFrame {
  Mat3<T> world_from_camera;  // Exp(r) · R0
  Vec3<T> centre;             // Exp(r) · t0 + t (= o of every ray)
  T fx, fy, half_W, half_H;
};

template <class T>
RayFrame<T> make_frame(const PoseParams<T>& pose, const FocalParams<T>& focal, ImageSize size) {
  Mat34<T> c2w = world_from_camera(pose);
  RayFrame<T> f;
  f.world_from_camera = c2w.template leftCols<3>();
  f.centre = c2w.col(3);
  f.fx = focal_fx(focal, size);
  f.fy = focal_fy(focal, size);
  f.half_W = T(size.W) / T(2);
  f.half_H = T(size.H) / T(2);
  return f;
}

// formulas.md §1: d_c = ((u − W/2)/fx, −(v − H/2)/fy, −1)
template <class T>
Vec3<T> camera_dir(const RayFrame<T>& f, int u, int v) {
  return Vec3<T>((T(u) - f.half_W) / f.fx, -(T(v) - f.half_H) / f.fy, T(-1));
}

// Per-thread partial sums of the ray backward (docs/math/camera.md §5):
//   dL_dd_cam = Σ dL/dd_i · d_c,iᵀ (world × camera, 3×3), dL_do = Σ dL/do_i,
//   dL_dsx, dL_dsy = NDC's direct dependence on sx = 2fx/W, sy = 2fy/H.
struct RayPartial {
  Eigen::Matrix3d dL_dd_cam = Eigen::Matrix3d::Zero();
  Eigen::Vector3d dL_do = Eigen::Vector3d::Zero();
  double dL_dsx = 0, dL_dsy = 0;
  char pad[64];  // keep neighbouring threads' partials off one cache line
};

// NDC of one ray (formulas.md §2), near = 1. With p = o + t_n d, t_n = −(1 + o_z)/d_z we have
// p_z = −1 identically, so o'_z = 1 + 2/p_z = −1 and d'_z = −2/p_z = 2, and with
// q = d_x/d_z, w = d_y/d_z, sx = 2fx/W, sy = 2fy/H:
//   o'_x = sx (o_x − (1 + o_z) q)      d'_x = −sx (o_x − o_z q)
//   o'_y = sy (o_y − (1 + o_z) w)      d'_y = −sy (o_y − o_z w)
template <class T>
T clamp_dz(T dz) {
  const T m = T(kNdcMinAbsDz);
  if (std::abs(dz) >= m) return dz;
  return dz > T(0) ? m : -m;  // 0 counts as forward (−z)
}

template <class T>
void ndc_ray_forward(T* on, T* dn, const T* o, const T* d, T sx, T sy) {
  T dz = clamp_dz(d[2]);
  T q = d[0] / dz, w = d[1] / dz;
  T ox = o[0], oy = o[1], oz = o[2];
  on[0] = sx * (ox - (T(1) + oz) * q);
  on[1] = sy * (oy - (T(1) + oz) * w);
  on[2] = T(-1);
  dn[0] = -sx * (ox - oz * q);
  dn[1] = -sy * (oy - oz * w);
  dn[2] = T(2);
}

// g_on = dL/do', g_dn = dL/dd' → g_o = dL/do, g_d = dL/dd (written), dL/dsx, dL/dsy (returned).
template <class T>
void ndc_ray_backward(T* g_o, T* g_d, double& dL_dsx, double& dL_dsy, const T* g_on,
                      const T* g_dn, const T* o, const T* d, T sx, T sy) {
  bool clamped = std::abs(d[2]) < T(kNdcMinAbsDz);
  T dz = clamp_dz(d[2]);
  T q = d[0] / dz, w = d[1] / dz;
  T ox = o[0], oy = o[1], oz = o[2];
  // o'_z, d'_z are constants: g_on[2], g_dn[2] contribute nothing.
  T ex = g_on[0] - g_dn[0], ey = g_on[1] - g_dn[1];  // o_x enters o'_x with +sx, d'_x with −sx
  g_o[0] = sx * ex;
  g_o[1] = sy * ey;
  g_o[2] = -sx * q * ex - sy * w * ey;
  // ∂o'_x/∂q = −sx (1 + o_z), ∂d'_x/∂q = sx o_z
  T dL_dq = sx * (-(T(1) + oz) * g_on[0] + oz * g_dn[0]);
  T dL_dw = sy * (-(T(1) + oz) * g_on[1] + oz * g_dn[1]);
  // q = d_x/d_z: ∂q/∂d_x = 1/d_z, ∂q/∂d_z = −q/d_z (0 inside the clamp)
  g_d[0] = dL_dq / dz;
  g_d[1] = dL_dw / dz;
  g_d[2] = clamped ? T(0) : -(dL_dq * q + dL_dw * w) / dz;
  // ∂o'_x/∂sx = o'_x/sx, ∂d'_x/∂sx = d'_x/sx
  dL_dsx += double(g_on[0]) * double(ox - (T(1) + oz) * q) - double(g_dn[0]) * double(ox - oz * q);
  dL_dsy += double(g_on[1]) * double(oy - (T(1) + oz) * w) - double(g_dn[1]) * double(oy - oz * w);
}

// One zeroed partial per thread, in a grow-only per-calling-thread buffer: the training step
// calls the camera backward every step and must not allocate.
std::vector<RayPartial>& zeroed_partials() {
  thread_local std::vector<RayPartial> buf;
  buf.assign(size_t(num_threads()), RayPartial{});
  return buf;
}

// The NDC box's x, y scales sx = 2fx/W, sy = 2fy/H: from the learned focal, or from the warp's
// own fixed focal (NdcWarp, camera.h).
template <class T>
std::pair<T, T> ndc_scales(const RayFrame<T>& f, const NdcWarp& ndc, ImageSize size) {
  const T fx = ndc.fixed() ? T(ndc.fx) : f.fx, fy = ndc.fixed() ? T(ndc.fy) : f.fy;
  return {T(2) * fx / T(size.W), T(2) * fy / T(size.H)};
}

template <class T>
void add_vec3(RayPartial& p, const Vec3<T>& dL_dd, const Vec3<T>& d_cam, const T* dL_do) {
  Eigen::Vector3d g = dL_dd.template cast<double>();
  p.dL_dd_cam.noalias() += g * d_cam.template cast<double>().transpose();
  p.dL_do += Eigen::Vector3d(dL_do[0], dL_do[1], dL_do[2]);
}

// Partials → d_pose[6], d_focal[2] (docs/math/camera.md §5):
//   G = dL/dExp(r) = dL_dd_cam · R0ᵀ + dL_do · t0ᵀ;  dL/dr_k = ⟨∂Exp/∂r_k, G⟩_F;  dL/dt = dL_do;
//   dL/dfx = −(Rᵀ dL_dd_cam)_00 / fx + dL_dsx · 2/W;  dL/dfy = −(Rᵀ dL_dd_cam)_11 / fy + dL_dsy · 2/H;
//   (the dL_ds terms only when the NDC box follows the learned focal: ndc_scale_learned)
//   fx = a²W → dL/da = 2aW dL/dfx (plus 2aW dL/dfy when fx_only); fy = b²H → dL/db = 2bH dL/dfy.
template <class T>
void finish_backward(T d_pose[6], T d_focal[2], const std::vector<RayPartial>& partials,
                     const PoseParams<T>& pose, const FocalParams<T>& focal, ImageSize size,
                     bool ndc_scale_learned = false) {
  RayPartial s;
  for (const RayPartial& p : partials) {  // fixed order: block 0, 1, …
    s.dL_dd_cam += p.dL_dd_cam;
    s.dL_do += p.dL_do;
    s.dL_dsx += p.dL_dsx;
    s.dL_dsy += p.dL_dsy;
  }
  const PoseParams<double> pd = pose.template cast<double>();
  Eigen::Matrix3d R0 = pd.has_P0 ? Eigen::Matrix3d(pd.P0.leftCols<3>()) : Eigen::Matrix3d::Identity();
  Eigen::Vector3d t0 = pd.has_P0 ? Eigen::Vector3d(pd.P0.col(3)) : Eigen::Vector3d::Zero();
  Eigen::Matrix3d dExp_dr[3];
  so3::exp_derivative<double>(pd.r, dExp_dr);
  Eigen::Matrix3d dL_dExp = s.dL_dd_cam * R0.transpose() + s.dL_do * t0.transpose();
  for (int k = 0; k < 3; ++k) d_pose[k] += T(dExp_dr[k].cwiseProduct(dL_dExp).sum());
  for (int k = 0; k < 3; ++k) d_pose[3 + k] += T(s.dL_do[k]);

  FocalParams<double> fd{double(focal.a), double(focal.b), focal.fx_only};
  double fx = focal_fx(fd, size), fy = focal_fy(fd, size);
  Eigen::Matrix3d world_from_camera = so3::exp<double>(pd.r) * R0;
  Eigen::Matrix3d dL_ddc_cam = world_from_camera.transpose() * s.dL_dd_cam;  // Σ dL/dd_c · d_cᵀ
  double dL_dfx = -dL_ddc_cam(0, 0) / fx, dL_dfy = -dL_ddc_cam(1, 1) / fy;
  if (ndc_scale_learned) {
    dL_dfx += s.dL_dsx * 2.0 / size.W;
    dL_dfy += s.dL_dsy * 2.0 / size.H;
  }
  double dfx_da = 2.0 * fd.a * size.W;
  if (focal.fx_only) {
    d_focal[0] += T(dfx_da * (dL_dfx + dL_dfy));  // fy = a²W as well
  } else {
    d_focal[0] += T(dfx_da * dL_dfx);
    d_focal[1] += T(2.0 * fd.b * size.H * dL_dfy);
  }
}

}  // namespace

template <class T>
Mat34<T> world_from_camera(const PoseParams<T>& pose) {
  Mat3<T> R_delta = so3::exp(pose.r);
  Mat34<T> c2w;
  if (pose.has_P0) {
    // [R_delta | t] · [R0 | t0] as 4×4 products (bottom rows 0 0 0 1)
    c2w.template leftCols<3>() = R_delta * pose.P0.template leftCols<3>();
    c2w.col(3) = R_delta * pose.P0.col(3) + pose.t;
  } else {
    c2w.template leftCols<3>() = R_delta;
    c2w.col(3) = pose.t;
  }
  return c2w;
}

template <class T>
void rays_forward(T* o, T* d, const int* px, int64_t N, const PoseParams<T>& pose,
                  const FocalParams<T>& focal, ImageSize size) {
  const RayFrame<T> f = make_frame(pose, focal, size);
  parallel_for(N, [&](int64_t i) {
    Vec3<T> d_cam = camera_dir(f, px[2 * i], px[2 * i + 1]);
    Eigen::Map<Vec3<T>>(d + 3 * i) = f.world_from_camera * d_cam;  // d = R d_c
    Eigen::Map<Vec3<T>>(o + 3 * i) = f.centre;                     // o = camera centre
  }, kMinRaysPerThread);
}

template <class T>
void rays_backward(T d_pose[6], T d_focal[2], const T* d_o, const T* d_d, const int* px,
                   int64_t N, const PoseParams<T>& pose, const FocalParams<T>& focal,
                   ImageSize size) {
  const RayFrame<T> f = make_frame(pose, focal, size);
  std::vector<RayPartial>& partials = zeroed_partials();
  parallel_blocks(N, [&](int64_t b, int64_t e, int t) {
    RayPartial& p = partials[t];
    for (int64_t i = b; i < e; ++i) {
      Vec3<T> d_cam = camera_dir(f, px[2 * i], px[2 * i + 1]);
      add_vec3(p, Vec3<T>(Eigen::Map<const Vec3<T>>(d_d + 3 * i)), d_cam, d_o + 3 * i);
    }
  }, kMinRaysPerThread);
  finish_backward(d_pose, d_focal, partials, pose, focal, size);
}

template <class T>
void ndc_forward(T* o_ndc, T* d_ndc, const T* o, const T* d, int64_t N, T fx, T fy,
                 ImageSize size) {
  const T sx = T(2) * fx / T(size.W), sy = T(2) * fy / T(size.H);  // fx/(W/2), fy/(H/2)
  parallel_for(N, [&](int64_t i) {
    T oi[3] = {o[3 * i], o[3 * i + 1], o[3 * i + 2]}, di[3] = {d[3 * i], d[3 * i + 1], d[3 * i + 2]};
    ndc_ray_forward(o_ndc + 3 * i, d_ndc + 3 * i, oi, di, sx, sy);  // copies: in-place safe
  }, kMinRaysPerThread);
}

template <class T>
void ndc_backward(T* d_o, T* d_d, T* d_fx, T* d_fy, const T* d_ondc, const T* d_dndc,
                  const T* o, const T* d, int64_t N, T fx, T fy, ImageSize size) {
  const T sx = T(2) * fx / T(size.W), sy = T(2) * fy / T(size.H);
  std::vector<RayPartial>& partials = zeroed_partials();
  parallel_blocks(N, [&](int64_t b, int64_t e, int t) {
    RayPartial& p = partials[t];
    for (int64_t i = b; i < e; ++i)
      ndc_ray_backward(d_o + 3 * i, d_d + 3 * i, p.dL_dsx, p.dL_dsy, d_ondc + 3 * i,
                       d_dndc + 3 * i, o + 3 * i, d + 3 * i, sx, sy);
  }, kMinRaysPerThread);
  double dL_dsx = 0, dL_dsy = 0;
  for (const RayPartial& p : partials) { dL_dsx += p.dL_dsx; dL_dsy += p.dL_dsy; }
  if (d_fx) *d_fx += T(dL_dsx * 2.0 / size.W);  // sx = 2fx/W
  if (d_fy) *d_fy += T(dL_dsy * 2.0 / size.H);
}

template <class T>
void camera_rays_forward(T* o_out, T* d_out, const int* px, int64_t N, const PoseParams<T>& pose,
                         const FocalParams<T>& focal, ImageSize size, NdcWarp ndc) {
  if (!ndc.on) { rays_forward(o_out, d_out, px, N, pose, focal, size); return; }
  const RayFrame<T> f = make_frame(pose, focal, size);
  const auto [sx, sy] = ndc_scales(f, ndc, size);
  parallel_for(N, [&](int64_t i) {
    Vec3<T> d_world = f.world_from_camera * camera_dir(f, px[2 * i], px[2 * i + 1]);
    ndc_ray_forward(o_out + 3 * i, d_out + 3 * i, f.centre.data(), d_world.data(), sx, sy);
  }, kMinRaysPerThread);
}

template <class T>
void camera_rays_backward(T d_pose[6], T d_focal[2], const T* d_o_out, const T* d_d_out,
                          const int* px, int64_t N, const PoseParams<T>& pose,
                          const FocalParams<T>& focal, ImageSize size, NdcWarp ndc) {
  if (!ndc.on) { rays_backward(d_pose, d_focal, d_o_out, d_d_out, px, N, pose, focal, size); return; }
  const RayFrame<T> f = make_frame(pose, focal, size);
  const auto [sx, sy] = ndc_scales(f, ndc, size);
  std::vector<RayPartial>& partials = zeroed_partials();
  parallel_blocks(N, [&](int64_t b, int64_t e, int t) {
    RayPartial& p = partials[t];
    for (int64_t i = b; i < e; ++i) {
      // Recompute the world ray (cheap) instead of caching it: no scratch buffers.
      Vec3<T> d_cam = camera_dir(f, px[2 * i], px[2 * i + 1]);
      Vec3<T> d_world = f.world_from_camera * d_cam;
      Vec3<T> dL_do, dL_dd;
      ndc_ray_backward(dL_do.data(), dL_dd.data(), p.dL_dsx, p.dL_dsy, d_o_out + 3 * i,
                       d_d_out + 3 * i, f.centre.data(), d_world.data(), sx, sy);
      add_vec3(p, dL_dd, d_cam, dL_do.data());
    }
  }, kMinRaysPerThread);
  finish_backward(d_pose, d_focal, partials, pose, focal, size, !ndc.fixed());
}

#define HCC_CAMERA_INSTANTIATE(T)                                                             \
  template Mat34<T> world_from_camera<T>(const PoseParams<T>&);                               \
  template void rays_forward<T>(T*, T*, const int*, int64_t, const PoseParams<T>&,            \
                                const FocalParams<T>&, ImageSize);                            \
  template void rays_backward<T>(T[6], T[2], const T*, const T*, const int*, int64_t,         \
                                 const PoseParams<T>&, const FocalParams<T>&, ImageSize);     \
  template void ndc_forward<T>(T*, T*, const T*, const T*, int64_t, T, T, ImageSize);         \
  template void ndc_backward<T>(T*, T*, T*, T*, const T*, const T*, const T*, const T*,       \
                                int64_t, T, T, ImageSize);                                    \
  template void camera_rays_forward<T>(T*, T*, const int*, int64_t, const PoseParams<T>&,     \
                                       const FocalParams<T>&, ImageSize, NdcWarp);            \
  template void camera_rays_backward<T>(T[6], T[2], const T*, const T*, const int*, int64_t,  \
                                        const PoseParams<T>&, const FocalParams<T>&, ImageSize, \
                                        NdcWarp);
HCC_CAMERA_INSTANTIATE(float)
HCC_CAMERA_INSTANTIATE(double)
#undef HCC_CAMERA_INSTANTIATE

}  // namespace hashcc
