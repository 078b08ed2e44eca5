// The pose preconditioner (--pose-precondition, camera/precondition.h, docs/math/precondition.md):
//   - the projection Jacobian J equals its closed form, at identity and at a turned camera
//     (θ near π, with P0), to 1e-7 of its largest entry;
//   - P = c (Σ + λ diag Σ)^(−1/2) whitens: P Σ' P = c² I, P symmetric, det P = 1;
//   - it frees the orbit: some orbit (turn about y while sliding along x) is amplified more than
//     any single parameter, and a huge damping leaves P diagonal;
//   - jointly with the focal: P whitens the joint Σ of several cameras and the shared focal;
//     without the focal it is block diagonal, each block the camera's own P;
//   - the trainer: Adam's first step in ψ is −lr · sign(P g) in every coordinate (so the
//     cameras move by P Δψ); with a fixed focal only the step's camera moves, with a learned one
//     every camera; P survives a resume; bad values are clear errors.
#include <catch2/catch.hpp>

#include "test/fixtures.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <cmath>
#include <filesystem>

#include "camera/precondition.h"
#include "core/error.h"
#include "test/gradcheck.h"

using namespace hashcc;
namespace fs = std::filesystem;

namespace {

// The closed form of J (docs/math/precondition.md): X_c = Rᵀ(X − C) with R = Exp(r)·R0 and
// C = Exp(r)·t0 + t, so dX_c/dt = −Rᵀ and dX_c/dr_k = (dExp/dr_k · R0)ᵀ (X − C)
// − Rᵀ (dExp/dr_k · t0); then u = W/2 + fx·x/(−z), v = H/2 − fy·y/(−z).
Eigen::MatrixXd closed_form_jacobian(const PoseParams<double>& pose, const FocalParams<double>& f,
                                     ImageSize size, const PreconditionOptions& o, int m = 0) {
  const double fx = focal_fx(f, size), fy = focal_fy(f, size);
  const Mat34<double> c2w = world_from_camera(pose);
  const Mat3<double> R = c2w.leftCols<3>();
  const Vec3<double> C = c2w.col(3);
  const Mat3<double> R0 = pose.has_P0 ? Mat3<double>(pose.P0.leftCols<3>()) : Mat3<double>::Identity();
  const Vec3<double> t0 = pose.has_P0 ? Vec3<double>(pose.P0.col(3)) : Vec3<double>::Zero();
  Mat3<double> dE[3];
  so3::exp_derivative(pose.r, dE);
  Eigen::MatrixXd J(2 * o.lattice * o.lattice * o.disparities, 6 + m);
  int row = 0;
  for (int a = 0; a < o.lattice; ++a)
    for (int b = 0; b < o.lattice; ++b)
      for (int k = 0; k < o.disparities; ++k) {
        const double u = (b + 0.5) * size.W / o.lattice, v = (a + 0.5) * size.H / o.lattice;
        const double depth = o.disparities / (k + 0.5);
        const Vec3<double> dc((u - 0.5 * size.W) / fx, -(v - 0.5 * size.H) / fy, -1.0);
        const Vec3<double> X = R * (depth * dc) + C;
        const Vec3<double> xc = R.transpose() * (X - C);
        Eigen::Matrix<double, 2, 3> dp;  // d(u, v)/d X_c
        const double z = xc.z();
        dp << fx / -z, 0, fx * xc.x() / (z * z), 0, -fy / -z, -fy * xc.y() / (z * z);
        for (int c = 0; c < 3; ++c) {
          const Vec3<double> dxc = (dE[c] * R0).transpose() * (X - C) - R.transpose() * (dE[c] * t0);
          J.block<2, 1>(row, c) = dp * dxc;
          J.block<2, 1>(row, 3 + c) = dp * (-R.transpose()).col(c);
        }
        // The focal (fx = a²W, fy = b²H): u − W/2 = fx·x/(−z) scales with fx.
        const double ux = xc.x() / -z, vy = xc.y() / -z;
        if (m >= 1) J.block<2, 1>(row, 6) << 2 * f.a * size.W * ux,
                                              f.fx_only ? -2 * f.a * size.W * vy : 0.0;
        if (m == 2) J.block<2, 1>(row, 7) << 0.0, f.fx_only ? 0.0 : -2 * f.b * size.H * vy;
        row += 2;
      }
  return J;
}

double max_rel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return hashcc::test::max_abs_entry(a - b) / hashcc::test::max_abs_entry(b);
}

const ImageSize kSize{64, 48};

}  // namespace

TEST_CASE("precondition: the projection Jacobian equals its closed form",
          "[precondition][hard]") {  // hard case: θ → π on top of a P0
  PreconditionOptions o;
  const FocalParams<double> f{1.1, 0.95, false};
  PoseParams<double> id;
  const double e_id = max_rel(pose_projection_jacobian(id, f, kSize, o),
                              closed_form_jacobian(id, f, kSize, o));
  // A moved camera without P0, and the hard case: turned by almost π about y, on top of a P0.
  PoseParams<double> moved;
  moved.r = Vec3<double>(0.3, -0.2, 0.1);
  moved.t = Vec3<double>(0.5, -0.1, 0.2);
  const double e_moved = max_rel(pose_projection_jacobian(moved, f, kSize, o),
                                 closed_form_jacobian(moved, f, kSize, o));
  PoseParams<double> back;
  back.r = Vec3<double>(0, M_PI - 1e-7, 0);
  back.t = Vec3<double>(0.1, 0.0, -0.3);
  back.has_P0 = true;
  back.P0.leftCols<3>() = so3::exp(Vec3<double>(0.1, 0.2, -0.05));
  back.P0.col(3) = Vec3<double>(1.0, 2.0, -0.5);
  const double e_back = max_rel(pose_projection_jacobian(back, f, kSize, o),
                                closed_form_jacobian(back, f, kSize, o));
  // With the focal's columns: a and b, and a alone with fx_only (it moves v too).
  const double e_focal = max_rel(pose_projection_jacobian(moved, f, kSize, o, 2),
                                 closed_form_jacobian(moved, f, kSize, o, 2));
  const FocalParams<double> fo{1.1, 0.95, true};
  const double e_fxonly = max_rel(pose_projection_jacobian(moved, fo, kSize, o, 1),
                                  closed_form_jacobian(moved, fo, kSize, o, 1));
  HCC_TEST_PRINTF("precondition J vs closed form: identity %.2e, moved %.2e, θ→π with P0 %.2e, "
                  "with the focal %.2e, fx-only %.2e (tolerance 1e-7)\n", e_id, e_moved, e_back,
                  e_focal, e_fxonly);
  CHECK(e_id < 1e-7);
  CHECK(e_moved < 1e-7);
  CHECK(e_back < 1e-7);
  CHECK(e_focal < 1e-7);
  CHECK(e_fxonly < 1e-7);
  // The centre-ray closed forms at identity, written out (docs/math/precondition.md): a turn
  // about y moves every point by fx per radian, a slide along x by −fx · disparity.
  PreconditionOptions one;
  one.lattice = 1;
  one.disparities = 2;  // disparities 1/4 and 3/4
  const Eigen::MatrixXd J1 = pose_projection_jacobian(id, f, kSize, one);
  const double fx = focal_fx(f, kSize);
  CHECK(J1(0, 1) == Approx(fx).epsilon(1e-8));
  CHECK(J1(0, 3) == Approx(-fx * 0.25).epsilon(1e-8));
  CHECK(J1(2, 3) == Approx(-fx * 0.75).epsilon(1e-8));
}

TEST_CASE("precondition: P whitens the projection, symmetric, det 1", "[precondition]") {
  const FocalParams<double> f{1.0, 1.0, false};
  for (double lambda : {0.0, 0.1, 1.0}) {
    PreconditionOptions o;
    o.damping = lambda;
    PoseParams<double> pose;
    pose.r = Vec3<double>(0.05, 0.3, -0.02);
    pose.t = Vec3<double>(0.2, 0.1, -0.1);
    const Mat6d P = pose_preconditioner(pose, f, kSize, o);
    const Eigen::MatrixXd J = pose_projection_jacobian(pose, f, kSize, o);
    Mat6d S = J.transpose() * J / double(J.rows() / 2);
    S.diagonal() *= 1 + lambda;
    const double c2 = std::pow(S.determinant(), 1.0 / 6.0);
    const Mat6d W = P * S * P / c2;
    const double e_white = hashcc::test::max_abs_entry(W - Mat6d::Identity());
    const double e_sym = hashcc::test::max_abs_entry(P - P.transpose()) / hashcc::test::max_abs_entry(P);
    HCC_TEST_PRINTF("precondition λ %.1f: |P Σ' P / c² − I| %.2e, asymmetry %.2e, det P %.12f\n",
                    lambda, e_white, e_sym, P.determinant());
    CHECK(e_white < 1e-9);
    CHECK(e_sym < 1e-12);
    CHECK(P.determinant() == Approx(1.0).epsilon(1e-9));
    CHECK(Eigen::SelfAdjointEigenSolver<Mat6d>(P).eigenvalues().minCoeff() > 0);
  }
}

TEST_CASE("precondition: the joint P of cameras and focal whitens their joint Σ",
          "[precondition]") {
  const FocalParams<double> f{1.0, 0.9, false};
  PreconditionOptions o;
  std::vector<PoseParams<double>> poses(3);
  poses[1].r = Vec3<double>(0.0, 0.2, 0.0);
  poses[1].t = Vec3<double>(0.3, 0.0, 0.0);
  poses[2].r = Vec3<double>(0.1, -0.1, 0.05);
  poses[2].t = Vec3<double>(-0.2, 0.1, -0.1);
  // m = 0: block diagonal, each block its camera's own whitening up to the common det scale.
  const Eigen::MatrixXd P0 = camera_preconditioner(poses, f, kSize, 0, o);
  REQUIRE(P0.rows() == 18);
  double off = 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (i != j) hashcc::test::keep_worst(off, hashcc::test::max_abs_entry(P0.block(6 * i, 6 * j, 6, 6)));
  CHECK(off < 1e-12);
  for (int i = 0; i < 3; ++i) {
    const Mat6d Pi = pose_preconditioner(poses[i], f, kSize, o);
    const Mat6d B = P0.block(6 * i, 6 * i, 6, 6);
    const double scale = std::pow(B.determinant(), 1.0 / 6.0);  // the common det scale
    CHECK(max_rel(B / scale, Pi) < 1e-9);
  }
  // m = 2: Σ assembled here from each camera's J with the focal's columns.
  const int D = 20;
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(D, D);
  for (int i = 0; i < 3; ++i) {
    const Eigen::MatrixXd J = pose_projection_jacobian(poses[i], f, kSize, o, 2);
    Eigen::MatrixXd E = Eigen::MatrixXd::Zero(8, D);  // camera i's columns in Φ
    E.block(0, 6 * i, 6, 6).setIdentity();
    E.block(6, 18, 2, 2).setIdentity();
    S += E.transpose() * (J.transpose() * J / double(J.rows() / 2)) * E;
  }
  S.diagonal() *= 1 + o.damping;
  const Eigen::MatrixXd P = camera_preconditioner(poses, f, kSize, 2, o);
  const double c2 = std::exp(std::log(S.determinant()) / D);
  const double e_white = hashcc::test::max_abs_entry(P * S * P / c2 - Eigen::MatrixXd::Identity(D, D));
  HCC_TEST_PRINTF("precondition joint (3 cameras + a, b): |P Σ' P / c² − I| %.2e, det P %.12f, "
                  "largest pose–focal entry %.3f\n", e_white, P.determinant(),
                  hashcc::test::max_abs_entry(P.block(0, 18, 18, 2)));
  CHECK(e_white < 1e-9);
  CHECK(P.determinant() == Approx(1.0).epsilon(1e-9));
  CHECK(P.block(0, 18, 18, 2).cwiseAbs().maxCoeff() > 1e-3);  // the focal couples every camera
}

TEST_CASE("precondition: the orbit is freed, a huge damping leaves P diagonal", "[precondition]") {
  const FocalParams<double> f{1.0, 1.0, false};
  PreconditionOptions o;
  const Mat6d P = pose_preconditioner(PoseParams<double>{}, f, kSize, o);
  // The orbit about a point at depth D on the axis: turn about y by θ, slide along x by θ·D
  // (the point stays put). P lengthens some orbit far more than the turn alone (measured at
  // this size, λ = 0.1: 1.31 against 0.64; the longest axis is the slide along z, 2.08, the
  // least observed parameter).
  double best_orbit = 0;
  for (double D = 1; D <= 16; D *= 1.25) {
    Eigen::Matrix<double, 6, 1> orbit = Eigen::Matrix<double, 6, 1>::Zero();
    orbit(1) = 1;
    orbit(3) = D;
    orbit.normalize();
    best_orbit = std::max(best_orbit, (P * orbit).norm());
  }
  const double turn = P.col(1).norm();
  double longest = 0;
  int longest_axis = -1;
  for (int i = 0; i < 6; ++i)
    if (P.col(i).norm() > longest) longest = P.col(i).norm(), longest_axis = i;
  HCC_TEST_PRINTF("precondition: longest orbit under P %.3f, the turn alone %.3f, longest axis "
                  "%d (%.3f)\n", best_orbit, turn, longest_axis, longest);
  CHECK(best_orbit > 1.5 * turn);
  CHECK(longest_axis == 5);  // t_z
  // λ → ∞: Σ' is its own diagonal, P diagonal (each parameter scaled alone).
  o.damping = 1e8;
  const Mat6d Pd = pose_preconditioner(PoseParams<double>{}, f, kSize, o);
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j)
      if (i != j) CHECK(std::abs(Pd(i, j)) < 1e-6 * std::sqrt(Pd(i, i) * Pd(j, j)));
}

TEST_CASE("precondition: the trainer's first step is −lr·sign(P g) in ψ, and P is kept",
          "[precondition][trainer]") {
  const std::string data = test::sim_scene("pc", 6, 40, 30);
  for (const bool fixed_focal : {true, false}) {
    CAPTURE(fixed_focal);
    const std::string out = test::tmp(fixed_focal ? "run_fixed" : "run_focal", true);
    TrainConfig c = test::tiny_train_config(data, out, 3);
    c.pose_precondition = 0.1;
    c.fixed_focal = fixed_focal;
    Trainer t(c);
    const int n = int(t.scene().train.size()), m = fixed_focal ? 0 : 2, D = 6 * n + m;
    REQUIRE(t.state().cameras_P.size() == size_t(D) * D);
    const std::vector<float> poses0 = t.state().poses, focal0 = t.state().focal;
    const double lr_pose = t.lr_pose_at(0), lr_focal = t.lr_focal_at(0);
    t.step_once();
    const int cam = t.last_images()[0];
    Eigen::MatrixXd P(D, D);
    for (int r = 0; r < D; ++r)
      for (int k = 0; k < D; ++k) P(r, k) = t.state().cameras_P[int64_t(D) * r + k];
    Eigen::VectorXd g = Eigen::VectorXd::Zero(D), d(D);
    for (int k = 0; k < 6; ++k) g(6 * cam + k) = t.last_camera_grads().d_pose[k];
    for (int k = 0; k < m; ++k) g(6 * n + k) = t.last_camera_grads().d_focal[k];
    for (int i = 0; i < 6 * n; ++i) d(i) = double(t.state().poses[i]) - poses0[i];
    for (int k = 0; k < m; ++k) d(6 * n + k) = double(t.state().focal[k]) - focal0[k];
    // Adam's first step from zero moments is −lr · g/(|g| + ε) in every coordinate, g = dL/dψ
    // (kernels/adam.h, ε = 1e-8): −lr · sign(g) unless |g| is below ε.
    const Eigen::VectorXd dpsi = P.inverse() * d, Pg = P * g;
    int moved = 0;
    for (int i = 0; i < n; ++i) moved += d.segment(6 * i, 6).norm() > 0;
    for (int k = 0; k < D; ++k) {
      const double lr = k < 6 * n ? lr_pose : lr_focal;
      const double want = -lr * Pg(k) / (std::abs(Pg(k)) + 1e-8);
      CHECK(dpsi(k) == Approx(want).epsilon(1e-3).margin(1e-3 * lr));
    }
    // Without the focal, P is block diagonal: only the step's camera moves. With it, the
    // focal couples every camera, and every camera moves.
    CHECK(moved == (fixed_focal ? 1 : n));
    CHECK(d.segment(6 * cam, 6).norm() > 0);
    // The same P after a resume (made from the starting cameras, not remade).
    t.run();
    Trainer r = Trainer::resume(out);
    CHECK(r.state().cameras_P == t.state().cameras_P);
    CHECK(r.config().pose_precondition == 0.1);
  }
  // Off by default: no P, and the step is the plain Adam step.
  Trainer d(test::tiny_train_config(data, "", 3));
  CHECK(d.state().cameras_P.empty());
}

TEST_CASE("precondition: bad values are clear errors naming the flag", "[precondition][cli]") {
  const std::string data = test::sim_scene("pc", 6, 40, 30);
  TrainConfig c = test::tiny_train_config(data, "", 3);
  c.pose_precondition = -1;
  REQUIRE_THROWS_WITH(validate_train_config(c), Catch::Contains("--pose-precondition"));
  c.pose_precondition = 0.1;
  c.ndc = false;
  REQUIRE_THROWS_WITH(validate_train_config(c), Catch::Contains("--pose-precondition") &&
                                                    Catch::Contains("NDC"));
  c.ndc = true;
  c.init_poses = data + "/poses_bounds.npy";
  c.refine_poses = false;
  REQUIRE_THROWS_WITH(validate_train_config(c), Catch::Contains("--pose-precondition") &&
                                                    Catch::Contains("--refine-poses"));
  CHECK(test::cli({"train", "--data", data, "--out", test::tmp("bad", true), "--steps", "2",
                   "--pose-precondition", "-0.5"}) == 2);
}
