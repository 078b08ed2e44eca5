// tools/cmd_bench.cpp — `hashcc bench`: ms per training step per variant and thread count,
// the stage breakdown, dense-layer GFLOP/s against the measured and nominal FP32 peak, the CC
// overhead (tools/bench.h). Timings only: nothing here is asserted.
#include <CLI/CLI.hpp>
#include <fmt/core.h>

#include "core/error.h"
#include "core/fileio.h"
#include "tools/bench.h"
#include "tools/cli.h"

namespace hashcc {

void add_bench_command(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("bench", "time one full training step (paper configuration) per "
                                          "variant and thread count, with a stage breakdown");
  auto o = std::make_shared<BenchOptions>();
  auto json_path = std::make_shared<std::string>();
  auto variants = std::make_shared<std::vector<std::string>>();
  sub->add_option("--variant", *variants, "variants to time (repeatable; default nerfmm sh hashcc; NAME+grid: that model on the grid field)")
      ->check(CLI::IsMember({"nerfmm", "sh", "hashcc", "nerfmm+grid", "sh+grid", "hashcc+grid"}));
  sub->add_option("--threads", o->threads, "thread counts to time (repeatable; default 1 and all)")
      ->check(CLI::Range(1, 1024));
  sub->add_option("--rays", o->rays, "rays per step (a rows × cols grid)")->capture_default_str()
      ->check(CLI::Range(1, 1 << 16));
  sub->add_option("--samples", o->samples, "samples per ray")->capture_default_str()
      ->check(CLI::Range(2, 4096));
  sub->add_option("--grid-samples", o->grid_samples, "samples per ray of the NAME+grid variants "
                  "(the grid field trains with 32)")->capture_default_str()->check(CLI::Range(2, 4096));
  sub->add_option("--width", o->width, "hidden width of the main network")->capture_default_str()
      ->check(CLI::Range(4, 4096));
  sub->add_option("--chunk-rays", o->chunk_rays, "rays per forward/backward chunk (0 = auto: "
                  "the largest power of two within 24 MiB a chunk, per variant)")->capture_default_str()->check(CLI::Range(0, 1024));
  sub->add_option("--steps", o->steps, "timed steps per run (default: fit --seconds, at least 3)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--warmup", o->warmup, "untimed steps before timing")->capture_default_str()
      ->check(CLI::Range(1, 1000));
  sub->add_option("--seconds", o->budget_seconds, "time budget of the timed steps when --steps is "
                  "not given")->capture_default_str()->check(CLI::Range(1.0, 1e6));
  sub->add_option("--data", o->scene_dir, "scene folder (default: simulate one into a temp folder)");
  sub->add_flag("--dense", o->dense, "also time the paper's dense layer shapes alone, Eigen's GEMM "
                "against the build's path, in one run");
  sub->add_option("--dense-reps", o->dense_reps, "repetitions per dense shape (median reported)")
      ->capture_default_str()->check(CLI::Range(1, 1000));
  auto no_step = std::make_shared<bool>(false);
  sub->add_flag("--no-step", *no_step, "skip the training-step timings (with --dense: the GEMMs only)");
  auto gemm = std::make_shared<std::string>("kernel");
  sub->add_option("--gemm", *gemm, "GEMM of the timed steps: kernel (the build's path), eigen "
                  "(the reference) or both (alternating step by step: a same-run comparison)")
      ->capture_default_str()->check(CLI::IsMember({"kernel", "eigen", "both"}));
  sub->add_option("--distortion", o->distortion, "also time each variant with the distortion "
                  "loss at this λ (detached from the cameras, as in training), alternating step by "
                  "step with it off: its cost as a same-run ratio")->check(CLI::Range(0.0, 1e6));
  sub->add_option("--json", *json_path, "also write the results as JSON to this file");
  auto render = std::make_shared<bool>(false);
  auto ro = std::make_shared<BenchRenderOptions>();
  sub->add_flag("--render", *render, "time one frame (504x378 for a fresh field) of a grid field "
                "at 32 and 64 samples, 1 and 2 threads (or --threads), exact and with the render "
                "shortcuts, against the training step (docs/render.md)");
  sub->add_option("--run", ro->run, "with --render: the grid-field run to render (default: a "
                  "freshly initialised field)");
  sub->add_option("--frames", ro->frames, "with --render: timed frames per row (the median)")
      ->capture_default_str()->check(CLI::Range(1, 1000));
  sub->add_option("--skip-sigma", ro->skip_sigmas, "with --render: also the shortcuts with an "
                  "empty-space grid that skips cells whose sampled density is below this "
                  "(repeatable; docs/render.md)")->check(CLI::PositiveNumber);
  sub->add_option("--skip-res", ro->skip_res, "with --render --skip-sigma: the grid's cells per axis")
      ->capture_default_str()->check(CLI::Range(4, 512));
  sub->add_option("--skip-passes", ro->skip_passes, "with --render --skip-sigma: jittered density "
                  "points a cell")->capture_default_str()->check(CLI::Range(1, 64));
  auto memory = std::make_shared<bool>(false);
  auto mem_kib = std::make_shared<std::vector<int64_t>>();
  sub->add_flag("--memory", *memory, "measure the memory hierarchy instead of a step: per working "
                "set (16 KiB … 256 MiB) and thread count, pointer-chase latency, random 8-byte "
                "gather and scatter-add throughput, streaming read and write bandwidth (the grid "
                "step's roofline: tools/grid_roofline.py)");
  sub->add_option("--memory-kib", *mem_kib, "with --memory: the working sets in KiB (repeatable)")
      ->check(CLI::Range(int64_t(1), int64_t(1) << 24));
  auto dense_probe = std::make_shared<bool>(false);
  sub->add_flag("--dense-probe", *dense_probe, "time the dense micro-kernel's three GEMMs alone at "
                "1 thread per paper layer shape, on L2-resident and streaming working sets "
                "(--dense-reps repetitions)");
  auto hashgrid = std::make_shared<bool>(false);
  auto ho = std::make_shared<BenchHashGridOptions>();
  sub->add_flag("--hashgrid", *hashgrid, "time the hash encoding's kernels alone (forward, "
                "training backward, frozen-table backward) per table size and thread count, in ms "
                "and ns a point a level (tools/bench_hashgrid.cpp)");
  sub->add_option("--hashgrid-log2", ho->log2_tables, "with --hashgrid: log2 table sizes "
                  "(repeatable; default 15 17)")->check(CLI::Range(4, 24));
  sub->add_option("--hashgrid-reps", ho->reps, "with --hashgrid: timed repetitions (the median)")
      ->capture_default_str()->check(CLI::Range(1, 100000));
  sub->callback([&run, o, json_path, variants, no_step, gemm, render, ro, memory, mem_kib, hashgrid,
                 ho, dense_probe] {
    if (*dense_probe) {
      run = [o] { run_bench_dense_probe(o->dense_reps); };
      return;
    }
    if (*hashgrid) {
      run = [o, ho] {
        ho->threads = o->threads;
        run_bench_hashgrid(*ho);
      };
      return;
    }
    if (*memory) {
      run = [o, json_path, mem_kib] {
        BenchMemoryOptions mo;
        mo.threads = o->threads;
        for (int64_t k : *mem_kib) mo.sizes.push_back(k << 10);
        mo.json = *json_path;
        run_bench_memory(mo);
      };
      return;
    }
    if (*render) {
      run = [o, ro] {
        ro->threads = o->threads;
        run_bench_render(*ro);
      };
      return;
    }
    run = [o, json_path, variants, no_step, gemm] {
      if (!variants->empty()) o->variants = *variants;
      o->step = !*no_step;
      o->gemm = *gemm;
      BenchReport r = run_bench(*o, [](const std::string& s) {
        fmt::print(stderr, "bench: {}\n", s);
      });
      fmt::print("{}", bench_table(r));
      if (!json_path->empty()) {
        write_file_atomic(*json_path, bench_json(r));
        fmt::print("wrote {}\n", *json_path);
      }
    };
  });
}

}  // namespace hashcc
