// tools/cmd_eval.cpp — `hashcc eval`: a run folder → eval/evaluate.h → RUN/eval/.
#include <CLI/CLI.hpp>
#include <fmt/core.h>

#include "core/error.h"
#include "core/parallel.h"
#include "eval/evaluate.h"
#include "train/trainer.h"
#include "tools/cli.h"
#include "tools/run_report.h"

namespace hashcc {

void add_eval_command(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("eval", "evaluate a run: pose error against the reference "
                                         "cameras, test-pose refinement, PSNR / SSIM / LPIPS");
  struct Opts {
    std::string run, data, test_init = "scale", refine_mode = "fast";
    EvalOptions eval;
    int threads = 0;
  };
  auto o = std::make_shared<Opts>();
  sub->add_option("--run", o->run, "run folder written by hashcc train")->required();
  sub->add_option("--data", o->data, "scene folder (default: the one in RUN/config.json)");
  sub->add_option("--refine-epochs", o->eval.refine_epochs,
                  "test-pose refinement epochs (spec: 1000)")->capture_default_str()
      ->check(CLI::Range(0, 1000000));
  sub->add_option("--refine-mode", o->refine_mode,
                  "fast: the spec's Adam schedule, the run's rays for the first 200 epochs and 128 "
                  "a view after, all views in one step, each pose the mean of its last 400 epochs, "
                  "and the renders' shortcuts; a view still moving at the end is refined again as "
                  "adam (docs/evaluation.md §3: within 0.04 dB of adam on the runs measured, in a "
                  "third to a half of its CPU time); adam: the spec's refinement (formulas.md §7, the run's 32x32 rays a view a step)")->capture_default_str()
      ->check(CLI::IsMember({"adam", "fast"}));
  sub->add_option("--refine-rays", o->eval.refine_rays,
                  "rays of each test view a refinement step (default: the mode's)")
      ->check(CLI::Range(1, 1 << 20));
  sub->add_option("--lpips-weights", o->eval.lpips_weights,
                  "folder of LPIPS-VGG .npy weights (tools/export_lpips_weights.py); "
                  "without it LPIPS is not computed");
  sub->add_option("--test-init", o->test_init,
                  "test-camera initial pose: scale (formulas.md §7, NeRF--), sim3 (inverse of the "
                  "train-camera Sim(3) alignment of the centres) or rig (the alignment's rotation "
                  "from the cameras' rotations, its scale and shift from the centres: a rig off in "
                  "depth does not tilt it)")->capture_default_str()
      ->check(CLI::IsMember({"scale", "sim3", "rig"}));
  sub->add_option("--threads", o->threads, "threads (default: all cores)")->check(CLI::Range(1, 1024));
  sub->add_flag("!--no-progress", o->eval.progress, "plain output only");
  sub->callback([&run, o] {
    run = [o] {
      o->eval.test_init = parse_test_init(o->test_init);
      o->eval.refine_mode = parse_refine_mode(o->refine_mode);
      Trainer tr = Trainer::open(o->run, -1, o->data);
      if (o->threads > 0) set_num_threads(o->threads);
      const Scene& sc = tr.scene();
      fmt::print("hashcc eval: {} | {} at step {} | {} images {}x{} ({} train, {} test) | {} "
                 "threads\n",
                 o->run, tr.config().data, tr.state().step, sc.names.size(), sc.width, sc.height,
                 sc.train.size(), sc.test.size(), num_threads());
      EvalResult r = evaluate(tr, o->eval);
      const std::string dir = o->run + "/eval";
      write_eval_outputs(r, dir);
      fmt::print("{}", eval_summary(r));
      fmt::print("wrote {}/metrics.json, renders/, gt/, error/, contact_sheet.png\n", dir);
      record_command(o->run, command_args());
      refresh_run_report(o->run);  // RUN/report.html (tools/run_report.h)
    };
  });
}

}  // namespace hashcc
