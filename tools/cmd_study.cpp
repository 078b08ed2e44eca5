// tools/cmd_study.cpp — `hashcc study`: budgets × knobs × variants, each a real budgeted
// `train` + `eval` in a child process; results.csv, SVG plots and report.md (tools/study.h,
// docs/study.md).
#include <CLI/CLI.hpp>
#include <fmt/core.h>

#include "core/error.h"
#include "tools/study.h"
#include "tools/cli.h"

namespace hashcc {

void add_study_command(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("study", "what accuracy costs in time: budgeted train + eval runs "
                                          "per variant and knob, results.csv, SVG plots, report.md");
  struct Opts {
    StudyOptions s;
    std::string budgets = "1,2,4,8,16", variants = "nerfmm,sh,hashcc";
    std::vector<std::string> knobs;
    std::string emit, collect;
  };
  auto o = std::make_shared<Opts>();
  sub->add_option("--data", o->s.data, "scene folder (required unless --collect)");
  sub->add_option("--out", o->s.out, "study folder (results.csv, report.md, *.svg, runs/; "
                                     "required unless --collect)");
  sub->add_option("--emit-commands", o->emit, "write one shell line per run (train && eval) to "
                                              "FILE for a scheduler, run nothing (then --collect)");
  sub->add_option("--collect", o->collect, "gather the finished runs of STUDY (made with "
                                           "--emit-commands) into results.csv and the report");
  sub->add_flag("--budget-steps", o->s.budget_steps, "--budgets are step counts (train --steps): "
                                                     "deterministic, not timed");
  sub->add_option("--budgets", o->budgets, "training minutes per run, comma-separated")
      ->capture_default_str();
  sub->add_option("--variants", o->variants, "comma-separated: nerfmm, sh, hashcc")->capture_default_str();
  sub->add_option("--knobs", o->knobs, "every combination is run: samples=32,64,128 width=64,128 "
                                       "res=8,4 (res r = image folder images_r) preset=paper,laptop field=mlp,grid "
                                       "bootstrap=0,5 (minutes of grid-field bootstrap, mlp runs only)");
  sub->add_option("--images", o->s.images_default, "image folder when no res knob (default: smallest)");
  sub->add_option("--refine-epochs", o->s.refine_epochs, "test-pose refinement epochs of each eval "
                                                         "(spec: 1000)")
      ->capture_default_str()->check(CLI::Range(0, 1000000));
  sub->add_option("--lpips-weights", o->s.lpips_weights, "LPIPS-VGG weights folder (default: LPIPS null)");
  sub->add_option("--bench-json", o->s.bench_json, "`hashcc bench --json` output: step-time bar chart");
  sub->add_option("--threads", o->s.threads, "threads per run (default: all cores)")->check(CLI::Range(1, 1024));
  sub->add_option("--seed", o->s.seed, "random seed of every run")->capture_default_str();
  sub->add_option("--train-args", o->s.train_args,
                  "extra flags for every train run, e.g. --train-args=--rays --train-args=512");
  sub->callback([&run, o] {
    run = [o] {
      if (!o->collect.empty()) {
        HCC_REQUIRE(o->emit.empty(), "--collect", "", "not with --emit-commands");
        const StudySummary sum = collect_study(o->collect);
        fmt::print("study {}: {} planned, {} gathered now, {} kept from before, {} missing or failed\n",
                   o->collect, sum.planned, sum.done, sum.skipped, sum.failed.size());
        for (const auto& f : sum.failed) fmt::print("  missing: {}\n", f);
        fmt::print("wrote {}/results.csv, {}/report.md, report.html and the SVG plots\n", o->collect,
                   o->collect);
        if (!sum.failed.empty())
          throw std::runtime_error(fmt::format("{} run(s) missing or failed (rerun their lines, then "
                                               "--collect again)", sum.failed.size()));
        return;
      }
      HCC_REQUIRE(!o->s.data.empty(), "--data", "", "missing (expected a scene folder)");
      HCC_REQUIRE(!o->s.out.empty(), "--out", "", "missing (expected a study folder)");
      StudyOptions s = o->s;
      s.budgets = parse_number_list("--budgets", o->budgets);
      s.variants.clear();
      for (const std::string& v : [&] {
             std::vector<std::string> out;
             std::string cur;
             for (char c : o->variants + ",") {
               if (c == ',') { if (!cur.empty()) out.push_back(cur); cur.clear(); }
               else if (c != ' ') cur += c;
             }
             return out;
           }())
        s.variants.push_back(v);
      for (const std::string& k : o->knobs) parse_study_knob(k, &s);
      if (!o->emit.empty()) {
        const int n = write_study_commands(s, o->emit);
        auto q = [](const std::string& p) {  // as the user would type it back
          if (p.find_first_of(" '\"\\$`!*?&;|<>()") == std::string::npos) return p;
          std::string r = "'";
          for (char c : p) r += c == '\'' ? std::string("'\\''") : std::string(1, c);
          return r + "'";
        };
        fmt::print("wrote {} command line(s) to {} (nothing run); run them, e.g. `parallel -j N < {}`, "
                   "then `hashcc study --collect {}`\n", n, o->emit, q(o->emit), q(s.out));
        return;
      }
      StopSignals signals;  // Ctrl-C: the running child checkpoints and stops; the study stops too
      s.stop = &signals.flag();
      const StudySummary sum = run_study(s);
      fmt::print("study {}: {} planned, {} already done, {} ran now, {} failed\n", s.out, sum.planned,
                 sum.skipped, sum.done, sum.failed.size());
      for (const auto& f : sum.failed) fmt::print("  failed: {}\n", f);
      fmt::print("wrote {}/results.csv, {}/report.md and the SVG plots\n", s.out, s.out);
      if (sum.interrupted) {
        fmt::print("interrupted: run the same command again to continue (finished runs are skipped)\n");
        throw Interrupted{};
      }
      if (!sum.failed.empty())
        throw std::runtime_error(fmt::format("{} run(s) failed (rerun the command to retry them)",
                                             sum.failed.size()));
    };
  });
}

}  // namespace hashcc
