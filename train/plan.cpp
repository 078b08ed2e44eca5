// train/plan.cpp — reading, resolving, recording and running a TrainPlan (train/plan.h).
#include "train/plan.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fmt/core.h>
#include <fmt/ranges.h>
#include <map>
#include <optional>

#include "core/error.h"
#include "core/fileio.h"
#include "train/checkpoint.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace hashcc {

namespace {

// ---- reading ----------------------------------------------------------------------------

// Keys a plan may not set: the run's identity and output, what the plan itself decides (a
// stage's length is its budget, its cameras come from "cameras"), and the fields of the old
// per-stage flags, which generated the plans that recipes now write down.
bool plan_owned_key(const std::string& k, bool in_stage) {
  static const std::set<std::string> owned = {
      "engine", "version", "data", "out", "cameras_from", "preset", "restarts", "restart_first",
      "restart_last", "restart_steps", "first_focal_hold", "bootstrap_minutes", "bootstrap_steps",
      "bootstrap_lr_pose"};
  if (owned.count(k) || k.rfind("last_", 0) == 0) return true;
  return in_stage && (k == "steps" || k == "minutes" || k == "epochs");
}

const json& config_keys() {
  static const json keys = json::parse(train_config_json_full(TrainConfig{}));
  return keys;
}

// A value as written: bare, or {"value": V, "why": "..."}.
json unwrap(const json& v) { return v.is_object() && v.contains("value") ? v.at("value") : v; }

json read_settings(const json& obj, const std::string& where, bool in_stage) {
  if (!obj.is_object()) throw Error(where, "", "is not an object", "{\"key\": value, ...}");
  json out = json::object();
  for (const auto& [k, v] : obj.items()) {
    if (plan_owned_key(k, in_stage))
      throw Error(where, k, "is decided by the plan",
                  in_stage ? "a stage's \"budget\" for its length; no per-stage copy of a key"
                           : "a run setting (the plan sets the stages)");
    if (!config_keys().contains(k))
      throw Error(where, k, "is not a setting", "a key of a run's config.json");
    out[k] = unwrap(v);
  }
  return out;
}

StageBudget read_budget(const json& b, const std::string& where) {
  if (b.is_string() && b.get<std::string>() == "rest") return {StageBudget::Kind::rest, 1};
  if (b.is_object()) {
    for (const auto& [key, kind] : {std::pair{"share", StageBudget::Kind::share},
                                    std::pair{"steps", StageBudget::Kind::steps},
                                    std::pair{"minutes", StageBudget::Kind::minutes},
                                    std::pair{"rest", StageBudget::Kind::rest}}) {
      if (!b.contains(key)) continue;
      const json v = unwrap(b.at(key));
      if (kind == StageBudget::Kind::rest && v.is_boolean()) return {kind, 1};
      if (!v.is_number() || !(v.get<double>() > 0))
        throw Error(where, "budget", fmt::format("\"{}\" is {}", key, v.dump()), "a positive number");
      if (kind == StageBudget::Kind::steps && v.get<double>() != std::floor(v.get<double>()))
        throw Error(where, "budget", "\"steps\" is not an integer", "a number of steps");
      if ((kind == StageBudget::Kind::share || kind == StageBudget::Kind::rest) && v.get<double>() > 1)
        throw Error(where, "budget", fmt::format("\"{}\" is more than 1", key), "a fraction of the run");
      return {kind, v.get<double>()};
    }
  }
  throw Error(where, "budget", fmt::format("{} is not a budget", b.dump()),
              "{\"share\": F}, {\"steps\": N} or \"rest\"");
}

std::string budget_text(const StageBudget& b) {
  switch (b.kind) {
    case StageBudget::Kind::share: return fmt::format("{:g} of the run", b.value);
    case StageBudget::Kind::steps: return fmt::format("{:g} steps", b.value);
    case StageBudget::Kind::minutes: return fmt::format("{:.3g} min", b.value);
    case StageBudget::Kind::rest: return b.value == 1 ? "the rest" : fmt::format("the rest of {:g}", b.value);
    case StageBudget::Kind::own: return "its own length";
  }
  return "";
}

json budget_json(const StageBudget& b) {
  static const char* names[] = {"share", "steps", "minutes", "rest", "own"};
  return {{names[int(b.kind)], b.value}};
}

}  // namespace

TrainPlan parse_plan(const std::string& text, const std::string& name, const std::string& source) {
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {
    throw Error(source, "", fmt::format("not valid JSON ({})", std::string(e.what()).substr(0, 200)));
  }
  if (!j.is_object()) throw Error(source, "", "not a JSON object", "a plan: {\"base\": …, \"stages\": […]}");
  TrainPlan p;
  p.name = name;
  p.source = source;
  if (j.contains("base")) p.base = read_settings(j.at("base"), source + " base", false);
  if (!j.contains("stages")) {  // a plan of one stage: the base alone (--preset laptop)
    p.stages.push_back({});
    p.stages[0].cameras_from_previous = false;
    return p;
  }
  if (!j.at("stages").is_array() || j.at("stages").empty())
    throw Error(source, "stages", "is not a list of stages", "[{\"budget\": …, \"set\": {…}}, …]");
  for (const json& s : j.at("stages")) {
    const std::string where = fmt::format("{} stage {}", source, p.stages.size() + 1);
    if (!s.is_object()) throw Error(where, "", "is not an object");
    PlanStage st;
    st.budget = read_budget(s.value("budget", json("rest")), where);
    if (s.contains("set")) st.set = read_settings(s.at("set"), where, true);
    const std::string cams = s.value("cameras", p.stages.empty() ? "fresh" : "previous");
    if (cams != "previous" && cams != "fresh")
      throw Error(where, "cameras", fmt::format("\"{}\"", cams), "\"previous\" or \"fresh\"");
    st.cameras_from_previous = cams == "previous";
    st.dir = s.value("dir", "");  // "" = stageK (the last: the run folder); "." = the run folder
    if (st.dir.find("..") != std::string::npos || (!st.dir.empty() && st.dir[0] == '/'))
      throw Error(where, "dir", fmt::format("\"{}\" leaves the run folder", st.dir),
                  "a folder inside it");
    p.stages.push_back(st);
  }
  return p;
}

TrainPlan load_plan(const std::string& name_or_file) {
  for (const auto& [name, text] : embedded_recipes())
    if (name == name_or_file) return parse_plan(text, name, "recipe " + name);
  HCC_REQUIRE(fs::exists(name_or_file), "--plan", name_or_file, "is neither a recipe nor a file",
              fmt::format("a plan file, or one of: {}", fmt::join(recipe_names(), ", ")));
  return parse_plan(read_file_bytes(name_or_file, 1 << 20),
                    fs::path(name_or_file).stem().string(), name_or_file);
}

void set_plan_value(TrainPlan& p, const std::string& a) {
  const size_t eq = a.find('=');
  HCC_REQUIRE(eq != std::string::npos && eq > 0, "--set", a, "is not KEY=VALUE",
              "e.g. samples=64, last.samples=64 or 2.lr_pose=1e-3");
  std::string lhs = a.substr(0, eq), key = lhs, sel;
  if (const size_t dot = lhs.find('.'); dot != std::string::npos) {
    sel = lhs.substr(0, dot);
    key = lhs.substr(dot + 1);
  }
  json v;
  try {
    v = json::parse(a.substr(eq + 1));
  } catch (const json::exception&) {
    v = a.substr(eq + 1);  // a bare word: a string ("grid", "sh")
  }
  if (sel.empty()) {
    (void)read_settings(json{{key, v}}, "--set " + a, false);
    p.base[key] = v;
    p.forced.insert(key);
    return;
  }
  // The stages it names, 1-based: "3", "2-4", "first", "last".
  const int n = int(p.stages.size());
  int lo = 0, hi = 0;
  try {
    if (sel == "first") lo = hi = 1;
    else if (sel == "last") lo = hi = n;
    else if (const size_t dash = sel.find('-'); dash != std::string::npos) {
      lo = std::stoi(sel.substr(0, dash));
      hi = std::stoi(sel.substr(dash + 1));
    } else {
      lo = hi = std::stoi(sel);
    }
  } catch (const std::exception&) {
    lo = hi = 0;
  }
  HCC_REQUIRE(lo >= 1 && lo <= hi && hi <= n, "--set", a,
              fmt::format("\"{}\" is not a stage of {} ({} stages)", sel, p.source, n),
              "a stage number, a range such as 2-4, first or last");
  for (int k = lo; k <= hi; ++k) {
    PlanStage& st = p.stages[k - 1];
    const std::string where = fmt::format("--set {}", a);
    if (key == "steps" || key == "share" || key == "budget")
      st.budget = read_budget(key == "budget" ? v : json{{key, v}}, where);
    else if (key == "cameras") {
      HCC_REQUIRE(v == "previous" || v == "fresh", where, "cameras", "is {}", v.dump(),
                  "previous or fresh");
      st.cameras_from_previous = v == "previous";
    } else {
      st.set[key] = read_settings(json{{key, v}}, where, true).at(key);
    }
  }
}

std::string flag_of_key(const std::string& key) {
  static const std::map<std::string, std::string> special = {
      {"c2f_end", "--c2f"}, {"model", "--model"}, {"focal_fx", "--focal"}, {"focal_fy", "--focal"},
      {"grid_smooth_grad", "--grid-smooth"}, {"sh_degree", "--view-dirs"}, {"ndc", "--no-ndc"},
      {"images_folder", "--images"}, {"width", "--width"}};
  if (auto it = special.find(key); it != special.end()) return it->second;
  std::string f = "--" + key;
  std::replace(f.begin(), f.end(), '_', '-');
  return f;
}

namespace {

// run's config with `set` on top, read back as a run's config.json is (the same ranges and
// types): errors name `where` and the key.
TrainConfig with_overrides(const TrainConfig& run, const json& set, const std::string& where) {
  json j = json::parse(train_config_json_full(run));
  for (const auto& [k, v] : set.items()) {
    if (!j.contains(k)) throw Error(where, k, "is not a setting", "a key of a run's config.json");
    j[k] = v;
  }
  TrainConfig c = train_config_from_json(j.dump(), where);
  c.progress = run.progress;  // not a config.json key
  return c;
}

// A key the stage's field or model does not have (a grid key on the MLP field, a CC key
// without the CC branch) is an error: it would be silently ignored.
void check_applies(const TrainConfig& c, const json& set, const std::string& where) {
  for (const auto& [k, v] : set.items()) {
    if (k.rfind("grid_", 0) == 0 && c.model.field != Field::grid)
      throw Error(where, k, "is a grid-field setting, and this stage trains the MLP field",
                  "field grid in this stage, or no such key");
    if (k.rfind("cc_", 0) == 0 && !c.model.has_cc())
      throw Error(where, k, "is a setting of the CC branch, and this stage's model has none",
                  "model hashcc");
  }
}

std::string stage_dir(const std::string& out, const std::string& dir, int k, int n) {
  if (dir == ".") return out;
  if (!dir.empty()) return out + "/" + dir;
  return k + 1 == n ? out : fmt::format("{}/stage{}", out, k + 1);
}

// The training seconds a stage's checkpoint records (0 without one).
double checkpoint_elapsed(const std::string& dir) {
  const std::string ck = dir + "/checkpoint.bin";
  if (!fs::exists(ck)) return 0;
  return json::parse(load_checkpoint(ck).text("state", ck)).value("elapsed", 0.0);
}

// A "rest" stage's minutes: what the stages before it left of its part of the budget, at least a
// twentieth of it (a loaded machine may have spent it all). spent_minutes: planned, or measured.
double rest_minutes(const StageBudget& b, double run_minutes, double spent_minutes) {
  const double part = b.value * run_minutes;
  return std::max(part - spent_minutes, part / 20);
}

void apply_budget(TrainConfig& c, const TrainConfig& run, const StageBudget& b, int n,
                  int64_t steps_before, double minutes_before, const std::string& where) {
  using K = StageBudget::Kind;
  const bool by_minutes = run.minutes > 0;
  if (b.kind == K::own || (b.kind == K::rest && n == 1 && b.value == 1)) return;
  HCC_REQUIRE(b.kind == K::steps || b.kind == K::minutes || run.minutes > 0 || run.steps > 0,
              where, "budget", "is a part of the run's budget, and the run has none",
              "--minutes or --steps");
  if (b.kind == K::steps || (b.kind == K::share && !by_minutes)) {
    c.minutes = 0;
    c.steps = b.kind == K::steps
                  ? int64_t(b.value)
                  : std::max<int64_t>(1, int64_t(std::floor(double(run.steps) * b.value + 1e-9)));
  } else if (b.kind == K::minutes || b.kind == K::share) {
    c.steps = 0;
    c.minutes = b.kind == K::minutes ? b.value : run.minutes * b.value;
  } else if (by_minutes) {  // rest, by minutes
    c.steps = 0;
    c.minutes = rest_minutes(b, run.minutes, minutes_before);
  } else {  // rest, by steps
    const int64_t left = int64_t(std::floor(double(run.steps) * b.value + 1e-9)) - steps_before;
    if (left <= 0)
      throw Error(where, "budget", fmt::format("the stages before it take {} of the {} steps",
                                               steps_before, int64_t(run.steps * b.value)),
                  "more --steps, or shorter stages before it");
    c.steps = left;
  }
}

void write_plan_json(const PlanRun& pr) {
  json stages = json::array();
  for (size_t k = 0; k < pr.stages.size(); ++k) {
    const ResolvedStage& s = pr.stages[k];
    const std::string rel = fs::relative(s.config.out, pr.run.out).string();
    stages.push_back({{"dir", rel}, {"budget", budget_json(s.budget)},
                      {"length", s.config.minutes > 0 ? json{{"minutes", s.config.minutes}}
                                                      : json{{"steps", s.config.steps}}},
                      {"cameras", pr.plan.stages[k].cameras_from_previous ? "previous" : "fresh"},
                      {"set", s.set}, {"finished", s.finished}});
  }
  const json j = {{"plan", pr.plan.name}, {"source", pr.plan.source}, {"base", pr.plan.base},
                  {"run", json::parse(train_config_json(pr.run))}, {"stages", stages}};
  write_file_atomic(pr.run.out + "/plan.json", j.dump(2) + "\n");
}

}  // namespace

std::vector<std::string> apply_plan_base(TrainConfig& c, const TrainPlan& p,
                                         const std::function<bool(const std::string&)>& given) {
  json set = json::object();
  std::vector<std::string> keys;
  for (const auto& [k, v] : p.base.items()) {
    if (!p.forced.count(k) && given && given(k)) continue;  // an explicit flag wins
    set[k] = v;
    keys.push_back(k);
  }
  c = with_overrides(c, set, p.source + " base");
  return keys;
}

PlanRun resolve_plan(const TrainPlan& plan, const TrainConfig& run) {
  PlanRun pr{plan, run, {}};
  const int n = int(plan.stages.size());
  HCC_REQUIRE(n >= 1, plan.source, "stages", "is empty", "at least one stage");
  int64_t steps_before = 0;
  double minutes_before = 0;
  for (int k = 0; k < n; ++k) {
    const PlanStage& s = plan.stages[k];
    const std::string where = fmt::format("{} stage {}", plan.source, k + 1);
    TrainConfig c = with_overrides(run, s.set, where);
    check_applies(c, s.set, where);
    c.out = stage_dir(run.out, s.dir, k, n);
    if (k > 0 && s.cameras_from_previous) c.cameras_from = pr.stages[k - 1].config.out;
    apply_budget(c, run, s.budget, n, steps_before, minutes_before, where);
    steps_before += c.steps;
    minutes_before += c.minutes;
    try {
      validate_train_config(c);
    } catch (const Error& e) {
      throw Error(where + ": " + e.file, e.field, e.problem, e.expected);
    }
    pr.stages.push_back({c, s.budget, s.set, false});
  }
  return pr;
}

PlanRun start_plan(const TrainPlan& plan, const TrainConfig& run) {
  PlanRun pr = resolve_plan(plan, run);
  if (run.out.empty()) return pr;
  for (const ResolvedStage& s : pr.stages) {
    std::error_code ec;
    fs::remove(s.config.out + "/checkpoint.bin", ec);
    fs::remove(s.config.out + "/checkpoint.bin.tmp", ec);
  }
  pr.made_run_dir = !fs::exists(run.out);
  make_dirs(run.out);
  write_plan_json(pr);
  return pr;
}

bool has_plan(const std::string& run_dir) { return fs::exists(run_dir + "/plan.json"); }

PlanRun open_plan(const std::string& dir) {
  const std::string path = dir + "/plan.json";
  json j;
  try {
    j = json::parse(read_file_bytes(path, 1 << 22));
  } catch (const json::exception&) {
    throw Error(path, "", "not valid JSON");
  }
  TrainPlan p;
  p.name = j.value("plan", "");
  p.source = path;
  p.base = j.value("base", json::object());
  TrainConfig run = train_config_from_json(j.at("run").dump(), path);
  run.out = dir;  // the folder may have moved
  std::vector<bool> finished;
  for (const json& s : j.at("stages")) {
    PlanStage st;
    const json& b = s.at("budget");
    st.budget = b.contains("own") ? StageBudget{StageBudget::Kind::own, 0} : read_budget(b, path);
    st.set = s.at("set");
    st.cameras_from_previous = s.value("cameras", "previous") == "previous";
    st.dir = s.value("dir", "");
    p.stages.push_back(st);
    finished.push_back(s.value("finished", false));
  }
  PlanRun pr = resolve_plan(p, run);
  for (size_t k = 0; k < finished.size(); ++k) pr.stages[k].finished = finished[k];
  return pr;
}

namespace {

// Stage k's config as it starts now: a "rest" budget by minutes counts what the stages before
// it trained (their checkpoints), so a resumed run spends the budget it had, not a fresh one.
TrainConfig stage_config_now(const PlanRun& pr, int k) {
  TrainConfig c = pr.stages[k].config;
  const StageBudget& b = pr.stages[k].budget;
  if (b.kind == StageBudget::Kind::rest && pr.run.minutes > 0 && pr.stages.size() > 1) {
    double spent = 0;
    for (int j = 0; j < k; ++j) spent += checkpoint_elapsed(pr.stages[j].config.out) / 60;
    c.minutes = rest_minutes(b, pr.run.minutes, spent);
  }
  return c;
}

void print_stage(const PlanRun& pr, int k, const TrainConfig& c, bool resuming) {
  const int n = int(pr.stages.size());
  std::string set;
  for (const auto& [key, v] : pr.stages[k].set.items()) set += fmt::format(" {}={}", key, v.dump());
  const bool counted = pr.stages[k].budget.kind == StageBudget::Kind::steps;
  fmt::print("plan {}: stage {} of {} ({}{}) {} {}{}{}\n", pr.plan.name, k + 1, n,
             budget_text(pr.stages[k].budget),
             counted ? "" : c.minutes > 0 ? fmt::format(": {:.3g} min", c.minutes)
                          : c.steps > 0 ? fmt::format(": {} steps", c.steps) : "",
             resuming ? "resumes in" : "in", c.out,
             c.cameras_from.empty() ? "" : ", from the cameras of " + c.cameras_from,
             set.empty() ? "" : ";" + set);
}

bool run_stage(PlanRun& pr, int k, const std::atomic<bool>* stop,
               const AfterStepFactory& observer_for) {
  std::optional<Trainer> t;
  const TrainConfig c = stage_config_now(pr, k);
  if (fs::exists(c.out + "/checkpoint.bin")) {
    print_stage(pr, k, c, true);
    t.emplace(Trainer::resume(c.out));
  } else {
    print_stage(pr, k, c, false);
    try {
      t.emplace(c);
    } catch (...) {
      if (k == 0 && pr.made_run_dir) {  // nothing trained yet: leave nothing behind
        std::error_code ec;
        fs::remove_all(pr.run.out, ec);
      }
      throw;
    }
  }
  const bool done = t->run(stop, observer_for ? observer_for(*t) : std::function<void(const Trainer&)>{});
  if (!done) {
    fmt::print("plan {} interrupted in stage {} of {}: continue it with `hashcc train --resume {}`\n",
               pr.plan.name, k + 1, pr.stages.size(), pr.run.out);
    return false;
  }
  pr.stages[k].finished = true;
  if (!pr.run.out.empty()) write_plan_json(pr);
  return true;
}

}  // namespace

bool run_plan_until_last(PlanRun& pr, const std::atomic<bool>* stop,
                         const AfterStepFactory& observer_for) {
  for (int k = 0; k + 1 < int(pr.stages.size()); ++k)
    if (!pr.stages[k].finished && !run_stage(pr, k, stop, observer_for)) return false;
  return true;
}

TrainConfig last_stage_config(const PlanRun& pr) {
  return stage_config_now(pr, int(pr.stages.size()) - 1);
}

bool last_stage_started(const PlanRun& pr) {
  return fs::exists(pr.stages.back().config.out + "/checkpoint.bin");
}

bool run_plan(PlanRun& pr, const std::atomic<bool>* stop, const AfterStepFactory& observer_for) {
  if (!run_plan_until_last(pr, stop, observer_for)) return false;
  return run_stage(pr, int(pr.stages.size()) - 1, stop, observer_for);
}

json config_diff(const TrainConfig& from, const TrainConfig& to) {
  const json a = json::parse(train_config_json_full(from)), b = json::parse(train_config_json_full(to));
  json d = json::object();
  for (const auto& [k, v] : b.items())
    if (k != "out" && k != "cameras_from" && a.value(k, json()) != v) d[k] = v;
  return d;
}

}  // namespace hashcc
