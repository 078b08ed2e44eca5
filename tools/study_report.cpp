// tools/study_report.cpp — `hashcc study`'s report: the SVG figures and report.md, one function
// per figure or table, all reading one Report (the rows of results.csv, sorted). See study.h.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fmt/core.h>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "core/error.h"
#include "core/fileio.h"
#include "tools/html.h"
#include "tools/study.h"
#include "tools/svg.h"

namespace hashcc {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct Row {
  std::map<std::string, std::string> s;
  double num(const std::string& k) const {
    auto it = s.find(k);
    return it == s.end() ? std::nan("") : study_number(it->second);
  }
  std::string str(const std::string& k) const {
    auto it = s.find(k);
    return it == s.end() ? "" : it->second;
  }
  // The knobs that tell runs of one variant apart: a line of the plots and a row label. The
  // field and the bootstrap are named only when they are not the paper's (MLP, none).
  std::string knobs() const {
    const std::string p = str("preset"), field = str("field");
    const double boot = num("bootstrap_minutes"), rs = num("restarts");
    return fmt::format("{} samples, width {}, {}{}{}{}{}", str("samples"), str("width"),
                       str("images"), p.empty() || p == "paper" ? "" : ", preset " + p,
                       field == "grid" ? ", grid field" : "",
                       std::isfinite(boot) && boot > 0 ? fmt::format(", bootstrap {:g} min", boot)
                                                       : "",
                       std::isfinite(rs) && rs > 0 ? fmt::format(", {:g} restarts", rs) : "");
  }
};

int variant_rank(const std::string& v) {
  return v == "nerfmm" ? 0 : v == "sh" ? 1 : v == "hashcc" ? 2 : 3;
}

std::string f2(double v, const char* unit = "") {
  return std::isfinite(v) ? fmt::format("{:.2f}{}", v, unit) : "—";
}
// SSIM and LPIPS in the tables: three decimals, or `missing` when the cell is null.
std::string f3(double v, const char* missing = "—") {
  return std::isfinite(v) ? fmt::format("{:.3f}", v) : missing;
}

// Series of (variant, knob combination), each sorted by training seconds.
struct Line {
  std::string variant, knobs;
  std::vector<const Row*> rows;
};
std::vector<Line> lines_of(const std::vector<Row>& rows) {
  std::map<std::pair<int, std::string>, Line> m;
  for (const Row& r : rows) {
    Line& l = m[{variant_rank(r.str("variant")), r.str("variant") + "|" + r.knobs()}];
    l.variant = r.str("variant");
    l.knobs = r.knobs();
    l.rows.push_back(&r);
  }
  std::vector<Line> out;
  for (auto& [k, l] : m) {
    std::sort(l.rows.begin(), l.rows.end(),
              [](const Row* a, const Row* b) { return a->num("seconds") < b->num("seconds"); });
    out.push_back(l);
  }
  return out;
}

std::string variant_color(const std::string& v) {
  return svg::palette(variant_rank(v));
}

// What every figure and table of one report reads, and where they go.
struct Report {
  std::string dir, data, scene;
  std::vector<Row> rows;         // budget, then knobs, then variant
  std::vector<Line> lines;
  bool several_knobs = false;
  std::string knob_note;         // the one knob combination, when there is only one
  std::string res_note;          // "W×H px" of the images
  std::string refine;            // refinement epochs
  std::vector<std::string> written;
  void put(const std::string& name, const std::string& text) {
    write_file_atomic(dir + "/" + name, text);
    written.push_back(name);
  }
  bool wrote(const std::string& name) const {
    return std::find(written.begin(), written.end(), name) != written.end();
  }
};

Report load_report(const std::string& dir) {
  Report rp;
  rp.dir = dir;
  const CsvTable t = read_csv(dir + "/results.csv");
  for (const auto& rr : t.rows) {
    Row r;
    for (size_t i = 0; i < t.header.size(); ++i) r.s[t.header[i]] = rr[i];
    rp.rows.push_back(r);
  }
  // Budget, then knobs, then variant: the order a reader compares in (a restarted study
  // appends redone runs at the end of the CSV).
  std::stable_sort(rp.rows.begin(), rp.rows.end(), [](const Row& a, const Row& b) {
    if (a.num("budget_minutes") != b.num("budget_minutes"))
      return a.num("budget_minutes") < b.num("budget_minutes");
    if (a.knobs() != b.knobs()) return a.knobs() < b.knobs();
    return variant_rank(a.str("variant")) < variant_rank(b.str("variant"));
  });
  json study = json::object();
  if (fs::exists(dir + "/study.json"))
    study = json::parse(read_file_bytes(dir + "/study.json", kStudyMaxText), nullptr, false);
  rp.data = study.is_object() ? study.value("data", "") : "";
  rp.scene = fs::path(rp.data).filename().string();
  rp.lines = lines_of(rp.rows);
  std::set<std::string> knob_set;
  for (const Row& r : rp.rows) knob_set.insert(r.knobs());
  rp.several_knobs = knob_set.size() > 1;
  rp.knob_note = rp.several_knobs ? "" : (knob_set.empty() ? "" : *knob_set.begin());
  const std::vector<Row>& rows = rp.rows;
  rp.res_note =
      rows.empty() ? "" : fmt::format("{}×{} px", rows[0].str("image_width"), rows[0].str("image_height"));
  rp.refine = rows.empty() ? "" : rows[0].str("refine_epochs");
  return rp;
}

svg::Plot time_plot(const Report& rp, const std::string& metric, const std::string& title,
                    const std::string& ylabel) {
  svg::Plot p;
  p.title = title;
  p.x = {"training time (s, log scale)", true};
  p.y = {ylabel, false};
  std::map<std::string, int> knob_index;
  for (const Line& l : rp.lines) knob_index.emplace(l.knobs, int(knob_index.size()));
  static const char* dashes[] = {"", "6,4", "2,3", "10,3,2,3"};
  for (const Line& l : rp.lines) {
    svg::Series s;
    s.name = variant_title(l.variant) + (rp.several_knobs ? " (" + l.knobs + ")" : "");
    s.color = variant_color(l.variant);
    s.dash = dashes[knob_index[l.knobs] % 4];
    for (const Row* r : l.rows) {
      s.x.push_back(r->num("seconds"));
      s.y.push_back(r->num(metric));
    }
    p.series.push_back(s);
  }
  return p;
}

// psnr_vs_time.svg
void plot_psnr(Report& rp) {
  svg::Plot p = time_plot(rp, "psnr", "Test PSNR vs training time" + (rp.scene.empty() ? "" : " — " + rp.scene),
                          "test PSNR (dB)");
  p.notes.push_back(fmt::format("{}{}{}; test poses refined {} epochs", rp.scene.empty() ? "" : rp.scene + ", ",
                                rp.res_note, rp.knob_note.empty() ? "" : ", " + rp.knob_note, rp.refine));
  rp.put("psnr_vs_time.svg", svg::render(p));
}

// rot_err_vs_time.svg: the Sim(3)-aligned rotation error.
void plot_rot_err(Report& rp) {
  svg::Plot p = time_plot(rp, "rot_err_deg",
                          "Camera rotation error ΔR (Sim(3)-aligned) vs training time",
                          "ΔR, mean over training cameras (degrees)");
  p.notes.push_back("early in training the Sim(3) fit is ill-conditioned: read the relative error plot too");
  rp.put("rot_err_vs_time.svg", svg::render(p));
}

// rel_rot_vs_time.svg: the alignment-free relative rotation error, with its do-nothing value.
void plot_rel_rot(Report& rp) {
  double do_nothing = 0;
  int n_dn = 0;
  for (const Row& r : rp.rows)
    if (std::isfinite(r.num("rel_rot_do_nothing_deg"))) do_nothing += r.num("rel_rot_do_nothing_deg"), ++n_dn;
  svg::Plot p = time_plot(rp, "rel_rot_err_deg", "Relative rotation error vs training time",
                          "relative rotation error, mean over pairs (degrees)");
  p.notes.push_back("alignment-free (formulas.md §7); below the dashed line = better than not moving the cameras");
  if (n_dn) p.hlines.push_back({do_nothing / n_dn, fmt::format("do nothing ({:.2f}°)", do_nothing / n_dn)});
  rp.put("rel_rot_vs_time.svg", svg::render(p));
}

// pareto.svg over every run; returns the indices (into rp.rows) of the front.
std::vector<int> plot_pareto(Report& rp) {
  std::vector<double> xs, ys;
  for (const Row& r : rp.rows) xs.push_back(r.num("seconds")), ys.push_back(r.num("psnr"));
  const std::vector<int> front = svg::pareto_front(xs, ys);
  svg::Plot p;
  p.title = "Which configuration buys the most PSNR per second";
  p.x = {"training time (s, log scale)", true};
  p.y = {"test PSNR (dB)", false};
  p.notes.push_back("every run (all budgets and knobs); the line joins the runs no other run beats on both");
  std::map<std::string, svg::Series> by_variant;
  for (const Row& r : rp.rows) {
    svg::Series& s = by_variant[fmt::format("{}{}", variant_rank(r.str("variant")), r.str("variant"))];
    s.name = variant_title(r.str("variant"));
    s.color = variant_color(r.str("variant"));
    s.line = false;
    s.x.push_back(r.num("seconds"));
    s.y.push_back(r.num("psnr"));
  }
  svg::Series fs_;
  fs_.name = "Pareto front";
  fs_.color = "#000000";
  fs_.hollow = true;
  fs_.radius = 7;
  fs_.width = 1.5;
  fs_.dash = "5,3";
  for (int i : front) fs_.x.push_back(xs[size_t(i)]), fs_.y.push_back(ys[size_t(i)]);
  p.series.push_back(fs_);
  for (auto& [k, s] : by_variant) p.series.push_back(s);
  rp.put("pareto.svg", svg::render(p));
  return front;
}

// The training curves of the runs at one budget, from each run's runs/<id>/log.csv (one row a
// step, written by `hashcc train`): what the end-of-run numbers cannot show is *when* the field
// got sharp and whether the cameras were still allowed to move then. A batch's train PSNR is
// noisy (1,024 rays), so it is shown as the mean of the last `kWindow` steps; every curve is
// thinned to at most ~400 points. Returns the number of runs that had a log.
struct CurvePlots {
  svg::Plot psnr, fx, lr, rot;  // rot: from runs/<id>/camera_error.csv (scenes with a reference)
  int runs = 0, rot_runs = 0;
};
CurvePlots training_curves(const std::string& dir, const std::vector<const Row*>& runs) {
  constexpr size_t kWindow = 50;
  CurvePlots c;
  c.psnr.title = fmt::format("Training curves: train PSNR (mean of the last {} steps)", kWindow);
  c.psnr.x = {"training time (s)", false};
  c.psnr.y = {"train PSNR of the rendered colour (dB)", false};
  c.fx.title = "Training curves: the learned focal fx";
  c.fx.x = {"training time (s)", false};
  c.fx.y = {"fx (pixels)", false};
  c.lr.title = "Training curves: the cameras' learning rate";
  c.lr.x = {"training time (s)", false};
  c.lr.y = {"camera (pose) lr, log scale", true};
  c.lr.notes.push_back("a camera moves at most ≈ lr per step it is drawn (Adam): once this is low, the cameras are frozen");
  c.rot.title = "Training curves: the cameras' relative rotation error";
  c.rot.x = {"training time (s)", false};
  c.rot.y = {"relative rotation error (degrees, log scale)", true};
  double ref = std::nan(""), do_nothing = std::nan("");
  int i = 0;
  for (const Row* r : runs) {
    const CsvTable t = read_csv(dir + "/runs/" + r->str("id") + "/log.csv");
    const int cs = t.col("seconds"), cp = t.col("psnr_cc"), cl = t.col("lr_pose"), cf = t.col("fx");
    if (t.rows.empty() || cs < 0 || cp < 0 || cl < 0 || cf < 0) continue;
    const std::string name = variant_title(r->str("variant")) + " (" + r->knobs() + ")";
    svg::Series sp, sf, sl;
    for (svg::Series* s : {&sp, &sf, &sl}) {
      s->name = name;
      s->color = svg::palette(i);
      s->markers = false;
      s->width = 1.5;
    }
    const size_t n = t.rows.size(), every = std::max<size_t>(1, n / 400);
    double sum = 0;
    for (size_t k = 0; k < n; ++k) {
      const double p = study_number(t.rows[k][size_t(cp)]);
      sum += std::isfinite(p) ? p : 0;
      if (k >= kWindow) {
        const double old = study_number(t.rows[k - kWindow][size_t(cp)]);
        sum -= std::isfinite(old) ? old : 0;
      }
      if (k % every != 0 && k + 1 != n) continue;
      const double sec = study_number(t.rows[k][size_t(cs)]);
      if (k + 1 >= kWindow) sp.x.push_back(sec), sp.y.push_back(sum / double(kWindow));
      sf.x.push_back(sec), sf.y.push_back(study_number(t.rows[k][size_t(cf)]));
      sl.x.push_back(sec), sl.y.push_back(study_number(t.rows[k][size_t(cl)]));
    }
    c.psnr.series.push_back(sp);
    c.fx.series.push_back(sf);
    c.lr.series.push_back(sl);
    // The rotation error every 25 steps (eval/camera_curve.h); its step-0 row is the do-nothing.
    const CsvTable e = read_csv(dir + "/runs/" + r->str("id") + "/camera_error.csv");
    const int es = e.col("seconds"), er = e.col("rel_rot_deg");
    if (!e.rows.empty() && es >= 0 && er >= 0) {
      svg::Series sr = sp;
      sr.x.clear(), sr.y.clear();
      for (const auto& row : e.rows) {
        const double sec = study_number(row[size_t(es)]), deg = study_number(row[size_t(er)]);
        if (!std::isfinite(sec) || !std::isfinite(deg)) continue;
        if (sec == 0 && !std::isfinite(do_nothing)) do_nothing = deg;
        sr.x.push_back(sec), sr.y.push_back(deg);
      }
      c.rot.series.push_back(sr);
      ++c.rot_runs;
    }
    if (std::isfinite(r->num("ref_focal"))) ref = r->num("ref_focal");
    ++i;
  }
  c.runs = i;
  if (std::isfinite(ref)) c.fx.hlines.push_back({ref, fmt::format("reference ({:.1f} px)", ref)});
  if (std::isfinite(do_nothing))
    c.rot.hlines.push_back({do_nothing, fmt::format("do nothing ({:.2f}°)", do_nothing)});
  return c;
}

// curves_*.svg for the largest budget whose runs have logs; returns that budget (NaN: none).
double plot_training_curves(Report& rp) {
  std::map<double, std::vector<const Row*>, std::greater<>> by_budget;
  for (const Row& r : rp.rows) by_budget[r.num("budget_minutes")].push_back(&r);
  for (auto& [b, rs] : by_budget) {
    CurvePlots curves = training_curves(rp.dir, rs);
    if (curves.runs == 0) continue;
    const std::string note = "the runs of the " + budget_text(b) + " budget (runs/<id>/log.csv)";
    for (svg::Plot* p : {&curves.psnr, &curves.fx, &curves.lr, &curves.rot})
      p->notes.insert(p->notes.begin(), note);
    rp.put("curves_psnr.svg", svg::render(curves.psnr));
    rp.put("curves_focal.svg", svg::render(curves.fx));
    rp.put("curves_camera_lr.svg", svg::render(curves.lr));
    if (curves.rot_runs > 0) rp.put("curves_rotation.svg", svg::render(curves.rot));
    return b;
  }
  return std::nan("");
}

// step_time.svg from the bench JSON (bench_json, else STUDY/bench.json). Returns "" when
// written, else the sentence the report prints instead.
std::string plot_step_time(Report& rp, const std::string& bench_json) {
  std::string bench_file = bench_json;
  if (bench_file.empty() && fs::exists(rp.dir + "/bench.json")) bench_file = rp.dir + "/bench.json";
  if (bench_file.empty())
    return "No step-time breakdown: no `--bench-json` was given (run `hashcc bench --json FILE` "
           "and pass it to `hashcc study --bench-json FILE`).";
  // ordered_json: the stages keep the order of the file.
  nlohmann::ordered_json b =
      nlohmann::ordered_json::parse(read_file_bytes(bench_file, kStudyMaxText), nullptr, false);
  if (b.is_discarded() || !b.is_object() || !b.contains("runs") || !b["runs"].is_array())
    throw Error(bench_file, "runs", "missing or not a list",
                "{\"runs\": [{\"variant\", \"threads\", \"ms_per_step\", \"stages\": {name: ms}}]}");
  svg::BarChart c;
  c.title = "Where a training step's time goes";
  c.value_label = "milliseconds per step";
  std::vector<std::string> cats;
  for (const auto& r : b["runs"])
    if (r.contains("stages") && r["stages"].is_object())
      for (auto& [name, ms] : r["stages"].items())
        if (std::find(cats.begin(), cats.end(), name) == cats.end()) cats.push_back(name);
  cats.push_back("whole step");
  c.categories = cats;
  int i = 0;
  std::set<std::string> used;
  for (const auto& r : b["runs"]) {
    svg::BarSeries s;
    const std::string v = r.value("variant", "?");
    // The variant's colour of the other plots, unless two runs share a variant.
    s.color = used.insert(v).second ? variant_color(v) : svg::palette(4 + i);
    ++i;
    s.name = fmt::format("{}, {} thread{}", variant_title(v), r.value("threads", 0),
                         r.value("threads", 0) == 1 ? "" : "s");
    for (const auto& name : cats) {
      double ms = std::nan("");
      if (name == "whole step") {
        if (r.contains("ms_per_step") && r["ms_per_step"].is_number()) ms = r["ms_per_step"].get<double>();
      } else if (r.contains("stages") && r["stages"].contains(name) && r["stages"][name].is_number()) {
        ms = r["stages"][name].get<double>();
      }
      s.values.push_back(ms);
    }
    c.series.push_back(s);
  }
  c.notes.push_back("from " + fs::path(bench_file).filename().string() + " (hashcc bench --json)");
  rp.put("step_time.svg", svg::render(c));
  return "";
}

// report.md: the opening paragraphs.
std::string md_intro(const Report& rp) {
  const std::vector<Row>& rows = rp.rows;
  std::string md;
  md += fmt::format("# hashcc study{}\n\n", rp.scene.empty() ? "" : ": " + rp.scene);
  md += fmt::format("Scene `{}`{}; {} run{} in `results.csv`. Each run is a budgeted `hashcc train "
                    "--minutes B` (its own learning-rate schedule, planned to fit the budget) "
                    "followed by `hashcc eval --refine-epochs {}` (test-pose refinement: {} epochs; "
                    "formulas.md §7 uses 1,000).\n\n",
                    rp.data, rp.res_note.empty() ? "" : ", images " + rp.res_note, rows.size(),
                    rows.size() == 1 ? "" : "s", rp.refine, rp.refine);
  bool lpips_any = false;
  for (const Row& r : rows) lpips_any |= std::isfinite(r.num("lpips"));
  md += lpips_any ? "LPIPS: computed (VGG, `--lpips-weights`).\n\n"
                  : "LPIPS: not computed (no weights).\n\n";
  md += "`seconds` is training time (the trainer's clock, excluding evaluation); peak memory is the "
        "larger of the train and eval child processes' `ru_maxrss`.\n\n";
  return md;
}

// One budget × knob group's line of "Who wins": variants by PSNR, then the best camera error.
std::string winner_line(const Report& rp, double budget, const std::string& knobs,
                        const std::vector<const Row*>& g) {
  std::vector<const Row*> ok;
  for (const Row* r : g) if (std::isfinite(r->num("psnr"))) ok.push_back(r);
  std::sort(ok.begin(), ok.end(), [](const Row* a, const Row* b) { return a->num("psnr") > b->num("psnr"); });
  std::string s = fmt::format("- at {}{}: ", budget_text(budget), rp.several_knobs ? " (" + knobs + ")" : "");
  for (size_t i = 0; i < ok.size(); ++i) {
    const double d = i + 1 < ok.size() ? ok[i]->num("psnr") - ok[i + 1]->num("psnr") : 1;
    s += fmt::format("{} {:.2f} dB ({} steps)", ok[i]->str("variant"), ok[i]->num("psnr"),
                     ok[i]->str("steps"));
    if (i + 1 < ok.size()) s += d >= 0.005 ? " > " : " ≈ ";
  }
  if (ok.empty()) s += "no PSNR";
  // Pose: the lowest relative rotation error, against doing nothing.
  const Row* best_pose = nullptr;
  for (const Row* r : g)
    if (std::isfinite(r->num("rel_rot_err_deg")) &&
        (!best_pose || r->num("rel_rot_err_deg") < best_pose->num("rel_rot_err_deg")))
      best_pose = r;
  if (best_pose) {
    const double e = best_pose->num("rel_rot_err_deg"), dn = best_pose->num("rel_rot_do_nothing_deg");
    if (e < dn)
      s += fmt::format("; cameras: {} has the lowest relative rotation error, {:.2f}° (do-nothing "
                       "{:.2f}°)", best_pose->str("variant"), e, dn);
    else
      s += fmt::format("; cameras: no variant is below the do-nothing relative rotation error "
                       "({:.2f}°) yet (closest: {} {:.2f}°)", dn, best_pose->str("variant"), e);
  }
  return s + "\n";
}

// report.md: "Who wins at each budget" (per knob combination).
std::string md_winners(const Report& rp) {
  std::string md = "## Who wins at each budget\n\n";
  if (rp.rows.empty()) md += "No finished runs yet.\n\n";
  std::map<std::pair<double, std::string>, std::vector<const Row*>> groups;
  for (const Row& r : rp.rows) groups[{r.num("budget_minutes"), r.knobs()}].push_back(&r);
  for (auto& [key, g] : groups) md += winner_line(rp, key.first, key.second, g);
  md += "\n";
  return md;
}

// report.md: the same variant and budget under different knobs (e.g. --knobs
// preset=paper,laptop), side by side; empty with one knob combination.
std::string md_knobs_table(const Report& rp) {
  if (!rp.several_knobs) return "";
  std::string md = "## Knobs compared at each budget\n\n";
  md += "| budget | variant | knobs | steps | test PSNR | SSIM | rel. rot (°) | do-nothing (°) | fx (ref) |\n";
  md += "|---|---|---|---|---|---|---|---|---|\n";
  std::map<std::pair<double, int>, std::vector<const Row*>> by;
  for (const Row& r : rp.rows) by[{r.num("budget_minutes"), variant_rank(r.str("variant"))}].push_back(&r);
  for (auto& [key, g] : by)
    for (const Row* r : g)
      md += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} | {} ({}) |\n", budget_text(key.first),
                        variant_title(r->str("variant")), r->knobs(), r->str("steps"), f2(r->num("psnr"), " dB"),
                        f3(r->num("ssim")),
                        f2(r->num("rel_rot_err_deg")), f2(r->num("rel_rot_do_nothing_deg")),
                        f2(r->num("fx")), f2(r->num("ref_focal")));
  md += "\n";
  return md;
}

// PSNR gain per doubling of training time between a line's two last rows (NaN: fewer than two).
double gain_per_doubling(const Line& l) {
  if (l.rows.size() < 2) return std::nan("");
  const Row* last = l.rows.back();
  const Row* prev = l.rows[l.rows.size() - 2];
  return (last->num("psnr") - prev->num("psnr")) / std::log2(last->num("seconds") / prev->num("seconds"));
}

// report.md: per variant, its longest run and its PSNR gain per doubling of time.
std::string md_per_variant(const Report& rp) {
  if (rp.lines.empty()) return "";
  std::string md = "Per variant (PSNR gain per doubling of training time between its two longest runs):\n\n";
  for (const Line& l : rp.lines) {
    const Row* last = l.rows.back();
    std::string gain = "—";
    if (l.rows.size() >= 2) {
      const Row* prev = l.rows[l.rows.size() - 2];
      const double dl = std::log2(last->num("seconds") / prev->num("seconds"));
      if (dl > 0) gain = fmt::format("{:+.2f} dB per doubling", (last->num("psnr") - prev->num("psnr")) / dl);
    }
    md += fmt::format("- {}{}: {} dB after {:.0f} s ({} steps); {}\n", variant_title(l.variant),
                      rp.several_knobs ? " (" + l.knobs + ")" : "", f2(last->num("psnr")),
                      last->num("seconds"), last->str("steps"), gain);
  }
  md += "\n";
  return md;
}

// report.md: the figures.
std::string md_plots(double curve_budget, bool rotation_curves, const std::string& bench_note) {
  std::string md = "## Plots\n\n";
  md += "![Test PSNR vs training time](psnr_vs_time.svg)\n\n";
  md += "![Relative rotation error vs training time](rel_rot_vs_time.svg)\n\n";
  md += "![Sim(3) rotation error vs training time](rot_err_vs_time.svg)\n\n";
  md += "![Pareto front of PSNR vs time](pareto.svg)\n\n";
  if (std::isfinite(curve_budget)) {
    md += fmt::format("Training curves of the {} runs (from each run's `log.csv`):\n\n", budget_text(curve_budget));
    md += "![Train PSNR vs time](curves_psnr.svg)\n\n";
    md += "![Learned focal vs time](curves_focal.svg)\n\n";
    md += "![Camera learning rate vs time](curves_camera_lr.svg)\n\n";
    if (rotation_curves)
      md += "![Relative rotation error during training](curves_rotation.svg) (from each run's "
            "`camera_error.csv`)\n\n";
  }
  if (bench_note.empty()) md += "![Where a step's time goes](step_time.svg)\n\n";
  else md += bench_note + "\n\n";
  return md;
}

// report.md: the Pareto front as a table.
std::string md_pareto_table(const Report& rp, const std::vector<int>& front) {
  std::string md = "## Pareto front (no other run is both faster and better)\n\n";
  md += "| seconds | PSNR (dB) | variant | budget | samples | width | images |\n|---|---|---|---|---|---|---|\n";
  for (int i : front) {
    const Row& r = rp.rows[size_t(i)];
    md += fmt::format("| {:.0f} | {:.2f} | {} | {} | {} | {} | {} |\n", r.num("seconds"), r.num("psnr"),
                      r.str("variant"), budget_text(r.num("budget_minutes")), r.str("samples"),
                      r.str("width"), r.str("images"));
  }
  return md;
}

// report.md: every run, one row each.
std::string md_all_runs(const Report& rp) {
  std::string md = "\n## All runs\n\n";
  md += "| id | steps | seconds | PSNR | SSIM | LPIPS | ΔR (°) | ΔT | rel. rot (°) | do-nothing (°) | peak MB | CPU s/step | load |\n";
  md += "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Row& r : rp.rows) {
    // CPU seconds per step is the step's own cost (≈ the bench's 1-thread time on a quiet
    // machine); it rises when another process shares the cores, as does the load average.
    const double cpu = r.num("train_cpu_seconds"), steps = r.num("steps");
    md += fmt::format("| {} | {} | {:.0f} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", r.str("id"),
                      r.str("steps"), r.num("seconds"), f2(r.num("psnr")),
                      f3(r.num("ssim")),
                      f3(r.num("lpips"), "null"),
                      f2(r.num("rot_err_deg")),
                      std::isfinite(r.num("trans_err")) ? fmt::format("{:.4f}", r.num("trans_err")) : "—",
                      f2(r.num("rel_rot_err_deg")), f2(r.num("rel_rot_do_nothing_deg")),
                      std::isfinite(r.num("peak_rss_mb")) ? fmt::format("{:.0f}", r.num("peak_rss_mb")) : "—",
                      std::isfinite(cpu) && steps > 0 ? fmt::format("{:.2f}", cpu / steps) : "—",
                      f2(r.num("load_avg")));
  }
  md += "\nCPU s/step (the training process's CPU time per step) and load (the 1-minute load "
        "average when training ended, counting the run's own threads) are there to judge the "
        "runs by: a load above the thread count means another process took steps away; the CPU "
        "time per step also varies with what shares the machine's caches and memory.\n";
  md += "\n";
  return md;
}

struct Published { const char* variant; double psnr, ssim, lpips, dr, dt; };

// How far a variant's longest run is from a published PSNR, at the rate of its last doubling
// ("" with fewer than two runs).
std::string extrapolation(const Published& pb, const Line& best) {
  if (best.rows.size() < 2) return "";
  const Row* r = best.rows.back();
  const double gap = pb.psnr - r->num("psnr"), per = gain_per_doubling(best);
  if (!(std::isfinite(per) && per > 0 && gap > 0)) {
    if (gap <= 0) return fmt::format("- {}: already at or above the published PSNR.\n", variant_title(pb.variant));
    return fmt::format("- {}: the curve is not rising at its end ({:+.2f} dB per doubling): "
                       "no extrapolation.\n", variant_title(pb.variant), per);
  }
  const double doublings = gap / per;
  if (doublings > 10)  // 2^10 = 1,024× the time: a number of minutes that long says nothing
    return fmt::format("- {}: {:+.2f} dB per doubling of time at the end of the curve; at that "
                       "rate the published {:.2f} dB is {:.0f} doublings away (more than 1,000× "
                       "this time): the curve is nearly flat and gives no sign that more time "
                       "with these settings closes the gap.\n",
                       variant_title(pb.variant), per, pb.psnr, doublings);
  return fmt::format("- {}: {:+.2f} dB per doubling of time at the end of the curve; at that "
                     "rate the published {:.2f} dB would need about {:.1f} more doublings "
                     "(≈ {:.0f} min of training at this resolution). Curves flatten, so "
                     "read this as a lower bound on the time.\n",
                     variant_title(pb.variant), per, pb.psnr, doublings,
                     r->num("seconds") * std::pow(2.0, doublings) / 60.0);
}

// report.md: fern only, our longest runs beside the published numbers.
std::string md_published(const Report& rp) {
  if (rp.scene != "fern") return "";
  const Published pubs[] = {{"nerfmm", 21.78, 0.62, 0.50, 1.43, 0.008},
                            {"hashcc", 22.27, 0.66, 0.40, 1.38, 0.007}};
  std::string md = "## Against the published fern numbers (formulas.md §9)\n\n";
  md += "Published: 756×1008 images, 10,000 epochs, GPU, 1,000 refinement epochs. Here: " +
        rp.res_note + ", the budgets above, CPU, " + rp.refine + " refinement epochs.\n\n";
  md += "| variant | published PSNR / SSIM / LPIPS / ΔR° / ΔT | ours (longest run) | PSNR gap |\n|---|---|---|---|\n";
  std::string extrap;
  for (const Published& pb : pubs) {
    const Line* best = nullptr;  // the line reaching furthest in time
    for (const Line& l : rp.lines)
      if (l.variant == pb.variant && (!best || l.rows.back()->num("seconds") > best->rows.back()->num("seconds")))
        best = &l;
    if (!best) continue;
    const Row* r = best->rows.back();
    md += fmt::format("| {} | {:.2f} / {:.2f} / {:.2f} / {:.2f} / {:.3f} | {} / {} / {} / {} / {} after {:.0f} s | {:.2f} dB |\n",
                      variant_title(pb.variant), pb.psnr, pb.ssim, pb.lpips, pb.dr, pb.dt,
                      f2(r->num("psnr")),
                      f3(r->num("ssim")),
                      f3(r->num("lpips"), "null"),
                      f2(r->num("rot_err_deg")),
                      std::isfinite(r->num("trans_err")) ? fmt::format("{:.4f}", r->num("trans_err")) : "—",
                      r->num("seconds"), pb.psnr - r->num("psnr"));
    extrap += extrapolation(pb, *best);
  }
  md += "\n" + (extrap.empty() ? std::string("Fewer than two budgets per variant: no extrapolation.\n") : extrap);
  md += "\nThe spec asks for the same ordering (HashCC ≥ NeRF-- at equal budget) and to show how the "
        "gap closes as the budget grows; the per-budget lines above give the ordering.\n\n";
  return md;
}

// report.html: the same findings as one self-contained page (tools/html.h) — the study's
// settings, every SVG written above inline, the results table with a link to each run's own
// page (runs/<id>/report.html, a file beside it), and report.md's text.
std::string study_html(const Report& rp, const std::string& md) {
  std::string body = fmt::format("<h1>hashcc study: {}</h1>\n<p class=\"note\">Scene {}, {} run(s); "
                                 "rebuilt from results.csv after every study invocation "
                                 "(docs/study.md).</p>\n",
                                 html::escape(rp.dir), html::escape(rp.data), rp.rows.size());
  std::string settings;
  if (fs::exists(rp.dir + "/study.json")) {
    const json study = json::parse(read_file_bytes(rp.dir + "/study.json", kStudyMaxText), nullptr, false);
    std::vector<std::vector<std::string>> rows;
    if (study.is_object())
      for (auto it = study.begin(); it != study.end(); ++it)
        rows.push_back({it.key(), it.value().is_string() ? it.value().get<std::string>() : it.value().dump()});
    settings = html::table({"setting", "value"}, rows);
  } else {
    settings = html::absent("No study.json: the settings every run shares are not recorded.");
  }
  body += html::section("settings", "Settings", settings);
  std::string plots;
  int k = 0;
  for (const std::string& name : rp.written)
    if (name.size() > 4 && name.substr(name.size() - 4) == ".svg")
      plots += html::inline_svg(read_file_bytes(rp.dir + "/" + name, kStudyMaxText), fmt::format("p{}", k++));
  body += html::section("plots", "Plots", plots.empty() ? html::absent("No plots: results.csv has no rows yet.")
                                                        : "<div class=\"plots\">\n" + plots + "</div>\n");
  std::vector<std::vector<std::string>> rows;
  for (const Row& r : rp.rows) {
    const std::string id = r.str("id");
    const std::string page = "runs/" + id + "/report.html";
    rows.push_back({fs::exists(rp.dir + "/" + page)
                        ? fmt::format("<a href=\"{}\">{}</a>", html::escape(page), html::escape(id))
                        : html::escape(id),
                    html::escape(variant_title(r.str("variant"))), html::escape(budget_text(r.num("budget_minutes"))),
                    html::escape(r.knobs()), html::escape(r.str("steps")), f2(r.num("seconds")),
                    f2(r.num("psnr")), f3(r.num("ssim")), f3(r.num("lpips")),
                    f2(r.num("rel_rot_err_deg")), f2(r.num("rot_err_deg")), f2(r.num("fx")),
                    f2(r.num("ref_focal"))});
  }
  body += html::section("results", "Results (results.csv)",
                        rows.empty() ? html::absent("results.csv has no rows yet.")
                                     : html::table_html({"run", "variant", "budget", "knobs", "steps",
                                                         "seconds", "PSNR", "SSIM", "LPIPS", "rel. rot. °",
                                                         "Sim(3) ΔR °", "fx", "ref. focal"}, rows));
  body += html::section("findings", "Findings (report.md)", "<pre>" + html::escape(md) + "</pre>\n");
  return html::page("hashcc study " + rp.dir, body);
}

}  // namespace

std::vector<std::string> write_study_report(const std::string& dir, const std::string& bench_json) {
  Report rp = load_report(dir);
  plot_psnr(rp);
  plot_rot_err(rp);
  plot_rel_rot(rp);
  const std::vector<int> front = plot_pareto(rp);
  const double curve_budget = plot_training_curves(rp);
  const std::string bench_note = plot_step_time(rp, bench_json);
  std::string md = md_intro(rp) + md_winners(rp) + md_knobs_table(rp) + md_per_variant(rp) +
                   md_plots(curve_budget, rp.wrote("curves_rotation.svg"), bench_note) + md_pareto_table(rp, front) +
                   md_all_runs(rp) + md_published(rp);
  md += "## Files\n\n`results.csv` (one row per run; empty cell = null), `runs/<id>/` (each run folder "
        "with `train.log`, `eval.log`, `eval/metrics.json`), `study.json` (the settings every row "
        "shares), the SVG plots above.\n";
  rp.put("report.md", md);
  rp.put("report.html", study_html(rp, md));
  return rp.written;
}

}  // namespace hashcc
