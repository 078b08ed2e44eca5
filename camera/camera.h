// camera/camera.h — learnable pinhole cameras: pose (axis-angle r, centre t), second-order
// focal (a, b), ray generation and NDC, each with an analytic backward.
// Convention (OpenGL, written once in camera/README.md): x right, y up, camera looks down −z.
// Derivations: docs/math/camera.md. Tests: test/test_camera.cpp ("[camera]").
// Gradient-write policy: parameter gradients (d_pose, d_focal, d_fx, d_fy) +=; per-ray
// activation gradients (ndc_backward's d_o, d_d) =.
#pragma once
#include <Eigen/Core>
#include <cmath>
#include <cstdint>
namespace hashcc {

template <class T> using Vec3 = Eigen::Matrix<T, 3, 1>;
template <class T> using Mat3 = Eigen::Matrix<T, 3, 3>;
template <class T> using Mat34 = Eigen::Matrix<T, 3, 4>;

namespace so3 {
// Rodrigues R = Exp(r); exact and finite for all θ = |r| (Taylor branches near 0).
template <class T> Mat3<T> exp(const Vec3<T>& r);
// dR/dr_k for k = 0,1,2 (each a 3×3 matrix), accurate for all θ including 0 and π.
template <class T> void exp_derivative(const Vec3<T>& r, Mat3<T> dR_dr[3]);
// Log(R) with |r| ≤ π, robust at θ → π.
template <class T> Vec3<T> log(const Mat3<T>& R);
// [r]× (the cross-product matrix, [r]× v = r × v).
template <class T> Mat3<T> hat(const Vec3<T>& r);
// Rotation angle of R in [0, π], atan2(|vee(R − Rᵀ)|/2, (tr R − 1)/2): accurate at 0 and π.
template <class T> T angle(const Mat3<T>& R);
}  // namespace so3

// Image geometry (fixed) and the learned intrinsics of formulas.md §1.
struct ImageSize { int W = 0, H = 0; };

// Learned pose of one image: c2w = [Exp(r) | t] · P0 (P0 = identity when absent).
// Parameter order everywhere (arenas, checkpoints, gradients): [r0 r1 r2 t0 t1 t2].
template <class T>
struct PoseParams {
  Vec3<T> r = Vec3<T>::Zero();
  Vec3<T> t = Vec3<T>::Zero();
  bool has_P0 = false;
  Mat34<T> P0 = Mat34<T>::Identity();  // fixed initial world_from_camera (3×4)

  // The same pose in precision U (the trainer holds float; evaluation and export compose in
  // double).
  template <class U>
  PoseParams<U> cast() const {
    PoseParams<U> p;
    p.r = r.template cast<U>();
    p.t = t.template cast<U>();
    p.has_P0 = has_P0;
    p.P0 = P0.template cast<U>();
    return p;
  }
};

// The camera-to-world map c2w = [Exp(r) | t] · P0 as a 3×4 matrix (composed as 4×4 matrices):
// rotation Exp(r)·R0, centre Exp(r)·t0 + t. The one name for it (pbrt-v4's "world from camera").
template <class T> Mat34<T> world_from_camera(const PoseParams<T>& pose);

// Focal parameters [a b]: fx = a²W, fy = b²H (fx_only: fy = fx, i.e. b ignored, b's grad 0).
template <class T>
struct FocalParams { T a = 1, b = 1; bool fx_only = false; };

template <class T> T focal_fx(const FocalParams<T>& f, ImageSize s) { return f.a * f.a * T(s.W); }
template <class T> T focal_fy(const FocalParams<T>& f, ImageSize s) {
  return f.fx_only ? f.a * f.a * T(s.W) : f.b * f.b * T(s.H);
}
// The focal in pixels of a pinhole `width` pixels wide whose horizontal field of view is
// `fov_deg` degrees: W / (2 tan(fov/2)). The simulator's --fov and train's --focal-fov prior.
inline double focal_for_fov(int width, double fov_deg) {
  return 0.5 * width / std::tan(0.5 * fov_deg * M_PI / 180);
}

// Pixels are given as N (u = column, v = row) pairs as ints: px (N, 2) = [u0 v0 u1 v1 …].
// Rays (formulas.md §1): d_c = ((u − W/2)/fx, −(v − H/2)/fy, −1), d = R d_c (unnormalised), o = t
// (both transformed by P0 when present). o (N,3), d (N,3).
template <class T>
void rays_forward(T* o, T* d, const int* px, int64_t N, const PoseParams<T>& pose,
                  const FocalParams<T>& focal, ImageSize size);
// Accumulates (+=) d_pose[6] (order r, t) and d_focal[2] (a, b) from d_o, d_d (N,3).
template <class T>
void rays_backward(T d_pose[6], T d_focal[2], const T* d_o, const T* d_d, const int* px,
                   int64_t N, const PoseParams<T>& pose, const FocalParams<T>& focal,
                   ImageSize size);

// NDC clamp. |d_z| below this is replaced by ±kNdcMinAbsDz (sign of d_z, − for 0) before
// the projection; inside the clamp the outputs do not depend on d_z (its gradient is 0).
// Rays from rays_forward have |d| ≥ 1, so the bound is also relative. See camera/README.md.
inline constexpr double kNdcMinAbsDz = 1e-6;

// NDC with near plane 1 (formulas.md §2): (o, d) → (o', d'), using fx, fy. o_ndc, d_ndc (N,3).
// In-place use (o_ndc == o, d_ndc == d) is allowed.
template <class T>
void ndc_forward(T* o_ndc, T* d_ndc, const T* o, const T* d, int64_t N, T fx, T fy,
                 ImageSize size);
// d_o, d_d (N,3) WRITTEN; d_fx, d_fy accumulated (+=) scalars.
template <class T>
void ndc_backward(T* d_o, T* d_d, T* d_fx, T* d_fy, const T* d_ondc, const T* d_dndc,
                  const T* o, const T* d, int64_t N, T fx, T fy, ImageSize size);

// The camera chain's last step, the NDC warp (formulas.md §2), and the focal it is drawn with.
//   on = false: rays stay in world space.
//   on, fx = fy = 0: the paper's NDC. Its x, y scales sx = 2fx/W, sy = 2fy/H follow the LEARNED
//     focal, so a focal step also stretches the box the field lives in: the focal's gradient has a
//     second term (dL/dsx · 2/W) through the field's own coordinates, not only through the rays'
//     directions. On every simulated lens it drifts the focal low (docs/training.md, "The NDC box").
//   on, fx, fy > 0: the box drawn with this focal, held (a plain change of coordinates for the
//     field, like the near plane): the focal's gradient comes from the ray directions alone.
// Implicit from bool, so `ndc = true` / `false` reads as it always did.
struct NdcWarp {
  bool on = true;
  double fx = 0, fy = 0;  // > 0: the box's focal, fixed; 0: the learned focal
  NdcWarp(bool on_ = true) : on(on_) {}  // NOLINT(google-explicit-constructor): see above
  NdcWarp(double fx_, double fy_) : on(true), fx(fx_), fy(fy_) {}
  bool fixed() const { return on && fx > 0 && fy > 0; }
};

// The whole camera chain the trainer uses: pixels → world rays → (NDC if ndc.on) → ray origin
// and direction handed to the sampler. Backward accumulates into d_pose[6], d_focal[2]
// (including the NDC's dependence on fx, fy unless ndc.fixed()). Scratch is internal.
template <class T>
void camera_rays_forward(T* o_out, T* d_out, const int* px, int64_t N, const PoseParams<T>& pose,
                         const FocalParams<T>& focal, ImageSize size, NdcWarp ndc);
template <class T>
void camera_rays_backward(T d_pose[6], T d_focal[2], const T* d_o_out, const T* d_d_out,
                          const int* px, int64_t N, const PoseParams<T>& pose,
                          const FocalParams<T>& focal, ImageSize size, NdcWarp ndc);

}  // namespace hashcc
