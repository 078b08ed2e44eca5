// tools/run_report.h — RUN/report.html: a run on one page (docs/report.md).
//
// A run's results are spread over a dozen files (config.json, plan.json, log.csv and
// camera_error.csv of every stage, cameras.json, eval/metrics.json and its PNGs, a render
// folder). The report reads them all and draws one self-contained HTML file (tools/html.h: no
// network, no script, inline SVG plots, base64 PNG images), in sections:
//
//   summary       the numbers a reader asks first: steps, time, train PSNR, focal, camera
//                 error, test PSNR
//   command       the hashcc commands run on the folder (RUN/commands.txt) and the settings:
//                 a staged run's stages (plan.json), every config.json key
//   curves        train PSNR, loss and the learned focal against training time, every stage
//                 on one time axis (log.csv of stage1..N and of the run)
//   camera-error  relative rotation error and Sim(3) ΔR against time (camera_error.csv)
//   cameras       the learned cameras from above and from the side, the reference beside them
//                 (Sim(3)-aligned onto it, formulas.md §7)
//   test-views    the evaluated views: photo, render, error map, PSNR / SSIM (RUN/eval/)
//   spiral        frames of a `hashcc render` folder
//
// A section whose inputs are absent says so in one line, and what would make it: the page's
// shape is the same for every run. Each section is built on its own: a file that does not
// parse spoils its section (one line naming the file and the problem), not the page.
//
// Written by `hashcc train` at the end (also when interrupted), refreshed by `hashcc eval` and
// `hashcc render`, and on demand by `hashcc report --run RUN`. Always through a temporary file
// and a rename (core/fileio.h): a crash leaves the old page or the new one.
#pragma once
#include <Eigen/Core>
#include <ctime>
#include <string>
#include <vector>

#include "core/llff.h"

namespace hashcc {

struct RunReportOptions {
  std::string render_dir;  // the spiral's frames; "" = the last folder RUN/renders.txt names
  int max_test_views = 8;  // evaluated views shown, evenly spaced (all are in the table)
  int test_side = 320;     // longest side, in pixels, of a test view's images on the page
  int max_frames = 8;      // spiral frames shown, evenly spaced
  int frame_side = 192;    // their longest side
  int curve_points = 400;  // points of a training curve (bins of steps, averaged) over all stages
};

// The page. run: a folder written by `hashcc train` (its config.json, or a staged run's
// plan.json, must exist: a hashcc::Error naming the folder otherwise).
std::string run_report_html(const std::string& run, const RunReportOptions& opt = {});
// Writes the page to `out` ("" = RUN/report.html) atomically; returns the path written.
std::string write_run_report(const std::string& run, const std::string& out = "",
                             const RunReportOptions& opt = {});
// For train, eval and render, whose own work is done when they call it: writes RUN/report.html
// and prints where; a failure is one printed line (the command still succeeds), never a throw.
void refresh_run_report(const std::string& run, const std::string& render_dir = "");

// RUN/commands.txt: one line per hashcc command run on the folder (train, train --resume, eval,
// render), shell-quoted, after the local time it started. Appended; a failure to write is
// ignored (a record, not a result).
// started: when the command started (0 = now).
void record_command(const std::string& run, const std::vector<std::string>& argv,
                    std::time_t started = 0);
// RUN/renders.txt: the absolute path of a render folder made from the run, appended (the
// report shows the last one that still has its frames).
void remember_render_dir(const std::string& run, const std::string& render_dir);

// ---- the building blocks (tested in test/test_report.cpp, [report]) -------------------------

// One argument as a POSIX shell reads it back: bare when it is made of safe characters
// (letters, digits, - _ . / : = , + @ %), else in single quotes ('it'\''s').
std::string shell_quote(const std::string& arg);
std::string command_text(const std::vector<std::string>& argv);

// A CSV of numbers (log.csv, camera_error.csv). A cell that is not a number is NaN; a row whose
// field count is not the header's (a line torn by a crash) is skipped and counted. A missing
// or empty file gives no header and no rows.
struct NumericCsv {
  std::vector<std::string> header;
  std::vector<std::vector<double>> rows;
  int skipped = 0;
  int col(const std::string& name) const;  // -1 when absent
  std::vector<double> column(const std::string& name) const;  // empty when absent
};
NumericCsv parse_numeric_csv(const std::string& text);
NumericCsv read_numeric_csv(const std::string& path);

// x, y thinned to at most `bins` points: consecutive rows averaged (x too), NaN values left
// out of a bin's mean (a bin of NaN only gives NaN, which a plot skips).
void bin_means(const std::vector<double>& x, const std::vector<double>& y, int bins,
               std::vector<double>* bx, std::vector<double>* by);

// One stage of a run: its folder and its logs, on the run's time axis (offset = the training
// seconds of the stages before it).
struct StageLogs {
  std::string name;  // "stage 1" … ; "run" for the last (the run folder), or a one-stage run
  std::string dir;
  NumericCsv log, cameras;  // log.csv, camera_error.csv (empty when absent)
  double offset = 0;
};
// The stages of a run in order: plan.json's (a stage that tried alternatives: the kept one),
// else the run alone.
std::vector<StageLogs> read_stage_logs(const std::string& run);

// The training-curve plots as SVG documents: train PSNR, loss (log axis) and focal (with the
// reference focal when ref_focal > 0), one series per stage. Empty when no stage has a row.
std::vector<std::string> training_curve_svgs(const std::vector<StageLogs>& stages,
                                             double ref_focal, int points);
// The camera-error plot (relative rotation error and Sim(3) ΔR against time; do_nothing_deg > 0
// draws its level). "" when no stage has a camera_error.csv row.
std::string camera_error_svg(const std::vector<StageLogs>& stages, double do_nothing_deg);

// A top view (looking down the y axis: x to the right, −z up the page) or a side view (−z to
// the right, y up) of cameras: a dot at each centre and a stroke along its viewing direction
// (−z of its camera-to-world), on equal axes. `reference` (may be empty) is drawn beside
// `learned` (same count then), each learned centre joined to its reference by a thin line.
std::string camera_view_svg(const std::vector<Mat34d>& learned, const std::vector<Mat34d>& reference,
                            bool top, const std::string& title);

}  // namespace hashcc
