// model/golden_step.h — one fully specified training step from files (`hashcc step`).
//
// Every input is a file in one folder (format: docs/golden-step.md): config.json, the target
// image, the pixel grid (rows × cols), the sample positions s, the camera (pose_r, pose_t,
// focal_ab) and every network tensor under its ModelLayout name. Nothing random happens inside:
//
//   rows × cols ─ px (u = col, v = row), ray k = (rows[k / C], cols[k % C])
//   camera_step(px; r, t, a, b; s, target = image[row, col])       (model/camera_step.h, the
//     trainer's step) ─ p̃, p̃_c, depth, loss, dL/dθ, dL/dr, dL/dt, dL/da, dL/db
//
// The outputs (rgb_main, rgb_cc, depth, loss, grad.<X> for every parameter file X, plus the
// intermediates rays_o, rays_d, x) are written as float64 .npy whatever the precision T of the
// run, so another implementation can diff every number. Test: test/test_golden.cpp ("[golden]").
#pragma once
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "model/model.h"
#include "model/camera_step.h"

namespace hashcc {

// Everything in an input folder, in double (the file precision).
struct GoldenInputs {
  ModelConfig model;
  int H = 0, W = 0, S = 0;
  bool ndc = true;
  // fy = fx = a²W (config key "fx_only", default false): b is ignored and its gradient is 0.
  bool fx_only = false;
  // Optional file P0.npy (3, 4): the fixed initial world_from_camera of a test-pose camera,
  // c2w = [Exp(r) | t] · P0 (camera/camera.h, eval's --init-poses). Absent: identity.
  bool has_P0 = false;
  double P0[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};  // row-major 3×4
  std::vector<double> image;            // (H, W, 3)
  std::vector<int64_t> rows, cols;      // (R,), (C,)
  std::vector<double> s;                // (R·C, S)
  double pose_r[3] = {0, 0, 0}, pose_t[3] = {0, 0, 0}, focal_ab[2] = {1, 1};
  std::vector<double> params;           // the arena of make_layout(model), (out, in) tensors
  // Optional file cc_x.npy (R·C·S, 3): the detached CC input (CameraBatch::cc_x) instead of the
  // step's own samples x. Feeding back a run's x.npy holds the CC input fixed while the camera
  // is perturbed (formulas.md §5). Empty when absent.
  std::vector<double> cc_x;

  int R() const { return int(rows.size()); }
  int C() const { return int(cols.size()); }
  int rays() const { return R() * C(); }
};

// What one step produces, in double whatever precision it ran in.
struct GoldenOutputs {
  std::vector<double> rgb_main, rgb_cc, depth;  // (R·C, 3), (R·C, 3) (hashcc), (R·C,)
  std::vector<double> rays_o, rays_d, x;        // (R·C, 3) NDC rays, (R·C·S, 3) samples
  double loss = 0;
  std::vector<double> grad_params;              // same layout as GoldenInputs::params
  double grad_pose_r[3] = {0, 0, 0}, grad_pose_t[3] = {0, 0, 0}, grad_focal_ab[2] = {0, 0};
};

// The .npy files of the network tensors and their shapes, in file-name order of the layout
// (e.g. "trunk.0.weight" → (W, 63)), plus the camera's pose_r (3,), pose_t (3,), focal_ab (2,).
struct GoldenTensor {
  std::string name;
  std::vector<int64_t> shape;
  int64_t offset = -1;  // into params; -1 for the camera tensors
};
std::vector<GoldenTensor> golden_parameter_files(const ModelLayout& L);

// Reads and validates a folder. Any missing, ill-shaped or malformed file, an unknown .npy
// file, a bad config key or value → hashcc::Error naming the file and what was expected.
GoldenInputs read_golden_inputs(const std::string& dir);
// Writes a folder that read_golden_inputs accepts (config.json + all .npy, float64/int64).
void write_golden_inputs(const std::string& dir, const GoldenInputs& in);

// A random tiny instance for tests and worked examples: init_params (formulas.md §4–§5), the CC
// table and the grid field's table (field grid) scaled to ±cc_table_scale (the ±1e-4 init makes
// a hash grid invisible in a check), a pose
// near identity, focal near 1, R distinct rows × C distinct columns, jittered s_k ∈
// [(k+0.1)/S, (k+0.9)/S], and a smooth synthetic target image.
struct GoldenMakeOptions {
  int H = 16, W = 16, S = 8, R = 3, C = 3;
  bool ndc = true;
  bool fx_only = false;
  bool p0 = false;  // draw a P0: a rotation of up to 0.3 rad about a random axis, a centre within ±0.3
  uint64_t seed = 1;
  double cc_table_scale = 0.5;
};
GoldenInputs make_golden_inputs(const ModelConfig& cfg, const GoldenMakeOptions& opt);

// Runs the step in precision T (float as in training, double for the checks) with the default
// StepOptions. ws (optional): the workspace to use, so a test can inspect the last chunk's
// activations (ReLU pattern).
template <class T>
GoldenOutputs golden_step(const GoldenInputs& in, CameraStepWorkspace<T>* ws = nullptr);

// Writes rgb_main, rgb_cc (hashcc), depth, loss (shape ()), rays_o, rays_d, x and grad.<X> for
// every parameter file X, all float64.
void write_golden_outputs(const std::string& dir, const GoldenInputs& in, const GoldenOutputs& out);

// Config keys written and accepted (see docs/golden-step.md).
std::string golden_config_json(const GoldenInputs& in);

}  // namespace hashcc
