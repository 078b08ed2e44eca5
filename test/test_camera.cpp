// test/test_camera.cpp — camera/: SO(3), rays, NDC, the fused camera chain (formulas.md §1, §2).
// Derivations these tests prove: docs/math/camera.md. Set HASHCC_TEST_VERBOSE=1 to print the
// worst error of every check next to its tolerance.
#include <catch2/catch.hpp>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>
#include "camera/camera.h"
#include "core/parallel.h"
#include "test/gradcheck.h"

using namespace hashcc;
using hashcc::test::keep_worst;
using hashcc::test::max_abs_entry;
using hashcc::test::rel_err;
using hashcc::test::worst_grad_error;
using Vec3d = Eigen::Vector3d;
using Mat3d = Eigen::Matrix3d;

namespace {

constexpr double kPi = 3.14159265358979323846;

void report(const std::string& what, double err, double tol) {
  HCC_TEST_PRINTF("  %-60s worst %.3e  (tol %.0e)\n", what.c_str(), err, tol);
}

Vec3d random_unit(Rng& rng) {
  Vec3d v(rng.normal(), rng.normal(), rng.normal());
  return v.normalized();
}

Mat3d random_rotation(Rng& rng, double max_angle = kPi) {
  return Eigen::AngleAxisd(rng.uniform(0, max_angle), random_unit(rng)).toRotationMatrix();
}

// Reference rotation independent of so3::exp (Eigen's axis-angle).
Mat3d reference_exp(const Vec3d& r) {
  double th = r.norm();
  if (th == 0) return Mat3d::Identity();
  return Eigen::AngleAxisd(th, r / th).toRotationMatrix();
}

std::vector<int> random_pixels(int64_t N, ImageSize s, Rng& rng) {
  std::vector<int> px(2 * N);
  for (int64_t i = 0; i < N; ++i) {
    px[2 * i] = int(rng.below(uint32_t(s.W)));
    px[2 * i + 1] = int(rng.below(uint32_t(s.H)));
  }
  return px;
}

// θ = [r0 r1 r2 t0 t1 t2 a b] ↔ (pose, focal).
std::vector<double> flatten(const PoseParams<double>& p, const FocalParams<double>& f) {
  return {p.r[0], p.r[1], p.r[2], p.t[0], p.t[1], p.t[2], f.a, f.b};
}
void unflatten(const std::vector<double>& th, PoseParams<double>& p, FocalParams<double>& f) {
  p.r = Vec3d(th[0], th[1], th[2]);
  p.t = Vec3d(th[3], th[4], th[5]);
  f.a = th[6];
  f.b = th[7];
}

enum class Head {
  kRays,     // L = ⟨g_o, o_out⟩ + ⟨g_d, d_out⟩
  kSamples,  // L = Σ_rays ⟨g_x, o_out + s·d_out⟩ + ⟨g_n, normalize(d_out)⟩  (formulas.md §2 samples)
};

struct ChainCase {
  PoseParams<double> pose;
  FocalParams<double> focal;
  ImageSize size{40, 30};
  NdcWarp ndc = true;  // on/off, and (NdcWarp(fx, fy)) a box drawn with a fixed focal
  Head head = Head::kSamples;
  bool separate_kernels = false;  // rays_forward/backward directly (requires !ndc, kRays)
  int64_t N = 64;
  double h = 1e-6;
  uint64_t seed = 1;
};

struct ChainResult { double worst; std::vector<double> grad; bool finite; };

// Gradient check of the whole camera chain w.r.t. the 6 pose and 2 focal numbers.
ChainResult check_chain(ChainCase c) {
  Rng rng(c.seed, 7);
  const int64_t N = c.N;
  std::vector<int> px = random_pixels(N, c.size, rng);
  std::vector<double> g1 = hashcc::test::random_vec(3 * N, rng), g2 = hashcc::test::random_vec(3 * N, rng);
  std::vector<double> s = hashcc::test::random_vec(N, rng, 0, 1);
  std::vector<double> o(3 * N), d(3 * N);

  auto forward = [&](const PoseParams<double>& p, const FocalParams<double>& f) {
    if (c.separate_kernels) rays_forward(o.data(), d.data(), px.data(), N, p, f, c.size);
    else camera_rays_forward(o.data(), d.data(), px.data(), N, p, f, c.size, c.ndc);
  };
  auto head_loss = [&]() {
    double L = 0;
    for (int64_t i = 0; i < N; ++i) {
      Eigen::Map<const Vec3d> oi(&o[3 * i]), di(&d[3 * i]), ga(&g1[3 * i]), gb(&g2[3 * i]);
      if (c.head == Head::kRays) L += ga.dot(oi) + gb.dot(di);
      else L += ga.dot(oi + s[i] * di) + gb.dot(di.normalized());
    }
    return L;
  };

  forward(c.pose, c.focal);
  bool finite = true;
  for (int64_t i = 0; i < 3 * N; ++i) finite &= std::isfinite(o[i]) && std::isfinite(d[i]);
  // Upstream gradients dL/do_out, dL/dd_out.
  std::vector<double> dL_do(3 * N), dL_dd(3 * N);
  for (int64_t i = 0; i < N; ++i) {
    Eigen::Map<const Vec3d> di(&d[3 * i]), ga(&g1[3 * i]), gb(&g2[3 * i]);
    Eigen::Map<Vec3d> go(&dL_do[3 * i]), gd(&dL_dd[3 * i]);
    if (c.head == Head::kRays) { go = ga; gd = gb; continue; }
    Vec3d n = di.normalized();
    go = ga;                                                  // ∂x/∂o' = I
    gd = s[i] * ga + (gb - n * n.dot(gb)) / di.norm();        // ∂x/∂d' = s I; normalize backward
  }
  double d_pose[6] = {0}, d_focal[2] = {0};
  if (c.separate_kernels)
    rays_backward(d_pose, d_focal, dL_do.data(), dL_dd.data(), px.data(), N, c.pose, c.focal, c.size);
  else
    camera_rays_backward(d_pose, d_focal, dL_do.data(), dL_dd.data(), px.data(), N, c.pose,
                         c.focal, c.size, c.ndc);
  std::vector<double> grad(d_pose, d_pose + 6);
  grad.push_back(d_focal[0]);
  grad.push_back(d_focal[1]);
  for (double g : grad) finite &= std::isfinite(g);

  std::vector<double> theta = flatten(c.pose, c.focal);
  PoseParams<double> p = c.pose;
  FocalParams<double> f = c.focal;
  auto loss = [&]() { unflatten(theta, p, f); forward(p, f); return head_loss(); };
  double worst = worst_grad_error(theta, grad, loss, c.h);
  if (test::verbose())
    for (size_t i = 0; i < 8; ++i)
      HCC_TEST_PRINTF("    param %zu grad %.6e err %.3e\n", i, grad[i], worst_grad_error(theta, grad, loss, c.h, {i}));
  return {worst, grad, finite};
}

PoseParams<double> forward_facing_pose(Rng& rng, bool with_P0) {
  PoseParams<double> p;
  p.r = Vec3d(rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15));
  p.t = Vec3d(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2));
  if (with_P0) {
    p.has_P0 = true;
    p.P0.leftCols<3>() = random_rotation(rng, 0.3);
    p.P0.col(3) = Vec3d(rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3));
  }
  return p;
}

// NDC gradient check w.r.t. every o, d entry and fx, fy. Rays given explicitly.
struct NdcResult { double worst; bool finite; std::vector<double> grad; };
// Every input but d_z enters o', d' linearly (one at a time: o, fx, fy, and d_x, d_y through
// d_x/d_z, d_y/d_z), so their central difference is exact and takes a large step (1e-3, little
// roundoff); h_dz is the step for the d_z entries, the only nonlinear ones.
NdcResult check_ndc(std::vector<double> o, std::vector<double> d, double fx, double fy,
                    ImageSize size, double h_dz, uint64_t seed) {
  const int64_t N = int64_t(o.size() / 3);
  Rng rng(seed, 3);
  std::vector<double> go = hashcc::test::random_vec(3 * N, rng), gd = hashcc::test::random_vec(3 * N, rng);
  std::vector<double> on(3 * N), dn(3 * N);
  ndc_forward(on.data(), dn.data(), o.data(), d.data(), N, fx, fy, size);
  bool finite = true;
  for (int64_t i = 0; i < 3 * N; ++i) finite &= std::isfinite(on[i]) && std::isfinite(dn[i]);
  std::vector<double> d_o(3 * N), d_d(3 * N);
  double d_fx = 0, d_fy = 0;
  ndc_backward(d_o.data(), d_d.data(), &d_fx, &d_fy, go.data(), gd.data(), o.data(), d.data(), N,
               fx, fy, size);
  // θ = [o (3N), d (3N), fx, fy]
  std::vector<double> theta, grad;
  theta.insert(theta.end(), o.begin(), o.end());
  theta.insert(theta.end(), d.begin(), d.end());
  theta.push_back(fx); theta.push_back(fy);
  grad.insert(grad.end(), d_o.begin(), d_o.end());
  grad.insert(grad.end(), d_d.begin(), d_d.end());
  grad.push_back(d_fx); grad.push_back(d_fy);
  for (double g : grad) finite &= std::isfinite(g);
  auto loss = [&]() {
    ndc_forward(on.data(), dn.data(), theta.data(), theta.data() + 3 * N, N, theta[6 * N],
                theta[6 * N + 1], size);
    return hashcc::test::dot(go, on) + hashcc::test::dot(gd, dn);
  };
  std::vector<size_t> idx_linear, idx_dz;
  for (size_t i = 0; i < theta.size(); ++i)
    (i >= size_t(3 * N) && i < size_t(6 * N) && i % 3 == 2 ? idx_dz : idx_linear).push_back(i);
  double worst = worst_grad_error(theta, grad, loss, 1e-3, idx_linear);
  keep_worst(worst, worst_grad_error(theta, grad, loss, h_dz, idx_dz));
  return {worst, finite, grad};
}

// Spec §2 written out literally (the moved origin's z kept as computed): the naive reference.
void ndc_naive(double* on, double* dn, const double* o, const double* d, double fx, double fy,
               ImageSize s) {
  double tn = -(1 + o[2]) / d[2];
  double p[3] = {o[0] + tn * d[0], o[1] + tn * d[1], o[2] + tn * d[2]};
  double ax = fx / (s.W / 2.0), ay = fy / (s.H / 2.0);
  on[0] = -ax * p[0] / p[2];
  on[1] = -ay * p[1] / p[2];
  on[2] = 1 + 2 / p[2];
  dn[0] = -ax * (d[0] / d[2] - p[0] / p[2]);
  dn[1] = -ay * (d[1] / d[2] - p[1] / p[2]);
  dn[2] = -2 / p[2];
}

const double kHardAngles[] = {0.0, 1e-12, 1e-8, 1e-5, 1.0, kPi - 1e-6, kPi, 25.0};

}  // namespace

// ---------------------------------------------------------------------------------- SO(3)

TEST_CASE("so3 exp matches axis-angle reference and is a rotation at hard angles", "[camera]") {
  Rng rng(11);
  double worst = 0;
  for (double th : kHardAngles) {
    for (int rep = 0; rep < 4; ++rep) {
      Vec3d r = th * random_unit(rng);
      Mat3d R = so3::exp(r);
      REQUIRE(R.allFinite());
      keep_worst(worst, max_abs_entry(R - reference_exp(r)));
      REQUIRE(hashcc::test::max_abs_entry(R.transpose() * R - Mat3d::Identity()) < 1e-14);
      REQUIRE(std::abs(R.determinant() - 1) < 1e-14);
    }
  }
  report("exp vs Eigen AngleAxis (max abs entry)", worst, 1e-14);
  REQUIRE(worst < 1e-14);
  REQUIRE(so3::exp(Vec3d::Zero().eval()) == Mat3d::Identity());
  // Small angle: R = I + K + K²/2 + O(θ³): at θ = 1e-5 the remainder is < 1e-15.
  Vec3d r(6e-6, -5e-6, 5e-6);
  Mat3d K = so3::hat(r);
  REQUIRE(hashcc::test::max_abs_entry(so3::exp(r) - (Mat3d::Identity() + K + 0.5 * K * K)) < 1e-15);
}

TEST_CASE("so3 exp derivative: central differences at random and hard angles", "[camera][grad]") {
  Rng rng(12);
  std::vector<double> angles(std::begin(kHardAngles), std::end(kHardAngles));
  for (int i = 0; i < 6; ++i) angles.push_back(rng.uniform(0, 3.1));
  const double tol = 1e-8;
  double worst = 0;
  for (double th : angles) {
    for (int rep = 0; rep < 3; ++rep) {
      Vec3d r = th * random_unit(rng);
      Mat3d G = Mat3d::Random();
      Mat3d dR[3];
      so3::exp_derivative(r, dR);
      std::vector<double> theta{r[0], r[1], r[2]}, grad(3);
      for (int k = 0; k < 3; ++k) {
        REQUIRE(dR[k].allFinite());
        grad[k] = dR[k].cwiseProduct(G).sum();
      }
      auto loss = [&]() { return so3::exp(Vec3d(theta[0], theta[1], theta[2])).cwiseProduct(G).sum(); };
      double e = worst_grad_error(theta, grad, loss, 1e-5);
      INFO("theta " << th << " r " << r.transpose());
      CHECK(e < tol);
      keep_worst(worst, e);
    }
  }
  report("exp derivative, all angles", worst, tol);
}

TEST_CASE("so3 exp derivative is continuous across its Taylor branch and exact at 0", "[camera][hard]") {
  Mat3d dR[3], dR_lo[3], dR_hi[3];
  so3::exp_derivative(Vec3d::Zero().eval(), dR);
  for (int k = 0; k < 3; ++k) REQUIRE(dR[k] == so3::hat(Vec3d::Unit(k).eval()));  // dR/dr_k = [e_k]× at 0
  // Series/closed-form switch at θ² = 1e-2: the series value just below the switch must equal the
  // linear extrapolation of two closed-form values just above it (extrapolation error ~δ² ≈ 1e-14).
  Vec3d axis = Vec3d(0.3, -0.5, 0.8).normalized();
  const double delta = 1e-7;
  Mat3d dR_hi2[3];
  so3::exp_derivative(Vec3d((0.1 - delta) * axis), dR_lo);
  so3::exp_derivative(Vec3d((0.1 + delta) * axis), dR_hi);
  so3::exp_derivative(Vec3d((0.1 + 3 * delta) * axis), dR_hi2);
  double jump = 0;
  for (int k = 0; k < 3; ++k)
    keep_worst(jump, max_abs_entry(dR_lo[k] - (2 * dR_hi[k] - dR_hi2[k])));
  report("exp derivative jump at Taylor switch", jump, 1e-13);
  REQUIRE(jump < 1e-13);
  // θ = 1e-8: dR/dr_k = E_k + (E_k K + K E_k)/2 + O(θ²)
  Vec3d r = 1e-8 * axis;
  so3::exp_derivative(r, dR);
  Mat3d K = so3::hat(r);
  for (int k = 0; k < 3; ++k) {
    Mat3d E = so3::hat(Vec3d::Unit(k).eval());
    REQUIRE(hashcc::test::max_abs_entry(dR[k] - (E + 0.5 * (E * K + K * E))) < 1e-15);
  }
}

TEST_CASE("so3 log/exp round trip and angle at hard angles", "[camera][hard]") {
  Rng rng(13);
  double worst = 0, worst_angle = 0;
  for (double th : kHardAngles) {
    for (int rep = 0; rep < 4; ++rep) {
      Vec3d axis = random_unit(rng), r = th * axis;
      Mat3d R = so3::exp(r);
      Vec3d back = so3::log(R);
      REQUIRE(back.allFinite());
      REQUIRE(back.norm() <= kPi + 1e-12);
      Vec3d expected = r;
      if (th == kPi) {  // r and −r are the same rotation
        if ((back + r).norm() < (back - r).norm()) expected = -r;
      } else if (th > kPi) {  // wrap: θ − 2πk along the same axis
        expected = (th - 2 * kPi * std::round(th / (2 * kPi))) * axis;
      }
      double e = (back - expected).norm();
      INFO("theta " << th);
      CHECK(e < 1e-13);
      keep_worst(worst, e);
      REQUIRE(hashcc::test::max_abs_entry(so3::exp(back) - R) < 1e-14);
      double ea = std::abs(so3::angle(R) - std::abs(expected.norm()));
      CHECK(ea < 1e-13);
      keep_worst(worst_angle, ea);
    }
  }
  report("log(exp(r)) − r", worst, 1e-13);
  report("angle(exp(r)) − |r|", worst_angle, 1e-13);
  // Exactly π about a known axis (R = 2aaᵀ − I, built without so3::exp): norm π on ±axis.
  for (Vec3d a : std::vector<Vec3d>{Vec3d(1, 0, 0), Vec3d(0, 1, 0), Vec3d(0, 0, 1), Vec3d(1, 2, -2) / 3.0}) {
    Mat3d R = 2 * a * a.transpose() - Mat3d::Identity();
    Vec3d r = so3::log(R);
    REQUIRE(std::abs(r.norm() - kPi) < 1e-14);
    REQUIRE(r.cross(a).norm() < 1e-14);
    REQUIRE(std::abs(so3::angle(R) - kPi) < 1e-15);
  }
  REQUIRE(so3::log(Mat3d::Identity().eval()) == Vec3d::Zero());
  REQUIRE(so3::angle(Mat3d::Identity().eval()) == 0.0);
}

// ---------------------------------------------------------------------------------- rays

TEST_CASE("rays follow the OpenGL convention (x right, y up, -z forward)", "[camera]") {
  ImageSize s{40, 30};
  PoseParams<double> pose;
  FocalParams<double> focal;  // fx = W, fy = H
  int px[6] = {20, 15, 40, 0, 0, 30};  // centre, top-right corner, bottom-left corner
  double o[9], d[9];
  rays_forward(o, d, px, 3, pose, focal, s);
  REQUIRE(Vec3d(d[0], d[1], d[2]) == Vec3d(0, 0, -1));
  REQUIRE(Vec3d(d[3], d[4], d[5]) == Vec3d(0.5, 0.5, -1));
  REQUIRE(Vec3d(d[6], d[7], d[8]) == Vec3d(-0.5, -0.5, -1));
  for (double x : o) REQUIRE(x == 0.0);
  // With P0 = [R0 | t0] and r = 0: o = t0 + t, d = R0 d_c.
  pose.has_P0 = true;
  pose.P0.leftCols<3>() = reference_exp(Vec3d(0.1, 0.2, -0.3));
  pose.P0.col(3) = Vec3d(1, 2, 3);
  pose.t = Vec3d(0.5, 0, 0);
  rays_forward(o, d, px, 3, pose, focal, s);
  REQUIRE((Vec3d(o[0], o[1], o[2]) - Vec3d(1.5, 2, 3)).norm() < 1e-15);
  REQUIRE((Vec3d(d[3], d[4], d[5]) - pose.P0.leftCols<3>() * Vec3d(0.5, 0.5, -1)).norm() < 1e-15);
}

TEST_CASE("world_from_camera composes [Exp(r)|t]·P0 as 4x4 matrices", "[camera]") {
  Rng rng(21);
  PoseParams<double> p = forward_facing_pose(rng, true);
  Eigen::Matrix4d delta = Eigen::Matrix4d::Identity(), P0 = Eigen::Matrix4d::Identity();
  delta.topLeftCorner<3, 3>() = reference_exp(p.r);
  delta.topRightCorner<3, 1>() = p.t;
  P0.topRows<3>() = p.P0;
  Eigen::Matrix<double, 3, 4> expected = (delta * P0).topRows<3>();
  REQUIRE(hashcc::test::max_abs_entry(world_from_camera(p) - expected) < 1e-15);
  p.has_P0 = false;
  REQUIRE(hashcc::test::max_abs_entry(world_from_camera(p) - delta.topRows<3>()) < 1e-15);
}

TEST_CASE("rays_backward: central differences w.r.t. r, t, a, b", "[camera][grad]") {
  Rng rng(31);
  const double tol = 1e-7;
  for (bool with_P0 : {false, true}) {
    for (bool fx_only : {false, true}) {
      ChainCase c;
      c.pose = forward_facing_pose(rng, with_P0);
      c.pose.r = Vec3d(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));  // general angle
      c.focal = {1.1, 0.9, fx_only};
      c.size = {41, 31};  // odd: W/2 not an integer
      c.ndc = false;
      c.head = Head::kRays;
      c.separate_kernels = true;
      c.seed = 100 + 2 * with_P0 + fx_only;
      ChainResult res = check_chain(c);
      INFO("P0 " << with_P0 << " fx_only " << fx_only);
      REQUIRE(res.finite);
      CHECK(res.worst < tol);
      if (fx_only) REQUIRE(res.grad[7] == 0.0);
      else REQUIRE(res.grad[7] != 0.0);
      report(std::string("rays P0=") + (with_P0 ? "1" : "0") + " fx_only=" + (fx_only ? "1" : "0"),
             res.worst, tol);
    }
  }
}

TEST_CASE("round trip: projected known points lie on their pixel's ray", "[camera]") {
  Rng rng(41);
  ImageSize s{64, 48};
  FocalParams<double> focal{1.05, 0.97, false};
  const double fx = focal_fx(focal, s), fy = focal_fy(focal, s);
  double worst_dist = 0, worst_px = 0;
  for (int cam = 0; cam < 6; ++cam) {
    PoseParams<double> pose = forward_facing_pose(rng, cam % 2 == 1);
    // c2w built independently: Eigen axis-angle and 4×4 homogeneous products.
    Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity(), P0 = Eigen::Matrix4d::Identity();
    c2w.topLeftCorner<3, 3>() = reference_exp(pose.r);
    c2w.topRightCorner<3, 1>() = pose.t;
    if (pose.has_P0) P0.topRows<3>() = pose.P0;
    c2w = c2w * P0;
    const Eigen::Matrix4d w2c = c2w.inverse();
    for (int k = 0; k < 20; ++k) {
      int u = int(rng.below(s.W)), v = int(rng.below(s.H));
      double depth = rng.uniform(0.5, 20);
      // The camera-frame point at this depth that projects to (u, v).
      Eigen::Vector4d Xc(depth * (u - s.W / 2.0) / fx, -depth * (v - s.H / 2.0) / fy, -depth, 1);
      Eigen::Vector4d Xw = c2w * Xc;
      // Project it back with the pinhole model: u = fx x/(−z) + W/2, v = −fy y/(−z) + H/2.
      Eigen::Vector4d Xc2 = w2c * Xw;
      double up = fx * Xc2.x() / -Xc2.z() + s.W / 2.0, vp = -fy * Xc2.y() / -Xc2.z() + s.H / 2.0;
      keep_worst(worst_px, std::abs(up - u));
      keep_worst(worst_px, std::abs(vp - v));
      int px[2] = {u, v};
      double o[3], d[3];
      rays_forward(o, d, px, 1, pose, focal, s);
      Vec3d O(o[0], o[1], o[2]), D(d[0], d[1], d[2]), X = Xw.head<3>();
      double dist = (X - O).cross(D).norm() / D.norm();
      keep_worst(worst_dist, dist);
      REQUIRE((X - O).dot(D) / D.squaredNorm() == Approx(depth).epsilon(1e-12));  // in front, at depth
    }
  }
  report("round trip: point-to-ray distance", worst_dist, 1e-9);
  report("round trip: reprojection (px)", worst_px, 1e-9);
  REQUIRE(worst_dist < 1e-9);
  REQUIRE(worst_px < 1e-9);
}

// ---------------------------------------------------------------------------------- NDC

TEST_CASE("ndc_forward matches the literal spec formula", "[camera]") {
  Rng rng(51);
  ImageSize s{40, 30};
  double worst = 0;
  for (int i = 0; i < 200; ++i) {
    double o[3] = {rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5)};
    double d[3] = {rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1.5, -0.3)};
    double on[3], dn[3], onr[3], dnr[3];
    double fx = rng.uniform(20, 60), fy = rng.uniform(20, 60);
    ndc_forward(on, dn, o, d, 1, fx, fy, s);
    ndc_naive(onr, dnr, o, d, fx, fy, s);
    for (int k = 0; k < 3; ++k) {
      keep_worst(worst, std::abs(on[k] - onr[k]) / std::max(1.0, std::abs(onr[k])));
      keep_worst(worst, std::abs(dn[k] - dnr[k]) / std::max(1.0, std::abs(dnr[k])));
    }
  }
  report("ndc vs literal spec formula", worst, 1e-13);
  REQUIRE(worst < 1e-13);
  // In-place use is allowed.
  std::vector<double> o = {0.1, -0.2, 0.3, 0, 0, 0}, d = {0.2, 0.1, -1, -0.3, 0.2, -0.7};
  std::vector<double> on(6), dn(6);
  ndc_forward(on.data(), dn.data(), o.data(), d.data(), 2, 45.0, 35.0, s);
  ndc_forward(o.data(), d.data(), o.data(), d.data(), 2, 45.0, 35.0, s);
  REQUIRE(o == on);
  REQUIRE(d == dn);
}

TEST_CASE("ndc_backward: central differences w.r.t. o, d, fx, fy", "[camera][grad]") {
  Rng rng(52);
  ImageSize s{40, 30};
  const int N = 32;
  std::vector<double> o(3 * N), d(3 * N);
  for (int i = 0; i < N; ++i) {
    o[3 * i] = rng.uniform(-0.5, 0.5); o[3 * i + 1] = rng.uniform(-0.5, 0.5); o[3 * i + 2] = rng.uniform(-0.5, 0.5);
    d[3 * i] = rng.uniform(-1, 1); d[3 * i + 1] = rng.uniform(-1, 1); d[3 * i + 2] = rng.uniform(-1.5, -0.3);
  }
  const double tol = 1e-7;
  NdcResult r = check_ndc(o, d, 43.0, 29.0, s, 1e-5, 5);
  REQUIRE(r.finite);
  report("ndc w.r.t. o, d, fx, fy", r.worst, tol);
  REQUIRE(r.worst < tol);
}

// ---------------------------------------------------------------------------------- chain

TEST_CASE("camera chain: pixel -> NDC sample point and direction w.r.t. pose and focal", "[camera][grad]") {
  Rng rng(61);
  const double tol = 1e-7;
  double worst = 0;
  int id = 0;
  // ndc: 0 off, 1 the box follows the learned focal (the paper), 2 the box drawn with a fixed
  // focal 10% wider / 5% narrower than the learned one (--ndc-fixed-focal): the difference then
  // sees the focal only through the rays' directions, and the backward must drop the box's term.
  for (int ndc : {1, 0, 2}) {
    for (bool with_P0 : {false, true}) {
      for (bool fx_only : {false, true}) {
        ChainCase c;
        c.pose = forward_facing_pose(rng, with_P0);
        c.focal = {rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2), fx_only};
        c.ndc = ndc == 2 ? NdcWarp(1.1 * focal_fx(c.focal, c.size), 0.95 * focal_fy(c.focal, c.size))
                         : NdcWarp(ndc == 1);
        c.seed = 200 + id++;
        c.h = 1e-5;
        ChainResult res = check_chain(c);
        INFO("ndc " << ndc << " P0 " << with_P0 << " fx_only " << fx_only);
        REQUIRE(res.finite);
        CHECK(res.worst < tol);
        if (fx_only) REQUIRE(res.grad[7] == 0.0);
        keep_worst(worst, res.worst);
        // The rays head as well (o_out, d_out directly).
        c.head = Head::kRays;
        res = check_chain(c);
        CHECK(res.worst < tol);
        keep_worst(worst, res.worst);
      }
    }
  }
  report("chain (ndc off / learned box / fixed box, P0, fx_only; samples + rays heads)", worst, tol);
}

TEST_CASE("camera chain equals rays then ndc kernels, forward and backward", "[camera]") {
  Rng rng(62);
  ImageSize s{40, 30};
  const int64_t N = 100;
  std::vector<int> px = random_pixels(N, s, rng);
  PoseParams<double> pose = forward_facing_pose(rng, true);
  FocalParams<double> focal{1.07, 0.93, false};
  std::vector<double> o(3 * N), d(3 * N), on(3 * N), dn(3 * N), co(3 * N), cd(3 * N);
  rays_forward(o.data(), d.data(), px.data(), N, pose, focal, s);
  const double fx = focal_fx(focal, s), fy = focal_fy(focal, s);
  ndc_forward(on.data(), dn.data(), o.data(), d.data(), N, fx, fy, s);
  camera_rays_forward(co.data(), cd.data(), px.data(), N, pose, focal, s, true);
  for (int64_t i = 0; i < 3 * N; ++i) {
    REQUIRE(co[i] == Approx(on[i]).epsilon(1e-14).margin(1e-14));
    REQUIRE(cd[i] == Approx(dn[i]).epsilon(1e-14).margin(1e-14));
  }
  camera_rays_forward(co.data(), cd.data(), px.data(), N, pose, focal, s, false);
  REQUIRE(co == o);  // ndc off: exactly the world rays
  REQUIRE(cd == d);
  // Backward: chain vs ndc_backward → rays_backward (+ NDC's fx, fy through a, b).
  std::vector<double> g1 = hashcc::test::random_vec(3 * N, rng), g2 = hashcc::test::random_vec(3 * N, rng);
  std::vector<double> d_o(3 * N), d_d(3 * N);
  double d_fx = 0, d_fy = 0, p1[6] = {0}, f1[2] = {0}, p2[6] = {0}, f2[2] = {0};
  ndc_backward(d_o.data(), d_d.data(), &d_fx, &d_fy, g1.data(), g2.data(), o.data(), d.data(), N,
               fx, fy, s);
  rays_backward(p1, f1, d_o.data(), d_d.data(), px.data(), N, pose, focal, s);
  f1[0] += d_fx * 2 * focal.a * s.W;
  f1[1] += d_fy * 2 * focal.b * s.H;
  camera_rays_backward(p2, f2, g1.data(), g2.data(), px.data(), N, pose, focal, s, true);
  for (int k = 0; k < 6; ++k) REQUIRE(p2[k] == Approx(p1[k]).epsilon(1e-12).margin(1e-12));
  for (int k = 0; k < 2; ++k) REQUIRE(f2[k] == Approx(f1[k]).epsilon(1e-12).margin(1e-12));

  // A box drawn with a fixed focal (NdcWarp(fx', fy')): the NDC kernels at fx', fy', and the
  // focal's gradient from rays_backward alone (ndc_backward's d_fx, d_fy not taken).
  const double fx2 = 1.2 * fx, fy2 = 0.9 * fy;
  ndc_forward(on.data(), dn.data(), o.data(), d.data(), N, fx2, fy2, s);
  camera_rays_forward(co.data(), cd.data(), px.data(), N, pose, focal, s, NdcWarp(fx2, fy2));
  for (int64_t i = 0; i < 3 * N; ++i) {
    REQUIRE(co[i] == Approx(on[i]).epsilon(1e-14).margin(1e-14));
    REQUIRE(cd[i] == Approx(dn[i]).epsilon(1e-14).margin(1e-14));
  }
  double p3[6] = {0}, f3[2] = {0}, p4[6] = {0}, f4[2] = {0};
  ndc_backward(d_o.data(), d_d.data(), static_cast<double*>(nullptr), static_cast<double*>(nullptr),
               g1.data(), g2.data(), o.data(), d.data(),
               N, fx2, fy2, s);
  rays_backward(p3, f3, d_o.data(), d_d.data(), px.data(), N, pose, focal, s);
  camera_rays_backward(p4, f4, g1.data(), g2.data(), px.data(), N, pose, focal, s,
                       NdcWarp(fx2, fy2));
  for (int k = 0; k < 6; ++k) REQUIRE(p4[k] == Approx(p3[k]).epsilon(1e-12).margin(1e-12));
  for (int k = 0; k < 2; ++k) REQUIRE(f4[k] == Approx(f3[k]).epsilon(1e-12).margin(1e-12));
  // …and it is a different gradient from the learned box's (the box's term is not zero here).
  REQUIRE(std::abs(f4[0] - f2[0]) > 1e-6 * (std::abs(f2[0]) + 1e-12));
}

TEST_CASE("camera backward does not depend on the thread count beyond rounding", "[camera]") {
  Rng rng(63);
  ImageSize s{64, 48};
  const int64_t N = 4096;  // enough to split across threads
  std::vector<int> px = random_pixels(N, s, rng);
  PoseParams<double> pose = forward_facing_pose(rng, true);
  FocalParams<double> focal{1.02, 0.98, false};
  std::vector<double> g1 = hashcc::test::random_vec(3 * N, rng), g2 = hashcc::test::random_vec(3 * N, rng);
  const int keep = num_threads();
  double p[2][6] = {{0}}, f[2][2] = {{0}};
  for (int run = 0; run < 2; ++run) {
    set_num_threads(run + 1);
    camera_rays_backward(p[run], f[run], g1.data(), g2.data(), px.data(), N, pose, focal, s, true);
  }
  set_num_threads(keep);
  for (int k = 0; k < 6; ++k) REQUIRE(p[1][k] == Approx(p[0][k]).epsilon(1e-12));
  for (int k = 0; k < 2; ++k) REQUIRE(f[1][k] == Approx(f[0][k]).epsilon(1e-12));
}

// ---------------------------------------------------------------------------------- hard cases

TEST_CASE("hard: NDC with rays almost parallel to the image plane and origins on the near plane", "[camera][hard]") {
  ImageSize s{40, 30};
  // Correct (unclamped) regime, |d_z| = 1e-3: ratios ~1e3, FD step scaled down.
  {
    std::vector<double> o = {0.1, -0.2, 0.3, -0.1, 0.05, -0.2};
    std::vector<double> d = {0.7, -0.4, -1e-3, -0.5, 0.6, 2e-3};
    NdcResult r = check_ndc(o, d, 40.0, 30.0, s, 1e-9, 71);
    REQUIRE(r.finite);
    report("ndc |d_z| = 1e-3", r.worst, 1e-6);
    REQUIRE(r.worst < 1e-6);
  }
  // Origins exactly on the near plane (o_z = −1, t_n = 0): o' = (sx o_x, sy o_y, −1).
  {
    std::vector<double> o = {0.1, -0.2, -1.0, -0.3, 0.25, -1.0};
    std::vector<double> d = {0.2, -0.1, -1.0, 0.4, 0.3, -0.6};
    NdcResult r = check_ndc(o, d, 40.0, 30.0, s, 1e-6, 72);
    REQUIRE(r.finite);
    report("ndc origins on the near plane", r.worst, 1e-7);
    REQUIRE(r.worst < 1e-7);
    double on[6], dn[6];
    ndc_forward(on, dn, o.data(), d.data(), 2, 40.0, 30.0, s);
    REQUIRE(on[0] == Approx(2.0 * 0.1));
    REQUIRE(on[1] == Approx(2.0 * -0.2));
    REQUIRE(on[2] == -1.0);
    REQUIRE(dn[2] == 2.0);
  }
  // Inside the clamp (|d_z| < 1e-6): finite, d_z gradient exactly 0, and the other gradients
  // match finite differences of the clamped function (steps kept inside the clamp, same sign).
  {
    std::vector<double> o = {0.1, -0.2, 0.3, -0.1, 0.05, -0.2, 0.2, 0.1, -0.4};
    std::vector<double> d = {0.7, -0.4, -1e-9, -0.5, 0.6, -5e-7, 0.3, 0.2, 3e-7};
    NdcResult r = check_ndc(o, d, 40.0, 30.0, s, 1e-11, 73);
    REQUIRE(r.finite);
    REQUIRE(r.grad[9 + 2] == 0.0);
    REQUIRE(r.grad[9 + 5] == 0.0);
    REQUIRE(r.grad[9 + 8] == 0.0);
    report("ndc clamped |d_z| < 1e-6 (-1e-9, -5e-7, 3e-7)", r.worst, 1e-6);
    REQUIRE(r.worst < 1e-6);
  }
  // d_z exactly +0 and −0: both taken as forward (−1e-6); finite values and gradients. (At d_z = 0
  // the clamp switches sign, a jump no finite difference across 0 can match: not checked there.)
  {
    std::vector<double> o = {0.1, -0.2, 0.3, -0.1, 0.05, -0.2};
    std::vector<double> d = {0.7, -0.4, 0.0, -0.5, 0.6, -0.0};
    std::vector<double> on(6), dn(6), g(6, 0.5), d_o(6), d_d(6);
    double d_fx = 0, d_fy = 0;
    ndc_forward(on.data(), dn.data(), o.data(), d.data(), 2, 40.0, 30.0, s);
    ndc_backward(d_o.data(), d_d.data(), &d_fx, &d_fy, g.data(), g.data(), o.data(), d.data(), 2,
                 40.0, 30.0, s);
    for (int k = 0; k < 6; ++k) {
      REQUIRE(std::isfinite(on[k])); REQUIRE(std::isfinite(dn[k]));
      REQUIRE(std::isfinite(d_o[k])); REQUIRE(std::isfinite(d_d[k]));
    }
    REQUIRE(std::isfinite(d_fx)); REQUIRE(std::isfinite(d_fy));
    REQUIRE(d_d[2] == 0.0);
    REQUIRE(d_d[5] == 0.0);
    // Value at d_z = 0 (ray 0 above) equals the unclamped formula at d_z = −1e-6.
    double onr[3], dnr[3], dzc[3] = {0.7, -0.4, -1e-6};
    ndc_naive(onr, dnr, o.data(), dzc, 40.0, 30.0, s);
    for (int k = 0; k < 3; ++k) {
      REQUIRE(on[k] == Approx(onr[k]).epsilon(1e-9));
      REQUIRE(dn[k] == Approx(dnr[k]).epsilon(1e-9));
    }
  }
}

TEST_CASE("hard: whole chain at extreme poses and focals", "[camera][hard][grad]") {
  Rng rng(81);
  struct Hard { const char* name; Vec3d r; double a, b; double h; double tol; bool ndc; };
  const Vec3d tilt = Vec3d(1, 0.1, 0.05).normalized();  // near-π turns about ~x: d_z > 0, well away from 0
  // Turn about y by π/2 − 1e-2: the centre ray has d_z ≈ −1e-2 (almost parallel to the image plane).
  const Hard cases[] = {
      {"zero rotation exactly", Vec3d::Zero(), 1.0, 1.0, 1e-6, 1e-7, true},
      {"rotation pi - 1e-6", (kPi - 1e-6) * tilt, 1.0, 1.0, 1e-6, 1e-7, true},
      {"rotation pi - 1e-6 (no ndc)", (kPi - 1e-6) * tilt, 1.0, 1.0, 1e-6, 1e-7, false},
      {"rotation exactly pi", kPi * tilt, 1.0, 1.0, 1e-6, 1e-7, true},
      {"rotation 25 rad", 25.0 * tilt, 1.0, 1.0, 1e-6, 1e-7, false},
      {"rays nearly parallel to image plane", Vec3d(0, kPi / 2 - 1e-2, 0), 1.0, 1.0, 1e-7, 1e-5, true},
      {"huge focal a = b = 30", Vec3d(0.05, -0.03, 0.02), 30.0, 30.0, 1e-6, 1e-7, true},
      {"tiny focal a = b = 0.05", Vec3d(0.05, -0.03, 0.02), 0.05, 0.05, 1e-6, 1e-6, true},
  };
  for (const Hard& hc : cases) {
    ChainCase c;
    c.pose.r = hc.r;
    c.pose.t = Vec3d(0.1, -0.05, 0.08);
    c.focal = {hc.a, hc.b, false};
    c.ndc = hc.ndc;
    c.h = hc.h;
    c.seed = 300;
    // Near-parallel case: d_z = −sinφ·(u − 20)/40 − cosφ over the integer columns of W = 40
    // takes |d_z| ∈ {0.01, 0.015, …}: as close to 0 as the pixel grid allows without the clamp.
    ChainResult res = check_chain(c);
    INFO(hc.name);
    REQUIRE(res.finite);
    CHECK(res.worst < hc.tol);
    report(std::string("chain hard: ") + hc.name, res.worst, hc.tol);
  }
}

TEST_CASE("hard: chain outputs and gradients stay finite when d_z is exactly 0", "[camera][hard]") {
  // Turn by exactly π/2 about y: the ray of pixel column W/2 has d_z = −sin(π/2 − π/2)… ≈ 0.
  ImageSize s{40, 30};
  PoseParams<double> pose;
  pose.r = Vec3d(0, kPi / 2, 0);
  FocalParams<double> focal;
  int px[4] = {20, 15, 20, 3};
  double o[6], d[6], dw[6], ow[6];
  rays_forward(ow, dw, px, 2, pose, focal, s);
  REQUIRE(std::abs(dw[2]) < 1e-15);  // genuinely inside the clamp
  camera_rays_forward(o, d, px, 2, pose, focal, s, true);
  for (double x : o) REQUIRE(std::isfinite(x));
  for (double x : d) REQUIRE(std::isfinite(x));
  double g[6] = {0.3, -0.2, 0.1, 0.5, 0.4, -0.6}, dp[6] = {0}, df[2] = {0};
  camera_rays_backward(dp, df, g, g, px, 2, pose, focal, s, true);
  for (double x : dp) REQUIRE(std::isfinite(x));
  for (double x : df) REQUIRE(std::isfinite(x));
}

// ---------------------------------------------------------------------------------- float

TEST_CASE("float agrees with double for rays, NDC and their backward", "[camera][float]") {
  Rng rng(91);
  ImageSize s{64, 48};
  const int64_t N = 256;
  std::vector<int> px = random_pixels(N, s, rng);
  PoseParams<double> pd = forward_facing_pose(rng, true);
  FocalParams<double> fd{1.04, 0.95, false};
  PoseParams<float> pf;
  pf.r = pd.r.cast<float>(); pf.t = pd.t.cast<float>(); pf.has_P0 = true; pf.P0 = pd.P0.cast<float>();
  FocalParams<float> ff{float(fd.a), float(fd.b), false};
  std::vector<double> od(3 * N), dd(3 * N), g1 = hashcc::test::random_vec(3 * N, rng),
                      g2 = hashcc::test::random_vec(3 * N, rng);
  std::vector<float> of(3 * N), df(3 * N), g1f(g1.begin(), g1.end()), g2f(g2.begin(), g2.end());
  const double tol = 2e-6, tol_grad = 1e-5;
  for (bool ndc : {false, true}) {
    camera_rays_forward(od.data(), dd.data(), px.data(), N, pd, fd, s, ndc);
    camera_rays_forward(of.data(), df.data(), px.data(), N, pf, ff, s, ndc);
    double worst = 0;
    for (int64_t i = 0; i < 3 * N; ++i) {
      keep_worst(worst, std::abs(of[i] - od[i]) / std::max(1.0, std::abs(od[i])));
      keep_worst(worst, std::abs(df[i] - dd[i]) / std::max(1.0, std::abs(dd[i])));
    }
    report(std::string("float vs double forward, ndc=") + (ndc ? "1" : "0"), worst, tol);
    REQUIRE(worst < tol);
    double ppd[6] = {0}, pfd[2] = {0};
    float ppf[6] = {0}, pff[2] = {0};
    camera_rays_backward(ppd, pfd, g1.data(), g2.data(), px.data(), N, pd, fd, s, ndc);
    camera_rays_backward(ppf, pff, g1f.data(), g2f.data(), px.data(), N, pf, ff, s, ndc);
    double wg = 0;
    for (int k = 0; k < 6; ++k) keep_worst(wg, rel_err(ppf[k], ppd[k], 1.0));
    for (int k = 0; k < 2; ++k) keep_worst(wg, rel_err(pff[k], pfd[k], 1.0));
    report(std::string("float vs double backward, ndc=") + (ndc ? "1" : "0"), wg, tol_grad);
    REQUIRE(wg < tol_grad);
  }
}
