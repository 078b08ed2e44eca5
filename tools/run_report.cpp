#include "tools/run_report.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fmt/core.h>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>

#include "core/camera_models.h"
#include "core/error.h"
#include "core/fileio.h"
#include "core/image.h"
#include "eval/pose_eval.h"
#include "tools/html.h"
#include "tools/svg.h"

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace hashcc {

namespace {

constexpr int64_t kMaxText = int64_t(1) << 28;  // largest text file read (log.csv of a long run)
const double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string path_in(const std::string& dir, const std::string& name) {
  return (fs::path(dir) / name).lexically_normal().string();
}

json read_json(const std::string& path) {
  try {
    return json::parse(read_file_bytes(path, kMaxText));
  } catch (const json::exception& e) {
    throw Error(path, "", fmt::format("not valid JSON ({})", e.what()));
  }
}

std::string num(double v, int digits = 2, const char* unit = "") {
  return std::isfinite(v) ? fmt::format("{:.{}f}{}", v, digits, unit) : std::string("—");
}

// The last finite value of a column, NaN when none.
double last_finite(const std::vector<double>& v) {
  for (auto it = v.rbegin(); it != v.rend(); ++it)
    if (std::isfinite(*it)) return *it;
  return kNaN;
}

double json_number(const json& j, const char* key) {
  return j.is_object() && j.contains(key) && j[key].is_number() ? j[key].get<double>() : kNaN;
}

std::string json_text(const json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); }

// A plan's values as a reader writes them: {"share": 0.0833} → "share=0.0833", numbers to six
// significant digits (29.999999999999996 → 30), objects as key=value pairs.
std::string compact(const json& v) {
  if (v.is_number_float()) return fmt::format("{:.6g}", v.get<double>());
  if (v.is_object()) {
    std::string o;
    for (auto it = v.begin(); it != v.end(); ++it) o += (o.empty() ? "" : " ") + it.key() + "=" + compact(it.value());
    return o;
  }
  return json_text(v);
}

}  // namespace

// ---- command lines ---------------------------------------------------------------------------

std::string shell_quote(const std::string& arg) {
  const bool safe = !arg.empty() && std::all_of(arg.begin(), arg.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) ||
           std::string_view("-_./:=,+@%").find(c) != std::string_view::npos;
  });
  if (safe) return arg;
  std::string o = "'";
  for (char c : arg) o += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return o + "'";
}

std::string command_text(const std::vector<std::string>& argv) {
  std::string o;
  for (const std::string& a : argv) o += (o.empty() ? "" : " ") + shell_quote(a);
  return o;
}

void record_command(const std::string& run, const std::vector<std::string>& argv,
                    std::time_t started) {
  if (run.empty() || argv.empty() || !fs::is_directory(run)) return;
  const std::time_t now = started ? started : std::time(nullptr);
  char when[32];
  std::strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S", std::localtime(&now));
  std::ofstream f(path_in(run, "commands.txt"), std::ios::app);
  f << when << "  " << command_text(argv) << "\n";
}

void remember_render_dir(const std::string& run, const std::string& render_dir) {
  if (run.empty() || !fs::is_directory(run)) return;
  std::error_code ec;
  const fs::path abs = fs::absolute(render_dir, ec);
  std::ofstream f(path_in(run, "renders.txt"), std::ios::app);
  f << (ec ? render_dir : abs.lexically_normal().string()) << "\n";
}

// ---- CSV -------------------------------------------------------------------------------------

int NumericCsv::col(const std::string& name) const {
  const auto it = std::find(header.begin(), header.end(), name);
  return it == header.end() ? -1 : int(it - header.begin());
}

std::vector<double> NumericCsv::column(const std::string& name) const {
  const int c = col(name);
  std::vector<double> v;
  if (c < 0) return v;
  for (const auto& r : rows) v.push_back(r[size_t(c)]);
  return v;
}

NumericCsv parse_numeric_csv(const std::string& text) {
  NumericCsv t;
  size_t at = 0;
  bool first = true;
  while (at < text.size()) {
    size_t end = text.find('\n', at);
    const bool complete = end != std::string::npos;
    if (!complete) end = text.size();
    std::string line = text.substr(at, end - at);
    at = end + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    std::vector<std::string> cells;
    size_t s = 0;
    for (size_t k; (k = line.find(',', s)) != std::string::npos; s = k + 1) cells.push_back(line.substr(s, k - s));
    cells.push_back(line.substr(s));
    if (first) {
      t.header = cells;
      first = false;
      continue;
    }
    // A last line without its newline was being written when the file was read (or the run
    // died mid-line): skipped like any row of the wrong length.
    if (cells.size() != t.header.size() || !complete) {
      ++t.skipped;
      continue;
    }
    std::vector<double> row;
    for (const std::string& c : cells) {
      double v = kNaN;
      try {
        size_t n = 0;
        v = std::stod(c, &n);
        if (n != c.size()) v = kNaN;
      } catch (...) {
      }
      row.push_back(v);
    }
    t.rows.push_back(std::move(row));
  }
  return t;
}

NumericCsv read_numeric_csv(const std::string& path) {
  if (!fs::exists(path)) return {};
  return parse_numeric_csv(read_file_bytes(path, kMaxText));
}

void bin_means(const std::vector<double>& x, const std::vector<double>& y, int bins,
               std::vector<double>* bx, std::vector<double>* by) {
  bx->clear();
  by->clear();
  const size_t n = std::min(x.size(), y.size());
  if (n == 0 || bins <= 0) return;
  const size_t per = (n + size_t(bins) - 1) / size_t(bins);
  for (size_t b = 0; b < n; b += per) {
    double sx = 0, sy = 0;
    int kx = 0, ky = 0;
    for (size_t i = b; i < std::min(n, b + per); ++i) {
      if (std::isfinite(x[i])) sx += x[i], ++kx;
      if (std::isfinite(y[i])) sy += y[i], ++ky;
    }
    bx->push_back(kx ? sx / kx : kNaN);
    by->push_back(ky ? sy / ky : kNaN);
  }
}

// ---- stages ----------------------------------------------------------------------------------

std::vector<StageLogs> read_stage_logs(const std::string& run) {
  std::vector<StageLogs> st;
  const std::string plan = path_in(run, "plan.json");
  if (fs::exists(plan)) {
    const json p = read_json(plan);
    HCC_REQUIRE(p.contains("stages") && p["stages"].is_array(), plan, "stages", "missing",
                "an array of stages");
    const size_t n = p["stages"].size();
    for (size_t k = 0; k < n; ++k) {
      const json& s = p["stages"][k];
      std::string dir = s.value("dir", "");
      if (s.contains("kept_dir") && s["kept_dir"].is_string()) dir = s["kept_dir"].get<std::string>();
      const bool last = k + 1 == n;
      st.push_back({last ? "run" : fmt::format("stage {}", k + 1),
                    path_in(run, dir.empty() || dir == "." ? "." : dir), {}, {}, 0});
    }
  } else {
    st.push_back({"run", run, {}, {}, 0});
  }
  double offset = 0;
  for (StageLogs& s : st) {
    s.log = read_numeric_csv(path_in(s.dir, "log.csv"));
    s.cameras = read_numeric_csv(path_in(s.dir, "camera_error.csv"));
    s.offset = offset;
    const double end = last_finite(s.log.column("seconds"));
    if (std::isfinite(end)) offset += end;
  }
  return st;
}

// ---- plots -----------------------------------------------------------------------------------

std::vector<std::string> training_curve_svgs(const std::vector<StageLogs>& stages,
                                             double ref_focal, int points) {
  bool any = false;
  for (const StageLogs& s : stages) any = any || !s.log.rows.empty();
  if (!any) return {};
  const int per_stage = std::max(10, points / std::max<int>(1, int(stages.size())));
  svg::Plot psnr, loss, focal;
  psnr.title = "Train PSNR of the rendered colour";
  psnr.y.label = "PSNR (dB)";
  loss.title = "Training loss";
  loss.y.label = "loss (log scale)";
  loss.y.log = true;
  focal.title = "Learned focal";
  focal.y.label = "fx (pixels)";
  for (svg::Plot* p : {&psnr, &loss, &focal}) {
    p->x.label = "training time (s), every stage on one axis";
    p->width = 580;  // two plots a row on a 1240-px page
    p->height = 340;
  }
  size_t rows = 0;
  for (size_t k = 0; k < stages.size(); ++k) {
    const StageLogs& s = stages[k];
    if (s.log.rows.empty()) continue;
    rows += s.log.rows.size();
    std::vector<double> t = s.log.column("seconds");
    for (double& v : t) v += s.offset;
    const std::string color = svg::palette(int(k));
    auto add = [&](svg::Plot& p, const std::string& column) {
      svg::Series se;
      se.name = stages.size() > 1 ? s.name : "";
      se.color = color;
      se.markers = false;
      bin_means(t, s.log.column(column), per_stage, &se.x, &se.y);
      p.series.push_back(std::move(se));
    };
    add(psnr, "psnr");
    add(loss, "loss");
    add(focal, "fx");
  }
  const std::string binned = fmt::format("{} logged steps; each point the mean of consecutive "
                                         "steps (at most {} points a stage)", rows, per_stage);
  psnr.notes.push_back(binned);
  loss.notes.push_back(binned);
  if (ref_focal > 0) focal.hlines.push_back({ref_focal, fmt::format("reference {:.1f}", ref_focal)});
  return {svg::render(psnr), svg::render(loss), svg::render(focal)};
}

std::string camera_error_svg(const std::vector<StageLogs>& stages, double do_nothing_deg) {
  svg::Series rel, sim;
  rel.name = "relative rotation error";
  rel.color = svg::palette(0);
  sim.name = "Sim(3) ΔR (centres)";
  sim.color = svg::palette(1);
  sim.dash = "6,4";
  std::vector<std::string> ends;
  for (const StageLogs& s : stages) {
    if (s.cameras.rows.empty()) continue;
    const std::vector<double> t = s.cameras.column("seconds"), r = s.cameras.column("rel_rot_deg"),
                              d = s.cameras.column("sim3_dR_deg");
    for (size_t i = 0; i < t.size(); ++i) {
      rel.x.push_back(t[i] + s.offset);
      sim.x.push_back(t[i] + s.offset);
      rel.y.push_back(i < r.size() ? r[i] : kNaN);
      sim.y.push_back(i < d.size() ? d[i] : kNaN);
    }
    if (stages.size() > 1) ends.push_back(fmt::format("{} {:.0f} s", s.name, last_finite(rel.x)));
  }
  if (rel.x.empty()) return "";
  svg::Plot p;
  p.title = "Camera error against the reference";
  p.x.label = "training time (s), every stage on one axis";
  p.y.label = "degrees (log scale)";
  p.y.log = true;  // the Sim(3) ΔR of nearly coincident centres can be 100× the relative error
  p.width = 580;
  p.height = 340;
  rel.markers = sim.markers = false;
  p.series = {rel, sim};
  if (do_nothing_deg > 0)
    p.hlines.push_back({do_nothing_deg, fmt::format("do nothing {:.2f}°", do_nothing_deg)});
  if (!ends.empty()) {
    std::string note = "stages end at:";
    for (const std::string& e : ends) note += " " + e;
    p.notes.push_back(note);
  }
  return svg::render(p);
}

std::string camera_view_svg(const std::vector<Mat34d>& learned, const std::vector<Mat34d>& reference,
                            bool top, const std::string& title) {
  // Page coordinates (u to the right, v up) of a world point.
  auto uv = [top](const Eigen::Vector3d& p) {
    return top ? Eigen::Vector2d(p.x(), -p.z()) : Eigen::Vector2d(-p.z(), p.y());
  };
  std::vector<Eigen::Vector2d> pts;
  for (const auto* set : {&learned, &reference})
    for (const Mat34d& m : *set)
      if (m.allFinite()) pts.push_back(uv(m.col(3)));
  double extent = 0;
  Eigen::Vector2d lo(0, 0), hi(0, 0);
  if (!pts.empty()) {
    lo = hi = pts[0];
    for (const auto& p : pts) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
    extent = (hi - lo).maxCoeff();
  }
  // The viewing-direction strokes: a third of the rig's extent (a tenth of a unit for one camera).
  const double L = extent > 1e-9 ? extent / 3 : 0.1;
  auto tip = [&](const Mat34d& m) { return uv(m.col(3) - L * m.col(2)); };
  for (const auto* set : {&learned, &reference})
    for (const Mat34d& m : *set)
      if (m.allFinite()) {
        const Eigen::Vector2d t = tip(m);
        lo = lo.cwiseMin(t), hi = hi.cwiseMax(t);
      }
  // Equal scale on both axes: the box grows along its shorter side.
  const int W = 420, H = 380;
  const double left = 56, right = W - 14, topy = 58, bottom = H - 40;
  const double pw = right - left, ph = bottom - topy;
  Eigen::Vector2d span = (hi - lo).cwiseMax(1e-6) * 1.1;
  const double scale = std::min(pw / span.x(), ph / span.y());
  const Eigen::Vector2d mid = (lo + hi) / 2;
  auto px = [&](const Eigen::Vector2d& p) {
    return Eigen::Vector2d(left + pw / 2 + (p.x() - mid.x()) * scale,
                           topy + ph / 2 - (p.y() - mid.y()) * scale);
  };
  const auto f = [](double v) { return fmt::format("{:.1f}", v); };
  std::string o = fmt::format(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\" "
      "version=\"1.1\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" font-family=\"DejaVu "
      "Sans, Helvetica, Arial, sans-serif\">\n<title>{2}</title>\n<rect x=\"0\" y=\"0\" "
      "width=\"{0}\" height=\"{1}\" fill=\"#ffffff\"/>\n",
      W, H, svg::escape(title));
  o += fmt::format("<text x=\"{}\" y=\"20\" font-size=\"14\" font-weight=\"bold\" "
                   "text-anchor=\"middle\">{}</text>\n", W / 2, svg::escape(title));
  // Ticks at nice values of the visible range, on both axes (the same spacing: equal scale).
  const double u0 = mid.x() - pw / 2 / scale, u1 = mid.x() + pw / 2 / scale;
  const double v0 = mid.y() - ph / 2 / scale, v1 = mid.y() + ph / 2 / scale;
  o += "<g stroke=\"#e3e3e3\" stroke-width=\"1\">\n";
  for (double t : svg::linear_ticks(u0, u1, 5)) {
    const double x = px({t, mid.y()}).x();
    o += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\"/>\n", f(x), f(topy), f(bottom));
  }
  for (double t : svg::linear_ticks(v0, v1, 5)) {
    const double y = px({mid.x(), t}).y();
    o += fmt::format("<line x1=\"{1}\" y1=\"{0}\" x2=\"{2}\" y2=\"{0}\"/>\n", f(y), f(left), f(right));
  }
  o += "</g>\n";
  for (double t : svg::linear_ticks(u0, u1, 5))
    o += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\">{}</text>\n",
                     f(px({t, mid.y()}).x()), f(bottom + 14), svg::tick_label(t));
  for (double t : svg::linear_ticks(v0, v1, 5))
    o += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"11\" text-anchor=\"end\">{}</text>\n",
                     f(left - 5), f(px({mid.x(), t}).y() + 4), svg::tick_label(t));
  o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" "
                   "stroke=\"#333333\"/>\n", f(left), f(topy), f(pw), f(ph));
  o += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"12\" text-anchor=\"middle\">{}</text>\n",
                   f(left + pw / 2), f(H - 8), top ? "x (right)" : "−z (forward)");
  o += fmt::format("<text x=\"14\" y=\"{0}\" font-size=\"12\" text-anchor=\"middle\" "
                   "transform=\"rotate(-90 14 {0})\">{1}</text>\n",
                   f(topy + ph / 2), top ? "−z (forward)" : "y (up)");
  // Legend, under the title.
  const std::string c_learned = svg::palette(0), c_ref = svg::palette(1);
  o += fmt::format("<circle cx=\"{}\" cy=\"38\" r=\"4\" fill=\"{}\"/><text x=\"{}\" y=\"42\" "
                   "font-size=\"12\">learned</text>\n", f(left + 6), c_learned, f(left + 14));
  if (!reference.empty())
    o += fmt::format("<circle cx=\"{}\" cy=\"38\" r=\"4\" fill=\"none\" stroke=\"{}\" "
                     "stroke-width=\"1.5\"/><text x=\"{}\" y=\"42\" font-size=\"12\">reference"
                     "</text>\n", f(left + 96), c_ref, f(left + 104));
  o += fmt::format("<g clip-path=\"url(#cams)\"><defs><clipPath id=\"cams\"><rect x=\"{}\" "
                   "y=\"{}\" width=\"{}\" height=\"{}\"/></clipPath></defs>\n",
                   f(left), f(topy), f(pw), f(ph));
  if (reference.size() == learned.size())
    for (size_t i = 0; i < learned.size(); ++i) {
      if (!learned[i].allFinite() || !reference[i].allFinite()) continue;
      const Eigen::Vector2d a = px(uv(learned[i].col(3))), b = px(uv(reference[i].col(3)));
      o += fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#999999\" "
                       "stroke-width=\"0.8\"/>\n", f(a.x()), f(a.y()), f(b.x()), f(b.y()));
    }
  auto glyphs = [&](const std::vector<Mat34d>& set, const std::string& color, bool hollow) {
    for (const Mat34d& m : set) {
      if (!m.allFinite()) continue;
      const Eigen::Vector2d c = px(uv(m.col(3))), t = px(tip(m));
      o += fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" "
                       "stroke-width=\"1.5\"{}/>\n", f(c.x()), f(c.y()), f(t.x()), f(t.y()), color,
                       hollow ? " stroke-dasharray=\"3,2\"" : "");
      o += hollow ? fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"4\" fill=\"none\" stroke=\"{}\" "
                                "stroke-width=\"1.5\"/>\n", f(c.x()), f(c.y()), color)
                  : fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"3.5\" fill=\"{}\"/>\n", f(c.x()),
                                f(c.y()), color);
    }
  };
  glyphs(reference, c_ref, true);
  glyphs(learned, c_learned, false);
  o += "</g>\n</svg>\n";
  return o;
}

// ---- the page's sections ---------------------------------------------------------------------

namespace {

// What every section may need, read once.
struct RunFiles {
  std::string run;
  json config;                    // config.json
  std::vector<StageLogs> stages;  // empty when the logs could not be read (stages_error)
  std::string stages_error;
  std::optional<Scene> scene;     // reference cameras (pixels not loaded)
  std::string scene_error;
  json metrics;                   // eval/metrics.json (null when absent)
  std::string metrics_error;
};

// A section built on its own (make returns the whole <section>): an Error or a parse failure
// becomes the section's one line instead.
template <class F>
std::string guarded(const std::string& id, const std::string& title, F&& make) {
  try {
    return make();
  } catch (const std::exception& e) {
    return html::section(id, title, html::absent(fmt::format("could not be drawn: {}", e.what())));
  }
}

std::string plots_div(const std::vector<std::string>& svgs, const std::string& uid) {
  std::string o = "<div class=\"plots\">\n";
  for (size_t i = 0; i < svgs.size(); ++i)
    o += html::inline_svg(svgs[i], fmt::format("{}{}", uid, i));
  return o + "</div>\n";
}

double reference_focal(const RunFiles& rf) {
  if (rf.scene && rf.scene->has_reference) return rf.scene->ref_focal;
  for (const StageLogs& s : rf.stages) {
    const double f = last_finite(s.cameras.column("ref_focal"));
    if (std::isfinite(f)) return f;
  }
  return 0;
}

// The last stage that logged anything.
const StageLogs* last_logged(const RunFiles& rf) {
  for (auto it = rf.stages.rbegin(); it != rf.stages.rend(); ++it)
    if (!it->log.rows.empty()) return &*it;
  return nullptr;
}

std::string summary_section(const RunFiles& rf) {
  std::vector<std::vector<std::string>> rows;
  const json& c = rf.config;
  rows.push_back({"scene", json_text(c.value("data", json("")))});
  if (rf.scene)
    rows.push_back({"images", fmt::format("{} ({} train, {} test), {}x{} working size",
                                          rf.scene->names.size(), rf.scene->train.size(),
                                          rf.scene->test.size(), rf.scene->width, rf.scene->height)});
  rows.push_back({"model", fmt::format("{}, field {}", json_text(c.value("model", json(""))),
                                       json_text(c.value("field", json(""))))});
  if (rf.stages.size() > 1) rows.push_back({"stages", fmt::format("{}", rf.stages.size())});
  int64_t steps = 0;
  double seconds = 0;
  for (const StageLogs& s : rf.stages) {
    const double st = last_finite(s.log.column("step")), sec = last_finite(s.log.column("seconds"));
    if (std::isfinite(st)) steps += int64_t(st);
    if (std::isfinite(sec)) seconds += sec;
  }
  rows.push_back({"steps, training time", fmt::format("{} steps in {:.1f} s", steps, seconds)});
  if (const StageLogs* s = last_logged(rf)) {
    const std::vector<double> psnr = s->log.column("psnr");
    double sum = 0;
    int k = 0;
    for (size_t i = psnr.size() > 50 ? psnr.size() - 50 : 0; i < psnr.size(); ++i)
      if (std::isfinite(psnr[i])) sum += psnr[i], ++k;
    rows.push_back({"train PSNR (mean of the last 50 logged steps)", num(k ? sum / k : kNaN, 2, " dB")});
    const double fx = last_finite(s->log.column("fx")), ref = reference_focal(rf);
    rows.push_back({"focal fx", ref > 0 ? fmt::format("{} px (reference {:.2f}, {:+.1f}%)", num(fx),
                                                      ref, 100 * (fx / ref - 1))
                                        : num(fx, 2, " px")});
    rows.push_back({"focal from", json_text(c.value("focal_source", json("—")))});
  }
  for (auto it = rf.stages.rbegin(); it != rf.stages.rend(); ++it)
    if (!it->cameras.rows.empty()) {
      rows.push_back({"camera error at the end", fmt::format(
          "relative rotation {}°, Sim(3) ΔR {}°", num(last_finite(it->cameras.column("rel_rot_deg")), 3),
          num(last_finite(it->cameras.column("sim3_dR_deg")), 3))});
      break;
    }
  if (rf.metrics.is_object())
    rows.push_back({"test views (RUN/eval)", fmt::format("PSNR {} dB, SSIM {}{}",
                                                         num(json_number(rf.metrics, "psnr")),
                                                         num(json_number(rf.metrics, "ssim"), 3),
                                                         std::isfinite(json_number(rf.metrics, "lpips"))
                                                             ? ", LPIPS " + num(json_number(rf.metrics, "lpips"), 3)
                                                             : std::string())});
  else
    rows.push_back({"test views", "not evaluated yet: hashcc eval --run " + rf.run});
  return html::section("summary", "Summary", html::table({}, rows, "summary"));
}

std::string command_section(const RunFiles& rf) {
  std::string body;
  const std::string cmds = path_in(rf.run, "commands.txt");
  if (fs::exists(cmds))
    body += "<h3>Commands run on this folder</h3>\n<pre>" +
            html::escape(read_file_bytes(cmds, kMaxText)) + "</pre>\n";
  else
    body += html::absent("No commands.txt: this run was made before hashcc recorded its "
                         "commands. Its settings follow.");
  const std::string plan = path_in(rf.run, "plan.json");
  if (fs::exists(plan)) {
    try {
      const json p = read_json(plan);
      body += fmt::format("<h3>Plan {} ({}), {} stages</h3>\n",
                          html::escape(json_text(p.value("plan", json("")))),
                          html::escape(json_text(p.value("source", json("")))),
                          p.value("stages", json::array()).size());
      if (p.contains("base") && !p["base"].empty())
        body += "<p class=\"note\">every stage: <code>" + html::escape(compact(p["base"])) + "</code></p>\n";
      std::vector<std::vector<std::string>> rows;
      int k = 0;
      for (const json& s : p.value("stages", json::array())) {
        ++k;
        const json kept = s.value("kept_dir", json(nullptr));
        rows.push_back({std::to_string(k), json_text(s.value("dir", json(""))),
                        compact(s.value("budget", json::object())), compact(s.value("length", json::object())),
                        json_text(s.value("cameras", json(""))), compact(s.value("set", json::object())),
                        s.contains("try") ? fmt::format("{} tried, kept {}", s["try"].size(),
                                                        kept.is_null() ? "none yet" : json_text(kept))
                                          : "",
                        s.value("finished", false) ? "yes" : "no"});
      }
      body += html::table({"stage", "folder", "budget", "length", "cameras", "settings", "tries",
                           "finished"}, rows);
    } catch (const std::exception& e) {
      body += html::absent(fmt::format("plan.json could not be read: {}", e.what()));
    }
  }
  std::vector<std::vector<std::string>> rows;
  for (auto it = rf.config.begin(); it != rf.config.end(); ++it)
    rows.push_back({it.key(), compact(it.value())});
  body += fmt::format("<details><summary>Every setting of the run (config.json, {} keys)</summary>\n{}"
                      "</details>\n", rows.size(), html::table({"key", "value"}, rows));
  return html::section("command", "Command and settings", body);
}

std::string curves_section(const RunFiles& rf, const RunReportOptions& opt) {
  if (!rf.stages_error.empty())
    return html::section("curves", "Training curves", html::absent(rf.stages_error));
  const std::vector<std::string> svgs = training_curve_svgs(rf.stages, reference_focal(rf), opt.curve_points);
  if (svgs.empty())
    return html::section("curves", "Training curves",
                         html::absent("No training curve: log.csv has no rows yet (the run has not "
                                      "made a step)."));
  std::string note;
  for (const StageLogs& s : rf.stages)
    if (s.log.skipped > 0)
      note += fmt::format("<p class=\"note\">{}: {} incomplete row(s) of log.csv skipped.</p>\n",
                          html::escape(s.name), s.log.skipped);
  return html::section("curves", "Training curves", plots_div(svgs, "curve") + note);
}

double do_nothing_deg(const RunFiles& rf) {
  if (!rf.scene || !rf.scene->has_reference || rf.scene->train.size() < 2) return 0;
  std::vector<Pose34> ref, same;
  for (int i : rf.scene->train) {
    ref.push_back(rf.scene->ref_c2w[size_t(i)]);
    same.push_back(Pose34::Identity());
  }
  return relative_rotation_error(same, ref).do_nothing_deg;
}

std::string camera_error_section(const RunFiles& rf) {
  const std::string title = "Camera error against time";
  if (!rf.stages_error.empty()) return html::section("camera-error", title, html::absent(rf.stages_error));
  const std::string s = camera_error_svg(rf.stages, do_nothing_deg(rf));
  if (s.empty())
    return html::section("camera-error", title, html::absent(
        rf.scene && !rf.scene->has_reference
            ? "No reference cameras (the scene has no poses_bounds.npy): the camera error cannot be measured."
            : "No camera_error.csv rows (written every 25 steps when the scene has reference cameras)."));
  return html::section("camera-error", title,
                       plots_div({s}, "camerr") +
                           "<p class=\"note\">The relative rotation error needs no alignment (formulas.md "
                           "§7); the Sim(3) ΔR aligns the centres first and is ill-conditioned while they "
                           "nearly coincide. The dashed level is the error of doing nothing (every camera "
                           "at the identity).</p>\n");
}

std::string cameras_section(const RunFiles& rf) {
  const std::string title = "Cameras from above and from the side";
  const std::string path = path_in(rf.run, "cameras.json");
  if (!fs::exists(path))
    return html::section("cameras", title, html::absent("No cameras.json yet (written when training "
                                                        "ends or checkpoints)."));
  const CameraModel m = read_cameras_json(path);
  std::vector<Mat34d> learned = m.c2w, reference;
  std::string note;
  if (!rf.scene) {
    note = "Reference cameras not drawn: " + rf.scene_error;
  } else if (!rf.scene->has_reference) {
    note = "No reference cameras (the scene has no poses_bounds.npy): the learned cameras alone, in "
           "their own frame.";
  } else {
    const Scene& sc = *rf.scene;
    std::vector<Mat34d> l, r;
    for (size_t i = 0; i < m.names.size(); ++i) {
      const std::string name = fs::path(m.names[i]).filename().string();
      const auto it = std::find(sc.names.begin(), sc.names.end(), name);
      if (it == sc.names.end()) continue;
      l.push_back(m.c2w[i]);
      r.push_back(sc.ref_c2w[size_t(it - sc.names.begin())]);
    }
    // The similarity that puts the learned cameras on the reference: its rotation from the
    // cameras' rotations when that works (rotation_sim3, camera/sim3.h: a forward-facing rig's
    // centres spread little in depth, so Umeyama's rotation, fitted to the centres alone, can
    // tilt the whole drawing by tens of degrees while every camera turned right), else
    // formulas.md §7's Umeyama Sim(3) of the centres.
    std::optional<Sim3> sim;
    Alignment how = Alignment::kRotations;
    std::string how_text = "the Sim(3) whose rotation comes from the cameras' rotations and its "
                           "scale and shift from the centres (camera/sim3.h)";
    std::vector<Eigen::Matrix3d> lr, rr;
    std::vector<Eigen::Vector3d> lc, rc;
    for (size_t i = 0; i < l.size(); ++i) {
      lr.push_back(l[i].leftCols<3>()), lc.push_back(l[i].col(3));
      rr.push_back(r[i].leftCols<3>()), rc.push_back(r[i].col(3));
    }
    try {
      sim = rotation_sim3(lr, lc, rr, rc);
    } catch (const Error& e1) {
      try {
        sim = umeyama_sim3(lc, rc);
        how = Alignment::kCentres;
        how_text = fmt::format("Umeyama's Sim(3) of the centres, formulas.md §7 (the rotations' "
                               "alignment failed: {})", e1.problem);
      } catch (const Error& e2) {
        note = fmt::format("Not aligned ({}): both sets drawn as they are.", e2.what());
      }
    }
    if (l.size() < m.c2w.size())
      note += fmt::format(" {} of {} learned cameras matched a reference image by name.", l.size(),
                          m.c2w.size());
    learned = l;
    reference = r;
    if (sim) {
      for (Mat34d& p : learned) {
        p.leftCols<3>() = sim->R * p.leftCols<3>();
        p.col(3) = sim->apply(Eigen::Vector3d(p.col(3)));
      }
      const PoseErrors e = align_and_score(l, r, how);
      note = fmt::format("Learned cameras aligned onto the reference by {} (scale {:.3g}); then mean "
                         "ΔR {:.3f}°, ΔT {:.4f} (reference units).", how_text, sim->s, e.mean_dR_deg,
                         e.mean_dT) + note;
    }
  }
  const std::vector<std::string> svgs = {camera_view_svg(learned, reference, true, "Top view"),
                                         camera_view_svg(learned, reference, false, "Side view")};
  return html::section("cameras", title,
                       plots_div(svgs, "cams") + "<p class=\"note\">" + html::escape(note) +
                           " A dot is a camera centre, its stroke the viewing direction; grey lines "
                           "join each learned camera to its reference.</p>\n");
}

std::string picture(const std::string& path, int side, const std::string& alt) {
  if (!fs::exists(path)) return "<span class=\"note\">(missing)</span>";
  const ImageU8 im = read_image(path, side);
  return html::image_img(im, 0, alt);
}

std::string test_views_section(const RunFiles& rf, const RunReportOptions& opt) {
  const std::string title = "Test views";
  if (!rf.metrics_error.empty()) return html::section("test-views", title, html::absent(rf.metrics_error));
  if (!rf.metrics.is_object())
    return html::section("test-views", title, html::absent(
        "Not evaluated yet: hashcc eval --run " + rf.run + " writes RUN/eval/ (renders, error maps, "
        "metrics.json) and refreshes this page."));
  const json& m = rf.metrics;
  const std::string eval = path_in(rf.run, "eval");
  std::string body = "<p class=\"note\">" + html::escape(json_text(m.value("note", json("")))) + "</p>\n";
  std::error_code ec;
  const auto t_metrics = fs::last_write_time(path_in(eval, "metrics.json"), ec);
  const auto t_ckpt = fs::last_write_time(path_in(rf.run, "checkpoint.bin"), ec);
  if (!ec && t_ckpt > t_metrics)
    body += html::absent("These numbers are older than the run's checkpoint (it trained on after "
                         "the evaluation): run hashcc eval again.");
  const json per = m.value("per_image", json::array());
  std::vector<std::vector<std::string>> rows;
  const int n = int(per.size()), shown = std::min(n, std::max(1, opt.max_test_views));
  for (int k = 0; k < shown; ++k) {
    const int i = shown == n ? k : int(std::lround(double(k) * (n - 1) / std::max(1, shown - 1)));
    const json& im = per[size_t(i)];
    const std::string name = json_text(im.value("name", json("")));
    const std::string file = name + ".png";
    rows.push_back({html::escape(name), picture(path_in(eval, "gt/" + file), opt.test_side, "photo " + name),
                    picture(path_in(eval, "renders/" + file), opt.test_side, "render " + name),
                    picture(path_in(eval, "error/" + file), opt.test_side, "error " + name),
                    num(json_number(im, "psnr")), num(json_number(im, "ssim"), 3),
                    num(json_number(im, "lpips"), 3)});
  }
  body += html::table_html({"view", "photo", "render", "error |render − photo| (0–0.25)", "PSNR (dB)", "SSIM",
                            "LPIPS"}, rows, "images");
  body += fmt::format("<p class=\"note\">Mean over {} view(s): PSNR {} dB, SSIM {}{}.{}</p>\n", n,
                      num(json_number(m, "psnr")), num(json_number(m, "ssim"), 3),
                      std::isfinite(json_number(m, "lpips")) ? ", LPIPS " + num(json_number(m, "lpips"), 3)
                                                              : " (" + html::escape(json_text(m.value("lpips_note", json("")))) + ")",
                      shown < n ? fmt::format(" {} of them shown.", shown) : "");
  return html::section("test-views", title, body);
}

// The render folder to show: the option, else the last one RUN/renders.txt names that exists.
std::string render_folder(const RunFiles& rf, const RunReportOptions& opt) {
  if (!opt.render_dir.empty()) return opt.render_dir;
  const std::string list = path_in(rf.run, "renders.txt");
  if (!fs::exists(list)) return "";
  const std::string text = read_file_bytes(list, kMaxText);
  std::vector<std::string> dirs;
  size_t at = 0;
  for (size_t k; (k = text.find('\n', at)) != std::string::npos; at = k + 1)
    if (k > at) dirs.push_back(text.substr(at, k - at));
  for (auto it = dirs.rbegin(); it != dirs.rend(); ++it)
    if (fs::exists(path_in(*it, "poses.json"))) return *it;
  return "";
}

std::string spiral_section(const RunFiles& rf, const RunReportOptions& opt) {
  const std::string title = "Rendered path";
  const std::string dir = render_folder(rf, opt);
  if (dir.empty())
    return html::section("spiral", title, html::absent(
        "No render folder known: hashcc render --run " + rf.run + " --out DIR renders the spiral "
        "and adds its frames here."));
  const std::string poses = path_in(dir, "poses.json");
  if (!fs::exists(poses))
    return html::section("spiral", title, html::absent("No poses.json in " + dir + ": not a finished render folder."));
  const json p = read_json(poses);
  const int n = int(p.value("frames", json::array()).size());
  const int shown = std::min(n, std::max(1, opt.max_frames));
  std::string body = fmt::format("<p class=\"note\">{} path, {} frames of {}x{} in {} (colour above "
                                 "depth, near = warm); {} shown.</p>\n<div class=\"frames\">\n",
                                 html::escape(json_text(p.value("path", json("")))), n,
                                 json_text(p.value("width", json(0))), json_text(p.value("height", json(0))),
                                 html::escape(dir), shown);
  for (int k = 0; k < shown; ++k) {
    const int i = shown == n ? k : int(std::lround(double(k) * (n - 1) / std::max(1, shown - 1)));
    const std::string stem = path_in(dir, fmt::format("{:04d}", i));
    body += fmt::format("<figure>{}<br>{}<figcaption>frame {}</figcaption></figure>\n",
                        picture(stem + "_rgb.png", opt.frame_side, fmt::format("frame {}", i)),
                        picture(stem + "_depth.png", opt.frame_side, fmt::format("depth {}", i)), i);
  }
  return html::section("spiral", title, body + "</div>\n");
}

RunFiles read_run(const std::string& run) {
  RunFiles rf;
  rf.run = run;
  // A staged run stopped before its last stage has no config.json of its own yet: its
  // plan.json records the run's settings ("run"), which is what the page needs.
  const std::string cfg = path_in(run, "config.json"), plan = path_in(run, "plan.json");
  HCC_REQUIRE(fs::exists(cfg) || fs::exists(plan), run, "config.json", "missing",
              "a run folder written by hashcc train");
  if (fs::exists(cfg)) {
    rf.config = read_json(cfg);
    HCC_REQUIRE(rf.config.is_object(), cfg, "", "not a JSON object");
  } else {
    const json p = read_json(plan);
    HCC_REQUIRE(p.is_object() && p.contains("run") && p["run"].is_object(), plan, "run", "missing",
                "the run's settings");
    rf.config = p["run"];
  }
  try {
    rf.stages = read_stage_logs(run);
  } catch (const std::exception& e) {
    rf.stages_error = fmt::format("The logs could not be read: {}", e.what());
  }
  try {
    SceneOptions so;
    so.images_folder = json_text(rf.config.value("images_folder", json("")));
    so.load_pixels = false;
    so.max_side = rf.config.value("max_side", 0);
    rf.scene = load_scene(json_text(rf.config.value("data", json(""))), so);
  } catch (const std::exception& e) {
    rf.scene_error = fmt::format("the scene folder could not be read ({})", e.what());
  }
  const std::string metrics = path_in(run, "eval/metrics.json");
  if (fs::exists(metrics)) {
    try {
      rf.metrics = read_json(metrics);
    } catch (const std::exception& e) {
      rf.metrics_error = fmt::format("eval/metrics.json could not be read: {}", e.what());
    }
  }
  return rf;
}

}  // namespace

std::string run_report_html(const std::string& run, const RunReportOptions& opt) {
  const RunFiles rf = read_run(run);
  const std::time_t now = std::time(nullptr);
  char when[32];
  std::strftime(when, sizeof when, "%Y-%m-%d %H:%M", std::localtime(&now));
  std::string body = fmt::format("<h1>hashcc run: {}</h1>\n<p class=\"note\">Report written {} by "
                                 "hashcc {} from the files of the run folder (docs/report.md).</p>\n",
                                 html::escape(run), when, HASHCC_VERSION);
  body += guarded("summary", "Summary", [&] { return summary_section(rf); });
  body += guarded("command", "Command and settings", [&] { return command_section(rf); });
  body += guarded("curves", "Training curves", [&] { return curves_section(rf, opt); });
  body += guarded("camera-error", "Camera error against time", [&] { return camera_error_section(rf); });
  body += guarded("cameras", "Cameras from above and from the side", [&] { return cameras_section(rf); });
  body += guarded("test-views", "Test views", [&] { return test_views_section(rf, opt); });
  body += guarded("spiral", "Rendered path", [&] { return spiral_section(rf, opt); });
  return html::page("hashcc run " + run, body);
}

std::string write_run_report(const std::string& run, const std::string& out,
                             const RunReportOptions& opt) {
  const std::string path = out.empty() ? path_in(run, "report.html") : out;
  write_file_atomic(path, run_report_html(run, opt));
  return path;
}

void refresh_run_report(const std::string& run, const std::string& render_dir) {
  try {
    RunReportOptions opt;
    opt.render_dir = render_dir;
    fmt::print("report: {}\n", write_run_report(run, "", opt));
  } catch (const std::exception& e) {
    fmt::print("report: not written ({})\n", e.what());
  }
}

}  // namespace hashcc
