// test/test_plan.cpp — training plans as data (train/plan.h): recipes, --set, validation up
// front, the fern60 recipe against the stages the old preset made, and a staged run resumed
// from its first unfinished stage.
#include <catch2/catch.hpp>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/fileio.h"
#include "train/checkpoint.h"
#include "train/plan.h"
#include "train/trainer.h"
#include "test/fixtures.h"

using namespace hashcc;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

// A stage's config.json without what names its place or records the command that made it
// (the old per-stage fields, the preset's name): the values the stage trained with.
json stage_settings(const std::string& dir) {
  json j = json::parse(read_file_bytes(dir + "/config.json", 1 << 20));
  for (const char* k : {"out", "cameras_from", "preset", "restarts", "restart_first",
                        "restart_last", "restart_steps", "first_focal_hold", "bootstrap_minutes",
                        "bootstrap_steps", "bootstrap_lr_pose"})
    j.erase(k);
  for (auto it = j.begin(); it != j.end();)
    it = it.key().rfind("last_", 0) == 0 ? j.erase(it) : std::next(it);
  return j;
}

// The learned parameters of a run's checkpoint, bit for bit.
std::vector<std::string> learned(const std::string& dir) {
  const Checkpoint c = load_checkpoint(dir + "/checkpoint.bin");
  std::vector<std::string> out;
  for (const char* k : {"net", "poses", "focal", "net.m", "poses.v"}) out.push_back(c.sections.at(k));
  return out;
}

// The loss column of a run's log.csv (the first N steps' losses, as text: bitwise).
std::vector<std::string> losses(const std::string& dir) {
  std::ifstream in(dir + "/log.csv");
  std::string line;
  std::vector<std::string> out;
  std::getline(in, line);
  while (std::getline(in, line)) {
    const size_t a = line.find(','), b = line.find(',', a + 1), c = line.find(',', b + 1);
    out.push_back(line.substr(b + 1, c - b - 1));
  }
  return out;
}

}  // namespace

TEST_CASE("recipes: built in, readable, each value as the config.json key it sets",
          "[plan]") {
  const auto& names = recipe_names();
  CHECK(std::find(names.begin(), names.end(), "fern60") != names.end());
  CHECK(std::find(names.begin(), names.end(), "laptop") != names.end());
  const TrainPlan p = load_plan("fern60");
  REQUIRE(p.stages.size() == 5);
  CHECK(p.base.at("field") == "grid");
  CHECK(p.stages[0].budget.kind == StageBudget::Kind::share);
  CHECK(p.stages[1].budget.kind == StageBudget::Kind::steps);
  CHECK(p.stages[4].budget.kind == StageBudget::Kind::rest);
  CHECK(p.stages[4].set.at("samples") == 64);
  const TrainPlan l = load_plan("laptop");
  CHECK(l.stages.size() == 1);
  CHECK(l.base.at("images_per_step") == 4);
}

TEST_CASE("--set: the base, one stage, a range, the last; budgets; bad keys refused by name",
          "[plan]") {
  TrainPlan p = load_plan("fern60");
  set_plan_value(p, "samples=16");
  set_plan_value(p, "last.samples=48");
  set_plan_value(p, "2.lr_pose=1e-3");
  set_plan_value(p, "2-4.steps=2");
  set_plan_value(p, "first.share=0.5");
  CHECK(p.base.at("samples") == 16);
  CHECK(p.forced.count("samples") == 1);
  CHECK(p.stages[4].set.at("samples") == 48);
  CHECK(p.stages[1].set.at("lr_pose") == 1e-3);
  for (int k = 1; k <= 3; ++k) CHECK(p.stages[k].budget.value == 2);
  CHECK(p.stages[0].budget.value == 0.5);
  CHECK_THROWS_WITH(set_plan_value(p, "2.no_such_key=1"), Catch::Contains("no_such_key"));
  CHECK_THROWS_WITH(set_plan_value(p, "7.samples=1"), Catch::Contains("not a stage"));
  CHECK_THROWS_WITH(set_plan_value(p, "2.last_samples=64"), Catch::Contains("decided by the plan"));
  CHECK_THROWS_WITH(set_plan_value(p, "samples"), Catch::Contains("KEY=VALUE"));
}

TEST_CASE("a plan is resolved and checked whole before stage 1 runs: errors name the plan, the "
          "stage and the key", "[plan][cli]") {
  const std::string data = test::sim_scene("plan_check", 6, 48, 36);
  const std::string out = test::tmp("plan_check_run", true);
  const std::vector<std::string> base = {"train", "--data", data, "--out", out, "--rays", "64",
                                         "--no-progress", "--threads", "1", "--steps", "16",
                                         "--plan", "fern60", "--set", "2-4.steps=2"};
  // A bad value in the last stage: refused before stage 1 made its folder.
  std::vector<std::string> a = base;
  a.insert(a.end(), {"--set", "last.samples=1"});
  CHECK(test::cli(a) == 2);
  CHECK_FALSE(fs::exists(out + "/stage1"));
  TrainConfig run = test::tiny_train_config(data, out, 16);
  run.model.field = Field::grid;
  TrainPlan p = load_plan("fern60");
  set_plan_value(p, "2-4.steps=2");
  set_plan_value(p, "last.samples=1");
  CHECK_THROWS_WITH(resolve_plan(p, run), Catch::Contains("recipe fern60 stage 5") &&
                                              Catch::Contains("samples"));
  // A grid key for a stage of the MLP field.
  TrainPlan m = load_plan("fern60");
  set_plan_value(m, "2-4.steps=2");
  set_plan_value(m, "last.field=mlp");
  CHECK_THROWS_WITH(resolve_plan(m, run), Catch::Contains("recipe fern60 stage 5: grid_log2_table"));
  // Stages that do not fit the budget.
  TrainPlan f = load_plan("fern60");
  CHECK_THROWS_WITH(resolve_plan(f, run), Catch::Contains("stage 5: budget"));
}

// The fern60 recipe (recipes/fern60.json) is the old --preset fern60 written down. Before the
// recipe, the preset was a table of C++ setters whose stages came from --restarts 4
// --restart-first 0.25 --restart-steps N --last-focal-hold 0.1 --last-focal-stages 2 --last-*;
// the legacy generator restarts_plan still makes them from those fields (old config.json files
// hold them). At --threads 1 with a --steps budget the recipe trains those stages bit for bit:
// the same step counts, settings, losses and parameters. (Checked once more against the binary
// of the commit before plans, 8c9fa8f: the same, stage by stage, for this run, for --restarts
// with --last-focal-hold or --first-focal-hold, and for the bootstrap with restarts.)
TEST_CASE("plan fern60 trains the stages of the old --preset fern60 bitwise (--threads 1, --steps)",
          "[plan][cli][fern60]") {
  const std::string data = test::sim_scene("plan_fern60", 6, 48, 36);
  const std::string old_out = test::tmp("fern60_old", true), new_out = test::tmp("fern60_new", true);
  REQUIRE(test::cli({"train", "--data", data, "--rays", "64", "--samples", "8", "--no-progress",
                     "--threads", "1", "--steps", "16", "--out", new_out, "--plan", "fern60",
                     "--set", "2-4.steps=2"}) == 0);
  {
    // The old preset's values, as its table set them on top of the flags above, then the grid
    // field's defaults for the flags neither gave.
    TrainConfig c;
    c.data = data;
    c.out = old_out;
    c.rays = 64;
    c.samples = 8;
    c.threads = 1;
    c.steps = 16;
    c.progress = false;
    c.model.field = Field::grid;
    c.model.gf.density_init = 2;
    c.lr_pose = 3e-3;
    c.lr_net = 2e-2;
    c.lr_net_end = 1e-3;
    c.c2f_end = 0.5;
    c.lr_pose_end = 1e-4;
    c.lr_focal_end = 1e-4;
    c.images_per_step = 4;
    c.restarts = 4;
    c.restart_first = 0.25;
    c.restart_steps = 2;
    c.last_focal_hold = 0.1;
    c.last_focal_stages = 2;
    c.last_grid_log2_table = 17;
    c.last_samples = 64;
    c.last_lr_pose_end = 1e-5;
    c.last_hold_cameras_from = 0.7;
    REQUIRE(grid_restarts(c, nullptr));
    Trainer last(c);
    REQUIRE(last.run());
  }
  const std::vector<std::string> dirs = {"/stage1", "/stage2", "/stage3", "/stage4", ""};
  const std::vector<size_t> steps = {4, 2, 2, 2, 6};  // ⌊16/4⌋, 3 × 2, the rest
  for (size_t k = 0; k < dirs.size(); ++k) {
    INFO("stage " << k + 1);
    CHECK(stage_settings(old_out + dirs[k]) == stage_settings(new_out + dirs[k]));
    CHECK(losses(new_out + dirs[k]).size() == steps[k]);
    CHECK(losses(old_out + dirs[k]) == losses(new_out + dirs[k]));
    CHECK(learned(old_out + dirs[k]) == learned(new_out + dirs[k]));
  }
  // The new run records its plan: each stage's folder, budget and overrides.
  const json plan = json::parse(read_file_bytes(new_out + "/plan.json", 1 << 20));
  REQUIRE(plan.at("stages").size() == 5);
  CHECK(plan.at("stages")[1].at("dir") == "stage2");
  CHECK(plan.at("stages")[1].at("budget") == json{{"steps", 2}});
  CHECK(plan.at("stages")[4].at("set").at("samples") == 64);
  CHECK(plan.at("stages")[3].at("finished") == true);
  // --preset fern60 is not this plan any more: it names the default, the forward recipe that
  // replaced it (issue 49), bit for bit --preset forward's run, recorded as "forward".
  const auto run_preset = [&](const std::string& preset) {
    const std::string out = test::tmp("fern60_alias_" + preset, true);
    REQUIRE(test::cli({"train", "--data", data, "--rays", "64", "--samples", "8", "--no-progress",
                       "--threads", "1", "--steps", "16", "--out", out, "--preset", preset,
                       "--set", "2-4.steps=2"}) == 0);
    return out;
  };
  const std::string alias_out = run_preset("fern60"), forward_out = run_preset("forward");
  CHECK(learned(alias_out) == learned(forward_out));
  CHECK(learned(alias_out) != learned(new_out));
  CHECK(Trainer::open(alias_out).config().preset == "forward");
  CHECK(Trainer::open(alias_out).config().pose_precondition == 0.1);  // forward's; fern60 has none
}

// A staged run interrupted inside stage 2 of 3 and resumed ends where an uninterrupted run ends,
// bit for bit at one thread: the finished stage is not run again, the interrupted one continues
// from its checkpoint, and the last starts from its cameras.
TEST_CASE("a staged run interrupted in stage 2 resumes from its first unfinished stage, bitwise",
          "[plan][resume]") {
  test::ThreadGuard one(1);
  const std::string data = test::sim_scene("plan_resume", 6, 48, 36);
  const std::string dir = test::fresh_dir("plan_resume_files");
  write_file_atomic(dir + "/three.json", R"({
    "stages": [
      {"budget": {"share": 0.4}},
      {"budget": {"steps": 5}, "set": {"c2f_end": 0}},
      {"budget": "rest", "set": {"c2f_end": 0, "samples": 24}}
    ]})");
  const TrainPlan plan = load_plan(dir + "/three.json");
  const auto run_for = [&](const std::string& out) {
    TrainConfig c = test::tiny_train_config(data, out, 15);
    c.model.field = Field::grid;
    c.threads = 1;
    for (const PresetEntry& e : field_defaults("grid")) e.set(c);
    return c;
  };
  const std::string whole = test::tmp("plan_resume_whole", true);
  PlanRun a = start_plan(plan, run_for(whole));
  REQUIRE(run_plan(a, nullptr));

  const std::string cut = test::tmp("plan_resume_cut", true);
  PlanRun b = start_plan(plan, run_for(cut));
  std::atomic<bool> stop{false};
  const AfterStepFactory stop_in_stage2 = [&](const Trainer& t) {
    const bool stage2 = t.config().out == cut + "/stage2";
    return std::function<void(const Trainer&)>([&stop, stage2](const Trainer& s) {
      if (stage2 && s.state().step == 2) stop = true;
    });
  };
  REQUIRE_FALSE(run_plan(b, &stop, stop_in_stage2));
  CHECK(Trainer::open(cut + "/stage2").state().step == 2);
  CHECK_FALSE(fs::exists(cut + "/stage3"));
  CHECK_FALSE(fs::exists(cut + "/checkpoint.bin"));
  PlanRun c = open_plan(cut);
  CHECK(c.stages[0].finished);
  CHECK_FALSE(c.stages[1].finished);
  REQUIRE(run_plan(c, nullptr));
  for (const std::string& s : {"/stage1", "/stage2", ""}) {
    INFO(s);
    CHECK(learned(whole + s) == learned(cut + s));
    CHECK(losses(whole + s) == losses(cut + s));
  }
}

// The bootstrap's grid phase is the plan --restarts makes, so it keeps every restart setting:
// the hand copy before plans left out first_focal_hold, and `--bootstrap-minutes B --restarts K
// --first-focal-hold F` silently trained stage 1 without the hold (issue 50).
TEST_CASE("bootstrap with restarts keeps first_focal_hold; --set edits a generated plan",
          "[plan][gridfield]") {
  const std::string data = test::sim_scene("plan_boot", 6, 48, 36);
  const std::string out = test::tmp("plan_boot_run", true);
  TrainConfig c = test::tiny_train_config(data, out, 2);
  c.bootstrap_steps = 4;
  c.restarts = 1;
  c.first_focal_hold = 0.5;
  REQUIRE(bootstrap_cameras(c, nullptr, [](const std::string&) { return false; }));
  CHECK(Trainer::open(out + "/bootstrap/stage1").config().focal_delay == 0.5);
  CHECK(Trainer::open(out + "/bootstrap/stage1").config().model.field == Field::grid);
  CHECK(Trainer::open(out + "/bootstrap").config().focal_delay == 0);
  CHECK(c.model.field == Field::mlp);
  CHECK(c.cameras_from == out + "/bootstrap");
  const json plan = json::parse(read_file_bytes(out + "/plan.json", 1 << 20));
  REQUIRE(plan.at("stages").size() == 3);
  CHECK(plan.at("stages")[0].at("dir") == "bootstrap/stage1");
  CHECK(plan.at("stages")[2].at("dir") == ".");
  // --restarts K with --set STAGE.KEY=VALUE: the generated plan, edited stage by stage.
  const std::string out2 = test::tmp("plan_restarts_set", true);
  REQUIRE(test::cli({"train", "--data", data, "--out", out2, "--rays", "64", "--no-progress",
                     "--threads", "1", "--field", "grid", "--steps", "6", "--restarts", "1",
                     "--set", "last.samples=24", "--set", "1.lr_pose=2e-3"}) == 0);
  CHECK(Trainer::open(out2).config().samples == 24);
  CHECK(Trainer::open(out2 + "/stage1").config().samples == 32);  // the grid field's default
  CHECK(Trainer::open(out2 + "/stage1").config().lr_pose == 2e-3);
  CHECK(Trainer::open(out2).config().lr_pose == 1e-3);
  // A stage of a run that has none is refused.
  CHECK(test::cli({"train", "--data", data, "--out", out2 + "_x", "--rays", "64", "--no-progress",
                   "--steps", "2", "--set", "2.samples=24"}) == 2);
}

// recipes/bootstrap.json is the plan --bootstrap-minutes generates, written down: with the
// flags at their defaults (those both fields share) the recipe trains the same two phases, bit
// for bit at one thread, as the generator (its phase 1 built from the defaults by hand).
TEST_CASE("plan bootstrap trains the phases of the bootstrap generator bitwise (--threads 1)",
          "[plan][cli][bootstrap]") {
  const std::string data = test::sim_scene("plan_bootstrap", 6, 48, 36);
  const std::string old_out = test::tmp("boot_gen", true), new_out = test::tmp("boot_recipe", true);
  {
    TrainConfig c;
    c.data = data;
    c.out = old_out;
    c.model.width = 16;
    c.threads = 1;
    c.steps = 4;
    c.bootstrap_steps = 4;
    c.progress = false;
    REQUIRE(bootstrap_cameras(c, nullptr, [](const std::string&) { return false; }));
    Trainer last(c);
    REQUIRE(last.run());
  }
  REQUIRE(test::cli({"train", "--data", data, "--out", new_out, "--width", "16", "--threads", "1",
                     "--steps", "8", "--no-progress", "--plan", "bootstrap", "--set",
                     "1.share=0.5"}) == 0);
  json s_old = stage_settings(old_out + "/bootstrap"), s_new = stage_settings(new_out + "/bootstrap");
  s_old.erase("width");  // the MLP's width: phase 1 (the grid field) has none
  s_new.erase("width");
  CHECK(s_old == s_new);
  CHECK(stage_settings(old_out) == stage_settings(new_out));
  for (const std::string& d : {"/bootstrap", ""}) {
    INFO(d);
    CHECK(losses(new_out + d).size() == 4);
    CHECK(losses(old_out + d) == losses(new_out + d));
    CHECK(learned(old_out + d) == learned(new_out + d));
  }
}

// A plan file is user input: every malformed one is a hashcc::Error naming the file (and the
// stage and key where there is one), never a crash or a silently ignored value.
TEST_CASE("plan files: malformed input is an Error naming the file, stage and key", "[plan]") {
  const auto refused = [](const std::string& text, const std::string& says) {
    INFO(text);
    CHECK_THROWS_WITH(parse_plan(text, "p", "p.json"),
                      Catch::Contains("p.json") && Catch::Contains(says));
  };
  refused("", "not valid JSON");
  refused("[1, 2]", "not a JSON object");
  refused(R"({"stages": {}})", "stages");
  refused(R"({"stages": []})", "stages");
  refused(R"({"stages": [3]})", "stage 1");
  refused(R"({"base": [1]})", "base");
  refused(R"({"base": {"no_such": 1}})", "no_such");
  refused(R"({"base": {"restarts": 3}})", "decided by the plan");
  refused(R"({"stages": [{"set": {"steps": 3}}]})", "budget");
  refused(R"({"stages": [{"budget": {"share": 1.5}}]})", "more than 1");
  refused(R"({"stages": [{"budget": {"share": -1}}]})", "positive");
  refused(R"({"stages": [{"budget": {"steps": 2.5}}]})", "not an integer");
  refused(R"({"stages": [{"budget": "most"}]})", "budget");
  refused(R"({"stages": [{}, {"cameras": "left"}]})", "stage 2: cameras");
  refused(R"({"stages": [{"dir": "../elsewhere"}]})", "leaves the run folder");
  // Values of the wrong type are refused when the stage is resolved, naming stage and key.
  const TrainPlan p = parse_plan(R"({"stages": [{"budget": {"share": 0.5}},
      {"budget": "rest", "set": {"samples": "many"}}]})", "p", "p.json");
  TrainConfig run;
  run.steps = 10;
  CHECK_THROWS_WITH(resolve_plan(p, run), Catch::Contains("p.json stage 2: samples") &&
                                              Catch::Contains("wrong type"));
  // A staged plan needs a budget to share.
  TrainConfig none;
  CHECK_THROWS_WITH(resolve_plan(p, none), Catch::Contains("p.json stage 1: budget"));
}

// --preset auto (tools/cmd_train.cpp, default_preset): with no flag that chooses the field, the
// layout or the cameras, `train` runs the forward recipe in stages (RUN/plan.json, RUN/stage1);
// --field (either), --preset paper, --init-poses or --no-ndc keep one stage. A bad flag is still
// named by its flag, not by the recipe key it would be merged into.
TEST_CASE("the default of train is the forward recipe for photos without cameras; one flag "
          "gives one stage", "[plan][cli]") {
  const std::string data = test::sim_scene("plan_default", 6, 48, 36);
  const std::vector<std::string> small = {"--rays", "64", "--samples", "8", "--no-progress",
                                          "--threads", "1", "--steps", "40"};
  const auto run = [&](const std::string& name, std::vector<std::string> extra) {
    const std::string out = test::tmp(name, true);
    std::vector<std::string> a = {"train", "--data", data, "--out", out};
    a.insert(a.end(), small.begin(), small.end());
    a.insert(a.end(), extra.begin(), extra.end());
    REQUIRE(test::cli(a) == 0);
    return out;
  };
  const std::string dflt = run("default", {});
  REQUIRE(fs::exists(dflt + "/plan.json"));
  const json plan = json::parse(read_file_bytes(dflt + "/plan.json", 1 << 22));
  CHECK(plan.at("plan") == "forward");
  CHECK(plan.at("stages").size() == 5);
  for (const json& s : plan.at("stages"))  // the last too: it trains in RUN itself, not in a stage
    CHECK(s.at("finished").get<bool>());
  const json last = json::parse(read_file_bytes(dflt + "/config.json", 1 << 20));
  CHECK(last.at("field") == "grid");
  CHECK(last.at("pose_precondition").get<double>() == 0.1);
  CHECK(last.at("fx_only").get<bool>());
  CHECK(json::parse(read_file_bytes(dflt + "/stage1/config.json", 1 << 20)).at("focal_fov").get<double>() == 65);
  for (const auto& [name, flags] :
       {std::pair<std::string, std::vector<std::string>>{"field_grid", {"--field", "grid"}},
        {"field_mlp", {"--field", "mlp", "--width", "16"}},
        {"paper", {"--preset", "paper", "--width", "16"}},
        {"no_ndc", {"--no-ndc", "--width", "16"}},
        {"init_poses", {"--init-poses", data + "/poses_bounds.npy", "--width", "16"}}}) {
    INFO(name);
    const std::string out = run(name, flags);
    CHECK_FALSE(fs::exists(out + "/plan.json"));
    CHECK_FALSE(fs::exists(out + "/stage1"));
  }
  // Fewer training images than the grid field's 4 a step (3 of 4 photos; every 8th is held
  // out): the default takes the largest K <= 3 dividing the 64 rays, 2, in every stage; the
  // same 4 given by hand is refused by name before anything is written, with the way out.
  CHECK(auto_images_per_step(1024, 62) == 4);
  CHECK(auto_images_per_step(1024, 3) == 2);
  CHECK(auto_images_per_step(1023, 3) == 3);
  CHECK(auto_images_per_step(64, 1) == 1);
  CHECK(auto_images_per_step(63, 4) == 3);
  const std::string three = test::sim_scene("plan_default_few", 4, 48, 36);
  const std::string few = test::tmp("default_few", true);
  std::vector<std::string> f = {"train", "--data", three, "--out", few};
  f.insert(f.end(), small.begin(), small.end());
  REQUIRE(test::cli(f) == 0);
  for (const std::string& dir : {few + "/stage1", few})
    CHECK(json::parse(read_file_bytes(dir + "/config.json", 1 << 20)).at("images_per_step") == 2);
  CHECK(json::parse(read_file_bytes(dflt + "/config.json", 1 << 20)).at("images_per_step") == 4);
  const std::string few4 = test::tmp("default_few4", true);
  f = {"train", "--data", three, "--out", few4, "--images-per-step", "4"};
  f.insert(f.end(), small.begin(), small.end());
  CHECK(test::cli(f) == 2);
  CHECK_FALSE(fs::exists(few4));
  // A bad value in a flag that the recipe also sets: named by the flag.
  const std::string bad = test::tmp("default_bad", true);
  std::vector<std::string> a = {"train", "--data", data, "--out", bad, "--lr-net", "nan"};
  a.insert(a.end(), small.begin(), small.end());
  CHECK(test::cli(a) == 2);
  CHECK_FALSE(fs::exists(bad));
}

// ---- a stage that tries alternatives ("try", issue 49) ------------------------------------

TEST_CASE("plan files: a stage's \"try\" is a list of settings in a stage before the last; "
          "errors name the file, the stage and the key", "[plan]") {
  const auto refused = [](const std::string& text, const std::string& says) {
    INFO(text);
    CHECK_THROWS_WITH(parse_plan(text, "p", "p.json"),
                      Catch::Contains("p.json") && Catch::Contains(says));
  };
  refused(R"({"stages": [{"try": []}, {}]})", "stage 1: try: is an empty list");
  refused(R"({"stages": [{"try": {"focal_fov": 40}}, {}]})", "stage 1: try: is not a list");
  refused(R"({"stages": [{"try": [{"focal_fov": 40}, 3]}, {}]})",
          "stage 1: try: alternative 2 is 3, not an object");
  refused(R"({"stages": [{"try": [{"focal_fov": 40}, {"no_such": 1}]}, {}]})",
          "stage 1 try 2: no_such: is not a setting");
  refused(R"({"stages": [{"try": [{"steps": 40}]}, {}]})", "stage 1 try 1: steps");
  refused(R"({"stages": [{}, {"try": [{"focal_fov": 40}]}]})", "stage 2: try: is in the last stage");

  // Accepted: values bare or with their "why"; an empty alternative is the stage as it is.
  const TrainPlan p = parse_plan(R"({"stages": [
      {"budget": {"share": 0.5}, "set": {"fixed_focal": true, "focal_fov": 65},
       "try": [{"focal_fov": {"value": 40, "why": "narrow"}}, {}, {"focal_fov": 90}]},
      {"budget": "rest"}]})", "p", "p.json");
  REQUIRE(p.stages[0].tries.size() == 3);
  CHECK(p.stages[0].tries[0] == json{{"focal_fov", 40}});
  CHECK(p.stages[0].tries[1].empty());
  CHECK(p.stages[1].tries.empty());
  // Resolved: each alternative is the stage's settings with its own on top, in stage1/tryJ,
  // for a third of the stage's steps; the stage after counts the stage's whole budget.
  TrainConfig run;
  run.out = "/tmp/x";
  run.steps = 20;
  const PlanRun r = resolve_plan(p, run);
  REQUIRE(r.stages[0].tries.size() == 3);
  for (int j = 0; j < 3; ++j) {
    INFO(j);
    const TrainConfig& c = r.stages[0].tries[j].config;
    CHECK(c.out == fmt::format("/tmp/x/stage1/try{}", j + 1));
    CHECK(c.steps == 3);  // 10 steps among 3: 3 each
    CHECK(c.fixed_focal);
    CHECK(c.focal_fov == std::vector<double>{40, 65, 90}[j]);
  }
  CHECK(r.stages[1].config.steps == 10);
  CHECK(r.stages[1].config.cameras_from.rfind("/tmp/x/stage1/try", 0) == 0);
  // Every alternative is checked before stage 1: a bad value in the second is named.
  const TrainPlan q = parse_plan(R"({"stages": [{"budget": {"share": 0.5},
      "try": [{"samples": 8}, {"samples": 1}]}, {}]})", "q", "q.json");
  CHECK_THROWS_WITH(resolve_plan(q, run), Catch::Contains("q.json stage 1 try 2") &&
                                              Catch::Contains("samples"));
  // A grid key in an alternative of a stage of the MLP field.
  const TrainPlan g = parse_plan(R"({"stages": [{"budget": {"share": 0.5},
      "try": [{}, {"grid_log2_table": 14}]}, {}]})", "g", "g.json");
  CHECK_THROWS_WITH(resolve_plan(g, run), Catch::Contains("g.json stage 1 try 2: grid_log2_table"));
  // More alternatives than the stage has steps.
  TrainConfig few = run;
  few.steps = 4;
  CHECK_THROWS_WITH(resolve_plan(p, few), Catch::Contains("p.json stage 1: try") &&
                                              Catch::Contains("3 alternatives share 2 steps"));
  // --set still addresses the stage: its budget, and a value under the alternatives'.
  TrainPlan s = p;
  set_plan_value(s, "1.steps=9");
  set_plan_value(s, "1.samples=24");
  const PlanRun rs = resolve_plan(s, run);
  for (const ResolvedTry& t : rs.stages[0].tries) {
    CHECK(t.config.steps == 3);
    CHECK(t.config.samples == 24);
  }
  CHECK(rs.stages[1].config.steps == 11);
}

// A tiny run whose first stage tries three network rates, the good one second and a hopeless
// one first (a run that kept the first, or the last, would keep a worse one): each trains in its
// folder, plan.json records each fit, the highest is kept, and stage 2 starts from its cameras.
TEST_CASE("a stage that tries alternatives keeps the best fit; the next stage starts from it",
          "[plan][cli]") {
  const std::string data = test::sim_scene("plan_try", 6, 48, 36);
  const std::string dir = test::fresh_dir("plan_try_files");
  const std::string out = test::tmp("plan_try_run", true);
  write_file_atomic(dir + "/try.json", R"({
    "base": {"field": "grid"},
    "stages": [
      {"budget": {"share": 0.6},
       "try": [{"lr_net": 1e-7, "lr_net_end": 1e-7}, {"lr_net": 2e-2}, {"lr_net": {"value": 1e-4, "why": "slow"}}]},
      {"budget": "rest", "set": {"c2f_end": 0}}
    ]})");
  REQUIRE(test::cli({"train", "--data", data, "--out", out, "--rays", "64", "--samples", "16",
                     "--no-progress", "--threads", "1", "--steps", "60", "--plan",
                     dir + "/try.json"}) == 0);
  const json plan = json::parse(read_file_bytes(out + "/plan.json", 1 << 20));
  const json& st = plan.at("stages")[0];
  REQUIRE(st.at("try").size() == 3);
  CHECK(st.at("finished") == true);
  std::vector<double> fit;
  for (int j = 0; j < 3; ++j) {
    INFO(j);
    const json& t = st.at("try")[j];
    const std::string folder = fmt::format("stage1/try{}", j + 1);
    CHECK(t.at("dir") == folder);
    CHECK(t.at("finished") == true);
    CHECK(t.at("length") == json{{"steps", 12}});  // 36 steps among 3
    REQUIRE(fs::exists(out + "/" + folder + "/checkpoint.bin"));
    // The recorded fit is the alternative's own final running train PSNR.
    const Trainer tr = Trainer::open(out + "/" + folder);
    CHECK(tr.state().step == 12);
    CHECK(t.at("psnr_ema").get<double>() == tr.state().psnr_ema);
    CHECK(tr.config().lr_net == std::vector<double>{1e-7, 2e-2, 1e-4}[j]);
    fit.push_back(t.at("psnr_ema").get<double>());
  }
  const int argmax = int(std::max_element(fit.begin(), fit.end()) - fit.begin());
  CHECK(argmax == 1);  // the rate that learns: the hopeless one cannot fit the views
  CHECK(st.at("kept") == argmax + 1);
  CHECK(st.at("kept_dir") == fmt::format("stage1/try{}", argmax + 1));
  const json last = json::parse(read_file_bytes(out + "/config.json", 1 << 20));
  CHECK(last.at("cameras_from") == fmt::format("{}/stage1/try{}", out, argmax + 1));
  CHECK_FALSE(fs::exists(out + "/stage1/checkpoint.bin"));  // the stage itself never trains
  CHECK(Trainer::open(out).state().step == 24);
}

// Interrupted inside the second of three alternatives, the run resumes from it, keeps the same
// one, and ends as an uninterrupted run does, bit for bit (one thread).
TEST_CASE("a plan interrupted inside an alternative resumes from it and keeps the same one, "
          "bitwise", "[plan][resume]") {
  test::ThreadGuard one(1);
  const std::string data = test::sim_scene("plan_try_resume", 6, 48, 36);
  const std::string dir = test::fresh_dir("plan_try_resume_files");
  write_file_atomic(dir + "/try3.json", R"({
    "stages": [
      {"budget": {"share": 0.4}, "try": [{"lr_net": 1e-4}, {"c2f_end": 0}, {}]},
      {"budget": {"steps": 5}, "set": {"c2f_end": 0}},
      {"budget": "rest", "set": {"c2f_end": 0, "samples": 24}}
    ]})");
  const TrainPlan plan = load_plan(dir + "/try3.json");
  const auto run_for = [&](const std::string& out) {
    TrainConfig c = test::tiny_train_config(data, out, 30);
    c.model.field = Field::grid;
    c.threads = 1;
    for (const PresetEntry& e : field_defaults("grid")) e.set(c);
    return c;
  };
  const std::string whole = test::tmp("plan_try_resume_whole", true);
  PlanRun a = start_plan(plan, run_for(whole));
  REQUIRE(run_plan(a, nullptr));
  REQUIRE(a.stages[0].kept >= 0);

  const std::string cut = test::tmp("plan_try_resume_cut", true);
  PlanRun b = start_plan(plan, run_for(cut));
  std::atomic<bool> stop{false};
  const AfterStepFactory stop_in_try2 = [&](const Trainer& t) {
    const bool try2 = t.config().out == cut + "/stage1/try2";
    return std::function<void(const Trainer&)>([&stop, try2](const Trainer& s) {
      if (try2 && s.state().step == 2) stop = true;
    });
  };
  REQUIRE_FALSE(run_plan(b, &stop, stop_in_try2));
  CHECK(Trainer::open(cut + "/stage1/try2").state().step == 2);
  CHECK_FALSE(fs::exists(cut + "/stage1/try3"));
  CHECK_FALSE(fs::exists(cut + "/stage2"));
  PlanRun c = open_plan(cut);
  CHECK_FALSE(c.stages[0].finished);
  CHECK(c.stages[0].tries[0].finished);
  CHECK(c.stages[0].tries[0].psnr_ema == a.stages[0].tries[0].psnr_ema);
  CHECK_FALSE(c.stages[0].tries[1].finished);
  CHECK(c.stages[0].kept == -1);
  REQUIRE(run_plan(c, nullptr));
  CHECK(c.stages[0].kept == a.stages[0].kept);
  for (int j = 0; j < 3; ++j) CHECK(c.stages[0].tries[j].psnr_ema == a.stages[0].tries[j].psnr_ema);
  // Read back once more: the choice and the fits as recorded.
  const PlanRun d = open_plan(cut);
  CHECK(d.stages[0].finished);
  CHECK(d.stages[0].kept == a.stages[0].kept);
  CHECK(d.stages[1].config.cameras_from ==
        fmt::format("{}/stage1/try{}", cut, a.stages[0].kept + 1));
  for (const std::string& s : {"/stage1/try1", "/stage1/try2", "/stage1/try3", "/stage2", ""}) {
    INFO(s);
    CHECK(learned(whole + s) == learned(cut + s));
    CHECK(losses(whole + s) == losses(cut + s));
  }
}
