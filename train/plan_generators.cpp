// train/plan_generators.cpp — the plans that --restarts and --bootstrap-minutes generate.
//
// Before plans were data, these two wrote each stage's TrainConfig by hand, in place, and a
// field one of them forgot was silently dropped (the bootstrap's grid phase lost
// --first-focal-hold). Now each builds a TrainPlan — per stage an override, a budget and where
// its cameras come from — and the one plan runner (train/plan.cpp) resolves, validates, records
// and runs it, the same way as a recipe of recipes/.
#include <algorithm>
#include <fmt/core.h>

#include "core/error.h"
#include "train/plan.h"

using nlohmann::json;

namespace hashcc {

namespace {

// Whether restart stage k (1 … K+1) learns one focal held for its first last_focal_hold.
bool holds_one_focal(const TrainConfig& whole, int k) {
  return whole.last_focal_hold > 0 && k > whole.restarts + 1 - whole.last_focal_stages;
}

// The last stage's own values (old config.json keys last_*), as the keys they set.
json last_stage_set(const TrainConfig& w) {
  json set = json::object();
  const auto put = [&](const char* key, double v, bool integral) {
    if (v > 0) set[key] = integral ? json(int64_t(v)) : json(v);  // 0 = as the stages before
  };
  put("grid_log2_table", w.last_grid_log2_table, true);
  put("samples", w.last_samples, true);
  put("lr_net", w.last_lr_net, false);
  put("lr_net_end", w.last_lr_net_end, false);
  put("lr_focal_end", w.last_lr_focal_end, false);
  put("lr_pose_end", w.last_lr_pose_end, false);
  put("distortion", w.last_distortion, false);
  put("distortion_from", w.last_distortion_from, false);
  put("hold_cameras_from", w.last_hold_cameras_from, false);
  return set;
}

// Phase 1 of the bootstrap: the grid field with its own defaults, not the values meant for the
// MLP (lr_net, samples, c2f, … keep the grid's), same scene and seed. What phase 1 does take from
// the command: the grid field's own settings (grid_*, which only phase 1 can use), the camera's
// (the focal given or held, fx_only, focal_delay, pose_precondition, and the camera rate
// bootstrap_lr_pose), since the cameras are what the bootstrap is for, and the restarts.
TrainConfig bootstrap_phase1(const TrainConfig& c) {
  TrainConfig boot;
  boot.data = c.data;
  boot.images_folder = c.images_folder;
  boot.out = c.out + "/bootstrap";
  boot.model.variant = c.model.variant;
  boot.model.field = Field::grid;
  boot.model.gf = c.model.gf;  // no grid default sets a --grid-* flag, so these stay the user's
  for (const PresetEntry& e : field_defaults("grid")) e.set(boot);
  boot.ndc = c.ndc;
  boot.fx_only = c.fx_only;
  boot.focal_fx = c.focal_fx;
  boot.focal_fy = c.focal_fy;
  boot.fixed_focal = c.fixed_focal;
  boot.init_focal = c.init_focal;
  boot.focal_delay = c.focal_delay;
  boot.pose_precondition = c.pose_precondition;
  boot.restarts = c.restarts;  // the grid phase is cut into stages
  boot.restart_first = c.restart_first;
  boot.restart_last = c.restart_last;
  boot.restart_steps = c.restart_steps;
  boot.first_focal_hold = c.first_focal_hold;  // dropped by the hand copy before plans (issue 50)
  boot.last_focal_hold = c.last_focal_hold;
  boot.last_focal_stages = c.last_focal_stages;
  if (c.bootstrap_lr_pose > 0) {  // lr_pose is phase 2's; phase 1 has its own
    boot.lr_pose = c.bootstrap_lr_pose;
    boot.lr_pose_end = std::min(boot.lr_pose_end, boot.lr_pose);
  }
  boot.threads = c.threads;
  boot.seed = c.seed;
  boot.progress = c.progress;
  boot.checkpoint_minutes = c.checkpoint_minutes;
  boot.preview_minutes = c.preview_minutes;
  if (c.bootstrap_steps > 0) boot.steps = c.bootstrap_steps;
  else boot.minutes = c.bootstrap_minutes;
  validate_train_config(boot);
  return boot;
}

}  // namespace

// Why restarts (measured on fern, docs/results/grid): a field grown from identity settles the
// cameras early on one member of the rotation/depth family (2.0° at 30 minutes, flat from ~8,000
// steps on), and a young field pulls the focal down. A fresh field grown on those cameras, all
// levels on from its start, moves them on towards the truth (15 + 15 minutes: 1.43°; a third
// stage: 0.77°). The level curriculum has done its work in stage 1, where it lets the cameras
// travel far from identity; from near cameras the full field is better (1.44° against 1.63°).
TrainPlan restarts_plan(const TrainConfig& whole) {
  HCC_REQUIRE(whole.model.field == Field::grid, "--restarts", "", "given for the MLP field",
              "--field grid, or --bootstrap-minutes (its grid phase restarts)");
  HCC_REQUIRE(whole.minutes > 0 || whole.steps > 0, "--restarts", "", "without --minutes or --steps",
              "a budget in minutes or steps, cut into stages");
  // The command's own --focal-delay would hold the focal in every stage, beside the hold that
  // first_focal_hold gives stage 1.
  if (whole.first_focal_hold > 0 && whole.focal_delay > 0)
    throw Error("--first-focal-hold", fmt::format("{:g}", whole.first_focal_hold),
                "given with --focal-delay", "one of them (--focal-delay holds it in every stage)");
  const int stages = whole.restarts + 1;
  restart_share(whole, 1);  // shares that do not fill the budget: refused before any stage runs
  if (whole.restart_steps > 0 && whole.minutes <= 0) restart_stage_steps(whole, stages);  // nor steps
  TrainPlan p;
  p.name = fmt::format("restarts{}", whole.restarts);
  p.source = "--restarts";
  for (int k = 1; k <= stages; ++k) {
    PlanStage s;
    s.cameras_from_previous = k > 1;
    // By steps: each stage's count (restart_stage_steps). By minutes: a share, or with
    // restart_steps N steps for the stages between and the minutes left for the last.
    const bool between = whole.restart_steps > 0 && k > 1 && k < stages;
    if (whole.minutes <= 0 || between)
      s.budget = {StageBudget::Kind::steps, double(restart_stage_steps(whole, k))};
    else if (whole.restart_steps > 0 && k == stages)
      s.budget = {StageBudget::Kind::rest, 1};
    else
      s.budget = {StageBudget::Kind::share, restart_share(whole, k)};
    if (k == stages) s.set = last_stage_set(whole);
    if (k == 1 && whole.first_focal_hold > 0) s.set["focal_delay"] = whole.first_focal_hold;
    if (k > 1) s.set["c2f_end"] = 0.0;  // all levels on from a restart's start
    if (holds_one_focal(whole, k)) {    // one focal, held through the young field's steps
      s.set["fx_only"] = true;
      s.set["focal_delay"] = whole.last_focal_hold;
    }
    p.stages.push_back(s);
  }
  return p;
}

// The bootstrap: the grid field learns the cameras (RUN/bootstrap, with its own restarts in
// RUN/bootstrap/stageK), then the paper's network trains from them in RUN.
TrainPlan bootstrap_plan(const TrainConfig& c, const std::function<bool(const std::string&)>& given) {
  HCC_REQUIRE(c.model.field == Field::mlp, "--bootstrap-minutes", "", "given with --field grid",
              "--field mlp: the bootstrap hands the grid field's cameras to the paper's network");
  HCC_REQUIRE(c.cameras_from.empty() && c.init_poses.empty(), "--bootstrap-minutes", "",
              "given with --cameras-from or --init-poses", "one way to start the cameras");
  // Checked here, not in validate_train_config: phase 2's config keeps bootstrap_minutes as a
  // record of the bootstrap while its minutes are what was left (so it would fail that check).
  if (c.bootstrap_minutes > 0 && c.minutes > 0 && c.bootstrap_minutes >= c.minutes)
    throw Error("--bootstrap-minutes", "", fmt::format("{} is not less than --minutes {}",
                                                       c.bootstrap_minutes, c.minutes),
                "a part of the budget: the paper's network trains for the rest");
  const TrainConfig boot = bootstrap_phase1(c);

  TrainPlan p;
  p.name = "bootstrap";
  p.source = "--bootstrap-minutes";
  const json to_boot = config_diff(c, boot);
  const auto grid_stage = [&](PlanStage s, const std::string& dir) {
    json set = to_boot;
    set.update(s.set);  // the restart stage's own values win
    s.set = set;
    s.dir = dir;
    // Phase 1's budget is its own (bootstrap_minutes or _steps), not a part of the run's.
    if (s.budget.kind == StageBudget::Kind::share) s.budget = {StageBudget::Kind::minutes, s.budget.value * boot.minutes};
    if (s.budget.kind == StageBudget::Kind::rest) {
      HCC_REQUIRE(c.minutes > 0, "--bootstrap-minutes", "", "with --restart-steps and no --minutes",
                  "--minutes: the last grid stage takes what is left of the bootstrap's minutes");
      s.budget.value = boot.minutes / c.minutes;
    }
    p.stages.push_back(s);
  };
  if (boot.restarts > 0) {
    const TrainPlan r = restarts_plan(boot);
    for (size_t k = 0; k < r.stages.size(); ++k)
      grid_stage(r.stages[k], k + 1 == r.stages.size() ? "bootstrap" : fmt::format("bootstrap/stage{}", k + 1));
  } else {
    grid_stage({json::object(), {StageBudget::Kind::own, 0}, false, ""}, "bootstrap");
  }
  // Phase 2: the paper's network from those cameras, for what is left of the budget, its camera
  // rates starting at the bootstrap's end values (unless given).
  TrainConfig p2 = c;
  if (c.minutes > 0) p2.minutes = std::max(c.minutes - c.bootstrap_minutes, 1e-3);
  if (!given("--lr-pose")) p2.lr_pose = std::min(c.lr_pose, boot.lr_pose_end);
  if (!given("--lr-focal")) p2.lr_focal = std::min(c.lr_focal, boot.lr_focal_end);
  p2.lr_pose_end = std::min(p2.lr_pose_end, p2.lr_pose);
  p2.lr_focal_end = std::min(p2.lr_focal_end, p2.lr_focal);
  p.stages.push_back({config_diff(c, p2), {StageBudget::Kind::own, 0}, true, "."});
  return p;
}

bool grid_restarts(TrainConfig& c, const std::atomic<bool>* stop,
                   const AfterStepFactory& observer_for) {
  PlanRun pr = start_plan(restarts_plan(c), c);
  if (!run_plan_until_last(pr, stop, observer_for)) return false;
  c = last_stage_config(pr);
  return true;
}

bool bootstrap_cameras(TrainConfig& c, const std::atomic<bool>* stop,
                       const std::function<bool(const std::string&)>& given,
                       const AfterStepFactory& observer_for) {
  PlanRun pr = start_plan(bootstrap_plan(c, given), c);
  if (!run_plan_until_last(pr, stop, observer_for)) return false;
  c = last_stage_config(pr);
  if (c.refine_poses)
    fmt::print("bootstrap done: the {} network trains from its cameras in {} (camera lr {:g} -> {:g})\n",
               variant_name(c.model.variant), c.out, c.lr_pose, c.lr_pose_end);
  else
    fmt::print("bootstrap done: the {} network trains on its cameras, held (--refine-poses off), "
               "in {}\n", variant_name(c.model.variant), c.out);
  return true;
}

}  // namespace hashcc
