// train/plan.cpp — reading, resolving, recording and running a TrainPlan (train/plan.h).
#include "train/plan.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fmt/core.h>
#include <fmt/ranges.h>
#include <limits>
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

// A stage's "try": a non-empty list of alternatives, each an object of settings like its "set"
// (an empty object is the stage as it is). Errors name the stage, the alternative and the key.
std::vector<json> read_tries(const json& t, const std::string& where) {
  if (!t.is_array() || t.empty())
    throw Error(where, "try", t.is_array() ? "is an empty list" : "is not a list",
                "a list of alternatives: [{\"key\": value, ...}, ...]");
  std::vector<json> out;
  for (const json& alt : t) {
    if (!alt.is_object())
      throw Error(where, "try", fmt::format("alternative {} is {}, not an object", out.size() + 1,
                                            alt.dump()),
                  "{\"key\": value, ...} in config.json keys");
    out.push_back(read_settings(alt, fmt::format("{} try {}", where, out.size() + 1), true));
  }
  return out;
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
    if (s.contains("try")) st.tries = read_tries(s.at("try"), where);
    p.stages.push_back(st);
  }
  // The last stage's result is the run's (RUN itself): it cannot be one of several folders.
  if (!p.stages.back().tries.empty())
    throw Error(fmt::format("{} stage {}", source, p.stages.size()), "try",
                "is in the last stage, whose result is the run's",
                "alternatives in a stage before the last (add a stage after it)");
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

// An alternative's part of its stage's length: the stage's steps (or epochs) and minutes
// divided equally among the m alternatives (steps and epochs rounded down: at least 1 each).
void split_length(TrainConfig& t, const TrainConfig& stage, int m, const std::string& where) {
  const int64_t count = stage.steps > 0 ? stage.steps : stage.minutes > 0 ? 0 : stage.epochs;
  if (count > 0 && count < m)
    throw Error(where, "try", fmt::format("{} alternatives share {} {}", m, count,
                                          stage.steps > 0 ? "steps" : "epochs"),
                "a longer stage, or fewer alternatives");
  t.steps = stage.steps / m;
  t.epochs = stage.epochs / m;
  t.minutes = stage.minutes / m;
}

// The folder the cameras of stage k come from for the stage after it: the stage's own, or with
// alternatives the kept one's (before the choice, the first's: a placeholder that keep_try
// replaces before the next stage starts).
std::string cameras_of(const ResolvedStage& s) {
  return s.tries.empty() ? s.config.out : s.tries[std::max(s.kept, 0)].config.out;
}

// Keeps alternative j of stage k: the next stage (and its alternatives) start from its cameras.
void keep_try(PlanRun& pr, int k, int j) {
  pr.stages[k].kept = j;
  if (k + 1 >= int(pr.stages.size()) || !pr.plan.stages[k + 1].cameras_from_previous) return;
  ResolvedStage& next = pr.stages[k + 1];
  next.config.cameras_from = cameras_of(pr.stages[k]);
  for (ResolvedTry& t : next.tries) t.config.cameras_from = next.config.cameras_from;
}

json length_json(const TrainConfig& c) {
  return c.minutes > 0 ? json{{"minutes", c.minutes}} : json{{"steps", c.steps}};
}

void write_plan_json(const PlanRun& pr) {
  const auto rel = [&](const std::string& dir) { return fs::relative(dir, pr.run.out).string(); };
  json stages = json::array();
  for (size_t k = 0; k < pr.stages.size(); ++k) {
    const ResolvedStage& s = pr.stages[k];
    json st = {{"dir", rel(s.config.out)}, {"budget", budget_json(s.budget)},
               {"length", length_json(s.config)},
               {"cameras", pr.plan.stages[k].cameras_from_previous ? "previous" : "fresh"},
               {"set", s.set}, {"finished", s.finished}};
    if (!s.tries.empty()) {  // each alternative, its fit once finished, and the one kept (1-based)
      json tries = json::array();
      for (const ResolvedTry& t : s.tries)
        tries.push_back({{"dir", rel(t.config.out)}, {"set", t.set},
                         {"length", length_json(t.config)}, {"finished", t.finished},
                         {"psnr_ema", t.finished ? json(t.psnr_ema) : json(nullptr)}});
      st["try"] = tries;
      st["kept"] = s.kept >= 0 ? json(s.kept + 1) : json(nullptr);
      st["kept_dir"] = s.kept >= 0 ? json(rel(s.tries[s.kept].config.out)) : json(nullptr);
    }
    stages.push_back(st);
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

namespace {
// validate_train_config, its errors prefixed with the plan, the stage (and the alternative).
void validate_in(const TrainConfig& c, const std::string& where) {
  try {
    validate_train_config(c);
  } catch (const Error& e) {
    throw Error(where + ": " + e.file, e.field, e.problem, e.expected);
  }
}
}  // namespace

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
    if (k > 0 && s.cameras_from_previous) c.cameras_from = cameras_of(pr.stages[k - 1]);
    apply_budget(c, run, s.budget, n, steps_before, minutes_before, where);
    // The stages after it count the stage's whole budget, however many alternatives share it.
    steps_before += c.steps;
    minutes_before += c.minutes;
    ResolvedStage rs{c, s.budget, s.set, false, {}, -1};
    if (s.tries.empty()) {
      validate_in(c, where);
    } else {
      // Each alternative is what trains: the stage's settings with its own on top, in
      // stageK/tryJ, from the stage's cameras, for its part of the stage's length. (The stage's
      // config alone never trains; it holds the folder and the budget.)
      HCC_REQUIRE(k + 1 < n, where, "try", "is in the last stage, whose result is the run's",
                  "alternatives in a stage before the last");
      const int m = int(s.tries.size());
      for (int j = 0; j < m; ++j) {
        const std::string wj = fmt::format("{} try {}", where, j + 1);
        json set = s.set;
        set.update(s.tries[j]);
        TrainConfig t = with_overrides(run, set, wj);
        check_applies(t, set, wj);
        t.out = fmt::format("{}/try{}", c.out, j + 1);
        t.cameras_from = c.cameras_from;
        split_length(t, c, m, where);
        validate_in(t, wj);
        rs.tries.push_back({t, s.tries[j], false, 0});
      }
    }
    pr.stages.push_back(rs);
  }
  return pr;
}

PlanRun start_plan(const TrainPlan& plan, const TrainConfig& run) {
  PlanRun pr = resolve_plan(plan, run);
  if (run.out.empty()) return pr;
  for (const ResolvedStage& s : pr.stages) {
    std::vector<std::string> dirs = {s.config.out};
    for (const ResolvedTry& t : s.tries) dirs.push_back(t.config.out);
    for (const std::string& d : dirs) {
      std::error_code ec;
      fs::remove(d + "/checkpoint.bin", ec);
      fs::remove(d + "/checkpoint.bin.tmp", ec);
    }
  }
  pr.made_run_dir = !fs::exists(run.out);
  make_dirs(run.out);
  write_plan_json(pr);
  return pr;
}

bool has_plan(const std::string& run_dir) { return fs::exists(run_dir + "/plan.json"); }

// The last stage trains in the run folder itself, by `hashcc train`'s own trainer rather than by
// run_stage, so its end is recorded here; the rest of plan.json is left as written.
void mark_last_stage_finished(const std::string& run_dir) {
  const std::string path = run_dir + "/plan.json";
  json j;
  try {
    j = json::parse(read_file_bytes(path, 1 << 22));
  } catch (const json::exception& e) {
    throw Error(path, "", fmt::format("not valid JSON ({})", e.what()), "the plan.json train wrote");
  }
  HCC_REQUIRE(j.contains("stages") && j["stages"].is_array() && !j["stages"].empty(), path,
              "stages", "missing or empty", "the stages train recorded");
  j["stages"].back()["finished"] = true;
  write_file_atomic(path, j.dump(2) + "\n");
}

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
    if (s.contains("try"))
      for (const json& t : s.at("try")) st.tries.push_back(t.at("set"));
    p.stages.push_back(st);
    finished.push_back(s.value("finished", false));
  }
  PlanRun pr = resolve_plan(p, run);
  const json& stages = j.at("stages");
  for (size_t k = 0; k < finished.size(); ++k) {
    pr.stages[k].finished = finished[k];
    for (size_t t = 0; t < pr.stages[k].tries.size(); ++t) {
      const json& rec = stages[k].at("try")[t];
      ResolvedTry& rt = pr.stages[k].tries[t];
      rt.finished = rec.value("finished", false);
      // null: not finished, or a fit that was not a number (NaN is written as null)
      rt.psnr_ema = rec.at("psnr_ema").is_number() ? rec.at("psnr_ema").get<double>()
                                                    : std::numeric_limits<double>::quiet_NaN();
    }
    if (stages[k].contains("kept") && !stages[k].at("kept").is_null()) {
      const json& kept = stages[k].at("kept");
      const int m = int(pr.stages[k].tries.size());
      if (!kept.is_number_integer() || kept.get<int>() < 1 || kept.get<int>() > m)
        throw Error(path, fmt::format("stages[{}].kept", k), fmt::format("is {}", kept.dump()),
                    fmt::format("an alternative of the stage, 1 to {}", m));
      keep_try(pr, int(k), kept.get<int>() - 1);
    }
  }
  return pr;
}

namespace {

// Stage k's config as it starts now: a "rest" budget by minutes counts what the stages before
// it trained (their checkpoints), so a resumed run spends the budget it had, not a fresh one.
// The minutes stage j trained: its checkpoint's, or with alternatives the sum of theirs.
double stage_elapsed_minutes(const ResolvedStage& s) {
  if (s.tries.empty()) return checkpoint_elapsed(s.config.out) / 60;
  double sum = 0;
  for (const ResolvedTry& t : s.tries) sum += checkpoint_elapsed(t.config.out) / 60;
  return sum;
}

TrainConfig stage_config_now(const PlanRun& pr, int k) {
  TrainConfig c = pr.stages[k].config;
  const StageBudget& b = pr.stages[k].budget;
  if (b.kind == StageBudget::Kind::rest && pr.run.minutes > 0 && pr.stages.size() > 1) {
    double spent = 0;
    for (int j = 0; j < k; ++j) spent += stage_elapsed_minutes(pr.stages[j]);
    c.minutes = rest_minutes(b, pr.run.minutes, spent);
  }
  return c;
}

// Alternative j of stage k as it starts now: its part of the stage's length now.
TrainConfig try_config_now(const PlanRun& pr, int k, int j) {
  const TrainConfig stage = stage_config_now(pr, k);
  TrainConfig c = pr.stages[k].tries[j].config;
  const int m = int(pr.stages[k].tries.size());
  if (stage.minutes > 0) c.minutes = stage.minutes / m;  // a "rest" by minutes: as it is now
  return c;
}

std::string set_text(const json& set) {
  std::string s;
  for (const auto& [key, v] : set.items()) s += fmt::format(" {}={}", key, v.dump());
  return s;
}

// The length a stage (or an alternative) trains for, as printed: "4.2 min", "300 steps".
std::string length_words(const TrainConfig& c) {
  return c.minutes > 0 ? fmt::format("{:.3g} min", c.minutes)
         : c.steps > 0 ? fmt::format("{} steps", c.steps)
         : c.epochs > 0 ? fmt::format("{} epochs", c.epochs) : "its own length";
}
std::string length_text(const TrainConfig& c) {
  return c.minutes > 0 || c.steps > 0 ? ": " + length_words(c) : "";
}

// "plan forward: stage 2 of 5 (0.0833 of the run: 5 min) in RUN/stage2, from the cameras of
// RUN/stage1; c2f_end=0". With alternatives, the stage's line says how its budget is split.
void print_stage(const PlanRun& pr, int k, const TrainConfig& c, bool resuming) {
  const int n = int(pr.stages.size());
  const ResolvedStage& s = pr.stages[k];
  const std::string set = set_text(s.set);
  const bool counted = s.budget.kind == StageBudget::Kind::steps;
  const int m = int(s.tries.size());
  if (m > 0) {
    fmt::print("plan {}: stage {} of {} ({}{}) tries {} alternatives in {}/try1 … try{}, {} "
               "each{}{}; the best fit of the training views (train PSNR) is kept\n",
               pr.plan.name, k + 1, n, budget_text(s.budget), counted ? "" : length_text(c), m,
               c.out, m, length_words(try_config_now(pr, k, 0)),
               c.cameras_from.empty() ? "" : ", from the cameras of " + c.cameras_from,
               set.empty() ? "" : ";" + set);
    return;
  }
  fmt::print("plan {}: stage {} of {} ({}{}) {} {}{}{}\n", pr.plan.name, k + 1, n,
             budget_text(s.budget), counted ? "" : length_text(c),
             resuming ? "resumes in" : "in", c.out,
             c.cameras_from.empty() ? "" : ", from the cameras of " + c.cameras_from,
             set.empty() ? "" : ";" + set);
}

// Trains c to its end, or resumes it from its folder's checkpoint. `first` = nothing of the run
// trained before it (a start that fails then removes the run folder start_plan made). Returns
// the trainer's final running train PSNR, or nullopt when interrupted.
std::optional<double> train_to_end(PlanRun& pr, const TrainConfig& c, bool first,
                                   const std::atomic<bool>* stop,
                                   const AfterStepFactory& observer_for) {
  std::optional<Trainer> t;
  if (fs::exists(c.out + "/checkpoint.bin")) {
    t.emplace(Trainer::resume(c.out));
  } else {
    try {
      t.emplace(c);
    } catch (...) {
      if (first && pr.made_run_dir) {  // nothing trained yet: leave nothing behind
        std::error_code ec;
        fs::remove_all(pr.run.out, ec);
      }
      throw;
    }
  }
  const bool done = t->run(stop, observer_for ? observer_for(*t) : std::function<void(const Trainer&)>{});
  if (!done) return std::nullopt;
  return t->state().psnr_ema;
}

void print_interrupted(const PlanRun& pr, int k) {
  fmt::print("plan {} interrupted in stage {} of {}: continue it with `hashcc train --resume {}`\n",
             pr.plan.name, k + 1, pr.stages.size(), pr.run.out);
}

// The alternatives of stage k: each unfinished one trained (or resumed) in turn, its fit
// recorded in plan.json as it finishes, then the best kept. A resumed run reads the fits of
// those that finished from plan.json, so it keeps the same one.
bool run_tries(PlanRun& pr, int k, const std::atomic<bool>* stop,
               const AfterStepFactory& observer_for) {
  ResolvedStage& s = pr.stages[k];
  const int m = int(s.tries.size());
  print_stage(pr, k, stage_config_now(pr, k), false);
  for (int j = 0; j < m; ++j) {
    ResolvedTry& t = s.tries[j];
    if (t.finished) continue;
    const TrainConfig c = try_config_now(pr, k, j);
    fmt::print("plan {}: stage {} try {} of {}{} {} {}\n", pr.plan.name, k + 1, j + 1, m,
               set_text(t.set), fs::exists(c.out + "/checkpoint.bin") ? "resumes in" : "in", c.out);
    const std::optional<double> psnr = train_to_end(pr, c, k == 0 && j == 0, stop, observer_for);
    if (!psnr) {
      print_interrupted(pr, k);
      return false;
    }
    t.finished = true;
    t.psnr_ema = *psnr;
    fmt::print("plan {}: stage {} try {} of {}{} ends at train PSNR {:.3f} dB\n", pr.plan.name,
               k + 1, j + 1, m, set_text(t.set), t.psnr_ema);
    if (!pr.run.out.empty()) write_plan_json(pr);
  }
  // The highest fit; ties go to the first, and a fit that is not a number never wins.
  int best = 0;
  for (int j = 1; j < m; ++j)
    if (const double p = s.tries[j].psnr_ema, b = s.tries[best].psnr_ema;
        !std::isnan(p) && (p > b || std::isnan(b)))
      best = j;
  keep_try(pr, k, best);
  s.finished = true;
  fmt::print("plan {}: stage {} keeps try {} of {}{} (train PSNR {:.3f} dB), in {}\n",
             pr.plan.name, k + 1, best + 1, m, set_text(s.tries[best].set),
             s.tries[best].psnr_ema, s.tries[best].config.out);
  if (!pr.run.out.empty()) write_plan_json(pr);
  return true;
}

bool run_stage(PlanRun& pr, int k, const std::atomic<bool>* stop,
               const AfterStepFactory& observer_for) {
  if (!pr.stages[k].tries.empty()) return run_tries(pr, k, stop, observer_for);
  const TrainConfig c = stage_config_now(pr, k);
  print_stage(pr, k, c, fs::exists(c.out + "/checkpoint.bin"));
  if (!train_to_end(pr, c, k == 0, stop, observer_for)) {
    print_interrupted(pr, k);
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
