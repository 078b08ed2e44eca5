// train/plan.h — a training plan as data: a base override plus a list of stages.
//
// A staged run (the grid field's restarts, the camera bootstrap, a recipe such as fern60) is a
// TrainPlan: each stage is a partial override of the run's settings, in the keys of config.json,
// a budget, and whether it starts from the cameras the stage before it learned. Built-in plans
// are the JSON files of recipes/ (embedded in the binary at build time); `--plan FILE|NAME`
// picks one and `--set [STAGE.]KEY=VALUE` changes any of its values. Every stage's config is
// resolved and validated before stage 1 runs, so a bad value is refused up front, naming the
// plan, the stage and the key. RUN/plan.json records the resolved plan and which stages have
// finished: `hashcc train --resume RUN` continues a staged run from its first unfinished stage.
//
// A stage may try alternatives ("try": a list of overrides, e.g. focal_fov 40/55/70/90): its
// budget is split equally among them, each trains in RUN/stageK/tryJ from the same starting
// cameras, and the one whose training views fit best (the highest final running train PSNR,
// TrainState::psnr_ema; ties: the first) is kept: the next stage starts from its cameras. The
// last stage may not try (what it ends with is the run's result, in RUN itself).
//
// Why data rather than flags: a per-stage flag (--last-samples, --first-focal-hold, …) was one
// field, one flag, a JSON key, a range check and a hand copy per stage, and the hand copies
// drifted (a bootstrap dropped --first-focal-hold). A stage override reuses the keys and checks
// every run already has.
#pragma once
#include <atomic>
#include <functional>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "train/recipes.h"
#include "train/trainer.h"

namespace hashcc {

// How long a stage runs. Shares and "rest" are of the run's budget: --minutes, else --steps.
struct StageBudget {
  enum class Kind {
    share,    // value = a fraction of the run's minutes or steps (floor, at least 1 step)
    steps,    // value = a number of steps, whatever the run's budget
    minutes,  // value = minutes (generated plans: a bootstrap's phases)
    rest,     // what the stages before left of value × the run's budget (1 = of all of it);
              // by minutes at least a twentieth of it, counted from the earlier stages'
              // checkpoints (the minutes they trained), not from the clock
    own       // the length the stage's config already has (--epochs, --steps or --minutes)
  };
  Kind kind = Kind::rest;
  double value = 1;
};

struct PlanStage {
  nlohmann::json set = nlohmann::json::object();  // config.json key → value
  StageBudget budget;
  bool cameras_from_previous = true;  // start from the stage before's cameras (--cameras-from)
  std::string dir;                    // inside the run folder; "" = stageK, the last: the run's
  // Alternatives ("try"): each a partial override on top of `set`, in config.json keys. Empty =
  // the stage trains once. With N of them, each gets 1/N of the stage's budget and its own
  // folder dir/tryJ (1-based); the best fit of the training views is kept (train/plan.h, top).
  std::vector<nlohmann::json> tries;
};

struct TrainPlan {
  std::string name;    // the recipe's name ("fern60"), or the file it came from
  std::string source;  // what errors name: "recipe fern60", "plan /path/x.json", "--restarts"
  nlohmann::json base = nlohmann::json::object();  // every stage, unless a flag was given
  std::set<std::string> forced;  // base keys from --set: they win over the flags too
  std::vector<PlanStage> stages;
};

// The built-in recipes: recipe_names(), embedded_recipes() (train/recipes.h).
// Reads a plan: a built-in recipe's name, or a JSON file. Each value may be given bare or as
// {"value": V, "why": "..."}; the "why" is for the reader (and `hashcc train --help`).
TrainPlan load_plan(const std::string& name_or_file);
TrainPlan parse_plan(const std::string& text, const std::string& name, const std::string& source);
// --set [STAGE.]KEY=VALUE: STAGE is a number (1-based), a range "2-4", "first" or "last"; none =
// the base (every stage; it wins over the flags). A stage's "steps", "share" or "budget=rest" set
// its budget. VALUE is JSON (1e-3, true, "grid") or, if it does not parse, a string.
void set_plan_value(TrainPlan& plan, const std::string& assignment);

// The plan's base applied to a run's config: each key unless `given(key)` says its flag was on
// the command line (a --set key always applies). Returns the keys it set.
std::vector<std::string> apply_plan_base(TrainConfig& c, const TrainPlan& plan,
                                         const std::function<bool(const std::string&)>& given);
// The command-line flag of a config.json key ("lr_net" → "--lr-net", "c2f_end" → "--c2f").
std::string flag_of_key(const std::string& key);

// One alternative of a stage that tries several, resolved: the stage's config with its
// overrides, its folder (RUN/stageK/tryJ) and its share of the stage's budget.
struct ResolvedTry {
  TrainConfig config;
  nlohmann::json set;       // its own overrides (the stage's "set" is under them)
  bool finished = false;
  double psnr_ema = 0;      // its final running train PSNR (dB), once finished
};

// One stage, resolved: its whole config (out = its folder, cameras_from = the stage before's;
// with tries, the folder holding them and the budget they share, never trained itself).
struct ResolvedStage {
  TrainConfig config;
  StageBudget budget;
  nlohmann::json set;
  bool finished = false;            // with tries: all finished and one kept
  std::vector<ResolvedTry> tries;   // empty: the stage trains once
  int kept = -1;                    // with tries: the index (0-based) of the kept one, once chosen
};

// A plan resolved against one run: what RUN/plan.json records.
struct PlanRun {
  TrainPlan plan;
  TrainConfig run;  // the run's config before any stage override (flags, base, field defaults)
  std::vector<ResolvedStage> stages;
  // start_plan made the run folder: if stage 1 cannot start (a scene that does not load, a
  // setting this scene refuses), the folder goes again, so bad input leaves nothing behind.
  bool made_run_dir = false;
};

// Resolves and validates every stage and every alternative of a stage that tries several
// (Error naming the plan, the stage, the alternative and the key).
PlanRun resolve_plan(const TrainPlan& plan, const TrainConfig& run);
// A new staged run: resolve_plan, then the run folder gets plan.json (and loses any checkpoint
// an older run left in a stage's folder, which --resume would otherwise take for this plan's).
PlanRun start_plan(const TrainPlan& plan, const TrainConfig& run);
// RUN/plan.json read back (--resume), resolved again.
PlanRun open_plan(const std::string& run_dir);
bool has_plan(const std::string& run_dir);
// Records in RUN/plan.json that the last stage (trained in RUN itself) has finished.
void mark_last_stage_finished(const std::string& run_dir);

// Runs (or resumes) every stage before the last; false when interrupted. A stage with
// alternatives runs each unfinished one, records its fit, then keeps the best (train/plan.h, top). observer_for
// (optional) makes each stage's after_step hook from its trainer.
bool run_plan_until_last(PlanRun& pr, const std::atomic<bool>* stop,
                         const AfterStepFactory& observer_for = {});
// The last stage's config as it starts now (a "rest" budget counts the minutes spent so far).
TrainConfig last_stage_config(const PlanRun& pr);
// Whether the last stage has a checkpoint to resume from (it started).
bool last_stage_started(const PlanRun& pr);
// Every stage, the last included (tests, `hashcc study`). False when interrupted.
bool run_plan(PlanRun& pr, const std::atomic<bool>* stop, const AfterStepFactory& observer_for = {});

// Generators: the plans that --restarts and --bootstrap-minutes have always meant, from the
// fields of `whole` (which the stages keep as a record). The plan is then run like any other.
TrainPlan restarts_plan(const TrainConfig& whole);
TrainPlan bootstrap_plan(const TrainConfig& whole,
                         const std::function<bool(const std::string&)>& given);

// The keys whose values differ between two configs (a generated stage's override).
nlohmann::json config_diff(const TrainConfig& from, const TrainConfig& to);

}  // namespace hashcc
