// tools/study.h — `hashcc study`: what accuracy costs in time (docs/study.md).
//
//   plan:    budgets × knob combinations (samples, width, image folder, preset) × variants, cheapest
//            budget first, each a run id such as "b2_hashcc_s64_w128_images_8"
//   run:     per id, a child process of the same binary:  <exe> train … --minutes B  then
//            <exe> eval --run STUDY/runs/<id> --refine-epochs K; peak memory = the children's
//            ru_maxrss from wait4 (a crash ends one run, not the study)
//   record:  one row appended to STUDY/results.csv when both children succeeded (resumable:
//            ids already in the CSV are skipped; a half-done run folder is deleted and redone)
//   report:  STUDY/*.svg (tools/svg.h) and STUDY/report.md, always rebuilt from the whole CSV
//            (tools/study_report.cpp: one function per figure or table)
//
// Tests: test/test_study.cpp ("[study]", "[e2e]").
#pragma once
#include <atomic>
#include <map>
#include <cstdint>
#include <string>
#include <vector>

namespace hashcc {

struct StudyOptions {
  std::string data;                  // scene folder
  std::string out;                   // study folder
  std::vector<double> budgets = {1, 2, 4, 8, 16};           // minutes of training per run
  bool budget_steps = false;         // budgets are step counts (`train --steps`): deterministic
  std::vector<std::string> variants = {"nerfmm", "sh", "hashcc"};
  // Knobs (empty = the trainer's default / --images): every combination is run.
  std::vector<int> samples, widths;
  std::vector<std::string> images;   // image folders ("res=8" → "images_8", "res=1" → "images")
  std::string images_default;        // --images: the folder when no res knob ("" = smallest)
  std::vector<std::string> presets;  // "preset=paper,laptop": `train --preset`
  std::vector<std::string> fields;   // "field=mlp,grid": `train --field`
  std::vector<double> bootstraps;    // "bootstrap=0,5": `train --bootstrap-minutes` (mlp only)
  std::vector<int> restarts;         // "restarts=0,3": `train --restarts` (grid runs, bootstraps)
  int refine_epochs = 20;            // test-pose refinement epochs of each evaluation
  std::string lpips_weights;         // "" = LPIPS not computed (null)
  std::string bench_json;            // `hashcc bench --json` output for the step-time bar chart
  int threads = 0;                   // passed to train and eval (0 = all cores)
  uint64_t seed = 0;
  std::vector<std::string> train_args;  // extra flags for every `train` (e.g. --rays 256)
  std::string exe;                   // binary run as the child ("" = /proc/self/exe)
  bool quiet = false;                // no per-run lines on stdout
  const std::atomic<bool>* stop = nullptr;  // set by SIGINT/SIGTERM: stop after the current run
};

// "samples=32,64,128", "width=64,128", "res=8,4" (image folder images_<r>, 1 = "images"),
// "images=images_8,images_4", "preset=paper,laptop", "field=mlp,grid", "bootstrap=0,5"
// (minutes; a grid-field run ignores it), "restarts=0,3" (grid-field runs and bootstraps; a
// plain MLP run ignores it). Unknown knobs or bad values →
// hashcc::Error naming the token.
void parse_study_knob(const std::string& token, StudyOptions* opt);
std::vector<double> parse_number_list(const std::string& flag, const std::string& csv);

struct StudyRunSpec {
  std::string id;             // folder name under STUDY/runs/ and key in results.csv
  std::string variant;
  double budget_minutes = 0;
  int samples = 0, width = 0; // 0 = the trainer's default
  std::string images;         // "" = smallest present
  std::string preset;         // "" = no --preset flag (the paper's recipe)
  std::string field;          // "" = no --field flag (the MLP)
  double bootstrap = 0;       // --bootstrap-minutes (0 = none)
  int restarts = 0;           // --restarts (0 = none)
};
// Every configuration in run order: budgets ascending, then knobs, then variants.
std::vector<StudyRunSpec> study_plan(const StudyOptions& opt);

// The columns of results.csv, in order (docs/study.md says what each holds).
const std::vector<std::string>& study_columns();
// A finished run's steps and training seconds (the last row of RUN/log.csv). A bootstrapped run's
// seconds include its grid phase (RUN/bootstrap/log.csv), so it sits at its whole budget on the
// time axes; its steps are the paper network's.
std::pair<int64_t, double> study_run_steps_seconds(const std::string& run_dir);

// A CSV table: header + rows (fields unquoted; quoted fields with "" escapes are read back).
struct CsvTable {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  int col(const std::string& name) const;  // -1 when absent
};
CsvTable read_csv(const std::string& path);  // missing file → empty table
std::string csv_field(const std::string& s);  // quotes when needed

struct StudySummary {
  int planned = 0, skipped = 0, done = 0;
  std::vector<std::string> failed;  // "<id>: <reason>"
  bool interrupted = false;
};
// Runs every planned configuration not already in STUDY/results.csv, then writes the report.
// Bad options (missing data, unknown variant/knob, a results.csv of another layout, a study
// folder made for another scene) → hashcc::Error before anything runs.
StudySummary run_study(const StudyOptions& opt);

// Fan-out on a scheduler (docs/study.md#fan-out): writes to `file` one self-contained shell
// line per planned run not yet in results.csv (`rm -rf D && mkdir -p D && <exe> train … >
// D/train.log 2>&1 && <exe> eval … > D/eval.log 2>&1`, absolute paths, shell-quoted) and the
// plan into STUDY/study.json; runs nothing. Returns the number of lines.
int write_study_commands(const StudyOptions& opt, const std::string& file);
// Gathers the finished runs of the plan in STUDY/study.json into results.csv (plan order, as a
// direct run writes it; the children's wall time, memory, CPU and load cells are empty) and
// rebuilds the report. A missing or failed run is in `failed` with its log's last line, or
// "not run"; `done` = runs gathered now, `skipped` = rows kept from before.
StudySummary collect_study(const std::string& study_dir);

// Rebuilds STUDY/*.svg and STUDY/report.md from STUDY/results.csv (and the bench JSON when
// given). Returns the file names written.
std::vector<std::string> write_study_report(const std::string& study_dir,
                                            const std::string& bench_json = "");

// Shared by the runner and the report.
inline constexpr int64_t kStudyMaxText = int64_t(1) << 28;  // largest text file read
std::string budget_text(double minutes);         // "30 s", "2 min"
std::string variant_title(const std::string& v);  // "nerfmm" → "NeRF--", …
double study_number(const std::string& s);        // a CSV cell; NaN when empty or not a number

}  // namespace hashcc
