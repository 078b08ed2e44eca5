// tools/cmd_train.cpp — `hashcc train`: flags → TrainConfig → Trainer::run → report.
#include <algorithm>
#include <ctime>
#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <fmt/ranges.h>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "eval/camera_curve.h"
#include "train/plan.h"
#include "train/trainer.h"
#include "tools/cli.h"
#include "tools/report.h"
#include "tools/run_report.h"

namespace hashcc {

namespace {

// What the flags of `hashcc train` fill: the config, and the values that become config fields
// only once the run starts (they need parsing or depend on other flags).
struct TrainFlags {
  TrainConfig c;
  std::string model = "hashcc", resume, field = "mlp", grid_smooth = "on", preset = "auto";
  std::string view_dirs = "on", occupancy = "off";
  std::string init_focal = "model", refine = "on";
  std::vector<double> focal;  // --focal FX[,FY]
  std::string plan;              // --plan FILE|NAME
  std::vector<std::string> sets;  // --set [STAGE.]KEY=VALUE, in order
};

// The run: data, output, budget, batch and network size.
void add_run_options(CLI::App* sub, TrainFlags* f) {
  sub->add_option("--data", f->c.data, "scene folder: LLFF layout or a bare folder of photos");
  sub->add_option("--images", f->c.images_folder, "image folder inside --data (default: smallest)");
  sub->add_option("--max-side", f->c.max_side, "working resolution: images whose longer side "
                  "exceeds N pixels are downscaled (area filter) to N on load, the focal with "
                  "them; 0 = the files' size. eval and render use the run's")
      ->capture_default_str()->check(CLI::Range(0, 1 << 16));
  sub->add_option("--out", f->c.out, "run folder (config, log, checkpoint, cameras, preview)");
  sub->add_option("--resume", f->resume, "continue the run in this folder from its checkpoint (a staged run: from its first unfinished stage)");
  sub->add_option("--model", f->model, "nerfmm | sh | hashcc")->capture_default_str()
      ->check(CLI::IsMember({"nerfmm", "sh", "hashcc"}));
  sub->add_option("--epochs", f->c.epochs, "planned epochs (paper: 10000)")->check(CLI::Range(int64_t(1), int64_t(1) << 40));
  sub->add_option("--steps", f->c.steps, "planned steps (instead of epochs)")->check(CLI::Range(int64_t(1), int64_t(1) << 40));
  sub->add_option("--minutes", f->c.minutes, "time budget: plan the steps that fit, stop on time")
      ->check(CLI::Range(1e-3, 1e7));
  sub->add_option("--threads", f->c.threads, "threads (default: all cores)")->check(CLI::Range(1, 1024));
  sub->add_option("--seed", f->c.seed, "random seed")->capture_default_str();
  sub->add_option("--rays", f->c.rays, "rays per step, as a rows × cols grid")->capture_default_str()
      ->check(CLI::Range(1, 1 << 20));
  sub->add_option("--samples", f->c.samples, "samples per ray")->capture_default_str()->check(CLI::Range(2, 4096));
  sub->add_option("--width", f->c.model.width, "hidden width of the main network")->capture_default_str()
      ->check(CLI::Range(4, 4096));
}

// The radiance field and its grid, the CC grid, the chunk size.
void add_field_options(CLI::App* sub, TrainFlags* f) {
  {
    std::string help = "radiance field: mlp = the paper's 8x128 MLP; grid = hash grid + tiny MLPs "
                       "(~30x cheaper a sample, learns cameras; unset flags take its defaults:";
    for (const PresetEntry& e : field_defaults("grid")) help += " " + e.flag + " " + e.value;
    sub->add_option("--field", f->field, help + ")")->capture_default_str()
        ->check(CLI::IsMember({"mlp", "grid"}));
  }
  sub->add_option("--grid-levels", f->c.model.gf.grid.levels, "grid field: levels")
      ->capture_default_str()->check(CLI::Range(1, 64));
  sub->add_option("--grid-log2-table", f->c.model.gf.grid.log2_table,
                  "grid field: log2 of the table entries a level")->capture_default_str()
      ->check(CLI::Range(1, 24));
  sub->add_option("--grid-max-res", f->c.model.gf.grid.max_res, "grid field: finest resolution")
      ->capture_default_str()->check(CLI::Range(16.0, 1e6));
  sub->add_option("--grid-features", f->c.model.gf.grid.features, "grid field: features a "
                  "table entry holds (per level)")->capture_default_str()->check(CLI::Range(1, 16));
  sub->add_option("--grid-hidden", f->c.model.gf.hidden, "grid field: the density MLP's hidden "
                  "width")->capture_default_str()->check(CLI::Range(1, 4096));
  sub->add_option("--grid-rgb-hidden", f->c.model.gf.rgb_hidden, "grid field: the colour MLP's "
                  "hidden width")->capture_default_str()->check(CLI::Range(1, 4096));
  sub->add_option("--grid-smooth", f->grid_smooth, "grid field: smooth straight-through position "
                  "gradient (on) or the exact trilinear one (off)")->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}));
  sub->add_option("--grid-c2f-start", f->c.model.gf.c2f_start, "grid field: level curriculum "
                  "starts with this many levels on (with --c2f)")->capture_default_str()
      ->check(CLI::Range(0.0, 64.0));
  sub->add_option("--grid-density-init", f->c.model.gf.density_init, "grid field: σ starts "
                  "near exp(B) everywhere (0: a haze along the whole ray; 2: an opaque screen at "
                  "the near plane, which helps fern's cameras turn)")->capture_default_str()
      ->check(CLI::Range(-kGridDensityInitMax, kGridDensityInitMax));
  sub->add_option("--view-dirs", f->view_dirs, "view-dependent colour (sh, hashcc): on = SH degree "
                  "4 of the ray direction; off = degree 1, a constant: the colour cannot change "
                  "with the viewing direction, so it cannot absorb a camera error")
      ->capture_default_str()->check(CLI::IsMember({"on", "off"}));
  sub->add_option("--cc-max-res", f->c.model.cc.max_res, "finest hash-grid resolution of the CC branch")
      ->capture_default_str()->check(CLI::Range(16.0, 1e6));
  sub->add_option("--chunk-rays", f->c.chunk_rays, "rays per forward/backward chunk (memory); "
                  "0 = auto: the largest power of two within 24 MiB a chunk (16 rays of the paper's "
                  "network at 128 samples, 256 of the grid field's at 32)")
      ->capture_default_str()->check(CLI::Range(0, 1024));
}

// The learning rates (formulas.md §6).
void add_lr_options(CLI::App* sub, TrainFlags* f) {
  sub->add_option("--lr-net", f->c.lr_net, "initial learning rate of the networks")->capture_default_str()
      ->check(CLI::Range(1e-12, 10.0));
  sub->add_option("--lr-net-end", f->c.lr_net_end, "final learning rate of the networks")->capture_default_str()
      ->check(CLI::Range(1e-15, 10.0));
  sub->add_option("--lr-pose,--pose-lr", f->c.lr_pose,
                  "initial learning rate of the poses (NeRF-- refine mode: 5e-4)")->capture_default_str()
      ->check(CLI::Range(1e-15, 10.0));
  sub->add_option("--lr-pose-end", f->c.lr_pose_end, "final learning rate of the poses")->capture_default_str()
      ->check(CLI::Range(1e-15, 10.0));
  sub->add_option("--lr-focal", f->c.lr_focal, "initial learning rate of the focal")->capture_default_str()
      ->check(CLI::Range(1e-15, 10.0));
  sub->add_option("--lr-focal-end", f->c.lr_focal_end, "final learning rate of the focal")->capture_default_str()
      ->check(CLI::Range(1e-15, 10.0));
}

// Options beyond the paper (docs/architecture.md, "Options beyond the paper") and the presets.
void add_beyond_paper_options(CLI::App* sub, TrainFlags* f) {
  sub->add_option("--c2f", f->c.c2f_end, "beyond the paper: coarse-to-fine position encoding "
                  "over this fraction of the run (BARF; 0 = off)")->capture_default_str()->check(CLI::Range(0.0, 1.0));
  sub->add_option("--camera-delay", f->c.camera_delay, "beyond the paper: cameras frozen for this "
                  "fraction of the run (0 = off)")->capture_default_str()->check(CLI::Range(0.0, 0.99));
  sub->add_option("--images-per-step", f->c.images_per_step, "beyond the paper: the step's rays "
                  "come from K distinct training images, --rays / K each (a divisor of --rays, at "
                  "most the training images; 1 = one image a step)")->capture_default_str()
      ->check(CLI::Range(1, 1 << 20));
  sub->add_option("--pyramid", f->c.pyramid, "beyond the paper: image pyramid over this fraction "
                  "of the run: 4x coarser box-filtered images for its first half, 2x for its "
                  "second, then full resolution (0 = off)")->capture_default_str()
      ->check(CLI::Range(0.0, 0.99));
  sub->add_option("--camera-start-psnr", f->c.camera_start_psnr, "beyond the paper: cameras frozen "
                  "until the running train PSNR (EMA, factor 0.9) reaches this many dB; their "
                  "decay then runs from that step to the end (0 = off)")->capture_default_str()
      ->check(CLI::Range(0.0, 100.0));
  sub->add_option("--camera-warmup", f->c.camera_warmup, "beyond the paper: the cameras' lr ramps "
                  "linearly from 0 to its schedule over this many steps from their start "
                  "(0 = off)")->capture_default_str()->check(CLI::Range(int64_t(0), int64_t(1) << 40));
  sub->add_option("--focal-delay", f->c.focal_delay, "beyond the paper: the focal alone is frozen "
                  "for this fraction of the run (the poses learn), then learns with its schedule "
                  "compressed into the rest (0 = off)")->capture_default_str()->check(CLI::Range(0.0, 0.99));
  sub->add_option("--focal-guard", f->c.focal_guard, "beyond the paper: a focal leaving [start/G, "
                  "start*G] (or fx/fy its start ratio by more than sqrt G) is put back to its "
                  "start and held for the rest of the run or stage (0 = off)")
      ->capture_default_str()->check(CLI::Range(0.0, 100.0));
  sub->add_option("--pose-precondition", f->c.pose_precondition, "beyond the paper: learn each "
                  "camera's pose through the CamP preconditioner P = c (JᵀJ + λ diag)^(-1/2) of its "
                  "starting camera, with this damping λ (e.g. 0.1; 0 = off; NDC scenes)")
      ->capture_default_str()->check(CLI::Range(0.0, 1e6));
  sub->add_option("--occupancy", f->occupancy, "beyond the paper: on = the samples go only where "
                  "an occupancy grid of the field's density says something is (NDC scenes); "
                  "--samples then counts those samples")->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}));
  sub->add_option("--occupancy-start", f->c.occupancy_start, "with --occupancy on: the first "
                  "fraction of the run samples uniformly")->capture_default_str()
      ->check(CLI::Range(0.0, 0.99));
  sub->add_option("--occupancy-every", f->c.occupancy_every, "with --occupancy on: steps between "
                  "updates of the grid (each re-measures 1/8 of its cells)")->capture_default_str()
      ->check(CLI::Range(1, 1 << 20));
  sub->add_option("--occupancy-res", f->c.occupancy_res, "with --occupancy on: cells per axis "
                  "of the grid over the NDC box")->capture_default_str()->check(CLI::Range(4, 512));
  sub->add_option("--occupancy-probes", f->c.occupancy_probes, "with --occupancy on: probe "
                  "intervals per ray (≥ --samples)")->capture_default_str()
      ->check(CLI::Range(2, 1024));
  sub->add_option("--cameras-from", f->c.cameras_from, "start from the cameras an earlier run of "
                  "this scene learned (its checkpoint); the networks start fresh");
  sub->add_option("--bootstrap-minutes", f->c.bootstrap_minutes, "beyond the paper (--field mlp): "
                  "the first M minutes of --minutes learn the cameras with the grid field "
                  "(RUN/bootstrap), then the paper's network trains from them (a plan of two "
                  "phases, recorded in RUN/plan.json)")
      ->check(CLI::Range(0.0, 1e7));
  sub->add_option("--restarts", f->c.restarts, "beyond the paper (--field grid, or the grid "
                  "phase of --bootstrap-minutes): a plan of K+1 equal stages, each later one a "
                  "fresh grid field on the cameras the stage before learned (RUN/stage1..K, all "
                  "levels on); other layouts: --plan, --set (docs/training.md)")
      ->check(CLI::Range(0, 64));
  sub->add_option("--grid-decay", f->c.grid_decay, "grid field: adds λ Σ_levels mean(θ²) of "
                  "its table to the loss (Zip-NeRF's feature decay; 0 = off)")
      ->check(CLI::Range(0.0, 1e6));
  sub->add_option("--distortion", f->c.distortion, "adds λ · mean over rays of mip-NeRF 360's "
                  "distortion loss on the compositing weights, against floaters; it shapes the networks, "
                  "not the cameras (0 = off)")
      ->check(CLI::Range(0.0, 1e6));
  sub->add_option("--distortion-from", f->c.distortion_from, "the distortion loss starts at this "
                  "fraction of the run (0 = from the start)")->check(CLI::Range(0.0, 0.999));
  sub->add_option("--hold-cameras-from", f->c.hold_cameras_from, "from this fraction of the run "
                  "on, the cameras are held: no camera gradient, no update (0 = never)")
      ->check(CLI::Range(0.0, 0.999));
  std::vector<std::string> presets = {"auto"};
  for (const std::string& p : preset_names()) presets.push_back(p);
  sub->add_option("--preset", f->preset, fmt::format("auto = forward for photos whose cameras are "
                  "to be learned, paper otherwise (default_preset in tools/cmd_train.cpp); paper = "
                  "formulas.md §6 in one stage (sets nothing); fern60 = forward (the old "
                  "fern-tuned plan is --plan fern60); any other name is the built-in recipe of "
                  "that name, as --plan NAME ({})", preset_names_text()))
      ->capture_default_str()->check(CLI::IsMember(presets));
  sub->add_option("--plan", f->plan, fmt::format("a training plan: a JSON file, or a built-in "
                  "recipe ({}); its stages run in RUN/stage1 … and RUN (docs/training.md, Plans)",
                  fmt::join(recipe_names(), ", ")));
  sub->add_option("--set", f->sets, "[STAGE.]KEY=VALUE: a config.json key for every stage (it "
                  "wins over the flags) or for one stage: 2.lr_pose=1e-3, last.samples=64, "
                  "2-4.steps=600 (a stage's budget: steps=N, share=F, budget=rest)");
}

// Checkpoints, initial cameras, the focal, NDC, the ablation, output.
void add_camera_and_output_options(CLI::App* sub, TrainFlags* f) {
  sub->add_option("--checkpoint-minutes", f->c.checkpoint_minutes, "checkpoint interval")
      ->capture_default_str()->check(CLI::Range(0.0, 1e6));
  sub->add_option("--preview-minutes", f->c.preview_minutes, "preview render interval")
      ->capture_default_str()->check(CLI::Range(0.0, 1e6));
  sub->add_option("--init-poses", f->c.init_poses,
                  "start from approximate cameras: a COLMAP text model folder, poses_bounds.npy "
                  "or cameras.json (matched by file name; learned deltas on top)");
  sub->add_option("--init-focal", f->init_focal, "with --init-poses: focal from the model, or none "
                  "(start at fx = W, fy = H)")->capture_default_str()
      ->check(CLI::IsMember({"model", "none"}));
  sub->add_option("--refine-poses", f->refine, "with --init-poses, --cameras-from or a bootstrap's "
                  "phase 2: on = refine jointly, off = hold the given cameras: the poses, and the focal "
                  "that came with them (with --init-focal none the focal still learns, from --focal "
                  "or W, H, unless --fixed-focal; held cameras compute no camera gradient)")->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}));
  sub->add_flag("!--no-ndc", f->c.ndc, "switch NDC off (scenes that are not forward-facing)");
  sub->add_flag("--fx-only", f->c.fx_only, "one focal: fy tied to fx");
  sub->add_flag("--ndc-fixed-focal", f->c.ndc_fixed_focal, "beyond the paper: draw the NDC box with "
                "the focal the stage starts from, held, not the learned one (the focal then learns "
                "from the rays' directions alone; docs/training.md, \"The NDC box\")");
  sub->add_option("--ndc-box-scale", f->c.ndc_box_scale, "with --ndc-fixed-focal: draw the held box "
                  "with this multiple of the start focal (< 1: a wider box, room for the side views' "
                  "edge rays)");
  sub->add_option("--focal", f->focal, "a known focal in pixels at the training resolution, FX or "
                  "FX,FY: start from it instead of fx = W, fy = H")->delimiter(',')
      ->expected(1, 2);
  sub->add_option("--focal-fov", f->c.focal_fov, "start from the focal of this horizontal field "
                  "of view in degrees, fx = fy (0 = the paper's fx = W, fy = H; --focal wins)");
  sub->add_flag("--fixed-focal", f->c.fixed_focal, "keep the starting focal: the focal is not learned");
  sub->add_flag("--stop-cc-to-camera", f->c.stop_cc_to_camera,
                "ablation: the second loss reaches σ and c for the networks but not the camera");
  sub->add_flag("--distortion-to-camera", f->c.distortion_to_camera,
                "ablation: the distortion loss reaches the cameras too (by default only the networks)");
  sub->add_flag("!--no-progress", f->c.progress, "plain output only");
}

// Each stage's own RUN/.../camera_error.csv, as for any run (eval/camera_curve.h).
AfterStepFactory camera_curve_for() {
  return [](const Trainer& b) {
    auto curve = std::make_shared<CameraCurve>(b, b.config().out + "/camera_error.csv");
    return std::function<void(const Trainer&)>([curve](const Trainer& t) { (*curve)(t); });
  };
}

// Whether a flag was on the command line (a name CLI11 does not know: no).
bool flag_given(CLI::App* sub, const std::string& flag) {
  try {
    return sub->count(flag) > 0;
  } catch (const CLI::OptionNotFound&) {
    return false;
  }
}

// Whether a --set names a stage ("2.lr_pose=1e-3", "last.samples=64") or the base ("samples=64").
bool names_a_stage(const std::string& assignment) {
  const size_t dot = assignment.find('.'), eq = assignment.find('=');
  return dot != std::string::npos && dot < eq;
}

// --preset auto (the default): what `hashcc train --data DIR --minutes M` runs with no other flag.
// Photos whose cameras are to be learned from scratch get the recipe built for that
// (recipes/forward.json: the grid field in stages, issue 49). A run that chooses its field
// (--field mlp: the paper's network, formulas.md §6; --field grid: the grid field alone) or its
// layout (--plan, --restarts, the bootstrap), gives cameras (--init-poses, --cameras-from) or
// leaves forward-facing photos (--no-ndc) is one stage with the flags it gives, as before the
// recipe was the default; --preset paper says so outright.
std::string default_preset(const TrainFlags& f, const std::function<bool(const std::string&)>& given) {
  const TrainConfig& c = f.c;
  const bool paper_asked = given("--field");
  const bool layout_given = !f.plan.empty() || c.restarts > 0 || c.bootstrap_minutes > 0 ||
                            c.bootstrap_steps > 0;
  const bool cameras_given = !c.init_poses.empty() || !c.cameras_from.empty();
  return paper_asked || layout_given || cameras_given || !c.ndc ? "paper" : "forward";
}

// The plan of --plan / --preset (a recipe or a file) with every --set; without one, a plan of
// one stage holding the --set values for the base (those for a stage then go to the plan
// --restarts or the bootstrap generates, staged_sets). None: no plan and no --set.
std::optional<TrainPlan> plan_from_flags(const TrainFlags& f) {
  HCC_REQUIRE(f.plan.empty() || f.preset == "paper", "--plan", f.plan, "given with --preset",
              "one of them (--preset NAME is --plan NAME)");
  const std::string name = f.preset != "paper" ? f.preset : f.plan;
  if (name.empty() && f.sets.empty()) return std::nullopt;
  TrainPlan p;
  if (!name.empty()) {
    p = load_plan(name);
  } else {
    p.name = p.source = "--set";
    p.stages.push_back({});
    p.stages[0].cameras_from_previous = false;
  }
  for (const std::string& a : f.sets)
    if (!name.empty() || !names_a_stage(a)) set_plan_value(p, a);
  return p;
}

// --restarts K or --bootstrap-minutes M with --set STAGE.KEY=VALUE: the generated plan, edited.
void staged_sets(TrainPlan& p, const TrainFlags& f) {
  for (const std::string& a : f.sets)
    if (names_a_stage(a)) set_plan_value(p, a);
}

// A new run's config from the flags: the values that need parsing, the plan's base (--plan) or
// the preset, then the grid field's defaults for every flag not given (each printed), then the
// stages before the last of a plan, of --restarts or of the camera bootstrap; c becomes the last.
void finish_new_run_config(TrainFlags& f, CLI::App* sub, const StopSignals& signals) {
  TrainConfig* c = &f.c;
  HCC_REQUIRE(!c->data.empty(), "--data", "", "missing", "a scene folder (or --resume RUN)");
  HCC_REQUIRE(!c->out.empty(), "--out", "", "missing", "a run folder");
  HCC_REQUIRE(int(c->epochs > 0) + int(c->steps > 0) <= 1, "--epochs/--steps", "",
              "both given", "one of them");
  c->model.variant = parse_variant(f.model);
  c->model.field = parse_field(f.field);
  c->model.gf.grid.smooth_dx = f.grid_smooth == "on";
  if (f.view_dirs == "off") {
    HCC_REQUIRE(c->model.variant != Variant::nerfmm, "--view-dirs", "", "off with --model "
                "nerfmm", "--model sh or hashcc (SH directions; degree 1 is a constant)");
    c->model.sh_degree = 1;
  }
  c->init_focal = f.init_focal == "model";
  if (!f.focal.empty()) {
    c->focal_fx = f.focal.front();
    c->focal_fy = f.focal.back();  // FX alone: fy = fx (square pixels)
  }
  c->refine_poses = f.refine == "on";
  c->occupancy = f.occupancy == "on";
  const auto given = [&](const std::string& flag) { return flag_given(sub, flag); };
  if (f.preset == "auto") f.preset = default_preset(f, given);
  // --preset fern60 named the recipe tuned on fern alone (on horns it failed: Sim(3) 15.4°,
  // 11.9 dB), which the forward recipe replaced as the default (issue 49). The name now runs
  // the default; the old plan stays loadable as --plan fern60, to reproduce its figures.
  if (f.preset == "fern60") {
    fmt::print("--preset fern60 is the default forward recipe now (recipes/forward.json); the "
               "old fern-tuned plan is --plan fern60\n");
    f.preset = "forward";
  }
  const std::optional<TrainPlan> plan = plan_from_flags(f);
  const bool generated = c->restarts > 0 || c->bootstrap_minutes > 0 || c->bootstrap_steps > 0;
  HCC_REQUIRE(!generated || (f.plan.empty() && f.preset == "paper"), "--plan", f.plan,
              "given with --restarts or --bootstrap-minutes", "one of them: a plan's stages are "
              "its restarts");
  HCC_REQUIRE(generated || !plan || plan->name != "--set" ||
                  std::none_of(f.sets.begin(), f.sets.end(), names_a_stage),
              "--set", "", "names a stage, and the run has none",
              "--plan, --restarts or --bootstrap-minutes; or KEY=VALUE for the whole run");
  // The plan's base first (it may choose the field), then the field's defaults for the flags
  // that neither the command line nor the plan set.
  std::vector<std::string> set_by_plan;
  // The flags are checked before a plan's base is merged into them, so that a bad value is
  // reported by its flag (--lr-net nan), not as the recipe's key it would have been merged with.
  if (plan) validate_train_config(*c);
  if (plan) {
    std::string line;
    for (const std::string& key : apply_plan_base(*c, *plan, [&](const std::string& k) {
           return given(flag_of_key(k));
         })) {
      set_by_plan.push_back(flag_of_key(key));
      line += fmt::format(" {}={}", key, plan->base.at(key).dump());
    }
    if (!line.empty()) fmt::print("plan {}:{}\n", plan->name, line);
    // The recipe the run came from, as config.json has always recorded a preset.
    const auto& names = preset_names();
    if (std::find(names.begin(), names.end(), plan->name) != names.end()) c->preset = plan->name;
  }
  const auto set_already = [&](const std::string& flag) {
    return given(flag) ||
           std::find(set_by_plan.begin(), set_by_plan.end(), flag) != set_by_plan.end();
  };
  if (c->model.field == Field::grid) {
    std::string line = "field grid:";
    for (const PresetEntry& e : field_defaults("grid"))
      if (!set_already(e.flag)) { e.set(*c); line += " " + e.flag + " " + e.value; }
    fmt::print("{}\n", line);
  }
  HCC_REQUIRE(!c->init_poses.empty() || !sub->count("--init-focal"), "--init-focal", "",
              "given without --init-poses", "--init-poses PATH");
  HCC_REQUIRE(!c->init_poses.empty() || !c->cameras_from.empty() || c->bootstrap_minutes > 0 ||
                  c->bootstrap_steps > 0 || !sub->count("--refine-poses"),
              "--refine-poses", "", "given without cameras to start from",
              "--init-poses PATH, --cameras-from RUN or --bootstrap-minutes M");
  validate_train_config(*c);
  std::optional<TrainPlan> staged = plan;
  if (c->bootstrap_minutes > 0 || c->bootstrap_steps > 0) staged = bootstrap_plan(*c, given);
  else if (c->restarts > 0) staged = restarts_plan(*c);
  if (!staged) return;
  if (generated) staged_sets(*staged, f);
  PlanRun pr = start_plan(*staged, *c);  // every stage resolved and checked before stage 1
  if (!run_plan_until_last(pr, &signals.flag(), camera_curve_for())) throw Interrupted{};
  *c = last_stage_config(pr);
}

// The trainer: the run in --resume's folder, or a new run from the flags.
void open_trainer(std::optional<Trainer>& tr, TrainFlags& f, CLI::App* sub,
                  const StopSignals& signals) {
  if (!f.resume.empty()) {
    HCC_REQUIRE(!sub->count("--preset"), "--preset", "", "given with --resume",
                "no --preset: a resumed run keeps the settings in its config.json");
    HCC_REQUIRE(!sub->count("--plan") && !sub->count("--set"), "--plan/--set", "",
                "given with --resume", "no --plan or --set: a resumed staged run keeps the plan "
                "in its plan.json");
    if (has_plan(f.resume)) {  // a staged run: from its first unfinished stage
      PlanRun pr = open_plan(f.resume);
      HCC_REQUIRE(!sub->count("--minutes") || pr.stages.size() == 1, "--minutes", "",
                  "given with --resume of a staged run",
                  "no --minutes: the stages' budgets are in RUN/plan.json");
      if (!run_plan_until_last(pr, &signals.flag(), camera_curve_for())) throw Interrupted{};
      if (!last_stage_started(pr)) {
        tr.emplace(last_stage_config(pr));
        return;
      }
    }
    tr.emplace(Trainer::resume(f.resume, sub->count("--minutes") ? f.c.minutes : -1));
    fmt::print("resuming {} at step {} of {}\n", f.resume, tr->state().step, tr->planned_total());
    return;
  }
  finish_new_run_config(f, sub, signals);
  tr.emplace(f.c);
  for (const std::string& note : tr->init_report()) fmt::print("{}\n", note);
}

// One line saying what trains: scene, images, model, rays, threads.
void print_run_header(const Trainer& tr) {
  const TrainConfig& cfg = tr.config();
  const Scene& sc = tr.scene();
  if (auto note = ignored_files_note(sc); !note.empty()) fmt::print("{}\n", note);
  for (const std::string& note : sc.notes) fmt::print("note: {}\n", note);
  const std::string from = sc.width == sc.file_width && sc.height == sc.file_height ? "" :
      fmt::format(" (files {}x{}, --max-side {})", sc.file_width, sc.file_height, cfg.max_side);
  fmt::print("hashcc train: {} | {} images {}x{}{} ({} train, {} test) | model {} field {} | "
             "{}{}x{} rays x {} samples | {} threads\n",
             cfg.data, sc.names.size(), sc.width, sc.height, from, sc.train.size(), sc.test.size(),
             variant_name(cfg.model.variant), cfg.model.field == Field::grid ? "grid" :
             fmt::format("mlp width {}", cfg.model.width),
             cfg.images_per_step > 1 ? fmt::format("{} images x ", cfg.images_per_step) : "",
             cfg.step_rows(), cfg.step_cols(), cfg.samples, num_threads());
}

// Trains to the plan's end or the stop signal, then reports; Interrupted when stopped.
void train_and_report(Trainer& tr, const StopSignals& signals) {
  const TrainConfig& cfg = tr.config();
  const Scene& sc = tr.scene();
  // RUN/camera_error.csv: the cameras' error against the reference every 25 steps.
  CameraCurve curve(tr, cfg.out + "/camera_error.csv");
  bool done = tr.run(&signals.flag(), [&curve](const Trainer& t) { curve(t); });
  const TrainState& st = tr.state();
  const FocalParams<float> f = tr.focal();
  fmt::print("{} after {} steps ({} epochs) in {:.1f} s: fx {:.2f} fy {:.2f}{}\n",
             done ? "finished" : "interrupted", st.step,
             st.step / tr.steps_per_epoch(), st.elapsed, focal_fx(f, tr.image_size()),
             focal_fy(f, tr.image_size()),
             sc.has_reference ? fmt::format(" (reference {:.2f})", sc.ref_focal) : "");
  print_train_report(tr);
  fmt::print("run folder: {} (config.json, log.csv, camera_error.csv, checkpoint.bin, cameras.json, preview.png)\n",
             cfg.out);
  if (!done) {
    fmt::print("resume with: hashcc train --resume {}\n", cfg.out);
    throw Interrupted{};
  }
  if (has_plan(cfg.out)) mark_last_stage_finished(cfg.out);
}

// The options `hashcc train --help` leaves out, to fit one screen: each still works, is listed by
// --help-all and in docs/training.md, and --set KEY=VALUE reaches its config.json key too.
void hide_advanced_options(CLI::App* sub) {
  for (const char* name :
       {"--grid-levels", "--grid-max-res", "--grid-features", "--grid-hidden", "--grid-rgb-hidden",
        "--grid-smooth", "--grid-c2f-start", "--cc-max-res", "--occupancy-start",
        "--occupancy-every", "--occupancy-res", "--occupancy-probes", "--camera-start-psnr",
        "--camera-warmup", "--camera-delay", "--pyramid", "--stop-cc-to-camera",
        "--distortion-to-camera", "--distortion-from", "--hold-cameras-from",
        "--checkpoint-minutes", "--preview-minutes"})
    sub->get_option(name)->group(help_all() ? "More options (--set KEY=VALUE reaches every "
                                              "config.json key)" : "");
}

}  // namespace

void add_train_command(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("train", "learn a radiance field and the cameras from a folder "
                                          "of photos (no poses needed); --help-all lists every option");
  auto f = std::make_shared<TrainFlags>();
  add_run_options(sub, f.get());
  add_field_options(sub, f.get());
  add_lr_options(sub, f.get());
  add_beyond_paper_options(sub, f.get());
  add_camera_and_output_options(sub, f.get());
  hide_advanced_options(sub);
  sub->callback([&run, f, sub] {
    run = [f, sub] {
      Timer t;
      const std::time_t started = std::time(nullptr);
      StopSignals signals;  // Ctrl-C / SIGTERM: finish the step, checkpoint, exit 130
      std::optional<Trainer> tr;
      // Finished or interrupted, the run folder records the command and gets its page
      // (RUN/commands.txt, RUN/report.html: tools/run_report.h).
      const std::string out = f->resume.empty() ? f->c.out : f->resume;
      const auto record = [&] {
        record_command(out, command_args(), started);
        refresh_run_report(out);
      };
      try {
        open_trainer(tr, *f, sub, signals);
        print_run_header(*tr);
        train_and_report(*tr, signals);
      } catch (const Interrupted&) {
        record();
        throw;
      }
      record();
    };
  });
}

}  // namespace hashcc
