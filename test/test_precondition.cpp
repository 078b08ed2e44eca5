// The pose preconditioner (--pose-precondition, camera/precondition.h, docs/math/precondition.md):
//   - the projection Jacobian J equals its closed form, at identity and at a turned camera
//     (θ near π, with P0), to 1e-7 of its largest entry;
//   - P = c (Σ + λ diag Σ)^(−1/2) whitens: P Σ' P = c² I, P symmetric, det P = 1;
//   - it frees the orbit: some orbit (turn about y while sliding along x) is amplified more than
//     any single parameter, and a huge damping leaves P diagonal;
//   - the trainer: Adam's first step in ψ is −lr · sign(P g) for the step's camera (so the poses
//     move by P Δψ), only that camera moves, P survives a resume, bad values are clear errors.
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
                                     ImageSize size, const PreconditionOptions& o) {
  const double fx = focal_fx(f, size), fy = focal_fy(f, size);
  const Mat34<double> c2w = world_from_camera(pose);
  const Mat3<double> R = c2w.leftCols<3>();
  const Vec3<double> C = c2w.col(3);
  const Mat3<double> R0 = pose.has_P0 ? Mat3<double>(pose.P0.leftCols<3>()) : Mat3<double>::Identity();
  const Vec3<double> t0 = pose.has_P0 ? Vec3<double>(pose.P0.col(3)) : Vec3<double>::Zero();
  Mat3<double> dE[3];
  so3::exp_derivative(pose.r, dE);
  Eigen::MatrixXd J(2 * o.lattice * o.lattice * o.disparities, 6);
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
        row += 2;
      }
  return J;
}

double max_rel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
}

const ImageSize kSize{64, 48};

}  // namespace

TEST_CASE("precondition: the projection Jacobian equals its closed form", "[precondition]") {
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
  HCC_TEST_PRINTF("precondition J vs closed form: identity %.2e, moved %.2e, θ→π with P0 %.2e "
                  "(tolerance 1e-7)\n", e_id, e_moved, e_back);
  CHECK(e_id < 1e-7);
  CHECK(e_moved < 1e-7);
  CHECK(e_back < 1e-7);
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
    const double e_white = (W - Mat6d::Identity()).cwiseAbs().maxCoeff();
    const double e_sym = (P - P.transpose()).cwiseAbs().maxCoeff() / P.cwiseAbs().maxCoeff();
    HCC_TEST_PRINTF("precondition λ %.1f: |P Σ' P / c² − I| %.2e, asymmetry %.2e, det P %.12f\n",
                    lambda, e_white, e_sym, P.determinant());
    CHECK(e_white < 1e-9);
    CHECK(e_sym < 1e-12);
    CHECK(P.determinant() == Approx(1.0).epsilon(1e-9));
    CHECK(Eigen::SelfAdjointEigenSolver<Mat6d>(P).eigenvalues().minCoeff() > 0);
  }
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
  const std::string out = test::tmp("run", true);
  TrainConfig c = test::tiny_train_config(data, out, 3);
  c.pose_precondition = 0.1;
  Trainer t(c);
  const int n = int(t.scene().train.size());
  REQUIRE(t.state().poses_P.size() == size_t(36) * n);
  const std::vector<float> before = t.state().poses;
  const double lr = t.lr_pose_at(0);
  t.step_once();
  const int cam = t.last_images()[0];
  int moved = 0;
  for (int i = 0; i < n; ++i) {
    Eigen::Matrix<double, 6, 1> d;
    for (int k = 0; k < 6; ++k) d(k) = double(t.state().poses[6 * i + k]) - before[6 * i + k];
    if (d.norm() == 0) continue;
    ++moved;
    CHECK(i == cam);
    Mat6d P;
    for (int r = 0; r < 6; ++r)
      for (int k = 0; k < 6; ++k) P(r, k) = t.state().poses_P[36 * i + 6 * r + k];
    Eigen::Matrix<double, 6, 1> g;
    for (int k = 0; k < 6; ++k) g(k) = t.last_camera_grads().d_pose[k];
    const Eigen::Matrix<double, 6, 1> dpsi = P.inverse() * d, Pg = P * g;
    for (int k = 0; k < 6; ++k) {
      CHECK(std::abs(Pg(k)) > 0);
      CHECK(dpsi(k) == Approx(-lr * (Pg(k) > 0 ? 1 : -1)).epsilon(1e-3));
    }
  }
  CHECK(moved == 1);
  // The same P after a resume (it is made from the starting cameras, not remade).
  t.run();
  Trainer r = Trainer::resume(out);
  CHECK(r.state().poses_P == t.state().poses_P);
  CHECK(r.config().pose_precondition == 0.1);
  // Off by default: no P, and the step is the plain Adam step.
  Trainer d(test::tiny_train_config(data, "", 3));
  CHECK(d.state().poses_P.empty());
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
  CHECK(test::cli({"train", "--data", data, "--out", test::tmp("bad", true), "--steps", "2",
                   "--pose-precondition", "-0.5"}) == 2);
}
