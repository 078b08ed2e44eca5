// tools/study.cpp — `hashcc study`'s runner: options, plan, CSV, child processes (see study.h,
// docs/study.md). The report is tools/study_report.cpp.
#include "tools/study.h"
#include "train/trainer.h"  // preset_names

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <cmath>
#include <fcntl.h>
#include <filesystem>
#include <fmt/core.h>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <spawn.h>
#include <sstream>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "core/error.h"
#include "core/fileio.h"
#include "core/llff.h"
#include "core/progress.h"

extern char** environ;

namespace hashcc {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string trim(const std::string& s) {
  size_t a = s.find_first_not_of(" \t\r\n"), b = s.find_last_not_of(" \t\r\n");
  return a == std::string::npos ? "" : s.substr(a, b - a + 1);
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : s) {
    if (c == sep) { out.push_back(trim(cur)); cur.clear(); }
    else cur += c;
  }
  out.push_back(trim(cur));
  return out;
}

// "2" for 2.0, "0.05" for 0.05: the budget as written in ids and reports.
std::string short_num(double v) { return fmt::format("{:g}", v); }

std::string fmt_num(double v, int prec = 6) {
  return std::isfinite(v) ? fmt::format("{:.{}g}", v, prec) : "";
}

// ---- child processes ------------------------------------------------------------------------

struct ChildResult {
  int exit_code = -1;    // exit status, or -1 when killed by a signal
  int term_signal = 0;
  double seconds = 0;
  double maxrss_mb = 0;  // ru_maxrss of the child (KiB on Linux) / 1024
  double cpu_seconds = 0;  // user + system CPU time of the child
  double load_avg = -1;    // the machine's 1-minute load average when the child ended
  std::string error;     // spawn failure
};

ChildResult run_child(const std::vector<std::string>& args, const std::string& log_path) {
  ChildResult r;
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  posix_spawn_file_actions_addclose(&fa, 0);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  Timer t;
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) {
    r.error = fmt::format("cannot start {}: {}", args[0], std::strerror(rc));
    return r;
  }
  int status = 0;
  struct rusage ru {};
  while (wait4(pid, &status, 0, &ru) < 0) {
    if (errno != EINTR) {
      r.error = fmt::format("wait4: {}", std::strerror(errno));
      return r;
    }
  }
  r.seconds = t.seconds();
  r.maxrss_mb = double(ru.ru_maxrss) / 1024.0;
  r.cpu_seconds = double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
                  1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  // Budgeted runs measure the machine: another busy process steals steps. The load average
  // (which counts this run's own threads too) goes into results.csv so a reader can tell.
  if (std::FILE* f = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(f, "%lf", &r.load_avg) != 1) r.load_avg = -1;
    std::fclose(f);
  }
  if (WIFEXITED(status)) r.exit_code = WEXITSTATUS(status);
  else if (WIFSIGNALED(status)) r.term_signal = WTERMSIG(status);
  return r;
}

std::string child_failure(const ChildResult& c, const std::string& what, const std::string& log) {
  if (!c.error.empty()) return what + ": " + c.error;
  if (c.term_signal) return fmt::format("{} killed by signal {} (see {})", what, c.term_signal, log);
  return fmt::format("{} exited with status {} (see {})", what, c.exit_code, log);
}

std::string self_exe() {
  std::error_code ec;
  fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("/proc/self/exe") : p.string();
}

// Last data row of RUN/log.csv: steps done and training seconds.
std::pair<int64_t, double> last_log_row(const std::string& path) {
  const std::string text = read_file_bytes(path, kStudyMaxText);
  std::istringstream in(text);
  std::string line, last;
  std::getline(in, line);  // header
  while (std::getline(in, line)) if (!trim(line).empty()) last = line;
  if (last.empty()) return {0, 0.0};
  auto f = split(last, ',');
  HCC_REQUIRE(f.size() >= 2, path, "last row", "malformed: '{}'", last);
  return {int64_t(study_number(f[0])), study_number(f[1])};
}

// The steps and seconds of DIR/stage1/log.csv, DIR/stage2/log.csv, … summed (the stages
// `--restarts` leaves before its last, which is DIR itself).
std::pair<int64_t, double> stages_steps_seconds(const std::string& dir) {
  int64_t steps = 0;
  double seconds = 0;
  for (int k = 1; fs::exists(fmt::format("{}/stage{}/log.csv", dir, k)); ++k) {
    const auto [st, sec] = last_log_row(fmt::format("{}/stage{}/log.csv", dir, k));
    steps += st;
    seconds += sec;
  }
  return {steps, seconds};
}

}  // namespace

std::pair<int64_t, double> study_run_steps_seconds(const std::string& run_dir) {
  // A staged run names its stages in RUN/plan.json (train/plan.h): every stage's seconds count,
  // and the steps of the stages that trained the field the run ends with (a bootstrap's grid
  // phase trains another field: its steps are not the run's).
  if (fs::exists(run_dir + "/plan.json")) {
    const json plan = json::parse(read_file_bytes(run_dir + "/plan.json", kStudyMaxText));
    const json& stages = plan.at("stages");
    const std::string run_field = plan.at("run").value("field", "mlp");
    const auto field_of = [&](const json& s) { return s.at("set").value("field", run_field); };
    const std::string last_field = field_of(stages.back());
    int64_t steps = 0;
    double seconds = 0;
    for (const json& s : stages) {
      // A stage that tries alternatives trained in each of their folders (RUN/stageK/tryJ).
      std::vector<std::string> dirs;
      if (s.contains("try"))
        for (const json& t : s.at("try")) dirs.push_back(t.at("dir").get<std::string>());
      else
        dirs.push_back(s.at("dir").get<std::string>());
      for (const std::string& d : dirs) {
        const std::string log = run_dir + "/" + d + "/log.csv";
        if (!fs::exists(log)) continue;  // a stage not started yet
        const auto [st, sec] = last_log_row(log);
        if (field_of(s) == last_field) steps += st;
        seconds += sec;
      }
    }
    return {steps, seconds};
  }
  // Runs from before plans: the stage folders probed by name.
  auto [steps, seconds] = last_log_row(run_dir + "/log.csv");
  // The earlier stages of `--restarts` (RUN/stage1 …) are the same field: their steps and
  // seconds count. A bootstrap's grid phase (and its stages) counts in seconds only: the steps
  // column is the paper network's.
  const auto [stage_steps, stage_seconds] = stages_steps_seconds(run_dir);
  steps += stage_steps;
  seconds += stage_seconds;
  const std::string boot = run_dir + "/bootstrap";
  if (fs::exists(boot + "/log.csv")) seconds += last_log_row(boot + "/log.csv").second;
  seconds += stages_steps_seconds(boot).second;
  return {steps, seconds};
}

namespace {

std::string json_num(const json& j, const std::string& key) {
  if (!j.contains(key) || !j[key].is_number()) return "";
  return fmt_num(j[key].get<double>());
}

std::string images_folder_name(const std::string& data, const std::string& folder) {
  Scene sc = load_scene(data, {folder, false});
  return fs::path(sc.image_dir).filename().string();
}

}  // namespace


// ---- shared with the report -----------------------------------------------------------------

std::string budget_text(double minutes) {
  return minutes < 1 ? fmt::format("{:g} s", minutes * 60) : fmt::format("{:g} min", minutes);
}

std::string variant_title(const std::string& v) {
  if (v == "nerfmm") return "NeRF--";
  if (v == "sh") return "NeRF-- + SH";
  if (v == "hashcc") return "HashCC";
  return v;
}

double study_number(const std::string& s) {
  if (s.empty()) return std::nan("");
  try {
    size_t n = 0;
    double v = std::stod(s, &n);
    return n == s.size() ? v : std::nan("");
  } catch (...) {
    return std::nan("");
  }
}

// ---- options, plan, CSV ---------------------------------------------------------------------

std::vector<double> parse_number_list(const std::string& flag, const std::string& csv) {
  std::vector<double> out;
  for (const std::string& t : split(csv, ',')) {
    const double v = study_number(t);
    HCC_REQUIRE(std::isfinite(v) && v > 0, flag, t.empty() ? "(empty)" : t,
                "not a positive number (expected a comma-separated list such as 1,2,4)");
    out.push_back(v);
  }
  return out;
}

void parse_study_knob(const std::string& token, StudyOptions* opt) {
  const size_t eq = token.find('=');
  HCC_REQUIRE(eq != std::string::npos, "--knobs", token,
              "not name=values (expected e.g. samples=32,64 width=64,128 res=8,4)");
  const std::string name = trim(token.substr(0, eq)), values = token.substr(eq + 1);
  if (name == "samples" || name == "width") {
    for (double v : parse_number_list("--knobs " + name, values)) {
      HCC_REQUIRE(v == std::floor(v) && v >= (name == "samples" ? 2 : 4) && v <= 4096,
                  "--knobs " + name, short_num(v), "not an integer in range");
      (name == "samples" ? opt->samples : opt->widths).push_back(int(v));
    }
  } else if (name == "res") {
    for (double v : parse_number_list("--knobs res", values)) {
      HCC_REQUIRE(v == std::floor(v) && v >= 1, "--knobs res", short_num(v),
                  "not a downscale factor (expected 1, 2, 4, 8…: the folder images_<r>)");
      opt->images.push_back(v == 1 ? "images" : fmt::format("images_{}", int(v)));
    }
  } else if (name == "images") {
    for (const std::string& f : split(values, ',')) {
      HCC_REQUIRE(!f.empty(), "--knobs images", token, "empty folder name");
      opt->images.push_back(f);
    }
  } else if (name == "preset") {
    for (const std::string& f : split(values, ',')) {
      HCC_REQUIRE(std::find(preset_names().begin(), preset_names().end(), f) != preset_names().end(),
                  "--knobs preset", f, "unknown preset", preset_names_text());
      opt->presets.push_back(f);
    }
  } else if (name == "field") {
    for (const std::string& f : split(values, ',')) {
      HCC_REQUIRE(f == "mlp" || f == "grid", "--knobs field", f, "unknown field", "mlp or grid");
      opt->fields.push_back(f);
    }
  } else if (name == "bootstrap") {
    for (const std::string& f : split(values, ',')) {  // 0 = no bootstrap; else positive minutes
      if (trim(f) == "0") { opt->bootstraps.push_back(0); continue; }
      for (double v : parse_number_list("--knobs bootstrap", f)) opt->bootstraps.push_back(v);
    }
  } else if (name == "restarts") {
    for (const std::string& f : split(values, ',')) {
      if (trim(f) == "0") { opt->restarts.push_back(0); continue; }
      for (double v : parse_number_list("--knobs restarts", f)) {
        HCC_REQUIRE(v == std::floor(v) && v <= 64, "--knobs restarts", f,
                    "not a whole number of restarts", "0 to 64");
        opt->restarts.push_back(int(v));
      }
    }
  } else {
    throw Error("--knobs", token, "unknown knob '" + name + "'",
                "samples, width, res, images, preset, field, bootstrap or restarts");
  }
}

std::vector<StudyRunSpec> study_plan(const StudyOptions& opt) {
  std::vector<double> budgets = opt.budgets;
  std::sort(budgets.begin(), budgets.end());
  budgets.erase(std::unique(budgets.begin(), budgets.end()), budgets.end());
  const std::vector<int> samples = opt.samples.empty() ? std::vector<int>{0} : opt.samples;
  const std::vector<int> widths = opt.widths.empty() ? std::vector<int>{0} : opt.widths;
  const std::vector<std::string> images =
      opt.images.empty() ? std::vector<std::string>{opt.images_default} : opt.images;
  const std::vector<std::string> presets =
      opt.presets.empty() ? std::vector<std::string>{""} : opt.presets;
  const std::vector<std::string> fields =
      opt.fields.empty() ? std::vector<std::string>{""} : opt.fields;
  const std::vector<double> boots = opt.bootstraps.empty() ? std::vector<double>{0} : opt.bootstraps;
  const std::vector<int> restarts = opt.restarts.empty() ? std::vector<int>{0} : opt.restarts;
  // The product of the knobs, one axis each, the last fastest: budgets ascending, then the knobs,
  // then the variants (the order a reader compares in). A new knob is one row here.
  struct Axis {
    size_t n;
    std::function<void(StudyRunSpec&, size_t)> set;
  };
  const std::vector<Axis> axes = {
      {budgets.size(), [&](StudyRunSpec& r, size_t i) { r.budget_minutes = budgets[i]; }},
      {images.size(), [&](StudyRunSpec& r, size_t i) { r.images = images[i]; }},
      {samples.size(), [&](StudyRunSpec& r, size_t i) { r.samples = samples[i]; }},
      {widths.size(), [&](StudyRunSpec& r, size_t i) { r.width = widths[i]; }},
      {presets.size(), [&](StudyRunSpec& r, size_t i) { r.preset = presets[i]; }},
      {fields.size(), [&](StudyRunSpec& r, size_t i) { r.field = fields[i]; }},
      {boots.size(), [&](StudyRunSpec& r, size_t i) { r.bootstrap = boots[i]; }},
      {restarts.size(), [&](StudyRunSpec& r, size_t i) { r.restarts = restarts[i]; }},
      {opt.variants.size(), [&](StudyRunSpec& r, size_t i) { r.variant = opt.variants[i]; }}};
  std::vector<StudyRunSpec> plan;
  std::set<std::string> seen;
  for (const Axis& a : axes)
    if (a.n == 0) return plan;
  std::vector<size_t> at(axes.size(), 0);  // one value of each axis: a mixed-radix counter
  for (;;) {
    StudyRunSpec r;
    for (size_t k = 0; k < axes.size(); ++k) axes[k].set(r, at[k]);
    // A bootstrap hands the grid's cameras to the MLP: not for a grid run, and it must leave
    // the MLP part of the budget. Restarts cut a grid field's budget: a grid run's, or a
    // bootstrap's grid phase.
    const bool boot_fits = !(r.bootstrap > 0 && (r.field == "grid" || r.bootstrap >= r.budget_minutes));
    const bool restarts_fit = !(r.restarts > 0 && r.field != "grid" && r.bootstrap == 0);
    if (boot_fits && restarts_fit) {
      r.id = fmt::format("b{}{}_{}", short_num(r.budget_minutes), opt.budget_steps ? "steps" : "",
                         r.variant);
      if (r.samples) r.id += fmt::format("_s{}", r.samples);
      if (r.width) r.id += fmt::format("_w{}", r.width);
      if (!r.preset.empty()) r.id += "_" + r.preset;
      if (!r.field.empty()) r.id += "_" + r.field;
      if (r.bootstrap > 0) r.id += "_boot" + short_num(r.bootstrap);
      if (r.restarts > 0) r.id += fmt::format("_r{}", r.restarts);
      if (!r.images.empty()) r.id += "_" + r.images;
      if (seen.insert(r.id).second) plan.push_back(r);
    }
    int k = int(axes.size()) - 1;
    while (k >= 0 && ++at[k] == axes[k].n) at[k--] = 0;
    if (k < 0) break;
  }
  return plan;
}

const std::vector<std::string>& study_columns() {
  static const std::vector<std::string> c = {
      "id", "variant", "budget_minutes", "samples", "width", "rays", "images", "image_width",
      "image_height", "steps", "epochs", "seconds", "train_wall_seconds", "eval_seconds",
      "refine_epochs", "psnr", "ssim", "lpips", "rot_err_deg", "trans_err", "rel_rot_err_deg",
      "rel_rot_do_nothing_deg", "fx", "ref_focal", "peak_rss_mb", "train_rss_mb", "eval_rss_mb",
      "eval_mode", "threads", "train_cpu_seconds", "load_avg", "field", "bootstrap_minutes",
      "restarts",
      "preset"};
  return c;
}

int CsvTable::col(const std::string& name) const {
  for (size_t i = 0; i < header.size(); ++i) if (header[i] == name) return int(i);
  return -1;
}

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string o = "\"";
  for (char c : s) o += c == '"' ? std::string("\"\"") : std::string(1, c);
  return o + "\"";
}

CsvTable read_csv(const std::string& path) {
  CsvTable t;
  if (!fs::exists(path)) return t;
  const std::string text = read_file_bytes(path, kStudyMaxText);
  std::vector<std::vector<std::string>> recs;
  std::vector<std::string> rec;
  std::string cur;
  bool quoted = false, any = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (quoted) {
      if (c == '"' && i + 1 < text.size() && text[i + 1] == '"') { cur += '"'; ++i; }
      else if (c == '"') quoted = false;
      else cur += c;
    } else if (c == '"') {
      quoted = true;
      any = true;
    } else if (c == ',') {
      rec.push_back(cur); cur.clear(); any = true;
    } else if (c == '\n' || c == '\r') {
      if (c == '\r' && i + 1 < text.size() && text[i + 1] == '\n') ++i;
      if (any || !cur.empty()) { rec.push_back(cur); recs.push_back(rec); }
      rec.clear(); cur.clear(); any = false;
    } else {
      cur += c;
      any = true;
    }
  }
  if (any || !cur.empty()) { rec.push_back(cur); recs.push_back(rec); }
  if (recs.empty()) return t;
  t.header = recs[0];
  for (size_t i = 1; i < recs.size(); ++i) {
    HCC_REQUIRE(recs[i].size() == t.header.size(), path, fmt::format("row {}", i + 1),
                "{} fields, the header has {}", recs[i].size(), t.header.size());
    t.rows.push_back(recs[i]);
  }
  return t;
}

// ---- running --------------------------------------------------------------------------------

namespace {

// A run's `train` command line (argv). Previews and periodic checkpoints are off: their time
// would be charged to the budget (the final checkpoint, which eval reads, is always written).
std::vector<std::string> train_argv(const StudyOptions& opt, const std::string& exe,
                                    const StudyRunSpec& r, const std::string& dir) {
  std::vector<std::string> a = {exe, "train", "--data", opt.data, "--out", dir, "--model",
                                r.variant};
  if (opt.budget_steps) a.insert(a.end(), {"--steps", short_num(r.budget_minutes)});
  else a.insert(a.end(), {"--minutes", short_num(r.budget_minutes)});
  a.insert(a.end(), {"--seed", std::to_string(opt.seed), "--images", r.images,
                     "--checkpoint-minutes", "1e6", "--preview-minutes", "1e6", "--no-progress"});
  if (r.samples) a.insert(a.end(), {"--samples", std::to_string(r.samples)});
  if (r.width) a.insert(a.end(), {"--width", std::to_string(r.width)});
  // Without a preset knob a study measures the variants as the paper runs them, in one stage:
  // `--preset paper`, since train's own default (auto) is the forward recipe's five stages.
  a.insert(a.end(), {"--preset", r.preset.empty() ? std::string("paper") : r.preset});
  if (!r.field.empty()) a.insert(a.end(), {"--field", r.field});
  if (r.bootstrap > 0) a.insert(a.end(), {"--bootstrap-minutes", short_num(r.bootstrap)});
  if (r.restarts > 0) a.insert(a.end(), {"--restarts", std::to_string(r.restarts)});
  if (opt.threads) a.insert(a.end(), {"--threads", std::to_string(opt.threads)});
  a.insert(a.end(), opt.train_args.begin(), opt.train_args.end());
  return a;
}

std::vector<std::string> eval_argv(const StudyOptions& opt, const std::string& exe,
                                   const std::string& dir) {
  std::vector<std::string> e = {exe, "eval", "--run", dir, "--refine-epochs",
                                std::to_string(opt.refine_epochs), "--no-progress"};
  if (!opt.lpips_weights.empty()) e.insert(e.end(), {"--lpips-weights", opt.lpips_weights});
  if (opt.threads) e.insert(e.end(), {"--threads", std::to_string(opt.threads)});
  return e;
}

// A finished run's CSV row (values of study_columns()) from its folder: config.json, log.csv,
// eval/metrics.json. tr/ev: the children as the study measured them (wall time, memory, CPU,
// load); null when the run was started by someone else (--emit-commands): those cells are empty.
std::vector<std::string> read_run_row(const StudyOptions& opt, const StudyRunSpec& r,
                                      const Scene& sizes, const std::string& dir,
                                      const ChildResult* tr, const ChildResult* ev) {
  const auto [steps, seconds] = study_run_steps_seconds(dir);
  const json cfg = json::parse(read_file_bytes(dir + "/config.json", kStudyMaxText));
  const json m = json::parse(read_file_bytes(dir + "/eval/metrics.json", kStudyMaxText));
  const int n_train = int(sizes.train.size());
  std::map<std::string, std::string> v;
  v["id"] = r.id;
  v["variant"] = r.variant;
  v["budget_minutes"] = short_num(r.budget_minutes);
  v["samples"] = std::to_string(cfg.value("samples", 0));
  v["width"] = std::to_string(cfg.value("width", 0));
  v["rays"] = std::to_string(cfg.value("rays", 0));
  v["images"] = r.images;
  v["image_width"] = std::to_string(sizes.width);
  v["image_height"] = std::to_string(sizes.height);
  v["steps"] = std::to_string(steps);
  // An epoch visits every training image once: ⌈n / K⌉ steps with --images-per-step K.
  const int per_step = std::max(1, cfg.value("images_per_step", 1));
  const int steps_per_epoch = (n_train + per_step - 1) / per_step;
  v["epochs"] = n_train > 0 ? fmt::format("{:.2f}", double(steps) / steps_per_epoch) : "";
  v["seconds"] = fmt::format("{:.2f}", seconds);
  v["refine_epochs"] = m.contains("refine_epochs") && m["refine_epochs"].is_number()
                           ? std::to_string(m["refine_epochs"].get<int>()) : "";
  for (const char* k : {"psnr", "ssim", "lpips", "rot_err_deg", "trans_err", "rel_rot_err_deg",
                        "rel_rot_do_nothing_deg"})
    v[k] = json_num(m, k);
  if (m.contains("focal") && m["focal"].is_object()) {
    v["fx"] = json_num(m["focal"], "fx");
    v["ref_focal"] = json_num(m["focal"], "reference");
  }
  if (tr && ev) {
    v["train_wall_seconds"] = fmt::format("{:.2f}", tr->seconds);
    v["eval_seconds"] = fmt::format("{:.2f}", ev->seconds);
    v["peak_rss_mb"] = fmt::format("{:.1f}", std::max(tr->maxrss_mb, ev->maxrss_mb));
    v["train_rss_mb"] = fmt::format("{:.1f}", tr->maxrss_mb);
    v["eval_rss_mb"] = fmt::format("{:.1f}", ev->maxrss_mb);
    v["train_cpu_seconds"] = fmt::format("{:.1f}", tr->cpu_seconds);
    if (tr->load_avg >= 0) v["load_avg"] = fmt::format("{:.2f}", tr->load_avg);
  }
  v["eval_mode"] = m.value("mode", "");
  v["threads"] = opt.threads ? std::to_string(opt.threads) : "all";
  v["preset"] = cfg.value("preset", std::string("paper"));
  v["field"] = cfg.value("field", std::string("mlp"));
  v["bootstrap_minutes"] = short_num(cfg.value("bootstrap_minutes", 0.0));
  v["restarts"] = std::to_string(cfg.value("restarts", 0));
  std::vector<std::string> row;
  for (const auto& c : study_columns()) row.push_back(v.count(c) ? v[c] : "");
  return row;
}

// One run: train, eval, the CSV row (as values of study_columns()). Returns "" on success or
// the failure; *interrupted when a child stopped on SIGINT/SIGTERM.
std::string run_one(const StudyOptions& opt, const std::string& exe, const StudyRunSpec& r,
                    const Scene& sizes, std::vector<std::string>* row, bool* interrupted) {
  const std::string dir = opt.out + "/runs/" + r.id;
  std::error_code ec;
  fs::remove_all(dir, ec);  // a run folder without a CSV row is an interrupted run: redo it
  make_dirs(dir);
  const ChildResult tr = run_child(train_argv(opt, exe, r, dir), dir + "/train.log");
  if (tr.exit_code == 130 || (opt.stop && opt.stop->load())) { *interrupted = true; return "interrupted"; }
  if (tr.exit_code != 0) return child_failure(tr, "train", dir + "/train.log");
  const ChildResult ev = run_child(eval_argv(opt, exe, dir), dir + "/eval.log");
  if (opt.stop && opt.stop->load()) { *interrupted = true; return "interrupted"; }
  if (ev.exit_code != 0) return child_failure(ev, "eval", dir + "/eval.log");
  *row = read_run_row(opt, r, sizes, dir, &tr, &ev);
  return "";
}

std::string csv_line(const std::vector<std::string>& f) {
  std::string s;
  for (size_t i = 0; i < f.size(); ++i) {
    if (i) s += ',';
    s += csv_field(f[i]);
  }
  return s + "\n";
}

// STUDY/study.json: the settings every row shares. A restart with other values would mix
// incomparable rows, so it is refused.
void check_study_json(const StudyOptions& opt) {
  const std::string path = opt.out + "/study.json";
  std::error_code ec;
  const std::string data = fs::weakly_canonical(opt.data, ec).string();
  json want = {{"data", data}, {"refine_epochs", opt.refine_epochs},
               {"lpips_weights", opt.lpips_weights.empty() ? "" : fs::weakly_canonical(opt.lpips_weights, ec).string()},
               {"seed", opt.seed}, {"threads", opt.threads}, {"train_args", opt.train_args}};
  if (fs::exists(path)) {
    json have = json::parse(read_file_bytes(path, kStudyMaxText), nullptr, false);
    HCC_REQUIRE(!have.is_discarded(), path, "", "not valid JSON");
    for (auto& [k, val] : want.items())
      HCC_REQUIRE(have.value(k, json()) == val, path, k,
                  "this study was made with {} = {}, now {} (use another --out)", k,
                  have.value(k, json()).dump(), val.dump());
  }
  json all = want;
  // The whole plan, so that `hashcc study --collect` knows which runs to gather.
  all["plan"] = {{"data", data}, {"out", fs::absolute(opt.out).lexically_normal().string()},
                 {"budgets", opt.budgets}, {"budget_steps", opt.budget_steps},
                 {"variants", opt.variants}, {"samples", opt.samples}, {"widths", opt.widths},
                 {"images", opt.images}, {"images_default", opt.images_default},
                 {"presets", opt.presets}, {"fields", opt.fields},
                 {"bootstraps", opt.bootstraps}, {"restarts", opt.restarts},
                 {"refine_epochs", opt.refine_epochs}, {"lpips_weights", want["lpips_weights"]},
                 {"bench_json", opt.bench_json.empty() ? "" : "bench.json"},
                 {"threads", opt.threads}, {"seed", opt.seed}, {"train_args", opt.train_args}};
  all["engine"] = "hashcc";
  all["version"] = HASHCC_VERSION;
  write_file_atomic(path, all.dump(2) + "\n");
}

}  // namespace

namespace {

// Bad options fail before anything runs.
void check_study_options(const StudyOptions& opt) {
  HCC_REQUIRE(!opt.data.empty(), "--data", "", "missing (expected a scene folder)");
  HCC_REQUIRE(!opt.out.empty(), "--out", "", "missing (expected a study folder)");
  HCC_REQUIRE(!opt.budgets.empty(), "--budgets", "", "empty (expected minutes such as 1,2,4)");
  HCC_REQUIRE(!opt.variants.empty(), "--variants", "", "empty (expected nerfmm, sh, hashcc)");
  for (const auto& v : opt.variants)
    HCC_REQUIRE(v == "nerfmm" || v == "sh" || v == "hashcc", "--variants", v, "unknown variant (expected nerfmm, sh or hashcc)");
  HCC_REQUIRE(opt.refine_epochs >= 0, "--refine-epochs", "", "negative");
  if (!opt.lpips_weights.empty())
    HCC_REQUIRE(fs::is_directory(opt.lpips_weights), opt.lpips_weights, "", "not a folder (expected the LPIPS-VGG weights folder)");
  if (!opt.bench_json.empty())
    HCC_REQUIRE(fs::is_regular_file(opt.bench_json), opt.bench_json, "", "no such file (expected a `hashcc bench --json` output)");
}

// Resolves the image folders now (sizes only): a bad res knob fails before anything runs, and
// "" (smallest present) becomes its real name in the ids and the CSV. Returns folder → scene.
std::map<std::string, Scene> resolve_image_folders(StudyOptions& opt) {
  std::map<std::string, Scene> sizes;
  if (opt.images.empty()) opt.images_default = images_folder_name(opt.data, opt.images_default);
  for (auto& im : opt.images) im = images_folder_name(opt.data, im);
  for (const auto& im : opt.images.empty() ? std::vector<std::string>{opt.images_default} : opt.images)
    sizes[im] = load_scene(opt.data, {im, false, TrainConfig{}.max_side});  // train's default
  return sizes;
}

// STUDY/results.csv as text, with the header from the start (rows are appended as runs
// finish). A CSV begun by an older version is rewritten in this version's layout (new columns
// empty) when every old column still exists, otherwise refused. *finished: the ids it holds.
std::string open_results_csv(const std::string& csv_path, std::set<std::string>* finished) {
  CsvTable table = read_csv(csv_path);
  if (!table.header.empty() && table.header != study_columns()) {
    std::vector<int> from;
    for (const auto& c : study_columns()) from.push_back(table.col(c));
    for (const auto& h : table.header)
      HCC_REQUIRE(std::find(study_columns().begin(), study_columns().end(), h) != study_columns().end(),
                  csv_path, "header", "column '{}' is unknown to this version (use another --out)", h);
    std::string text = csv_line(study_columns());
    for (auto& row : table.rows) {
      std::vector<std::string> nr;
      for (int i : from) nr.push_back(i >= 0 ? row[i] : "");
      row = nr;
      text += csv_line(nr);
    }
    table.header = study_columns();
    write_file_atomic(csv_path, text);
  }
  for (const auto& row : table.rows) finished->insert(row[0]);
  std::string csv_text = fs::exists(csv_path) ? read_file_bytes(csv_path, kStudyMaxText) : "";
  if (csv_text.empty()) {
    csv_text = csv_line(study_columns());
    write_file_atomic(csv_path, csv_text);
  }
  return csv_text;
}

// The one-line summary of a finished run (row: its values of study_columns()).
void print_run_summary(const std::vector<std::string>& row) {
  const auto& c = study_columns();
  auto get = [&](const char* name) {
    return row[size_t(std::find(c.begin(), c.end(), name) - c.begin())];
  };
  auto n = [&](const char* name, int prec) {
    const double v = study_number(get(name));
    return std::isfinite(v) ? fmt::format("{:.{}f}", v, prec) : std::string("null");
  };
  fmt::print("  {} steps in {} s | PSNR {} SSIM {} | rel rot {}° (do-nothing {}°) | peak {} MB\n",
             get("steps"), n("seconds", 1), n("psnr", 2), n("ssim", 3), n("rel_rot_err_deg", 2),
             n("rel_rot_do_nothing_deg", 2), n("peak_rss_mb", 0));
}

}  // namespace

StudySummary run_study(const StudyOptions& o) {
  StudyOptions opt = o;
  check_study_options(opt);
  const std::map<std::string, Scene> sizes = resolve_image_folders(opt);
  make_dirs(opt.out + "/runs");
  check_study_json(opt);
  const std::string csv_path = opt.out + "/results.csv";
  std::set<std::string> finished;
  std::string csv_text = open_results_csv(csv_path, &finished);
  if (!opt.bench_json.empty() &&
      fs::weakly_canonical(opt.bench_json) != fs::weakly_canonical(opt.out + "/bench.json"))
    fs::copy_file(opt.bench_json, opt.out + "/bench.json", fs::copy_options::overwrite_existing);

  const std::string exe = opt.exe.empty() ? self_exe() : opt.exe;
  const auto plan = study_plan(opt);
  StudySummary sum;
  sum.planned = int(plan.size());
  int k = 0;
  for (const auto& r : plan) {
    ++k;
    if (finished.count(r.id)) { ++sum.skipped; continue; }
    if (opt.stop && opt.stop->load()) { sum.interrupted = true; break; }
    if (!opt.quiet)
      fmt::print("[{}/{}] {}: {} for {} …\n", k, plan.size(), r.id, variant_title(r.variant),
                 budget_text(r.budget_minutes));
    std::fflush(stdout);
    std::vector<std::string> row;
    bool interrupted = false;
    std::string err;
    try {
      err = run_one(opt, exe, r, sizes.at(r.images), &row, &interrupted);
    } catch (const std::exception& e) {
      err = e.what();  // unreadable outputs of one run: that run failed, the study goes on
    }
    if (interrupted) { sum.interrupted = true; break; }
    if (!err.empty()) {
      sum.failed.push_back(r.id + ": " + err);
      if (!opt.quiet) fmt::print("  failed: {}\n", err);
      continue;
    }
    csv_text += csv_line(row);
    write_file_atomic(csv_path, csv_text);  // the row appears only once train and eval finished
    ++sum.done;
    if (!opt.quiet) print_run_summary(row);
  }
  write_study_report(opt.out, opt.bench_json.empty() ? "" : opt.out + "/bench.json");
  return sum;
}

// ---- fan-out: --emit-commands and --collect ---------------------------------------------------

namespace {

// 'text' for a POSIX shell (a ' inside becomes '\'').
std::string shell_quote(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                        "0123456789_-./=:,+@%") == std::string::npos)
    return s;
  std::string o = "'";
  for (char c : s) o += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return o + "'";
}

std::string shell_line(const std::vector<std::string>& argv) {
  std::string s;
  for (const auto& a : argv) s += (s.empty() ? "" : " ") + shell_quote(a);
  return s;
}

// The line of a log that says why it failed: its last "hashcc: …" error line (a usage error is
// followed by a hint), else its last non-empty line ("" when absent or empty).
std::string last_log_line(const std::string& path) {
  if (!fs::exists(path)) return "";
  std::istringstream in(read_file_bytes(path, kStudyMaxText));
  std::string line, last, error;
  while (std::getline(in, line)) {
    line = trim(line);
    if (line.empty()) continue;
    last = line;
    if (line.rfind("hashcc: ", 0) == 0) error = line;
  }
  return error.empty() ? last : error;
}

// A process's own measurements (`hashcc … --rusage-json FILE`); false when absent or unreadable.
bool read_rusage(const std::string& path, ChildResult* c) {
  if (!fs::exists(path)) return false;
  const json j = json::parse(read_file_bytes(path, kStudyMaxText), nullptr, false);
  if (j.is_discarded() || !j.is_object()) return false;
  c->seconds = j.value("wall_seconds", 0.0);
  c->cpu_seconds = j.value("cpu_seconds", 0.0);
  c->maxrss_mb = j.value("maxrss_mb", 0.0);
  c->load_avg = j.value("load_avg", -1.0);
  return true;
}

// The study's options as --emit-commands recorded them in STUDY/study.json.
StudyOptions options_from_study_json(const std::string& study_dir) {
  const std::string path = study_dir + "/study.json";
  HCC_REQUIRE(fs::exists(path), path, "", "missing (expected a study folder made by `hashcc study` "
              "or `hashcc study --emit-commands`)");
  const json all = json::parse(read_file_bytes(path, kStudyMaxText), nullptr, false);
  HCC_REQUIRE(!all.is_discarded() && all.contains("plan") && all["plan"].is_object(), path, "plan",
              "missing (a study folder from an older version: rerun `hashcc study --emit-commands`)");
  const json& p = all["plan"];
  StudyOptions o;
  try {
    o.data = p.at("data").get<std::string>();
    o.out = study_dir;
    o.budgets = p.at("budgets").get<std::vector<double>>();
    o.budget_steps = p.value("budget_steps", false);
    o.variants = p.at("variants").get<std::vector<std::string>>();
    o.samples = p.at("samples").get<std::vector<int>>();
    o.widths = p.at("widths").get<std::vector<int>>();
    o.images = p.at("images").get<std::vector<std::string>>();
    o.images_default = p.at("images_default").get<std::string>();
    o.presets = p.at("presets").get<std::vector<std::string>>();
    o.fields = p.at("fields").get<std::vector<std::string>>();
    o.bootstraps = p.at("bootstraps").get<std::vector<double>>();
    o.restarts = p.at("restarts").get<std::vector<int>>();
    o.refine_epochs = p.at("refine_epochs").get<int>();
    o.lpips_weights = p.at("lpips_weights").get<std::string>();
    const std::string bench = p.value("bench_json", std::string());
    o.bench_json = bench.empty() ? "" : study_dir + "/" + bench;
    o.threads = p.at("threads").get<int>();
    o.seed = p.at("seed").get<uint64_t>();
    o.train_args = p.at("train_args").get<std::vector<std::string>>();
  } catch (const json::exception& e) {
    HCC_REQUIRE(false, path, "plan", "unreadable: {}", e.what());
  }
  return o;
}

}  // namespace

int write_study_commands(const StudyOptions& o, const std::string& file) {
  StudyOptions opt = o;
  check_study_options(opt);
  std::error_code ec;
  opt.data = fs::weakly_canonical(opt.data, ec).string();
  opt.out = fs::absolute(opt.out).lexically_normal().string();
  if (!opt.out.empty() && opt.out.back() == '/') opt.out.pop_back();
  if (!opt.lpips_weights.empty()) opt.lpips_weights = fs::weakly_canonical(opt.lpips_weights, ec).string();
  resolve_image_folders(opt);
  make_dirs(opt.out + "/runs");
  check_study_json(opt);
  std::set<std::string> finished;
  open_results_csv(opt.out + "/results.csv", &finished);
  if (!opt.bench_json.empty() &&
      fs::weakly_canonical(opt.bench_json) != fs::weakly_canonical(opt.out + "/bench.json"))
    fs::copy_file(opt.bench_json, opt.out + "/bench.json", fs::copy_options::overwrite_existing);
  const std::string exe = opt.exe.empty() ? self_exe() : fs::absolute(opt.exe).string();
  std::string text;
  int n = 0;
  for (const auto& r : study_plan(opt)) {
    if (finished.count(r.id)) continue;
    const std::string dir = opt.out + "/runs/" + r.id;
    // The same commands run_one runs, in the same folder; a rerun starts the run afresh.
    text += "rm -rf " + shell_quote(dir) + " && mkdir -p " + shell_quote(dir) + " && " +
            shell_line(train_argv(opt, exe, r, dir)) + " --rusage-json " +
            shell_quote(dir + "/train.rusage.json") + " < /dev/null > " +
            shell_quote(dir + "/train.log") + " 2>&1 && " + shell_line(eval_argv(opt, exe, dir)) +
            " --rusage-json " + shell_quote(dir + "/eval.rusage.json") + " < /dev/null > " +
            shell_quote(dir + "/eval.log") + " 2>&1\n";
    ++n;
  }
  write_file_atomic(file, text);
  return n;
}

StudySummary collect_study(const std::string& study_dir) {
  StudyOptions opt = options_from_study_json(study_dir);
  const std::map<std::string, Scene> sizes = resolve_image_folders(opt);
  const std::string csv_path = opt.out + "/results.csv";
  std::set<std::string> finished;
  open_results_csv(csv_path, &finished);
  const CsvTable old = read_csv(csv_path);
  std::map<std::string, std::vector<std::string>> rows;  // id → row
  for (const auto& row : old.rows) rows[row[0]] = row;
  const auto plan = study_plan(opt);
  std::set<std::string> planned;
  StudySummary sum;
  sum.planned = int(plan.size());
  for (const auto& r : plan) {
    planned.insert(r.id);
    const std::string dir = opt.out + "/runs/" + r.id;
    const bool done = fs::exists(dir + "/eval/metrics.json") && fs::exists(dir + "/config.json");
    if (!done) {
      if (rows.count(r.id)) { ++sum.skipped; continue; }  // gathered before, folder gone since
      std::string why;
      if (!fs::exists(dir + "/train.log")) why = "not run";
      else if (!fs::exists(dir + "/eval.log")) {
        const std::string l = last_log_line(dir + "/train.log");
        why = "train failed: " + (l.empty() ? std::string("(empty log)") : l) + " (see " + dir + "/train.log)";
      } else {
        const std::string l = last_log_line(dir + "/eval.log");
        why = "eval failed: " + (l.empty() ? std::string("(empty log)") : l) + " (see " + dir + "/eval.log)";
      }
      sum.failed.push_back(r.id + ": " + why);
      continue;
    }
    try {
      // What the process measured of itself (--rusage-json), in place of the study's children.
      ChildResult tr, ev;
      const bool measured = read_rusage(dir + "/train.rusage.json", &tr) &&
                            read_rusage(dir + "/eval.rusage.json", &ev);
      rows[r.id] = read_run_row(opt, r, sizes.at(r.images), dir, measured ? &tr : nullptr,
                                measured ? &ev : nullptr);
      ++sum.done;
    } catch (const std::exception& e) {
      sum.failed.push_back(r.id + ": " + e.what());
    }
  }
  // Rows of runs no longer planned first (as they were), then the plan's, in plan order: the
  // order a direct `hashcc study` appends them in.
  std::string text = csv_line(study_columns());
  for (const auto& row : old.rows) if (!planned.count(row[0])) text += csv_line(row);
  for (const auto& r : plan) if (rows.count(r.id)) text += csv_line(rows[r.id]);
  write_file_atomic(csv_path, text);
  write_study_report(opt.out, opt.bench_json);
  return sum;
}

}  // namespace hashcc
