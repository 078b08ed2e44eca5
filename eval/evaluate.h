// eval/evaluate.h — the evaluation pipeline of formulas.md §7 on a trained run (`hashcc eval`).
//
//   Trainer (resumed run) ─┬─ learned train c2w vs reference ─ align_and_score (Sim(3) ΔR, ΔT)
//                          │                                  relative_rotation_error
//                          ├─ test cameras: P0 from the reference pose (test_pose_init)
//                          │    → refine_test_poses: Adam on [r t] deltas only, networks and
//                          │      focal frozen, one jittered grid step per image per epoch
//                          └─ render_view (no jitter) → PSNR, SSIM, LPIPS vs ground truth
//   A scene without reference cameras: the training views are rendered with their learned
//   poses and scored instead (reconstruction only, no pose error).
//
// What is computed, exactly, and why: docs/evaluation.md. Tests: test/test_evaluate.cpp
// ("[evalcmd]"). Everything here reads the trainer; nothing writes to it.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "eval/metrics.h"
#include "eval/pose_eval.h"
#include "train/trainer.h"

namespace hashcc {

// How a test camera's fixed initial pose P0 is obtained from its reference pose.
enum class TestInit {
  kScale,  // formulas.md §7 and NeRF--'s eval.py: reference rotation as is, reference centre × ratio of
           // max distances from the first train camera (learned / reference)
  kSim3,   // the inverse of the train-camera Sim(3) (learned → reference) applied to the pose
  kRig,    // the same with the rotation-first similarity (Alignment::kRotations): a rig whose
           // centres are off in depth does not tilt the test cameras' start (issue 49)
};
TestInit parse_test_init(const std::string& s);  // "scale" | "sim3" | "rig", else hashcc::Error
const char* test_init_name(TestInit t);

// How the test poses are refined (docs/evaluation.md §3).
enum class RefineMode {
  kAdam,  // formulas.md §7: Adam at NeRF--'s schedule, one step of the run's ray grid (32 × 32)
          // per test image per epoch; the metric the spec defines
  kFast,  // the default (session 27): the same Adam, schedule and epochs, all test views in one
          // step: the run's grid for the first kFastRefineFullEpochs epochs, then kFastRefineRays
          // rays a view a step; a view still moving at the end is refined again as kAdam
};
RefineMode parse_refine_mode(const std::string& s);  // "adam" | "fast", else hashcc::Error
const char* refine_mode_name(RefineMode m);
inline constexpr int kFastRefineRays = 128;
inline constexpr int kFastRefineFullEpochs = 200;  // fast mode: epochs on the run's grid first
// Fast mode: the poses returned come from the iterates of the schedule's last two lr levels that
// follow the full-grid epochs (epochs 600–999 of 1,000; none for ≤ 200 epochs): their mean, or
// for a camera still travelling their trend line at the last epoch.
int fast_refine_average_from(int epochs);

// The fast mode's answer for view k from its iterates it[a … E − 1] (RefineResult::epoch_deltas
// rows, 6 a view): with fewer rays a step a settled camera jitters about its optimum, and the mean
// of the window is nearer to it than the last iterate (Polyak–Ruppert averaging); a camera still
// travelling would be left behind by the mean (by half its travel over the window), so there the
// answer is the least-squares line through the iterates, read at the last epoch. Which one: the
// means of the window's two halves are compared with the iterates' scatter about that line (the
// distance |Δr| + |Δt|): a shift of more than kTrendOverJitter times the scatter is a trend.
// Measured on eight runs (docs/evaluation.md §3): settled cameras below 1.4×, travelling ones 2×
// and more.
inline constexpr double kTrendOverJitter = 1.5;
struct WindowEstimate {
  float p[6];     // [r t]
  bool averaged;  // the mean (true) or the trend line at the last epoch (false)
};
WindowEstimate refine_window_estimate(const std::vector<std::vector<float>>& it, int a, int k);

struct EvalOptions {
  int refine_epochs = 100;         // spec: 1,000 (a CPU budget runs fewer, stated in the report)
  RefineMode refine_mode = RefineMode::kFast;  // docs/evaluation.md §3; kAdam: the spec's
  int refine_rays = 0;             // rays a view a step (0: the mode's: the run's grid, or 128)
  std::string lpips_weights;       // folder of LPIPS-VGG .npy weights; "" = not computed
  TestInit test_init = TestInit::kScale;
  bool progress = true;
};

// Learned training cameras (double, OpenGL c2w [Exp(r) | t]) in scene().train order, and the
// reference cameras of the same images (scene().ref_c2w, formulas.md §7 converted/centred/scaled).
std::vector<Pose34> learned_train_c2w(const Trainer& tr);
std::vector<Pose34> reference_c2w(const Scene& sc, const std::vector<int>& images);

// Pose error of the training cameras (formulas.md §7). Either part may be missing (nullopt) with the
// reason in note: no reference cameras, or a degenerate alignment (coincident/collinear centres,
// common early in training), which align_and_score rejects instead of returning noise.
struct TrainPoseReport {
  bool has_reference = false;
  std::optional<PoseErrors> sim3;
  std::optional<PoseErrors> rig;  // Alignment::kRotations: the rotations' own error
  std::optional<RelativeRotationError> relative;
  std::string note;  // "" when both are present
  double fx = 0, fy = 0, ref_focal = 0;  // learned fx, fy and the reference (0 when none), pixels
};
TrainPoseReport train_pose_report(const Trainer& tr);

// formulas.md §7 translation ratio: max over train cameras of ‖c_i − c_0‖ (c_0 = the first train camera)
// on the learned centres divided by the same on the reference centres (NeRF--'s pts_dist_max).
double learned_to_reference_distance_ratio(const Trainer& tr);

// Fixed initial poses P0 of the test cameras (scene().test order) in the learned world frame.
// kSim3 and kRig need `sim` (learned → reference, from the train cameras); kScale ignores it.
std::vector<Pose34> test_pose_init(const Trainer& tr, TestInit mode, const Sim3* sim);
// The same as the refinement's starting cameras: each P0 with zero deltas (c2w = [Exp(0)|0]·P0).
std::vector<PoseParams<float>> test_pose_params(const Trainer& tr, TestInit mode, const Sim3* sim);

// formulas.md §7 refinement learning rate at an epoch: 1e-3 halved every 200 epochs with the first
// halving at epoch 0, i.e. 1e-3 · 0.5^(1 + floor(epoch / 200)) (5e-4 for epochs 0–199; the
// PyTorch MultiStepLR(milestones = 0, 200, …) NeRF-- uses).
double refine_lr(int epoch);

struct RefineOptions {
  int epochs = 100;
  int rows = 0, cols = 0;    // each view's ray grid a step; 0: the run's (grid_rows × grid_cols)
  bool batched = true;       // all test views in one camera_step (the one-step-a-view numbers up
                             // to float rounding, when each view's rays are whole chunks); the
                             // spec's mode (refine_options, RefineMode::kAdam) turns it off
  bool split_chunks = false; // fast mode: halve the chunk until every thread has one
  int full_epochs = 0;       // the first this many epochs on the run's grid, then rows × cols
  int average_from = -1;     // ≥ 0: each pose from its iterates of epochs average_from … epochs − 1:
                             // their mean, or, for a camera still travelling, their least-squares
                             // line read at the last epoch (refine_window_estimate); −1: the last iterate
  bool progress = false;
  // Which views to refine (empty: all). The others take no step of their own: their epochs are
  // zero-gradient Adam steps of the one group, as they are in a run over all views, so the views
  // refined get the values a run over all of them gives, bit for bit (the spec's one step a view;
  // ray draws are per (epoch, view)). Their poses come back unchanged. Not with `batched`.
  std::vector<bool> views;
};

struct RefineResult {
  std::vector<PoseParams<float>> poses;  // per test image: P0 fixed, r, t the refined deltas
  std::vector<double> epoch_loss;        // mean training-style loss of each epoch
  std::vector<std::vector<float>> epoch_deltas;  // after each epoch: [r t] of every image (6n)
  int epochs = 0;
  double seconds = 0;                    // wall time of the refinement
  int rays_per_view = 0;                 // rays of each view a step (after full_epochs)
  int full_epochs = 0;                   // epochs on the run's grid first
  int average_from = -1;                 // the poses: from the epochs from this one (−1: the last)
  std::vector<bool> averaged;            // per view (with average_from): the window's mean (true)
                                         // or its trend line at the last epoch (false)
  bool batched = false;                  // all views in one step
};
// Refines the deltas [r t] of `init` (each with has_P0 and r = t = 0 normally) on the images
// scene().images[images[k]]: Adam (β 0.9/0.999, ε 1e-8, one group over all test poses, PyTorch
// semantics), lr refine_lr(epoch), per epoch one jittered rows × cols grid step per image (the
// run's grid and sample count; 32×32, 128 by default), loss and gradient exactly as a training
// step (model/step.h) with d_params = nullptr: networks and focal are read, never written.
// Deterministic in (run seed, epoch, image).
RefineResult refine_test_poses(const Trainer& tr, std::vector<PoseParams<float>> init,
                               const std::vector<int>& images, int epochs, bool progress = false);
RefineResult refine_test_poses(const Trainer& tr, std::vector<PoseParams<float>> init,
                               const std::vector<int>& images, const RefineOptions& ro);
// The same with the target images given directly (tests: targets rendered by the model itself).
RefineResult refine_poses(const Trainer& tr, std::vector<PoseParams<float>> init,
                          const std::vector<const ImageU8*>& targets, int epochs,
                          bool progress = false);
RefineResult refine_poses(const Trainer& tr, std::vector<PoseParams<float>> init,
                          const std::vector<const ImageU8*>& targets, const RefineOptions& ro);
// The refinement settings of an eval: the mode's rays (the run's grid, or kFastRefineRays),
// batched, and in fast mode split chunks.
RefineOptions refine_options(const Trainer& tr, const EvalOptions& opt);

struct EvalImage {
  std::string name;    // image file stem (outputs are <name>.png)
  int scene_index = 0;
  double psnr = 0, ssim = 0;
  std::optional<double> lpips;
  double refine_rot_deg = 0, refine_trans = 0;  // how far refinement moved the camera from P0
  ImageF render, gt;   // (H, W, 3) in [0,1]; the render is clamped to [0,1] before scoring
};

struct EvalResult {
  bool test_views = true;       // false: no reference cameras, training views were scored
  std::string mode_note;        // one line saying what was evaluated
  TestInit test_init = TestInit::kScale;
  double distance_ratio = 0;    // learned_to_reference_distance_ratio (kScale), else 0
  TrainPoseReport pose;
  int refine_epochs = 0;
  RefineMode refine_mode = RefineMode::kAdam;
  int refine_rays = 0;          // rays of each view a refinement step
  int refine_full_epochs = 0;   // fast mode: the first epochs on the run's grid
  int refine_average_from = -1; // fast mode: the poses come from the epochs from this one …
  std::vector<bool> refine_averaged;  // … per test view: their mean (true), or, still moving,
                                      // refined again in the spec's mode, whose pose it keeps (false)
  double refine_seconds = 0, render_seconds = 0;  // wall time of the refinement, of the renders
  std::vector<double> refine_loss;
  std::vector<std::vector<float>> refine_deltas;  // RefineResult::epoch_deltas (refine.csv)
  std::vector<EvalImage> images;
  double psnr = 0, ssim = 0;    // means over images
  std::optional<double> lpips;  // mean, or nullopt with the reason in lpips_note
  std::string lpips_note;
  double seconds = 0;
};

// The whole pipeline. Bad options (missing LPIPS folder, negative epochs) → hashcc::Error.
EvalResult evaluate(const Trainer& tr, const EvalOptions& opt);

// metrics.json content (keys in docs/evaluation.md; non-finite numbers become null).
std::string eval_metrics_json(const EvalResult& r);
// Writes DIR/metrics.json, DIR/renders/<name>.png, DIR/gt/<name>.png, DIR/error/<name>.png and
// DIR/contact_sheet.png (one row per image: render | ground truth | error heat-map).
void write_eval_outputs(const EvalResult& r, const std::string& dir);
// The human-readable summary `hashcc eval` prints.
std::string eval_summary(const EvalResult& r);

}  // namespace hashcc
