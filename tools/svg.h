// tools/svg.h — a small SVG writer for the plots of `hashcc study` (docs/study.md).
//
//   Plot      line plots and scatters on linear or log axes: ticks at "nice" values (1-2-5 per
//             decade on a log axis), axis labels with units, a legend, a title, optional
//             horizontal reference lines (e.g. a do-nothing level). A scatter is a series with
//             line = false; a Pareto front is one more series (pareto_front()).
//   BarChart  horizontal bars: one group per category, one bar per series (legend).
//
// Output is a self-contained, well-formed SVG 1.1 document (all text XML-escaped, every
// attribute quoted), readable in any browser. Tests: test/test_study.cpp ("[study]").
#pragma once
#include <string>
#include <vector>

namespace hashcc::svg {

// Text for XML content and attribute values: & < > " ' escaped.
std::string escape(const std::string& s);

// A data range mapped onto pixels [p0, p1] (p1 < p0 for a y axis), linear or log10.
struct Scale {
  double lo = 0, hi = 1;  // data range (log: both > 0)
  double p0 = 0, p1 = 1;  // pixels
  bool log = false;
  double map(double v) const;
};

// Tick values inside [lo, hi]. Log: 1, 2, 5 × 10^k (only powers of 10 when the range spans more
// than 3 decades; finer 1..9 × 10^k when it spans less than one). Linear: about `target` ticks at
// 1, 2, 5 × 10^k steps.
std::vector<double> log_ticks(double lo, double hi);
std::vector<double> linear_ticks(double lo, double hi, int target = 6);
// The data range [lo, hi] widened to whole tick positions (log: powers of 10 or 1-2-5 values;
// linear: multiples of the tick step), and never empty.
void nice_range(double* lo, double* hi, bool log);
// A tick's label: shortest of %g-like forms ("0.5", "20", "1e+04").
std::string tick_label(double v);

struct Axis {
  std::string label;       // with units, e.g. "training time (s, log scale)"
  bool log = false;
  double min = 0, max = 0; // fixed range when min < max; otherwise from the data (nice_range)
};

struct Series {
  std::string name;        // legend entry ("" = not in the legend)
  std::vector<double> x, y;  // non-finite points (and ≤ 0 on a log axis) are skipped
  std::string color = "#1f77b4";
  bool line = true;        // polyline through the points in the given order
  bool markers = true;     // a circle at each point
  std::string dash;        // stroke-dasharray, e.g. "6,4" ("" = solid)
  double width = 2;
  double radius = 3.5;     // marker radius
  bool hollow = false;     // markers as rings (e.g. to circle the points of a Pareto front)
};

struct HLine {             // horizontal reference line across the plot
  double y = 0;
  std::string label;       // drawn at the right end, above the line, and in the legend
  std::string color = "#555555";
  std::string dash = "4,4";
};

struct Plot {
  std::string title;
  Axis x, y;
  std::vector<Series> series;
  std::vector<HLine> hlines;
  std::vector<std::string> notes;  // small text lines under the title
  int width = 720, height = 450;
};
std::string render(const Plot& p);

struct BarSeries {
  std::string name;
  std::vector<double> values;  // one per category (non-finite: no bar)
  std::string color = "#1f77b4";
};
struct BarChart {
  std::string title;
  std::string value_label;     // x axis, with units, e.g. "ms per step"
  std::vector<std::string> categories;
  std::vector<BarSeries> series;
  std::vector<std::string> notes;
  int width = 720;             // height follows from the number of bars
};
std::string render(const BarChart& b);

// Indices of the Pareto-optimal points for "smaller x, larger y" (e.g. less time, more PSNR),
// sorted by increasing x. Non-finite points are never on the front.
std::vector<int> pareto_front(const std::vector<double>& x, const std::vector<double>& y);

// A fixed palette (colour-blind friendly, Okabe–Ito order) and colour by index.
const std::string& palette(int i);

}  // namespace hashcc::svg
