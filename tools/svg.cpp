// tools/svg.cpp — see svg.h.
#include "tools/svg.h"

#include <algorithm>
#include <cmath>
#include <fmt/core.h>
#include <limits>
#include <utility>

namespace hashcc::svg {

namespace {

constexpr double kFont = 12;       // px, labels and legend
constexpr double kCharW = 6.6;     // rough width of a character at kFont (sans-serif)

bool usable(double v, bool log) { return std::isfinite(v) && (!log || v > 0); }

// step = 1, 2 or 5 × 10^k closest above raw.
double nice_step(double raw) {
  if (!(raw > 0) || !std::isfinite(raw)) return 1;
  const double e = std::floor(std::log10(raw));
  const double base = std::pow(10.0, e);
  const double m = raw / base;
  const double n = m <= 1 ? 1 : m <= 2 ? 2 : m <= 5 ? 5 : 10;
  return n * base;
}

// Values 1, 2, 5 × 10^k (or every mantissa in `mant`) in [lo, hi], computed from the exponent so
// they print exactly.
std::vector<double> decade_values(double lo, double hi, const std::vector<int>& mant) {
  std::vector<double> out;
  const int e0 = int(std::floor(std::log10(lo))) - 1, e1 = int(std::ceil(std::log10(hi))) + 1;
  for (int e = e0; e <= e1; ++e)
    for (int m : mant) {
      const double v = std::stod(fmt::format("{}e{}", m, e));
      if (v >= lo * (1 - 1e-9) && v <= hi * (1 + 1e-9)) out.push_back(v);
    }
  return out;
}

std::vector<int> mantissas_for(double lo, double hi) {
  const double decades = std::log10(hi / lo);
  if (decades > 3) return {1};
  if (decades < 1) return {1, 2, 3, 4, 5, 6, 7, 8, 9};
  return {1, 2, 5};
}

std::string num(double v) { return fmt::format("{:.2f}", v); }

struct Frame {  // plot area in pixels
  double left, top, right, bottom;
};

std::string text(double x, double y, const std::string& s, const std::string& anchor = "start",
                 double size = kFont, const std::string& extra = "") {
  return fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"{}\" text-anchor=\"{}\"{}>{}</text>\n",
                     num(x), num(y), size, anchor, extra, escape(s));
}

std::string header(int w, int h, const std::string& title) {
  std::string s = fmt::format(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"{}\" height=\"{}\" "
      "viewBox=\"0 0 {} {}\" font-family=\"DejaVu Sans, Helvetica, Arial, sans-serif\">\n",
      w, h, w, h);
  s += fmt::format("<title>{}</title>\n", escape(title));
  s += fmt::format("<rect x=\"0\" y=\"0\" width=\"{}\" height=\"{}\" fill=\"#ffffff\"/>\n", w, h);
  return s;
}

void resolve_axis(const Axis& a, std::vector<double> data, double* lo, double* hi) {
  if (a.min < a.max && (!a.log || a.min > 0)) {
    *lo = a.min;
    *hi = a.max;
    return;
  }
  double l = std::numeric_limits<double>::infinity(), h = -l;
  for (double v : data)
    if (usable(v, a.log)) l = std::min(l, v), h = std::max(h, v);
  if (!(l <= h)) { l = a.log ? 1 : 0; h = a.log ? 10 : 1; }
  nice_range(&l, &h, a.log);
  *lo = l;
  *hi = h;
}

}  // namespace

std::string escape(const std::string& s) {
  std::string o;
  o.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': o += "&amp;"; break;
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '"': o += "&quot;"; break;
      case '\'': o += "&apos;"; break;
      default:
        // Control characters other than tab/newline are not allowed in XML 1.0.
        if (static_cast<unsigned char>(c) < 0x20 && c != '\t' && c != '\n') o += ' ';
        else o += c;
    }
  }
  return o;
}

double Scale::map(double v) const {
  double t;
  if (log) t = (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo));
  else t = (v - lo) / (hi - lo);
  return p0 + t * (p1 - p0);
}

std::vector<double> log_ticks(double lo, double hi) {
  if (!(lo > 0) || !(hi >= lo)) return {};
  return decade_values(lo, hi, mantissas_for(lo, hi));
}

std::vector<double> linear_ticks(double lo, double hi, int target) {
  if (!(hi > lo)) return {lo};
  const double step = nice_step((hi - lo) / std::max(1, target));
  std::vector<double> out;
  const int64_t k0 = int64_t(std::ceil(lo / step - 1e-9)), k1 = int64_t(std::floor(hi / step + 1e-9));
  for (int64_t k = k0; k <= k1 && out.size() < 1000; ++k) {
    double v = double(k) * step;
    if (std::abs(v) < step * 1e-9) v = 0;
    out.push_back(std::stod(fmt::format("{:.12g}", v)));  // no 0.30000000000000004
  }
  return out;
}

void nice_range(double* lo, double* hi, bool log) {
  double l = *lo, h = *hi;
  if (log) {
    if (!(l > 0)) l = 1;
    if (!(h > 0)) h = l;
    if (h <= l) { l /= 2; h *= 2; }
    const std::vector<int> mant = mantissas_for(l, h).size() == 1 ? std::vector<int>{1}
                                                                  : std::vector<int>{1, 2, 5};
    // Largest 1-2-5 value ≤ l and smallest ≥ h.
    const std::vector<double> vals = decade_values(l / 10.0, h * 10.0, mant);
    double nl = l, nh = h;
    for (double v : vals) if (v <= l * (1 + 1e-12)) nl = v;
    for (auto it = vals.rbegin(); it != vals.rend(); ++it) if (*it >= h * (1 - 1e-12)) nh = *it;
    *lo = nl;
    *hi = nh;
    return;
  }
  if (h <= l) {
    const double pad = l == 0 ? 1 : std::abs(l) * 0.1;
    l -= pad;
    h += pad;
  }
  const double step = nice_step((h - l) / 6);
  *lo = std::floor(l / step + 1e-9) * step;
  *hi = std::ceil(h / step - 1e-9) * step;
}

std::string tick_label(double v) { return fmt::format("{:g}", v); }

const std::string& palette(int i) {
  static const std::vector<std::string> p = {"#0072B2", "#D55E00", "#009E73", "#CC79A7",
                                             "#E69F00", "#56B4E9", "#F0E442", "#000000"};
  return p[size_t(((i % int(p.size())) + int(p.size())) % int(p.size()))];
}

std::vector<int> pareto_front(const std::vector<double>& x, const std::vector<double>& y) {
  std::vector<int> idx;
  for (int i = 0; i < int(std::min(x.size(), y.size())); ++i)
    if (std::isfinite(x[i]) && std::isfinite(y[i])) idx.push_back(i);
  // By x ascending, ties by y descending: a point is on the front when its y beats every point
  // with smaller (or equal) x.
  std::sort(idx.begin(), idx.end(), [&](int a, int b) {
    return x[a] != x[b] ? x[a] < x[b] : y[a] > y[b];
  });
  std::vector<int> front;
  double best = -std::numeric_limits<double>::infinity();
  for (int i : idx)
    if (y[i] > best) {
      front.push_back(i);
      best = y[i];
    }
  return front;
}

namespace {

// Legend entries of a plot: named series, then labelled reference lines.
std::vector<std::string> plot_legend(const Plot& p) {
  std::vector<std::string> legend;
  for (const Series& s : p.series) if (!s.name.empty()) legend.push_back(s.name);
  for (const HLine& h : p.hlines) if (!h.label.empty()) legend.push_back(h.label);
  return legend;
}

// The x and y scales of a plot, from its axes and every value it draws, onto frame f.
std::pair<Scale, Scale> plot_scales(const Plot& p, const Frame& f) {
  std::vector<double> xs, ys;
  for (const Series& s : p.series) {
    xs.insert(xs.end(), s.x.begin(), s.x.end());
    ys.insert(ys.end(), s.y.begin(), s.y.end());
  }
  for (const HLine& h : p.hlines) ys.push_back(h.y);
  Scale sx, sy;
  resolve_axis(p.x, xs, &sx.lo, &sx.hi);
  resolve_axis(p.y, ys, &sy.lo, &sy.hi);
  sx.log = p.x.log;
  sy.log = p.y.log;
  sx.p0 = f.left; sx.p1 = f.right;
  sy.p0 = f.bottom; sy.p1 = f.top;
  return {sx, sy};
}

// Grid, frame, ticks, tick labels and axis labels.
std::string plot_axes(const Plot& p, const Frame& f, const Scale& sx, const Scale& sy) {
  std::string o = "<g stroke=\"#e3e3e3\" stroke-width=\"1\">\n";
  const auto xt = sx.log ? log_ticks(sx.lo, sx.hi) : linear_ticks(sx.lo, sx.hi);
  const auto yt = sy.log ? log_ticks(sy.lo, sy.hi) : linear_ticks(sy.lo, sy.hi);
  for (double t : xt)
    o += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\"/>\n", num(sx.map(t)),
                     num(f.top), num(f.bottom));
  for (double t : yt)
    o += fmt::format("<line x1=\"{1}\" y1=\"{0}\" x2=\"{2}\" y2=\"{0}\"/>\n", num(sy.map(t)),
                     num(f.left), num(f.right));
  o += "</g>\n";
  o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" "
                   "stroke=\"#333333\" stroke-width=\"1\"/>\n",
                   num(f.left), num(f.top), num(f.right - f.left), num(f.bottom - f.top));
  for (double t : xt) {
    const double px = sx.map(t);
    o += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"#333333\"/>\n",
                     num(px), num(f.bottom), num(f.bottom + 5));
    o += text(px, f.bottom + 18, tick_label(t), "middle");
  }
  for (double t : yt) {
    const double py = sy.map(t);
    o += fmt::format("<line x1=\"{1}\" y1=\"{0}\" x2=\"{2}\" y2=\"{0}\" stroke=\"#333333\"/>\n",
                     num(py), num(f.left - 5), num(f.left));
    o += text(f.left - 8, py + 4, tick_label(t), "end");
  }
  o += text((f.left + f.right) / 2, f.bottom + 40, p.x.label, "middle", 13);
  o += fmt::format("<text x=\"0\" y=\"0\" font-size=\"13\" text-anchor=\"middle\" "
                   "transform=\"translate({},{}) rotate(-90)\">{}</text>\n",
                   num(18), num((f.top + f.bottom) / 2), escape(p.y.label));
  return o;
}

// One series' line and markers (pts: its usable points, in pixels).
std::string series_svg(const Series& s, const std::vector<std::pair<double, double>>& pts) {
  std::string o;
  if (s.line && pts.size() >= 2) {
    std::string d;
    for (auto& [x, y] : pts) d += fmt::format("{},{} ", num(x), num(y));
    d.pop_back();
    o += fmt::format("<polyline points=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"{}\"{}/>\n",
                     d, escape(s.color), s.width,
                     s.dash.empty() ? "" : fmt::format(" stroke-dasharray=\"{}\"", escape(s.dash)));
  }
  if (s.markers)
    for (auto& [x, y] : pts)
      o += s.hollow ? fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"none\" stroke=\"{}\" "
                                  "stroke-width=\"1.5\"/>\n", num(x), num(y), s.radius, escape(s.color))
                    : fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"{}\" stroke=\"#ffffff\" "
                                  "stroke-width=\"0.8\"/>\n", num(x), num(y), s.radius, escape(s.color));
  return o;
}

// Reference lines and series, clipped to the frame; then the reference lines' labels.
std::string plot_data(const Plot& p, const Frame& f, const Scale& sx, const Scale& sy) {
  std::string o = fmt::format("<defs><clipPath id=\"frame\"><rect x=\"{}\" y=\"{}\" width=\"{}\" "
                              "height=\"{}\"/></clipPath></defs>\n",
                              num(f.left), num(f.top), num(f.right - f.left), num(f.bottom - f.top));
  o += "<g clip-path=\"url(#frame)\">\n";
  for (const HLine& h : p.hlines) {
    if (!usable(h.y, sy.log)) continue;
    const double py = sy.map(h.y);
    o += fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" "
                     "stroke-width=\"1.5\" stroke-dasharray=\"{}\"/>\n",
                     num(f.left), num(py), num(f.right), num(py), escape(h.color), escape(h.dash));
  }
  for (const Series& s : p.series) {
    std::vector<std::pair<double, double>> pts;
    for (size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i)
      if (usable(s.x[i], sx.log) && usable(s.y[i], sy.log))
        pts.emplace_back(sx.map(s.x[i]), sy.map(s.y[i]));
    o += series_svg(s, pts);
  }
  o += "</g>\n";
  for (const HLine& h : p.hlines)
    if (usable(h.y, sy.log) && !h.label.empty())
      o += text(f.right - 4, sy.map(h.y) - 4, h.label, "end", 11, fmt::format(" fill=\"{}\"", escape(h.color)));
  return o;
}

// The legend, right of the frame: named series, then labelled reference lines.
std::string plot_legend_svg(const Plot& p, const Frame& f) {
  std::string o;
  const double lx = f.right + 14;
  double ly = f.top + 8;
  for (const Series& s : p.series) {
    if (s.name.empty()) continue;
    if (s.line)
      o += fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" "
                       "stroke-width=\"{}\"{}/>\n", num(lx), num(ly), num(lx + 24), num(ly),
                       escape(s.color), s.width,
                       s.dash.empty() ? "" : fmt::format(" stroke-dasharray=\"{}\"", escape(s.dash)));
    if (s.markers)
      o += fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"{}\" stroke=\"{}\"/>\n",
                       num(lx + 12), num(ly), std::min(s.radius, 6.0), s.hollow ? "none" : escape(s.color),
                       escape(s.color));
    o += text(lx + 30, ly + 4, s.name);
    ly += 18;
  }
  for (const HLine& h : p.hlines) {
    if (h.label.empty()) continue;
    o += fmt::format("<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" "
                     "stroke-width=\"1.5\" stroke-dasharray=\"{}\"/>\n", num(lx), num(ly),
                     num(lx + 24), num(ly), escape(h.color), escape(h.dash));
    o += text(lx + 30, ly + 4, h.label);
    ly += 18;
  }
  return o;
}

}  // namespace

std::string render(const Plot& p) {
  const std::vector<std::string> legend = plot_legend(p);
  size_t longest = 0;
  for (auto& l : legend) longest = std::max(longest, l.size());
  const double legend_w = legend.empty() ? 0 : 40 + kCharW * double(longest);
  const Frame f{72, 44 + 15.0 * double(p.notes.size()), double(p.width) - 20 - legend_w,
                double(p.height) - 52};
  const auto [sx, sy] = plot_scales(p, f);

  std::string o = header(p.width, p.height, p.title);
  o += text(p.width / 2.0, 22, p.title, "middle", 15, " font-weight=\"bold\"");
  for (size_t i = 0; i < p.notes.size(); ++i)
    o += text(p.width / 2.0, 40 + 15.0 * double(i), p.notes[i], "middle", 11, " fill=\"#444444\"");
  o += plot_axes(p, f, sx, sy);
  o += plot_data(p, f, sx, sy);
  if (!legend.empty()) o += plot_legend_svg(p, f);
  o += "</svg>\n";
  return o;
}

std::string render(const BarChart& b) {
  const int nc = int(b.categories.size()), ns = std::max<int>(1, int(b.series.size()));
  const double bar_h = 14, group_gap = 10;
  const double group_h = bar_h * ns + group_gap;
  size_t longest_cat = 0, longest_leg = 0;
  for (auto& c : b.categories) longest_cat = std::max(longest_cat, c.size());
  for (auto& s : b.series) longest_leg = std::max(longest_leg, s.name.size());
  const double legend_w = b.series.size() > 1 || !b.series.empty() ? 40 + kCharW * double(longest_leg) : 0;
  const double left = 20 + kCharW * double(std::max<size_t>(longest_cat, 4));
  const double top = 44 + 15.0 * double(b.notes.size());
  const double plot_h = std::max(60.0, group_h * nc);
  const int height = int(top + plot_h + 56);
  const Frame f{left, top, double(b.width) - 20 - legend_w, top + plot_h};

  double vmax = 0;
  for (auto& s : b.series)
    for (double v : s.values) if (std::isfinite(v)) vmax = std::max(vmax, v);
  double lo = 0, hi = vmax > 0 ? vmax : 1;
  nice_range(&lo, &hi, false);
  lo = 0;
  Scale sx{lo, hi, f.left, f.right, false};

  std::string o = header(b.width, height, b.title);
  o += text(b.width / 2.0, 22, b.title, "middle", 15, " font-weight=\"bold\"");
  for (size_t i = 0; i < b.notes.size(); ++i)
    o += text(b.width / 2.0, 40 + 15.0 * double(i), b.notes[i], "middle", 11, " fill=\"#444444\"");
  o += "<g stroke=\"#e3e3e3\" stroke-width=\"1\">\n";
  const auto xt = linear_ticks(lo, hi);
  for (double t : xt)
    o += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\"/>\n", num(sx.map(t)),
                     num(f.top), num(f.bottom));
  o += "</g>\n";
  for (double t : xt) {
    o += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"#333333\"/>\n",
                     num(sx.map(t)), num(f.bottom), num(f.bottom + 5));
    o += text(sx.map(t), f.bottom + 18, tick_label(t), "middle");
  }
  o += text((f.left + f.right) / 2, f.bottom + 40, b.value_label, "middle", 13);
  for (int c = 0; c < nc; ++c) {
    const double gy = f.top + group_gap / 2 + group_h * c;
    o += text(f.left - 8, gy + bar_h * ns / 2 + 4, b.categories[size_t(c)], "end");
    for (int s = 0; s < int(b.series.size()); ++s) {
      const BarSeries& bs = b.series[size_t(s)];
      if (size_t(c) >= bs.values.size() || !std::isfinite(bs.values[size_t(c)])) continue;
      const double v = std::max(0.0, bs.values[size_t(c)]);
      const double w = sx.map(v) - f.left;
      o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"{}\"/>\n",
                       num(f.left), num(gy + bar_h * s), num(w), num(bar_h - 2), escape(bs.color));
      o += text(f.left + w + 4, gy + bar_h * s + bar_h - 4, fmt::format("{:.3g}", v), "start", 10,
                " fill=\"#333333\"");
    }
  }
  o += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"#333333\"/>\n",
                   num(f.left), num(f.top), num(f.bottom));
  o += fmt::format("<line x1=\"{0}\" y1=\"{2}\" x2=\"{1}\" y2=\"{2}\" stroke=\"#333333\"/>\n",
                   num(f.left), num(f.right), num(f.bottom));
  double ly = f.top + 8;
  for (const BarSeries& s : b.series) {
    o += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"14\" height=\"10\" fill=\"{}\"/>\n",
                     num(f.right + 14), num(ly - 5), escape(s.color));
    o += text(f.right + 34, ly + 4, s.name);
    ly += 18;
  }
  o += "</svg>\n";
  return o;
}

}  // namespace hashcc::svg
