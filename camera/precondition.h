// camera/precondition.h — a preconditioner for one camera's pose (CamP, Park et al. 2023):
// the six pose parameters [r t] are learned as φ = φ0 + P ψ, Adam working on ψ.
//
// Why: at a forward-facing camera, turning about y and sliding along x move the image almost
// the same way (the bas-relief ambiguity), so the two parameters' gradients are nearly parallel
// and Adam, which scales each parameter alone, cannot tell "slide" from "orbit". P whitens the
// parameters by what they do to the image: with J the Jacobian of the projected pixel
// positions of points spread over the camera's frustum,
//     Σ = JᵀJ / N,   Σ' = Σ + λ·diag(Σ),   P = c · Σ'^(−1/2),   c = det(Σ')^(1/12)  (det P = 1),
// so a unit step of ψ along any direction moves the points equally (up to the damping λ),
// and the nearly-free "orbit" direction is no longer a thousand times slower than a turn.
// The gradient is dL/dψ = Pᵀ dL/dφ = P dL/dφ (P is symmetric) and Adam's step Δψ maps back to
// Δφ = P Δψ. c keeps the volume of a step: the user's --lr-pose keeps its meaning on average.
//
// The points: a G × G lattice of pixel centres times D disparities (k + ½)/D, k = 0 … D−1, in
// the camera frame (depth 1/disparity from the NDC near plane z = −1 to far away: the NDC box of
// a forward-facing scene, formulas.md §2), placed in the world by the camera's starting pose;
// J by central differences in double. Derivation and tests: docs/math/precondition.md,
// test/test_precondition.cpp ("[precondition]").
#pragma once
#include <Eigen/Core>
#include <vector>

#include "camera/camera.h"

namespace hashcc {

using Mat6d = Eigen::Matrix<double, 6, 6>;

struct PreconditionOptions {
  double damping = 0.1;  // λ
  int lattice = 8;       // G: pixels per image axis
  int disparities = 8;   // D
};

// The projected pixels' Jacobian at `pose`: J (2·G·G·D × (6 + m)), rows (u, v) of point after
// point, columns [r0 r1 r2 t0 t1 t2] (camera/camera.h's order) and, for focal_params m = 1 or 2,
// the focal's a (and b): the points stay where the starting focal put them, the focal moves
// their pixels (fx = a²W, fy = b²H, or fy = fx when focal.fx_only).
Eigen::MatrixXd pose_projection_jacobian(const PoseParams<double>& pose,
                                         const FocalParams<double>& focal, ImageSize size,
                                         const PreconditionOptions& opt, int focal_params = 0);

// The joint preconditioner of n cameras and m = 0, 1 or 2 shared focal parameters:
// Φ = [φ_1 … φ_n, a (, b)], Σ = Σ_i J_iᵀJ_i / N over each camera's own points (J_i with the
// columns φ_i and the focal's; the focal's block sums over every camera), D = 6n + m,
// P = c · (Σ + λ·diag Σ)^(−1/2), c = det(Σ')^(1/(2D)) (det P = 1). m = 0: block diagonal.
Eigen::MatrixXd camera_preconditioner(const std::vector<PoseParams<double>>& poses,
                                      const FocalParams<double>& focal, ImageSize size,
                                      int focal_params, const PreconditionOptions& opt);

// P = c · (Σ + λ·diag Σ)^(−1/2), det P = 1 (the header comment). Symmetric positive definite.
Mat6d pose_preconditioner(const PoseParams<double>& pose, const FocalParams<double>& focal,
                          ImageSize size, const PreconditionOptions& opt);

}  // namespace hashcc
