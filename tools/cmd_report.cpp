// tools/cmd_report.cpp — `hashcc report`: RUN/report.html on demand (tools/run_report.h,
// docs/report.md). train writes it when it ends and eval and render refresh it; this command
// redraws it after anything else changed (a render folder moved, the page deleted, a run
// trained by an older hashcc) or writes it elsewhere.
#include <CLI/CLI.hpp>
#include <filesystem>
#include <fmt/core.h>

#include "core/error.h"
#include "tools/cli.h"
#include "tools/run_report.h"

namespace hashcc {

void add_report_command(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("report", "write a run's report: one self-contained HTML page "
                                           "(curves, cameras, test views, spiral frames)");
  struct Opts {
    std::string run, out;
    RunReportOptions report;
  };
  auto o = std::make_shared<Opts>();
  sub->add_option("--run", o->run, "run folder written by hashcc train")->required();
  sub->add_option("--out", o->out, "the page to write (default: RUN/report.html)");
  sub->add_option("--render", o->report.render_dir, "a hashcc render folder whose frames to show "
                  "(default: the last one rendered from the run, RUN/renders.txt)");
  sub->add_option("--test-views", o->report.max_test_views, "evaluated views shown (evenly spaced)")
      ->capture_default_str()->check(CLI::Range(1, 1000));
  sub->add_option("--frames", o->report.max_frames, "render frames shown (evenly spaced)")
      ->capture_default_str()->check(CLI::Range(1, 1000));
  sub->callback([&run, o] {
    run = [o] {
      HCC_REQUIRE(std::filesystem::is_directory(o->run), "--run", o->run, "no such folder",
                  "a run folder written by hashcc train");
      HCC_REQUIRE(o->report.render_dir.empty() || std::filesystem::is_directory(o->report.render_dir),
                  "--render", o->report.render_dir, "no such folder", "a hashcc render --out folder");
      const std::string path = write_run_report(o->run, o->out, o->report);
      fmt::print("wrote {} ({:.0f} KB)\n", path, double(std::filesystem::file_size(path)) / 1024);
    };
  });
}

}  // namespace hashcc
