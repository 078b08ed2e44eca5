// train/train_config.cpp — TrainConfig <-> JSON (RUN/config.json and the checkpoint's copy).
// Kept apart from the training loop so the config reader can be fuzzed on its own
// (tools/fuzz/fuzz_config.cpp). Every malformed input is a hashcc::Error naming the key.
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "train/recipes.h"
#include "train/trainer.h"

using nlohmann::json;

namespace hashcc {

namespace {

// Every key, with its value in c.
json config_object(const TrainConfig& c) {
  return {
      {"engine", "hashcc"}, {"version", HASHCC_VERSION},
      {"data", c.data}, {"images_folder", c.images_folder},
      {"max_side", c.max_side}, {"out", c.out},
      {"model", variant_name(c.model.variant)}, {"width", c.model.width},
      {"rgb_width", c.model.rgb_width}, {"pos_bands", c.model.pos_bands},
      {"dir_bands", c.model.dir_bands}, {"sh_degree", c.model.sh_degree},
      {"cc_levels", c.model.cc.levels}, {"cc_features", c.model.cc.features},
      {"cc_log2_table", c.model.cc.log2_table}, {"cc_base_res", c.model.cc.base_res},
      {"cc_max_res", c.model.cc.max_res}, {"cc_hidden", c.model.cc_hidden},
      {"field", field_name(c.model.field)}, {"grid_levels", c.model.gf.grid.levels},
      {"grid_features", c.model.gf.grid.features}, {"grid_log2_table", c.model.gf.grid.log2_table},
      {"grid_base_res", c.model.gf.grid.base_res}, {"grid_max_res", c.model.gf.grid.max_res},
      {"grid_smooth_grad", c.model.gf.grid.smooth_dx}, {"grid_hidden", c.model.gf.hidden},
      {"grid_geo", c.model.gf.geo}, {"grid_rgb_hidden", c.model.gf.rgb_hidden},
      {"grid_c2f_start", c.model.gf.c2f_start}, {"grid_density_init", c.model.gf.density_init},
      {"ndc", c.ndc}, {"ndc_fixed_focal", c.ndc_fixed_focal}, {"ndc_box_scale", c.ndc_box_scale}, {"fx_only", c.fx_only}, {"stop_cc_to_camera", c.stop_cc_to_camera},
      {"epochs", c.epochs}, {"steps", c.steps}, {"minutes", c.minutes}, {"threads", c.threads},
      {"seed", c.seed}, {"rays", c.rays}, {"samples", c.samples}, {"chunk_rays", c.chunk_rays},
      {"lr_net", c.lr_net}, {"lr_net_end", c.lr_net_end}, {"lr_pose", c.lr_pose},
      {"lr_pose_end", c.lr_pose_end}, {"lr_focal", c.lr_focal}, {"lr_focal_end", c.lr_focal_end},
      {"c2f_end", c.c2f_end}, {"camera_delay", c.camera_delay},
      {"images_per_step", c.images_per_step}, {"pyramid", c.pyramid},
      {"camera_start_psnr", c.camera_start_psnr}, {"camera_warmup", c.camera_warmup},
      {"focal_delay", c.focal_delay}, {"pose_precondition", c.pose_precondition}, {"focal_fx", c.focal_fx}, {"focal_fy", c.focal_fy},
      {"focal_fov", c.focal_fov}, {"focal_guard", c.focal_guard},
      {"fixed_focal", c.fixed_focal}, {"cameras_from", c.cameras_from},
      {"bootstrap_minutes", c.bootstrap_minutes}, {"bootstrap_steps", c.bootstrap_steps},
      {"bootstrap_lr_pose", c.bootstrap_lr_pose}, {"restarts", c.restarts},
      {"restart_first", c.restart_first}, {"restart_last", c.restart_last},
      {"restart_steps", c.restart_steps}, {"last_focal_hold", c.last_focal_hold},
      {"first_focal_hold", c.first_focal_hold},
      {"last_focal_stages", c.last_focal_stages},
      {"last_grid_log2_table", c.last_grid_log2_table}, {"last_samples", c.last_samples},
      {"last_lr_net", c.last_lr_net}, {"last_lr_net_end", c.last_lr_net_end},
      {"last_lr_focal_end", c.last_lr_focal_end}, {"last_lr_pose_end", c.last_lr_pose_end},
      {"grid_decay", c.grid_decay}, {"distortion", c.distortion},
      {"last_distortion", c.last_distortion}, {"distortion_to_camera", c.distortion_to_camera},
      {"distortion_from", c.distortion_from}, {"hold_cameras_from", c.hold_cameras_from},
      {"last_distortion_from", c.last_distortion_from},
      {"last_hold_cameras_from", c.last_hold_cameras_from},
      {"occupancy", c.occupancy}, {"occupancy_start", c.occupancy_start},
      {"occupancy_every", c.occupancy_every}, {"occupancy_res", c.occupancy_res},
      {"occupancy_probes", c.occupancy_probes},
      {"checkpoint_minutes", c.checkpoint_minutes}, {"preview_minutes", c.preview_minutes},
      {"init_poses", c.init_poses}, {"init_focal", c.init_focal},
      {"refine_poses", c.refine_poses}, {"preset", c.preset}};
}

// The keys of the per-stage flags before plans (the inputs of restarts_plan and bootstrap_plan,
// train/plan.h): written only when set, so a stage's config.json holds the values it trained
// with. Old config.json files that hold them still load (read_run_keys reads them all).
bool legacy_stage_key(const std::string& k) {
  return k.rfind("last_", 0) == 0 || k.rfind("restart", 0) == 0 || k.rfind("bootstrap_", 0) == 0 ||
         k == "first_focal_hold";
}

}  // namespace

std::string train_config_json_full(const TrainConfig& c) { return config_object(c).dump(); }

std::string train_config_json(const TrainConfig& c) {
  static const json defaults = config_object(TrainConfig{});
  json j = config_object(c);
  for (auto it = j.begin(); it != j.end();)
    it = legacy_stage_key(it.key()) && *it == defaults.at(it.key()) ? j.erase(it) : std::next(it);
  return j.dump(2) + "\n";
}

namespace {

// Reads key k into v when present. Numbers are range-checked BEFORE conversion (a JSON 1e300
// read into an int would be undefined behaviour), integers must be integral, and a value
// outside [lo, hi] is an Error naming the key and the accepted range.
struct Reader {
  const json& j;
  const std::string& file;
  void str(const char* k, std::string& v) const {
    if (!j.contains(k)) return;
    if (!j.at(k).is_string()) throw Error(file, k, "has the wrong type", "a string");
    v = j.at(k).get<std::string>();
  }
  void flag(const char* k, bool& v) const {
    if (!j.contains(k)) return;
    if (!j.at(k).is_boolean()) throw Error(file, k, "has the wrong type", "true or false");
    v = j.at(k).get<bool>();
  }
  double number(const char* k, double lo, double hi, bool integral) const {
    const json& x = j.at(k);
    if (!x.is_number())
      throw Error(file, k, "has the wrong type", integral ? "an integer" : "a number");
    double d = x.get<double>();
    if (!std::isfinite(d) || d < lo || d > hi || (integral && d != std::floor(d)))
      throw Error(file, k, fmt::format("value {} is out of range", x.dump()),
                  fmt::format("{} from {} to {}", integral ? "an integer" : "a number", lo, hi));
    return d;
  }
  template <class I> void integer(const char* k, I& v, double lo, double hi) const {
    if (!j.contains(k)) return;
    v = I(number(k, lo, hi, true));
  }
  void real(const char* k, double& v, double lo, double hi) const {
    if (!j.contains(k)) return;
    v = number(k, lo, hi, false);
  }
};

}  // namespace

double restart_share(const TrainConfig& c, int k) {
  const int stages = c.restarts + 1;
  const bool first_given = c.restart_first > 0, last_given = c.restart_last > 0;
  const int free_stages = stages - first_given - last_given;
  const double rest = 1 - c.restart_first - c.restart_last;
  // The shares given leave the stages not given a share something: with K = 1 both given must
  // sum to 1 (there is no middle); otherwise to less than 1.
  if (free_stages > 0 ? rest <= 0 : std::abs(rest) > 1e-9)
    throw Error("--restart-last", "",
                fmt::format("{:g} with --restart-first {:g} leaves {} for the stages between",
                            c.restart_last, c.restart_first,
                            c.restarts == 1 ? "no stage between to take the rest" : "nothing"),
                c.restarts == 1 ? "shares that sum to 1 with --restarts 1"
                                : "shares that sum to less than 1");
  if (k == 1 && first_given) return c.restart_first;
  if (k == stages && last_given) return c.restart_last;
  return rest / free_stages;
}

int64_t restart_stage_steps(const TrainConfig& c, int k) {
  const int stages = c.restarts + 1;
  const auto share_of = [&](int j) {
    return std::max<int64_t>(1, int64_t(std::floor(double(c.steps) * restart_share(c, j) + 1e-9)));
  };
  if (c.restart_steps <= 0) return share_of(k);
  if (k == 1) return share_of(1);
  if (k < stages) return c.restart_steps;
  const int64_t left = c.steps - share_of(1) - (c.restarts - 1) * c.restart_steps;
  if (left <= 0)
    throw Error("--restart-steps", "",
                fmt::format("{} x {} stages between, after stage 1's {} steps, leave the last "
                            "stage nothing of --steps {}",
                            c.restart_steps, c.restarts - 1, share_of(1), c.steps),
                "fewer or shorter restarts, or more --steps");
  return left;
}

namespace {

// A setting's range, naming its flag. CLI11's Range lets NaN through (every comparison with NaN
// is false): checked here.
void real(const char* flag, double v, double lo, double hi) {
  if (!(std::isfinite(v) && v >= lo && v <= hi))
    throw Error(flag, "", fmt::format("{} is out of range", v),
                fmt::format("a number from {} to {}", lo, hi));
}
void integer(const char* flag, int64_t v, int64_t lo, int64_t hi) {
  if (!(v >= lo && v <= hi))
    throw Error(flag, "", fmt::format("{} is out of range", v), fmt::format("{} to {}", lo, hi));
}

// The fields of the per-stage flags before plans (restarts_plan's and bootstrap_plan's inputs,
// which old config.json files and tests still set): the bootstrap, the restarts' layout, the
// focal holds.
void validate_restart_fields(const TrainConfig& c) {
  real("--bootstrap-minutes", c.bootstrap_minutes, 0, 1e7);
  integer("--bootstrap-steps", c.bootstrap_steps, 0, int64_t(1) << 40);
  real("--bootstrap-lr-pose", c.bootstrap_lr_pose, 0, 10);
  integer("--restarts", c.restarts, 0, 64);
  if (c.restarts > 0 && c.model.field != Field::grid && c.bootstrap_minutes <= 0 &&
      c.bootstrap_steps <= 0)
    throw Error("--restarts", "", "given for the MLP field without a bootstrap",
                "--field grid, or --bootstrap-minutes (its grid phase restarts)");
  real("--restart-first", c.restart_first, 0, 0.99);
  real("--restart-last", c.restart_last, 0, 0.99);
  for (const auto& [flag, share] : {std::pair{"--restart-first", c.restart_first},
                                    std::pair{"--restart-last", c.restart_last}})
    if (share > 0 && c.restarts == 0)
      throw Error(flag, "", "given without --restarts",
                  "--restarts K: a stage's share of the budget only means something with stages");
  integer("--restart-steps", c.restart_steps, 0, int64_t(1) << 40);
  if (c.restart_steps > 0 && c.restarts < 2)
    throw Error("--restart-steps", "", c.restarts == 0 ? "given without --restarts"
                                                       : "given with --restarts 1 (no stage between)",
                "--restarts K with K >= 2: the stages between the first and the last run N steps");
  real("--first-focal-hold", c.first_focal_hold, 0, 0.99);
  if (c.first_focal_hold > 0 && c.restarts == 0)
    throw Error("--first-focal-hold", fmt::format("{:g}", c.first_focal_hold),
                "given without --restarts", "--restarts K (without stages, --focal-delay F)");
  // Beside --focal-delay it is refused by grid_restarts, not here: the stages' configs keep
  // first_focal_hold as a record of the command while --last-focal-hold sets their focal_delay.
  real("--last-focal-hold", c.last_focal_hold, 0, 0.99);
  if (c.last_focal_hold > 0 && c.restarts == 0)
    throw Error("--last-focal-hold", "", "given without --restarts",
                "--restarts K: the hold is for the last stage's young field");
  integer("--last-focal-stages", c.last_focal_stages, 1, 64);
  if (c.last_focal_stages > 1 && c.last_focal_hold <= 0)
    throw Error("--last-focal-stages", "", "given without --last-focal-hold",
                "--last-focal-hold F: the stages it names learn one focal held for F of each");
  if (c.last_focal_stages > c.restarts && c.last_focal_hold > 0)
    throw Error("--last-focal-stages", std::to_string(c.last_focal_stages),
                fmt::format("more than the {} stage(s) after the first (--restarts {})",
                            c.restarts, c.restarts),
                "at most --restarts: stage 1 starts from identity and learns both focals");
  integer("--last-grid-log2-table", c.last_grid_log2_table, 0, 24);
  integer("--last-samples", c.last_samples, 0, 4096);
  real("--last-lr-net", c.last_lr_net, 0, 10);
  real("--last-lr-net-end", c.last_lr_net_end, 0, 10);
  real("--last-lr-focal-end", c.last_lr_focal_end, 0, 10);
  real("--last-lr-pose-end", c.last_lr_pose_end, 0, 10);
}

// The last stage's own values (last_*): only for the grid field's restarts, and its rates must
// still decay.
void validate_last_stage_fields(const TrainConfig& c) {
  // The last stage's field options (size and rate) only mean something for the grid field's
  // restarts.
  for (const auto& [flag, v] : {std::pair{"--last-grid-log2-table", double(c.last_grid_log2_table)},
                                std::pair{"--last-samples", double(c.last_samples)},
                                std::pair{"--last-lr-net", c.last_lr_net},
                                std::pair{"--last-lr-net-end", c.last_lr_net_end},
                                std::pair{"--last-lr-focal-end", c.last_lr_focal_end},
                                std::pair{"--last-lr-pose-end", c.last_lr_pose_end},
                                std::pair{"--last-distortion", c.last_distortion},
                                std::pair{"--last-distortion-from", c.last_distortion_from},
                                std::pair{"--last-hold-cameras-from", c.last_hold_cameras_from}}) {
    if (v > 0 && c.restarts == 0)
      throw Error(flag, fmt::format("{:g}", v), "given without --restarts",
                  "--restarts K: it sets the last stage's fresh field");
    if (v > 0 && c.model.field != Field::grid)
      throw Error(flag, fmt::format("{:g}", v), "given for the MLP field",
                  "--field grid (the bootstrap's grid phase hands on only its cameras, so a "
                  "last grid field's size or rate would be thrown away)");
  }
  for (const auto& [flag, v] : {std::pair{"--last-grid-log2-table", c.last_grid_log2_table},
                                std::pair{"--last-samples", c.last_samples}})
    if (v == 1) throw Error(flag, "1", "is out of range", "0 (as before) or at least 2");
  if (c.restarts > 0) {  // the last stage's schedule must still decay (or stay flat)
    const double a = c.last_lr_net > 0 ? c.last_lr_net : c.lr_net;
    const double b = c.last_lr_net_end > 0 ? c.last_lr_net_end : c.lr_net_end;
    if (b > a)
      throw Error(c.last_lr_net_end > 0 ? "--last-lr-net-end" : "--last-lr-net",
                  fmt::format("{:g}", c.last_lr_net_end > 0 ? b : a),
                  fmt::format("makes the last stage's field rate rise ({:g} → {:g})", a, b),
                  "a final rate at most the starting one");
    struct CameraEnd {
      const char *flag, *what, *start_flag;
      double start, end;
    };
    for (const CameraEnd& e : {CameraEnd{"--last-lr-focal-end", "focal", "--lr-focal", c.lr_focal,
                                         c.last_lr_focal_end},
                               CameraEnd{"--last-lr-pose-end", "pose", "--lr-pose", c.lr_pose,
                                         c.last_lr_pose_end}})
      if (e.end > e.start)
        throw Error(e.flag, fmt::format("{:g}", e.end),
                    fmt::format("makes the last stage's {} rate rise ({:g} → {:g})", e.what,
                                e.start, e.end),
                    fmt::format("a final rate at most {}", e.start_flag));
  }
  if (c.last_focal_hold > 0 && c.fixed_focal)
    throw Error("--last-focal-hold", "", "given with --fixed-focal",
                "one of them (a fixed focal is never learned)");
  if (c.first_focal_hold > 0 && c.fixed_focal)
    throw Error("--first-focal-hold", "", "given with --fixed-focal",
                "one of them (a fixed focal is never learned)");
  if (c.restart_steps > 0 && c.restart_last > 0)
    throw Error("--restart-steps", "", "given with --restart-last",
                "one of them (with --restart-steps the last stage takes what is left)");
  if (c.restarts > 0) restart_share(c, 1);  // throws for shares that do not fill the budget
  if (c.restarts > 0 && !c.init_poses.empty())
    throw Error("--restarts", "", "given with --init-poses",
                "one of them (a restart starts from the cameras the stage before it learned)");
}

}  // namespace

int auto_images_per_step(int rays, int n_train) {
  int k = std::max(1, std::min(4, n_train));
  while (k > 1 && rays % k != 0) --k;
  return k;
}

void validate_train_config(const TrainConfig& c, int n_train) {
  integer("--rays", c.rays, 1, 1 << 20);
  integer("--samples", c.samples, 2, 4096);
  integer("--width", c.model.width, 1, 4096);
  integer("--chunk-rays", c.chunk_rays, 0, 1024);
  integer("--threads", c.threads, 0, 1024);
  integer("--epochs", c.epochs, 0, int64_t(1) << 40);
  integer("--steps", c.steps, 0, int64_t(1) << 40);
  real("--minutes", c.minutes, 0, 1e7);
  real("--lr-net", c.lr_net, 1e-15, 10);
  real("--lr-net-end", c.lr_net_end, 1e-15, 10);
  real("--lr-pose", c.lr_pose, 1e-15, 10);
  real("--lr-pose-end", c.lr_pose_end, 1e-15, 10);
  real("--lr-focal", c.lr_focal, 1e-15, 10);
  real("--lr-focal-end", c.lr_focal_end, 1e-15, 10);
  real("--checkpoint-minutes", c.checkpoint_minutes, 0, 1e12);  // huge = never (tests use 1e9)
  real("--preview-minutes", c.preview_minutes, 0, 1e12);
  real("--cc-max-res", c.model.cc.max_res, 1, 1e6);
  real("--c2f", c.c2f_end, 0, 1);
  if (c.model.field == Field::grid) {
    integer("--grid-levels", c.model.gf.grid.levels, 1, 64);
    integer("--grid-log2-table", c.model.gf.grid.log2_table, 1, 24);
    real("--grid-max-res", c.model.gf.grid.max_res, c.model.gf.grid.base_res, 1e6);
    real("--grid-c2f-start", c.model.gf.c2f_start, 0, 64);
    real("--grid-density-init", c.model.gf.density_init, -kGridDensityInitMax, kGridDensityInitMax);
  }
  real("--camera-delay", c.camera_delay, 0, 0.99);
  // Options beyond the paper.
  integer("--images-per-step", c.images_per_step, 0, 1 << 20);  // 0: auto, resolved on load
  if (c.images_per_step > 0 && c.rays % c.images_per_step != 0)
    throw Error("--images-per-step", "", fmt::format("{} does not divide --rays {}",
                                                     c.images_per_step, c.rays),
                "a divisor of --rays: each image gets --rays / K rays");
  if (n_train > 0 && c.images_per_step > n_train)
    // Said in terms of the photos (the grid field's default, 0 = auto, never lands here: it
    // takes min(4, photos) on load).
    throw Error("--images-per-step", "",
                fmt::format("{} is more than the {} training image{} (every 8th photo, from the "
                            "first, is held out as a test view)",
                            c.images_per_step, n_train, n_train == 1 ? "" : "s"),
                fmt::format("1 to {}, a step's images being distinct: pass --images-per-step {}, "
                            "or add photos", n_train, n_train));
  real("--pyramid", c.pyramid, 0, 0.99);  // < 1: the run must end at full resolution
  real("--camera-start-psnr", c.camera_start_psnr, 0, 100);
  real("--focal-delay", c.focal_delay, 0, 0.99);
  if (c.focal_guard != 0 && !(c.focal_guard > 1 && c.focal_guard <= 100))
    throw Error("--focal-guard", fmt::format("{:g}", c.focal_guard), "out of range",
                "a factor above 1 (e.g. 2: the focal stays within half to twice its start), or 0 = off");
  real("--pose-precondition", c.pose_precondition, 0, 1e6);
  if (c.pose_precondition > 0 && c.holds_given_poses())
    throw Error("--pose-precondition", "", "given with --refine-poses off (nothing to precondition)",
                "--refine-poses on, or 0");
  if (c.pose_precondition > 0 && !c.ndc)
    throw Error("--pose-precondition", "", "given for a scene without NDC",
                "a forward-facing scene (its points fill the NDC box), or 0");
  if (c.ndc_fixed_focal && !c.ndc)
    throw Error("--ndc-fixed-focal", "", "given for a scene without NDC (--no-ndc)",
                "a forward-facing scene: the flag sets the focal of the NDC box");
  real("--ndc-box-scale", c.ndc_box_scale, 0.25, 4);
  if (c.ndc_box_scale != 1 && !c.ndc_fixed_focal)
    throw Error("--ndc-box-scale", fmt::format("{:g}", c.ndc_box_scale),
                "given without --ndc-fixed-focal (the learned box follows the learned focal)",
                "--ndc-fixed-focal too, or 1");
  real("--focal", c.focal_fx, 0, 1e7);
  real("--focal", c.focal_fy, 0, 1e7);
  if (c.focal_fov != 0 && !(c.focal_fov >= 10 && c.focal_fov <= 170))
    throw Error("--focal-fov", fmt::format("{:g}", c.focal_fov), "out of range",
                "a horizontal field of view of 10 to 170 degrees, or 0 (fx = W, fy = H)");
  if ((c.focal_fx > 0) != (c.focal_fy > 0))
    throw Error("--focal", "", "only one of fx, fy is set", "FX or FX,FY, both positive");
  if (c.focal_fx > 0 && !c.init_poses.empty() && c.init_focal)
    throw Error("--focal", "", "given with --init-poses, which also sets the focal",
                "--init-focal none with --init-poses, or no --focal");
  validate_restart_fields(c);
  real("--grid-decay", c.grid_decay, 0, 1e6);
  if (c.grid_decay > 0 && c.model.field != Field::grid)
    throw Error("--grid-decay", fmt::format("{:g}", c.grid_decay), "given for the MLP field",
                "--field grid (it decays the grid field's table)");
  real("--distortion", c.distortion, 0, 1e6);
  real("--last-distortion", c.last_distortion, 0, 1e6);
  real("--distortion-from", c.distortion_from, 0, 0.999);  // < 1: the loss has steps to act on
  real("--hold-cameras-from", c.hold_cameras_from, 0, 0.999);
  real("--last-distortion-from", c.last_distortion_from, 0, 0.999);
  real("--last-hold-cameras-from", c.last_hold_cameras_from, 0, 0.999);
  if (c.distortion_from > 0 && c.distortion <= 0)
    throw Error("--distortion-from", fmt::format("{:g}", c.distortion_from),
                "given without --distortion", "--distortion λ: the loss it starts");
  if (c.last_distortion_from > 0 && c.distortion <= 0 && c.last_distortion <= 0)
    throw Error("--last-distortion-from", fmt::format("{:g}", c.last_distortion_from),
                "given without --last-distortion or --distortion", "the loss it starts");
  validate_last_stage_fields(c);
  // (bootstrap_minutes < minutes is checked where the bootstrap starts, bootstrap_cameras: after
  // it, the run's config keeps bootstrap_minutes as a record while minutes is the rest.)
  integer("--camera-warmup", c.camera_warmup, 0, int64_t(1) << 40);
  real("--occupancy-start", c.occupancy_start, 0, 0.99);
  integer("--occupancy-every", c.occupancy_every, 1, 1 << 20);
  integer("--occupancy-res", c.occupancy_res, 4, 512);
  integer("--occupancy-probes", c.occupancy_probes, 2, 1024);
  if (c.occupancy && !c.ndc)
    throw Error("--occupancy", "", "on without NDC", "an NDC (forward-facing) scene: the grid "
                "covers the NDC box [-1, 1]³");
  if (c.occupancy && c.occupancy_probes < c.samples)
    throw Error("--occupancy-probes", "", fmt::format("{} is fewer than --samples {}",
                                                      c.occupancy_probes, c.samples),
                "at least as many probe intervals as samples");
  if (c.camera_start_psnr > 0 && c.camera_delay > 0)
    throw Error("--camera-start-psnr", "", "given with --camera-delay",
                "one of them: both choose when the cameras start");
}

namespace {

// The networks' keys (ModelConfig). Ranges: the CLI's (tools/cmd_train.cpp) where it has one,
// else what the kernels support.
// The five keys of a hash grid (the CC branch's "cc_", the grid field's "grid_"), same ranges.
void read_hashgrid_keys(const Reader& r, const std::string& prefix, HashGridConfig& g) {
  r.integer((prefix + "levels").c_str(), g.levels, 1, 64);
  r.integer((prefix + "features").c_str(), g.features, 1, 16);
  r.integer((prefix + "log2_table").c_str(), g.log2_table, 1, 24);
  r.real((prefix + "base_res").c_str(), g.base_res, 1, 1e6);
  r.real((prefix + "max_res").c_str(), g.max_res, 1, 1e6);
}

void read_model_keys(const Reader& r, ModelConfig& m) {
  std::string model = "hashcc";
  r.str("model", model);
  m.variant = parse_variant(model);
  r.integer("width", m.width, 1, 4096);
  r.integer("rgb_width", m.rgb_width, 1, 4096);
  r.integer("pos_bands", m.pos_bands, 0, 24);
  r.integer("dir_bands", m.dir_bands, 0, 24);
  r.integer("sh_degree", m.sh_degree, 1, 4);
  read_hashgrid_keys(r, "cc_", m.cc);
  r.integer("cc_hidden", m.cc_hidden, 1, 4096);
  std::string field = "mlp";  // configs from before the grid field have no "field": the MLP
  r.str("field", field);
  if (field != "mlp" && field != "grid")
    throw Error(r.file, "field", fmt::format("\"{}\" is not a field", field), "mlp or grid");
  m.field = parse_field(field);
  GridFieldConfig& gf = m.gf;
  read_hashgrid_keys(r, "grid_", gf.grid);
  r.flag("grid_smooth_grad", gf.grid.smooth_dx);
  r.integer("grid_hidden", gf.hidden, 1, 4096);
  r.integer("grid_geo", gf.geo, 0, 4096);
  r.integer("grid_rgb_hidden", gf.rgb_hidden, 1, 4096);
  r.real("grid_c2f_start", gf.c2f_start, 0, 64);
  r.real("grid_density_init", gf.density_init, -kGridDensityInitMax, kGridDensityInitMax);
}

// The run's keys: the step, the schedules, the options beyond the paper, the initial cameras.
void read_run_keys(const Reader& r, TrainConfig& c) {
  const json& j = r.j;
  const std::string& file = r.file;
  r.flag("ndc", c.ndc); r.flag("fx_only", c.fx_only);
  r.flag("ndc_fixed_focal", c.ndc_fixed_focal);  // absent before it: the learned focal, as ran
  r.real("ndc_box_scale", c.ndc_box_scale, 0.25, 4);  // absent before it: 1, as ran
  r.flag("stop_cc_to_camera", c.stop_cc_to_camera);
  r.integer("epochs", c.epochs, 0, double(int64_t(1) << 40));
  r.integer("steps", c.steps, 0, double(int64_t(1) << 40));
  r.real("minutes", c.minutes, 0, 1e7);
  r.integer("threads", c.threads, 0, 1024);
  if (j.contains("seed")) {
    if (!j.at("seed").is_number_unsigned() && !(j.at("seed").is_number_integer() && j.at("seed").get<int64_t>() >= 0))
      throw Error(file, "seed", "has the wrong type", "a non-negative integer");
    c.seed = j.at("seed").get<uint64_t>();
  }
  r.integer("rays", c.rays, 1, 1 << 20);
  r.integer("samples", c.samples, 2, 4096);
  r.integer("chunk_rays", c.chunk_rays, 0, 1024);
  r.real("lr_net", c.lr_net, 1e-15, 10); r.real("lr_net_end", c.lr_net_end, 1e-15, 10);
  r.real("lr_pose", c.lr_pose, 1e-15, 10); r.real("lr_pose_end", c.lr_pose_end, 1e-15, 10);
  r.real("lr_focal", c.lr_focal, 1e-15, 10); r.real("lr_focal_end", c.lr_focal_end, 1e-15, 10);
  r.real("checkpoint_minutes", c.checkpoint_minutes, 0, 1e12);
  r.real("preview_minutes", c.preview_minutes, 0, 1e12);
  r.real("c2f_end", c.c2f_end, 0, 1);
  r.real("camera_delay", c.camera_delay, 0, 0.99);
  r.integer("images_per_step", c.images_per_step, 0, 1 << 20);  // 0: auto (a plan's run record)
  r.real("pyramid", c.pyramid, 0, 0.99);
  r.real("camera_start_psnr", c.camera_start_psnr, 0, 100);
  r.integer("camera_warmup", c.camera_warmup, 0, double(int64_t(1) << 40));
  r.real("focal_delay", c.focal_delay, 0, 0.99);
  r.real("pose_precondition", c.pose_precondition, 0, 1e6);
  r.real("focal_fx", c.focal_fx, 0, 1e7); r.real("focal_fy", c.focal_fy, 0, 1e7);
  r.real("focal_fov", c.focal_fov, 0, 170);  // absent in older config.json: 0, the paper's start
  // Absent in a config.json from before the guard: off, so an old run resumes as it ran.
  c.focal_guard = 0;
  r.real("focal_guard", c.focal_guard, 0, 100);
  r.flag("fixed_focal", c.fixed_focal);
  r.str("cameras_from", c.cameras_from);
  r.real("bootstrap_minutes", c.bootstrap_minutes, 0, 1e7);
  r.integer("bootstrap_steps", c.bootstrap_steps, 0, double(int64_t(1) << 40));
  r.real("bootstrap_lr_pose", c.bootstrap_lr_pose, 0, 10);
  r.integer("restarts", c.restarts, 0, 64);
  r.real("restart_first", c.restart_first, 0, 0.99);
  r.real("restart_last", c.restart_last, 0, 0.99);
  r.integer("restart_steps", c.restart_steps, 0, double(int64_t(1) << 40));
  r.real("last_focal_hold", c.last_focal_hold, 0, 0.99);
  r.real("first_focal_hold", c.first_focal_hold, 0, 0.99);
  r.integer("last_focal_stages", c.last_focal_stages, 1, 64);
  r.integer("last_grid_log2_table", c.last_grid_log2_table, 0, 24);
  r.integer("last_samples", c.last_samples, 0, 4096);
  r.real("last_lr_net", c.last_lr_net, 0, 10);
  r.real("last_lr_net_end", c.last_lr_net_end, 0, 10);
  r.real("last_lr_focal_end", c.last_lr_focal_end, 0, 10);
  r.real("last_lr_pose_end", c.last_lr_pose_end, 0, 10);
  r.real("grid_decay", c.grid_decay, 0, 1e6);
  r.real("distortion", c.distortion, 0, 1e6);
  r.real("last_distortion", c.last_distortion, 0, 1e6);
  r.flag("distortion_to_camera", c.distortion_to_camera);
  r.real("distortion_from", c.distortion_from, 0, 0.999);
  r.real("hold_cameras_from", c.hold_cameras_from, 0, 0.999);
  r.real("last_distortion_from", c.last_distortion_from, 0, 0.999);
  r.real("last_hold_cameras_from", c.last_hold_cameras_from, 0, 0.999);
  r.flag("occupancy", c.occupancy);
  r.real("occupancy_start", c.occupancy_start, 0, 0.99);
  r.integer("occupancy_every", c.occupancy_every, 1, 1 << 20);
  r.integer("occupancy_res", c.occupancy_res, 4, 512);
  r.integer("occupancy_probes", c.occupancy_probes, 2, 1024);
  r.str("init_poses", c.init_poses);
  r.flag("init_focal", c.init_focal);
  r.flag("refine_poses", c.refine_poses);
  r.str("preset", c.preset);
  const auto& names = preset_names();
  if (std::find(names.begin(), names.end(), c.preset) == names.end())
    throw Error(file, "preset", fmt::format("\"{}\" is not a preset", c.preset), preset_names_text());
}

}  // namespace

TrainConfig train_config_from_json(const std::string& text, const std::string& file) {
  json j;
  try {
    j = json::parse(text);
  } catch (const std::exception& e) {
    std::string what = e.what();
    throw Error(file, "", fmt::format("not valid JSON ({})", what.substr(0, 200)));
  }
  if (!j.is_object()) throw Error(file, "", "not a JSON object", "a hashcc run config");
  TrainConfig c;
  const Reader r{j, file};
  r.str("data", c.data); r.str("images_folder", c.images_folder); r.str("out", c.out);
  // Absent in a config.json from before --max-side: 0, the files' size, as that run trained.
  c.max_side = 0;
  r.integer("max_side", c.max_side, 0, 1 << 16);
  read_model_keys(r, c.model);
  read_run_keys(r, c);
  return c;
}

// --preset NAME: "paper" (the default, formulas.md §6) sets nothing; every other name is a
// built-in recipe (recipes/NAME.json, train/plan.h), so `--preset laptop` is `--plan laptop`.
const std::vector<std::string>& preset_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n = {"paper"};
    for (const std::string& r : recipe_names()) n.push_back(r);
    return n;
  }();
  return names;
}

std::string preset_names_text() {
  std::string text;
  const auto& names = preset_names();
  for (size_t i = 0; i < names.size(); ++i)
    text += (i == 0 ? "" : i + 1 == names.size() ? " or " : ", ") + names[i];
  return text;
}

const std::vector<PresetEntry>& field_defaults(const std::string& field) {
  static const std::vector<PresetEntry> mlp = {};
  static const std::vector<PresetEntry> grid = {
      {"--lr-net", "1e-2", "a hash table learns ~10x faster than an MLP's weights (instant-ngp's "
       "rate): at 1e-3 the grid field's PSNR lagged",
       [](TrainConfig& c) { c.lr_net = 1e-2; }},
      {"--lr-net-end", "1e-4", "the paper's 100x decay of the networks' rate",
       [](TrainConfig& c) { c.lr_net_end = 1e-4; }},
      {"--c2f", "0.5", "level curriculum over the first half of the run (Heo et al.)",
       [](TrainConfig& c) { c.c2f_end = 0.5; }},
      {"--samples", "32", "the grid's cost is per sample, and more steps beat more samples: at "
       "equal CPU time on the simulated scene 32 samples reached 0.44 deg and 27.0 dB against "
       "0.80 deg and 25.9 dB with 64 (docs/results/grid)",
       [](TrainConfig& c) { c.samples = 32; }},
      {"--lr-pose-end", "1e-4", "the laptop preset's travel budget for the cameras",
       [](TrainConfig& c) { c.lr_pose_end = 1e-4; }},
      {"--lr-focal-end", "1e-4", "the same for the focal",
       [](TrainConfig& c) { c.lr_focal_end = 1e-4; }},
      {"--images-per-step", "min(4, photos)", "each camera gets a gradient 4x as often (the laptop "
       "preset); a folder of fewer training photos takes them all (0 = auto in config.json until "
       "the scene is loaded)",
       [](TrainConfig& c) { c.images_per_step = 0; }},
  };
  if (field == "grid") return grid;
  return mlp;
}

}  // namespace hashcc
