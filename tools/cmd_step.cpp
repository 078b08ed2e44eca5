// tools/cmd_step.cpp — `hashcc step`: one fully specified training step from files, every output
// and gradient dumped as float64 .npy (docs/golden-step.md). `--make-inputs DIR` writes
// a random tiny input folder to start from.
#include <CLI/CLI.hpp>
#include <fmt/core.h>

#include "core/error.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "model/golden_step.h"
#include "tools/cli.h"

namespace hashcc {

namespace {
struct StepFlags {
  std::string in, out, make;
  bool use_double = false;
  int threads = 0;
  std::string model = "hashcc";
  std::string field = "mlp";
  double c2f_alpha = -1;
  uint64_t seed = 1;
  bool no_ndc = false, fx_only = false, p0 = false, grid_smooth = false;
};
}  // namespace

void add_step_command(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand(
      "step", "run ONE training step from an input folder and write every output and gradient "
              "(docs/golden-step.md)");
  auto f = std::make_shared<StepFlags>();
  sub->add_option("--in", f->in, "input folder: config.json, image, rows, cols, s, camera, tensors");
  sub->add_option("--out", f->out, "output folder (rgb_main, rgb_cc, depth, loss, grad.*.npy)");
  sub->add_flag("--double", f->use_double, "run in double precision (default: float, as in training)");
  sub->add_option("--threads", f->threads, "threads (default: all cores)")->check(CLI::Range(1, 1024));
  sub->add_option("--make-inputs", f->make,
                  "instead: write a random tiny input folder here (width 16, 3×3 rays, 8 samples)");
  sub->add_option("--model", f->model, "model of --make-inputs: nerfmm | sh | hashcc")
      ->capture_default_str()->check(CLI::IsMember({"nerfmm", "sh", "hashcc"}));
  sub->add_option("--field", f->field, "field of --make-inputs: mlp (the paper's) | grid (tiny grid field)")
      ->capture_default_str()->check(CLI::IsMember({"mlp", "grid"}));
  sub->add_option("--c2f-alpha", f->c2f_alpha,
                  "coarse-to-fine alpha of --make-inputs (Fourier bands or grid levels; < 0: off)")
      ->capture_default_str();
  sub->add_option("--seed", f->seed, "random seed of --make-inputs")->capture_default_str();
  sub->add_flag("--no-ndc", f->no_ndc, "--make-inputs: \"ndc\": false (rays stay in world space)");
  sub->add_flag("--fx-only", f->fx_only, "--make-inputs: \"fx_only\": true (fy = fx = a²W)");
  sub->add_flag("--p0", f->p0, "--make-inputs: a P0.npy (test-pose camera, c2w = [Exp(r) | t]·P0)");
  sub->add_flag("--grid-smooth", f->grid_smooth,
                "--make-inputs with --field grid: \"grid_smooth\": true (the smooth position gradient)");
  sub->callback([&run, f] {
    run = [f] {
      if (f->threads > 0) set_num_threads(f->threads);
      if (!f->make.empty()) {
        HCC_REQUIRE(f->in.empty(), "--make-inputs", "", "given with --in", "one of them");
        ModelConfig cfg = tiny_model_config(parse_variant(f->model), parse_field(f->field));
        cfg.pos_c2f_alpha = f->c2f_alpha;
        HCC_REQUIRE(!f->grid_smooth || cfg.field == Field::grid, "--grid-smooth", "",
                    "given without --field grid", "--field grid");
        cfg.gf.grid.smooth_dx = f->grid_smooth;
        GoldenMakeOptions o;
        o.seed = f->seed;
        o.ndc = !f->no_ndc;
        o.fx_only = f->fx_only;
        o.p0 = f->p0;
        GoldenInputs in = make_golden_inputs(cfg, o);
        write_golden_inputs(f->make, in);
        fmt::print("wrote a {} ({} field) step input ({} x {} rays x {} samples, {} parameters) to {}\n",
                   f->model, f->field, in.R(), in.C(), in.S, in.params.size() + 8, f->make);
        return;
      }
      HCC_REQUIRE(!f->in.empty(), "--in", "", "missing", "an input folder (or --make-inputs DIR)");
      HCC_REQUIRE(!f->out.empty(), "--out", "", "missing", "an output folder");
      Timer t;
      GoldenInputs in = read_golden_inputs(f->in);
      GoldenOutputs out = f->use_double ? golden_step<double>(in) : golden_step<float>(in);
      write_golden_outputs(f->out, in, out);
      fmt::print("hashcc step: {} {} | {} x {} rays x {} samples | loss {:.17g} | {:.2f} s → {}\n",
                 variant_name(in.model.variant), f->use_double ? "double" : "float", in.R(),
                 in.C(), in.S, out.loss, t.seconds(), f->out);
    };
  });
}

}  // namespace hashcc
