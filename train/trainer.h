// train/trainer.h — the NeRF-- / HashCC training loop (formulas.md §6), fixed and readable.
//
// One step:
//   1. the next training image of the epoch (each epoch visits every training image once,
//      shuffled) and a grid of 32 random distinct rows × 32 random distinct columns;
//      (--images-per-step K: the next K images, a smaller grid on each; --pyramid F: early
//      steps draw their rows and columns from a coarse lattice of filtered colours)
//   2. 128 jittered samples per ray
//   3. camera_step (model/camera_step.h): pixels → rays (o, d) → NDC [r, t of each image; a, b]
//      → the model, the compositor, the loss → backward: networks (+=), then dL/do', dL/dd'
//      → camera backward → dL/dr, dL/dt per image, dL/da, dL/db
//   4. divergence guard (nothing non-finite reaches the parameters; an empty field, whose
//      gradient is all zero, is restored too), then Adam on three groups
//      — networks, poses, focal — each with its own exponentially decaying learning rate.
// Randomness comes from streams keyed by (seed, step), so a run is reproducible step for step
// and a resumed run continues exactly where it stopped.
#pragma once
#include <array>
#include <atomic>
#include <functional>
#include <memory>
#include <cstdint>
#include <string>
#include <vector>

#include "camera/camera.h"
#include "core/llff.h"
#include "model/model.h"
#include "train/pyramid.h"
#include "model/camera_step.h"
#include "model/render_view.h"
#include "render/occupancy.h"
#include <optional>

namespace hashcc {

struct TrainConfig {
  std::string data;             // scene folder
  std::string images_folder;    // "" = the smallest present
  // --max-side N: the working resolution, images downscaled (area filter) so that their longer
  // side is at most N, the focal scaled with them; 0 = the files' size. Default 504: LLFF's
  // images_8 width, the size every recipe and result here was measured at, and exactly a 12 MP
  // phone photo (4032x3024) at factor 8. images_8 and the simulated scenes (≤ 504) are not
  // touched. A config.json without the key (runs before it) means 0: they trained full size.
  int max_side = 504;
  std::string out;              // run folder
  ModelConfig model;
  bool ndc = true;              // forward-facing scenes: on (formulas.md §2)
  bool fx_only = false;         // tie fy to fx
  // --ndc-fixed-focal: draw the NDC box with the focal the stage starts from, held, instead of the
  // learned one (camera.h's NdcWarp): the focal then learns from the rays' directions alone.
  bool ndc_fixed_focal = false;
  // --ndc-box-scale S (with --ndc-fixed-focal): the held box is drawn with S x that focal; S < 1
  // widens it, leaving room for the side views' edge rays (docs/training.md, "The NDC box's focal").
  double ndc_box_scale = 1;
  bool stop_cc_to_camera = false;  // ablation (formulas.md §5/§6)
  // --init-poses: approximate cameras (COLMAP text model, poses_bounds.npy, cameras.json; see
  // core/camera_models.h) become each training image's fixed P0, c2w = [Exp(r)|t]·P0, with the
  // learned deltas r = t = 0 at start. "" = camera-less (formulas.md §1), unchanged.
  std::string init_poses;
  bool init_focal = true;          // --init-focal model|none: a = sqrt(fx/W), b = sqrt(fy/H)
  bool refine_poses = true;        // --refine-poses off: the cameras given (--init-poses, or
                                   // --cameras-from, e.g. a bootstrap's phase 1) are held: no Adam
                                   // update of the poses, nor of the focal when it came with them
                                   // (classical NeRF); held both, no ray gradient is computed
  int64_t epochs = 0, steps = 0;   // length; 0 = unset
  double minutes = 0;              // time budget; 0 = unset (then epochs, default 10,000)
  int threads = 0;                 // 0 = all
  uint64_t seed = 0;
  int rays = 1024;                 // per step, as a rows × cols grid (32 × 32)
  int samples = 128;
  int chunk_rays = 0;               // rays per chunk; 0 = auto, ≤ 24 MiB a chunk (model/step.h)
  double lr_net = 1e-3, lr_net_end = 1e-5;
  double lr_pose = 1e-3, lr_pose_end = 1e-8;
  double lr_focal = 1e-3, lr_focal_end = 1e-8;
  // Options beyond the paper, all off by default:
  double c2f_end = 0;              // coarse-to-fine γ(x): α rises 0 → L over this fraction of
                                   // the run (0 = off)
  double camera_delay = 0;         // cameras frozen for this fraction of the run, then learn with
                                   // their schedule compressed into the rest (0 = off)
  int images_per_step = 1;         // K: the step's rays come from K distinct training images, a
                                   // step_rows() × step_cols() grid on each (1 = the paper);
                                   // 0 = auto (the grid field's default): the scene's load sets
                                   // it to auto_images_per_step, min(4, training images)
  double pyramid = 0;              // image pyramid over this fraction of the run: level 4 for the
                                   // first half of it, level 2 for the second (train/pyramid.h;
                                   // 0 = off)
  double camera_start_psnr = 0;    // cameras frozen until the running train PSNR (dB) reaches
                                   // this; their schedule then runs from that step (0 = off)
  int64_t camera_warmup = 0;       // camera lr ramps linearly up to its schedule over this many
                                   // steps from the cameras' start (0 = off)
  // --focal FX[,FY]: a known focal (pixels at the training resolution) to start from instead of
  // fx = W, fy = H (0 = unset); --fixed-focal keeps the starting focal for the whole run.
  double focal_fx = 0, focal_fy = 0;
  bool fixed_focal = false;
  // --focal-fov DEG: start from the focal of this horizontal field of view, fx = fy =
  // W / (2 tan(DEG/2)) (square pixels), instead of the paper's fx = W, fy = H (0 = the paper's).
  // The paper's start is 53° wide and anisotropic (fy/fx = H/W): on LLFF horns its fy fell to 37%
  // of the truth while fx held (issue 49). A phone's main camera is 63–72° wide (26–28 mm
  // equivalent, 4:3); --focal and a focal from --init-poses or --cameras-from take precedence.
  double focal_fov = 0;
  // --focal-guard G: a focal that leaves [start/G, start·G], or whose fx/fy leaves its start
  // ratio by more than √G, is put back to the focal it started from and held there for the rest
  // of the run (a stage of a plan: the next stage learns it again). Never silently kept: horns'
  // fy fell to 0.41× its start in five minutes and took the cameras with it (issue 49). 0 = off.
  double focal_guard = 2.0;
  double focal_delay = 0;          // the focal alone frozen for this fraction of the run, then
                                   // its schedule compressed into the rest (0 = off)
  // --pose-precondition λ: each camera's [r t] learned as φ0 + P ψ, Adam on ψ, P the CamP
  // preconditioner of its starting camera with damping λ (camera/precondition.h; 0 = off).
  double pose_precondition = 0;
  // --cameras-from RUN: start from the cameras (poses, focal) an earlier run of the same scene
  // learned, read from RUN's checkpoint; the networks start fresh. "" = off.
  std::string cameras_from;
  // --bootstrap-minutes M (paper's MLP field only): the first M minutes learn the cameras with
  // the grid field (RUN/bootstrap/), then the MLP trains from them for the rest (train_bootstrapped).
  double bootstrap_minutes = 0;
  int64_t bootstrap_steps = 0;     // the same by step count (tests; deterministic)
  // --bootstrap-lr-pose: the camera rate of the bootstrap's phase 1 (0 = the grid field's 1e-3).
  // Its own flag because --lr-pose is phase 2's (the paper's network refining the cameras).
  double bootstrap_lr_pose = 0;
  // --restarts K (the grid field, or the grid phase of a bootstrap): the budget is cut into K + 1
  // equal stages; each stage after the first is a fresh grid field on the cameras the stage
  // before it ended with, all levels on (grid_restarts). 0 = one stage, the plain run.
  int restarts = 0;
  // --restart-first F, --restart-last L: stage 1's and the last stage's shares of that budget
  // (0 = an equal share, 1/(K+1)); the stages between split the rest equally. A long first stage
  // takes the cameras from identity to the family's plateau; short middle ones each take the
  // first ~1,000 steps of a fresh field, where most of a restart's gain comes; a long last one
  // grows the field the run ends with (fern, docs/results/grid).
  double restart_first = 0;
  double restart_last = 0;
  // --restart-steps N: the stages between run N steps each, whatever their time; stage 1 takes
  // its share (--restart-first, else 1/(K+1)) and the last stage what is left of the budget. A
  // restart's worth is its steps (~1,000 on fern), which a share of minutes gives only on a quiet
  // machine. Not with --restart-last (the last stage's share is the rest).
  int64_t restart_steps = 0;
  // --first-focal-hold F (with --restarts): stage 1 holds the focal for its first fraction F
  // (--focal-delay F in stage 1 alone; the stages after learn it from their start as before).
  // From identity the young field pulls the focal from 504 / 378 to ~300 / ~220 on fern in 1,000
  // steps and the restarts spend the hour climbing back; held through the grid's coarse-to-fine
  // ramp (F = 0.5), stage 1 ends with worse poses but the focal near the truth, and the restarts
  // mend the poses (docs/results/grid).
  double first_focal_hold = 0;
  // --last-focal-hold F: the last stage of --restarts learns one focal for both axes (fy tied to
  // fx, started at the fx learned so far) and holds it for its first fraction F. A young field
  // pulls the focal down for its first ~500 steps (fern: −5…−28% even from the truth); held
  // through them, on cameras the restarts have brought near, it climbs towards the truth
  // (docs/results/grid). The short restarts leave fy at the young field's level; the tie mends it.
  double last_focal_hold = 0;
  // --last-focal-stages N (with --last-focal-hold): the last N stages each learn one focal, held
  // for their first fraction F, not only the last. Each held stage lifts the focal a step (fern:
  // ~+15–25 px a stage from 6–10% low), so N = 2 ends nearer the truth than one longer stage.
  int last_focal_stages = 1;
  // --last-grid-log2-table N, --last-samples S (with --restarts): the last stage's fresh field
  // gets a larger hash table and/or more samples a ray (0 = as the stages before). The cameras
  // are learned by the cheap stages; the field the run ends with, the one that renders, is grown
  // once, in the last stage. On fern a 2^17 table renders better than 2^15 but its stages learn
  // worse cameras and take 1.6x longer a step (docs/results/grid).
  int last_grid_log2_table = 0;
  int last_samples = 0;
  // --last-lr-net A, --last-lr-net-end B (with --restarts): the last stage's field learns at A
  // decaying to B (0 = as --lr-net / --lr-net-end). On fern's reference cameras a 2^17 field
  // renders 0.25 dB better at 2e-2 → 1e-3 than at the grid default 1e-2 → 1e-4, while a camera
  // stage at that rate ends ~0.5° worse (docs/results/grid): the render's rate, in the last
  // stage only.
  double last_lr_net = 0;
  double last_lr_net_end = 0;
  // --last-lr-focal-end B (with --restarts): the last stage's focal decays from --lr-focal to B
  // (0 = as --lr-focal-end). On fern the last stage's focal is still climbing towards the truth
  // when its run ends, but not held back by its rate: flat at 1e-3 it ended 2.6 px higher and
  // rendered the same (docs/results/grid).
  double last_lr_focal_end = 0;
  // --last-lr-pose-end B (with --restarts): the last stage's poses decay from --lr-pose to B
  // (0 = as --lr-pose-end). Adam moves every pose ~ its rate a step whatever the gradient's noise,
  // so at the end of a stage the cameras wander by about the rate times √steps; the field the run
  // ends with is fitted to cameras that still move.
  double last_lr_pose_end = 0;
  // --grid-decay λ (grid field): adds λ Σ_levels mean(θ²) of the grid's table to every step's loss
  // (hashgrid_decay; Zip-NeRF's normalised weight decay), a regulariser for the views between the
  // training views. 0 = off, and costs nothing.
  double grid_decay = 0;
  // --distortion λ (either field): adds λ · mean over rays of mip-NeRF 360's distortion loss on the
  // main field's compositing weights (render/distortion.h), against floaters in front of the
  // surface that only held-out views see. 0 = off, and costs nothing.
  double distortion = 0;
  // --last-distortion λ (with --restarts, --field grid): the last stage's field alone gets
  // --distortion λ (0 = as --distortion). On fern the loss helps the field that renders (+0.18 dB
  // on the reference cameras); when it still reached the cameras, it cost stage 1's cameras
  // (3.1° against 2.6° at step 7,000) and the last stage's (0.65° → 1.19°).
  double last_distortion = 0;
  // --distortion-from F: the distortion loss starts at fraction F of the run's planned steps
  // (0 = from the start). --hold-cameras-from F: from fraction F on, the cameras (poses and
  // focal) are held, and the step computes no camera gradient (0 = never). Together they give
  // the loss to the field alone once the cameras have settled: on fern, a detached loss on a
  // field whose cameras still learn moved them off all the same (0.73° → 1.25° in 1,700 steps),
  // as a sharper field gives the colour loss a rougher camera gradient. --last-distortion-from /
  // --last-hold-cameras-from (with --restarts): the same for the last stage alone.
  // F is of planned_total(), as the schedules are: a --minutes run plans it early, refines it
  // once at 10% of its budget, and extends it only at its end (then F of the new total stays
  // behind the step unless the plan grew by 1/F).
  double distortion_from = 0, hold_cameras_from = 0;
  double last_distortion_from = 0, last_hold_cameras_from = 0;
  // --distortion-to-camera (ablation): the distortion loss's gradient reaches the cameras too
  // (before 2026-11-26 10:00 UTC it always did: the runs in docs/results/grid that measured it).
  bool distortion_to_camera = false;
  // --occupancy on: the samples go only where an occupancy grid of the field's density says
  // something is (render/occupancy.h); --samples then counts those samples. Needs NDC.
  bool occupancy = false;
  double occupancy_start = 0.1;    // the first fraction of the run samples uniformly
  int occupancy_every = 16;        // steps between updates (each re-measures 1/8 of the cells)
  int occupancy_res = 64;          // cells per axis over the NDC box
  int occupancy_probes = 128;      // probe intervals per ray
  std::string preset = "paper";    // --preset / --plan: the built-in recipe the run came from
                                   // ("paper": none; recorded in config.json)
  double checkpoint_minutes = 2;   // checkpoint interval
  double preview_minutes = 2;      // preview render interval
  bool progress = true;
  int grid_rows() const;           // rays → rows × cols: the one-image grid (the paper's step,
  int grid_cols() const;           // and hashcc eval's test-pose refinement)
  // The grid on each of a training step's K images: the same rule applied to rays / K, so the
  // step has K · step_rows() · step_cols() rays (equal to the grid above when K = 1).
  int step_rows() const;
  int step_cols() const;
  // --refine-poses off with cameras to hold (--init-poses or --cameras-from): the poses do not learn.
  bool holds_given_poses() const {
    return (!init_poses.empty() || !cameras_from.empty()) && !refine_poses;
  }
};

// One Adam parameter group: its values and the two moments (the same length), and the name its
// three tensors carry in the checkpoint (name, name.m, name.v). A view into TrainState.
struct AdamGroup {
  const char* name;
  std::vector<float>& value;
  std::vector<float>& m;
  std::vector<float>& v;
};

// Everything a checkpoint holds.
struct TrainState {
  int64_t step = 0;                // steps completed
  int64_t planned_steps = 0;       // schedule length (0 until planned in --minutes mode)
  bool plan_refined = false;       // --minutes: the plan was refined once, at 10% of the budget
  double elapsed = 0;              // training seconds so far (across resumes)
  double lr_scale = 1;             // networks' lr multiplier (halved by the divergence guard)
  int diverged = 0;                // times the guard fired
  double psnr_ema = 0;             // running train PSNR of p̃ (EMA, factor kPsnrEma), dB
  int64_t camera_start = -1;       // --camera-start-psnr: first step whose cameras learn
                                   // (−1 = not reached yet)
  int64_t focal_guarded = -1;      // --focal-guard: the step it fired at (−1 = not fired); the
                                   // focal is held from then on
  std::array<float, 2> focal_start = {1.f, 1.f};  // the focal (a, b) the run started from
  std::vector<float> net, net_m, net_v;
  std::vector<float> poses, poses_m, poses_v;  // (n_train, 6): r, t per training image
  std::vector<float> poses_P0;                 // (n_train, 12): fixed initial 3×4 c2w, row-major;
                                               // empty without --init-poses (checkpoint "poses.P0")
  std::vector<float> focal, focal_m, focal_v;  // (2): a, b
  // --pose-precondition: the joint P (D × D, row-major, D = 6·n_train + m, m = the focal's
  // learned parameters: 2, 1 with --fx-only, 0 when it is fixed), made from the starting cameras
  // and kept for the run (checkpoint "cameras.P"); poses_m/v and focal_m/v are then Adam's
  // moments of ψ. Empty when off.
  std::vector<float> cameras_P;
  // The Adam groups, in update order: networks, poses, focal.
  std::array<AdamGroup, 3> groups() {
    return {{{"net", net, net_m, net_v}, {"poses", poses, poses_m, poses_v},
             {"focal", focal, focal_m, focal_v}}};
  }
};

class Trainer {
 public:
  // New run: loads the scene, initialises the model and cameras, writes config.json.
  explicit Trainer(const TrainConfig& cfg);
  // Open a finished or interrupted run read-only: reads RUN/config.json and RUN/checkpoint.bin
  // and writes nothing, so eval, render, export and --cameras-from may read a run that another
  // process is training or reading. data_override (non-empty): load the scene from this folder
  // instead of the one in config.json (a moved dataset; `hashcc eval --data`).
  static Trainer open(const std::string& run_dir, double minutes_override = -1,
                      const std::string& data_override = "");
  // Resume training (`hashcc train --resume`): open(), then drop the log.csv rows written after
  // the checkpoint's step, so the continued run's log has each step once.
  static Trainer resume(const std::string& run_dir, double minutes_override = -1,
                        const std::string& data_override = "");

  // Trains until the plan is done, the time budget is spent, or *stop becomes true (SIGINT).
  // Returns true when the run completed, false when it was interrupted (checkpoint written).
  // after_step (optional) sees the trainer after every step: how the CLI records the camera
  // error curve (eval/camera_curve.h) without the training loop depending on eval/.
  bool run(const std::atomic<bool>* stop = nullptr,
           const std::function<void(const Trainer&)>& after_step = {});

  // One step at the current state (exposed for tests and the bench). Returns the loss.
  // Allocates nothing after the first steps (buffers are members, grown once).
  StepResult<float> step_once();

  // Optional per-stage profiler (hashcc bench): step_once adds each stage's time to *p.
  // nullptr (the default) switches it off at no cost.
  void set_stage_times(StageTimes* p) { prof_ = p; ws_.rays.chunk.cache.prof = p; }

  const TrainConfig& config() const { return cfg_; }
  // --occupancy on: the grid renders and test-pose refinement sample with (this process's
  // training grid, or measured whole from the field on first use); null when off.
  const OccupancyGrid* render_occupancy() const;
  const TrainState& state() const { return st_; }
  TrainState& mutable_state() { return st_; }
  const Scene& scene() const { return *scene_; }
  const ModelLayout& layout() const { return layout_; }
  PoseParams<float> pose_of(int train_index) const;
  FocalParams<float> focal() const;
  // The networks as they are now, and a camera of this scene (the learned focal) at `pose`:
  // what render_view takes.
  NetView<float> net() const { return {st_.net.data(), cfg_.model, layout_}; }
  ViewCamera view_camera(const PoseParams<float>& pose) const {
    return {pose, focal(), image_size(), ndc_warp()};
  }
  // NDC on or off, and the focal its box is drawn with: the learned one, or (--ndc-fixed-focal)
  // the focal this stage started from, held (camera.h's NdcWarp; docs/training.md).
  NdcWarp ndc_warp() const;
  ImageSize image_size() const { return {scene_->width, scene_->height}; }

  void save_checkpoint_now();
  void write_cameras_json() const;
  void write_preview(const std::string& path);
  int64_t planned_total() const;
  bool poses_frozen() const;   // --refine-poses off (with --init-poses or --cameras-from)
  bool focal_frozen() const;   // --refine-poses off with the focal from the model
  // Whether the cameras are held at step `step`: frozen (--refine-poses off, both poses and
  // focal) or past --hold-cameras-from. Held cameras get no gradient and no update.
  bool cameras_held_at(int64_t step) const;
  double distortion_at(int64_t step) const;  // --distortion's λ at `step` (0 before --distortion-from)
  // What --init-poses found (matching, scale, ignored terms): printed by the CLI.
  const std::vector<std::string>& init_report() const { return init_report_; }
  // Where the starting focal came from ("--focal", "exif 26 mm (35 mm equivalent)", "fov
  // prior 65 deg", …): written into config.json as "focal_source".
  const std::string& focal_source() const { return focal_source_; }

  // Learning rates at a step of the plan (exponential decay over planned_total()).
  double lr_net_at(int64_t step) const;
  double lr_pose_at(int64_t step) const;
  double lr_focal_at(int64_t step) const;
  // The first step at which the cameras learn: 0, ⌊camera_delay · total⌋, or (with
  // --camera-start-psnr) TrainState::camera_start, −1 while the PSNR has not been reached.
  int64_t camera_start_step() const;
  // Steps per epoch: ⌈n_train / K⌉ (every training image at least once; see images_for_step).
  int64_t steps_per_epoch() const;
  // --pyramid: the level (4, 2 or 1 = full resolution) a step trains on.
  int pyramid_level_at(int64_t step) const;
  // The K distinct training images of a step (indices into scene().train), in ray order.
  void images_for_step(int64_t step, int* out) const;

  // The last step's K images (indices into scene().train, in the order of the step's rays) and
  // the camera gradients Adam received: d_pose (K, 6) = dL/d[r t] of image j of the step's mean
  // loss over all its rays, d_focal = dL/d[a b]. Read-only, for tests.
  const std::vector<int>& last_images() const { return step_images_; }
  const CameraStepGrads<float>& last_camera_grads() const { return grads_; }
  // The last step's rays (for tests; views into the trainer's buffers, valid until the next
  // step): R rays, full-resolution pixels px (R, 2) = [u v …], target colours (R, 3), jittered
  // samples s (R, S). Image last_images()[j] owns rays [j·R/K, (j+1)·R/K).
  struct StepRays {
    int R = 0;
    const int* px = nullptr;
    const float* target = nullptr;
    const float* s = nullptr;
  };
  StepRays last_rays() const { return {last_R_, px_.data(), target_.data(), s_.data()}; }
  // EMA factor of TrainState::psnr_ema: psnr_ema ← 0.9·psnr_ema + 0.1·PSNR(step), starting at
  // the first step's PSNR (a memory of ~10 steps: smooths the per-image spread of the PSNR).
  static constexpr double kPsnrEma = 0.9;

 private:
  Trainer() = default;
  void setup_buffers();
  void load_scene_and_layout();
  bool apply_update(const StepResult<float>& r, const CameraStepGrads<float>& g);
  // apply_update's parts: one Adam group's gradient, rate and whether it learns this step.
  struct GroupStep {
    const float* grad;
    double lr;
    bool learns;
  };
  void scatter_pose_grads(const CameraStepGrads<float>& g);          // → d_poses_
  const char* bad_step(const StepResult<float>& r, const GroupStep* steps);  // nullptr: fine
  void restore_good_state(const char* what);                         // the divergence guard
  void adam_on_groups(const GroupStep* steps, const float* d_focal);
  void track_psnr(const StepResult<float>& r);                       // psnr_ema, camera_start
  void guard_focal();                                                // --focal-guard
  void build_pyramid();

  TrainConfig cfg_;
  TrainState st_;
  // Shared with the scene cache (load_scene_cached) and with the runs a stage opens
  // (--cameras-from): the photos are held once, not once per holder.
  std::shared_ptr<const Scene> scene_;
  ModelLayout layout_;
  CameraStepWorkspace<float> ws_;
  std::vector<float> d_net_;
  CameraStepGrads<float> grads_;  // the step's camera gradients (grads_.d_params = d_net_)
  std::vector<int> px_;
  std::vector<float> s_, target_;
  std::vector<PoseParams<float>> step_poses_;  // (K) the step's poses
  // Per-step scratch kept across steps so a step never allocates.
  mutable std::vector<int> perm_;
  std::vector<int> rsel_, csel_, step_images_;
  int last_R_ = 0;
  std::vector<float> d_poses_;
  // --pyramid: levels 2 and 4 of each training image (pyr2_[i], pyr4_[i]; empty when off).
  std::vector<PyramidLevel> pyr2_, pyr4_;
  StageTimes* prof_ = nullptr;
  // --occupancy on: the grid (made at the first step that samples with it; a resumed run
  // re-measures it whole there) and the model activations of its density queries.
  // Mutable: a run resumed to be rendered or evaluated measures it on first use (render_occupancy).
  mutable std::optional<OccupancyGrid> occ_;
  mutable ModelCache<float> occ_cache_;
  const OccupancyGrid* occupancy_for_step();
  void measure_occupancy(uint64_t seed) const;  // occ_ made and measured whole
  DensityFn density_fn() const;                  // σ of the current field (model_density)
  TrainState good_;  // last known-good state for the divergence guard
  std::vector<std::string> init_report_;
  std::string focal_source_ = "fx = W, fy = H (the paper's start)";
  void init_cameras_from_model();
  void init_pose_preconditioner();  // st_.cameras_P from the starting cameras
  int preconditioned_focal_params() const;  // m of cameras_P
  // --pose-precondition: the poses' and the focal's Adam step through P (apply_update).
  void preconditioned_camera_step(float* d_poses, const float* d_focal, double lr_pose,
                                  double lr_focal, int64_t t);
  std::vector<double> cam_g_, cam_step_;  // scratch (D): dL/dΦ → dL/dψ; Δψ → ΔΦ
  std::vector<float> cam_psi_, cam_gpsi_; // scratch (6n + 2): Adam's step from ψ = 0, dL/dψ
};

// The restarts and the camera bootstrap (train/plan_generators.cpp): each builds a TrainPlan
// from c's fields (restarts_plan, bootstrap_plan in train/plan.h), resolves and checks every
// stage, records it in c.out/plan.json, runs the stages before the last (RUN/stage1 …
// RUN/stageK; the bootstrap's grid phase in RUN/bootstrap), then turns c into the last stage.
// Returns false when interrupted (it prints how to go on: `hashcc train --resume RUN`).
// observer_for (optional) makes each stage's after_step hook from its trainer (the CLI records
// each stage's camera_error.csv with it, as for any run).
using AfterStepFactory = std::function<std::function<void(const Trainer&)>(const Trainer&)>;
bool grid_restarts(TrainConfig& c, const std::atomic<bool>* stop,
                   const AfterStepFactory& observer_for = {});
bool bootstrap_cameras(TrainConfig& c, const std::atomic<bool>* stop,
                       const std::function<bool(const std::string&)>& given,
                       const AfterStepFactory& observer_for = {});

// Checks every setting that is not a file (ranges, finite numbers), naming the CLI flag:
// hashcc::Error on the first bad one. Called before anything is loaded or written, and again
// with n_train > 0 once the scene is loaded (the settings bounded by the number of training
// images: --images-per-step).
void validate_train_config(const TrainConfig& c, int n_train = 0);
// images_per_step 0 (auto), resolved once the scene is loaded: the largest K <= min(4, n_train)
// that divides rays, so a folder of 2-4 photos trains instead of being refused.
int auto_images_per_step(int rays, int n_train);
// Stage k's share (k = 1 … restarts + 1) of a --restarts budget: stage 1 --restart-first and the
// last --restart-last if given; the stages given no share split the rest equally (all 1/stages
// if none is given). Throws (naming --restart-last) for shares that leave the others nothing.
double restart_share(const TrainConfig& c, int k);
// Stage k's steps in a --restarts budget of --steps: its share, or with --restart-steps N, N for
// the stages between and what is left for the last (throws, naming --restart-steps, when
// nothing is).
int64_t restart_stage_steps(const TrainConfig& c, int k);

// --preset NAME: "paper" (the default) sets nothing; any other name is a built-in recipe, the
// plan of that name (recipes/NAME.json; train/plan.h). preset_names() lists them.
const std::vector<std::string>& preset_names();  // {"paper", then the recipes}
std::string preset_names_text();                 // "paper, fern60 or laptop", for messages
// The defaults the grid field brings for the flags the user did not give (`--field grid`): each
// the flag, the value, the measurement behind it, and what it does to the config. "mlp": none
// (the paper's values).
struct PresetEntry {
  std::string flag, value, why;       // as printed: "--images-per-step", "4", the measurement
  void (*set)(TrainConfig&) = nullptr;  // what the entry does to the config
};
const std::vector<PresetEntry>& field_defaults(const std::string& field);

// Serialises the config to JSON and back (config.json and the checkpoint use it).
std::string train_config_json(const TrainConfig& c);
// Every key, the old per-stage ones at 0 too (which config.json leaves out): what a plan's
// overrides and diffs are made on (train/plan.cpp).
std::string train_config_json_full(const TrainConfig& c);
TrainConfig train_config_from_json(const std::string& text, const std::string& file);

}  // namespace hashcc
