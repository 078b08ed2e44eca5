// tools/cli.cpp — the hashcc command line. Each subcommand registers its flags here and runs
// a library function, so tests can drive it in-process. Exit status: 0 ok, 2 bad input (one
// line naming the file/flag and the problem), 1 internal failure.
#include "tools/cli.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <fmt/core.h>

#include "core/error.h"
#include "core/llff.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "model/trainer.h"
#include "tools/report.h"
#include "tools/simulator.h"
#include <atomic>
#include <csignal>
#include <optional>

namespace hashcc {

namespace {

struct Interrupted {};

// CLI11 validators that name the flag and the accepted range in its message.
void add_simulate(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("simulate", "render the built-in forward-facing scene (known "
                                             "cameras) as an LLFF folder");
  auto opts = std::make_shared<std::pair<SimOptions, std::string>>();
  SimOptions& o = opts->first;
  std::string& out = opts->second;
  sub->add_option("--out", out, "output folder")->required();
  sub->add_option("--views", o.views, "number of cameras")->check(CLI::Range(2, 10000))->capture_default_str();
  sub->add_option("--width", o.width, "image width in pixels")->check(CLI::Range(8, 8192))->capture_default_str();
  sub->add_option("--height", o.height, "image height in pixels")->check(CLI::Range(8, 8192))->capture_default_str();
  sub->add_option("--seed", o.seed, "random seed of the rig")->capture_default_str();
  sub->add_flag("--specular", o.specular, "add view-dependent highlights (off: Lambertian only)");
  sub->add_option("--supersample", o.supersample, "s×s samples per pixel")->check(CLI::Range(1, 8))->capture_default_str();
  sub->callback([&run, opts] {
    run = [opts] {
      const SimOptions& o = opts->first;
      const std::string& out = opts->second;
      Timer t;
      auto rig = write_sim_scene(out, o);
      Scene sc = load_scene(out);  // read back through the same loader as real data
      fmt::print("simulated {} views of {}x{} px (focal {:.1f} px, {}) in {:.1f} s → {}\n",
                  rig.size(), o.width, o.height, o.focal_ratio * o.width,
                  o.specular ? "specular" : "Lambertian", t.seconds(), out);
      fmt::print("  {}/images/*.png, {}/poses_bounds.npy (LLFF convention), {}/scene.json\n", out,
                 out, out);
      fmt::print("  loader check: {} images, {} train / {} test, reference focal {:.2f} px, "
                 "pose scale {:.4f}\n",
                 sc.names.size(), sc.train.size(), sc.test.size(), sc.ref_focal, sc.scale);
    };
  });
}

void add_info(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("info", "check a scene folder and print what the loader sees");
  auto opts = std::make_shared<std::pair<std::string, std::string>>();
  std::string& data = opts->first;
  std::string& folder = opts->second;
  sub->add_option("--data", data, "scene folder (LLFF layout or a bare folder of photos)")->required();
  sub->add_option("--images", folder, "image folder inside --data (images, images_4, images_8; "
                                      "default: the smallest present)");
  sub->callback([&run, opts] {
    run = [opts] {
      const std::string& data = opts->first;
      Scene sc = load_scene(data, {opts->second, true});
      fmt::print("{}: {} images of {}x{} from {} (factor {}), {} train / {} test\n", data,
                 sc.names.size(), sc.width, sc.height, sc.image_dir, sc.factor, sc.train.size(),
                 sc.test.size());
      if (sc.has_reference)
        fmt::print("reference cameras: poses_bounds.npy, focal {:.2f} px at this size, near "
                   "{:.3f} (scaled), scale {:.5f}\n",
                   sc.ref_focal, *std::min_element(sc.near.begin(), sc.near.end()), sc.scale);
      else
        fmt::print("no reference cameras (camera-less; pose error will not be reported)\n");
    };
  });
}

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop.store(true); }

void add_train(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("train", "learn a radiance field and the cameras from a folder "
                                          "of photos (no poses needed)");
  auto c = std::make_shared<TrainConfig>();
  auto model = std::make_shared<std::string>("hashcc");
  auto resume = std::make_shared<std::string>();
  sub->add_option("--data", c->data, "scene folder: LLFF layout or a bare folder of photos");
  sub->add_option("--images", c->images_folder, "image folder inside --data (default: smallest)");
  sub->add_option("--out", c->out, "run folder (config, log, checkpoint, cameras, preview)");
  sub->add_option("--resume", *resume, "continue the run in this folder from its checkpoint");
  sub->add_option("--model", *model, "nerfmm | sh | hashcc")->capture_default_str()
      ->check(CLI::IsMember({"nerfmm", "sh", "hashcc"}));
  sub->add_option("--epochs", c->epochs, "planned epochs (paper: 10000)")->check(CLI::Range(int64_t(1), int64_t(1) << 40));
  sub->add_option("--steps", c->steps, "planned steps (instead of epochs)")->check(CLI::Range(int64_t(1), int64_t(1) << 40));
  sub->add_option("--minutes", c->minutes, "time budget: plan the steps that fit, stop on time")
      ->check(CLI::Range(1e-3, 1e7));
  sub->add_option("--threads", c->threads, "threads (default: all cores)")->check(CLI::Range(1, 1024));
  sub->add_option("--seed", c->seed, "random seed")->capture_default_str();
  sub->add_option("--rays", c->rays, "rays per step, as a rows × cols grid")->capture_default_str()
      ->check(CLI::Range(1, 1 << 20));
  sub->add_option("--samples", c->samples, "samples per ray")->capture_default_str()->check(CLI::Range(2, 4096));
  sub->add_option("--width", c->model.width, "hidden width of the main network")->capture_default_str()
      ->check(CLI::Range(4, 4096));
  sub->add_option("--cc-max-res", c->model.cc.max_res, "finest hash-grid resolution of the CC branch")
      ->capture_default_str()->check(CLI::Range(16.0, 1e6));
  sub->add_option("--chunk-rays", c->chunk_rays, "rays per forward/backward chunk (memory)")
      ->capture_default_str()->check(CLI::Range(1, 1024));
  sub->add_option("--lr-net", c->lr_net, "initial learning rate of the networks")->capture_default_str()
      ->check(CLI::Range(1e-12, 10.0));
  sub->add_option("--checkpoint-minutes", c->checkpoint_minutes, "checkpoint interval")
      ->capture_default_str()->check(CLI::Range(0.0, 1e6));
  sub->add_option("--preview-minutes", c->preview_minutes, "preview render interval")
      ->capture_default_str()->check(CLI::Range(0.0, 1e6));
  sub->add_flag("!--no-ndc", c->ndc, "switch NDC off (scenes that are not forward-facing)");
  sub->add_flag("--fx-only", c->fx_only, "one focal: fy tied to fx");
  sub->add_flag("--stop-cc-to-camera", c->stop_cc_to_camera,
                "ablation: the second loss reaches σ and c for the networks but not the camera");
  sub->add_flag("!--no-progress", c->progress, "plain output only");
  sub->callback([&run, c, model, resume, sub] {
    run = [c, model, resume, sub] {
      Timer t;
      std::signal(SIGINT, on_signal);
      std::signal(SIGTERM, on_signal);
      g_stop = false;
      std::optional<Trainer> tr;
      if (!resume->empty()) {
        tr.emplace(Trainer::resume(*resume, sub->count("--minutes") ? c->minutes : -1));
        fmt::print("resuming {} at step {} of {}\n", *resume, tr->state().step, tr->planned_total());
      } else {
        HCC_REQUIRE(!c->data.empty(), "--data", "", "missing", "a scene folder (or --resume RUN)");
        HCC_REQUIRE(!c->out.empty(), "--out", "", "missing", "a run folder");
        HCC_REQUIRE(int(c->epochs > 0) + int(c->steps > 0) <= 1, "--epochs/--steps", "",
                    "both given", "one of them");
        c->model.variant = parse_variant(*model);
        tr.emplace(*c);
      }
      const TrainConfig& cfg = tr->config();
      const Scene& sc = tr->scene();
      fmt::print("hashcc train: {} | {} images {}x{} ({} train, {} test) | model {} width {} | "
                 "{}x{} rays x {} samples | {} threads\n",
                 cfg.data, sc.names.size(), sc.width, sc.height, sc.train.size(), sc.test.size(),
                 variant_name(cfg.model.variant), cfg.model.width, cfg.grid_rows(), cfg.grid_cols(),
                 cfg.samples, num_threads());
      bool done = tr->run(&g_stop);
      std::signal(SIGINT, SIG_DFL);
      std::signal(SIGTERM, SIG_DFL);
      const TrainState& st = tr->state();
      const FocalParams<float> f = tr->focal();
      fmt::print("{} after {} steps ({} epochs) in {:.1f} s: fx {:.2f} fy {:.2f}{}\n",
                 done ? "finished" : "interrupted", st.step,
                 st.step / int64_t(sc.train.size()), st.elapsed, focal_fx(f, tr->image_size()),
                 focal_fy(f, tr->image_size()),
                 sc.has_reference ? fmt::format(" (reference {:.2f})", sc.ref_focal) : "");
      print_train_report(*tr);
      fmt::print("run folder: {} (config.json, log.csv, checkpoint.bin, cameras.json, preview.png)\n",
                 cfg.out);
      if (!done) {
        fmt::print("resume with: hashcc train --resume {}\n", cfg.out);
        throw Interrupted{};
      }
    };
  });
}

}  // namespace

bool has_subcommand(CLI::App& app, const std::string& name) {
  for (auto* s : app.get_subcommands({})) if (s->get_name() == name) return true;
  return false;
}

int run_cli(int argc, char** argv) {
  CLI::App app{"hashcc: NeRF-- + HashCC on a CPU: a radiance field and its cameras, learned "
               "from photos alone"};
  app.set_version_flag("--version", std::string(HASHCC_VERSION));
  app.require_subcommand(1);
  std::function<void()> run;
  add_simulate(app, run);
  add_info(app, run);
  add_train(app, run);
  if (argc >= 2 && argv[1][0] != '-' && !has_subcommand(app, argv[1])) {
    fmt::print(stderr, "hashcc: unknown subcommand '{}' (run 'hashcc --help' for the list)\n", argv[1]);
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    fmt::print(stderr, "hashcc: {}\n", e.what());
    fmt::print(stderr, "run 'hashcc --help' for usage\n");
    return 2;
  }
  try {
    if (run) run();
  } catch (const Error& e) {
    fmt::print(stderr, "hashcc: {}\n", e.what());
    return 2;
  } catch (const Interrupted&) {
    return 130;
  } catch (const std::exception& e) {
    fmt::print(stderr, "hashcc: internal error: {}\n", e.what());
    return 1;
  }
  return 0;
}

}  // namespace hashcc
