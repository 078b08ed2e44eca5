// tools/cli.cpp — the hashcc command line. Small subcommands live here; larger ones in
// tools/cmd_<name>.cpp (add_<name>_command). Each runs a library function, so tests can drive
// it in-process. Exit status: 0 ok, 2 bad input (one
// line naming the file/flag and the problem), 1 internal failure.
#include "tools/cli.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <sys/resource.h>
#include <csignal>
#include <filesystem>
#include <fmt/core.h>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/llff.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "tools/simulator.h"
#include "train/trainer.h"

namespace hashcc {

namespace {

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
  sub->add_flag("--jpeg", o.jpeg, "write images/*.jpg with an EXIF block (35 mm equivalent focal; "
                "image001 stored on its side, orientation 6), as a phone does");
  sub->add_option("--supersample", o.supersample, "s×s samples per pixel")->check(CLI::Range(1, 8))->capture_default_str();
  // --rig: one word, two switches (look_at, sweep); the callback below sets them.
  auto rig = std::make_shared<std::string>("parallel");
  sub->add_option("--rig", *rig, "parallel: cameras on a small spiral look down -z (+ jitter); lookat: they turn towards the focus point; sweep: they walk a horizontal arc round the focus point turning to follow it (as LLFF horns)")
      ->check(CLI::IsMember({"parallel", "lookat", "sweep"}))->capture_default_str();
  sub->add_option("--sweep", o.sweep_deg, "with --rig sweep: the arc's whole angle, degrees (the rotation spread)")
      ->check(CLI::Range(1.0, 120.0))->capture_default_str();
  sub->add_option("--focus-depth", o.focus_depth, "the point lookat/sweep cameras turn to, world units ahead")
      ->check(CLI::Range(1.0, 100.0))->capture_default_str();
  sub->add_option("--fov", o.fov_deg, "horizontal field of view, degrees (0 = the built-in focal 0.8 x width, 64 deg)")
      ->check(CLI::Range(0.0, 150.0))->capture_default_str();
  sub->add_option("--backdrop-depth", o.backdrop_depth, "depth of the far wall (objects at 2.6-6; 8 = built-in, 40 = a near subject before a far wall)")
      ->check(CLI::Range(7.0, 1000.0))->capture_default_str();
  sub->add_option("--baseline", o.baseline, "radius of the spiral of camera centres (world units; surfaces at depth 2.6-8)")
      ->check(CLI::Range(0.0, 2.0))->capture_default_str();
  sub->add_option("--rot-jitter", o.rot_jitter_deg, "hand-held rotation noise per axis, degrees (0 = none)")
      ->check(CLI::Range(0.0, 45.0))->capture_default_str();
  sub->callback([&run, opts, rig] {
    opts->first.look_at = *rig == "lookat";
    opts->first.sweep = *rig == "sweep";
    run = [opts] {
      const SimOptions& o = opts->first;
      const std::string& out = opts->second;
      Timer t;
      auto rig = write_sim_scene(out, o);
      Scene sc = load_scene(out);  // read back through the same loader as real data
      fmt::print("simulated {} views of {}x{} px (focal {:.1f} px, {}) in {:.1f} s → {}\n",
                  rig.size(), o.width, o.height, o.focal_px(),
                  o.specular ? "specular" : "Lambertian", t.seconds(), out);
      fmt::print("  {}/images/*.{}, {}/poses_bounds.npy (LLFF convention), {}/scene.json\n", out,
                 o.jpeg ? "jpg (EXIF)" : "png", out, out);
      fmt::print("  loader check: {} images, {} train / {} test, reference focal {:.2f} px, "
                 "pose scale {:.4f}\n",
                 sc.names.size(), sc.train.size(), sc.test.size(), sc.ref_focal, sc.scale);
    };
  });
}

void add_info(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("info", "check a scene folder and print what the loader sees");
  struct InfoOptions {
    std::string data, folder;
    int max_side = TrainConfig{}.max_side;
  };
  auto o = std::make_shared<InfoOptions>();
  sub->add_option("--data", o->data, "scene folder (LLFF layout or a bare folder of photos)")->required();
  sub->add_option("--images", o->folder, "image folder inside --data (images, images_4, images_8; "
                                         "default: the smallest present)");
  sub->add_option("--max-side", o->max_side, "working resolution, as train's --max-side (0 = the "
                  "files' size)")->capture_default_str()->check(CLI::Range(0, 1 << 16));
  sub->callback([&run, o] {
    run = [o] {
      const std::string& data = o->data;
      Scene sc = load_scene(data, {o->folder, true, o->max_side});
      if (auto note = ignored_files_note(sc); !note.empty()) fmt::print("{}\n", note);
      for (const std::string& note : sc.notes) fmt::print("note: {}\n", note);
      fmt::print("{}: {} images of {}x{} from {} (factor {}), {} train / {} test\n", data,
                 sc.names.size(), sc.file_width, sc.file_height, sc.image_dir, sc.factor,
                 sc.train.size(), sc.test.size());
      if (sc.turned > 0)
        fmt::print("EXIF orientation: {} of {} photos stored turned or mirrored, loaded upright "
                   "(sizes are as displayed)\n", sc.turned, sc.names.size());
      fmt::print("working size: {}x{} ({})\n", sc.width, sc.height,
                 sc.width == sc.file_width && sc.height == sc.file_height
                     ? (o->max_side > 0 ? fmt::format("within --max-side {}", o->max_side)
                                        : std::string("--max-side 0: the files' size"))
                     : fmt::format("--max-side {}, area filter, {:.3g}x smaller", o->max_side,
                                   double(sc.file_width) / sc.width));
      // The starting focal train would take when no --focal, --init-poses or --cameras-from
      // is given (train/trainer.cpp's order).
      if (sc.exif_focal > 0)
        fmt::print("starting focal: {:.2f} px at the working size, from {}\n", sc.exif_focal,
                   sc.exif_focal_source);
      else
        fmt::print("starting focal: no EXIF focal; train starts from the recipe's field-of-view "
                   "prior (focal_fov), or fx = W, fy = H without one\n");
      if (sc.has_reference)
        fmt::print("reference cameras: poses_bounds.npy, focal {:.2f} px at this size, near "
                   "{:.3f} (scaled), scale {:.5f}\n",
                   sc.ref_focal, *std::min_element(sc.near.begin(), sc.near.end()), sc.scale);
      else
        fmt::print("no reference cameras (camera-less; pose error will not be reported)\n");
    };
  });
}

}  // namespace

namespace {
std::atomic<bool> g_stop{false};
extern "C" void on_stop_signal(int) { g_stop.store(true); }
}  // namespace

StopSignals::StopSignals() {
  g_stop = false;
  std::signal(SIGINT, on_stop_signal);
  std::signal(SIGTERM, on_stop_signal);
}
StopSignals::~StopSignals() {
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
}
const std::atomic<bool>& StopSignals::flag() const { return g_stop; }

bool has_subcommand(CLI::App& app, const std::string& name) {
  for (auto* s : app.get_subcommands({})) if (s->get_name() == name) return true;
  return false;
}

namespace {
bool g_help_all = false;
std::vector<std::string> g_command;
}  // namespace
bool help_all() { return g_help_all; }
const std::vector<std::string>& command_args() { return g_command; }

int run_cli(int argc, char** argv) {
  // --help-all is --help with the advanced options shown (their group is chosen as they are
  // added, so it is read before the commands are built).
  const auto started = std::chrono::steady_clock::now();
  std::vector<std::string> args(argv, argv + argc);
  // --rusage-json FILE (anywhere; the lines of `hashcc study --emit-commands` add it): on success
  // this process's wall and CPU seconds, peak resident memory and the load average are written
  // to FILE — what a direct study measures of its children (docs/study.md#fan-out-on-a-scheduler).
  std::string rusage_json;
  for (size_t i = 1; i + 1 < args.size(); ++i)
    if (args[i] == "--rusage-json") {
      rusage_json = args[i + 1];
      args.erase(args.begin() + long(i), args.begin() + long(i) + 2);
      break;
    }
  g_command = args;
  if (!g_command.empty()) g_command[0] = std::filesystem::path(g_command[0]).filename().string();
  g_help_all = false;
  for (std::string& a : args)
    if (a == "--help-all") { g_help_all = true; a = "--help"; }
  std::vector<char*> argp;
  for (std::string& a : args) argp.push_back(a.data());
  argv = argp.data();
  argc = int(argp.size());
  CLI::App app{"hashcc: NeRF-- + HashCC on a CPU: a radiance field and its cameras, learned "
               "from photos alone"};
  app.set_version_flag("--version", std::string(HASHCC_VERSION));
  app.require_subcommand(1);
  std::function<void()> run;
  add_simulate(app, run);
  add_info(app, run);
  add_train_command(app, run);
  add_render_command(app, run);
  add_export_command(app, run);
  add_eval_command(app, run);
  add_step_command(app, run);
  add_study_command(app, run);
  add_bench_command(app, run);
  add_report_command(app, run);
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
    fmt::print(stderr, "hashcc: interrupted\n");
    return 130;
  } catch (const std::exception& e) {
    fmt::print(stderr, "hashcc: internal error: {}\n", e.what());
    return 1;
  }
  if (!rusage_json.empty()) {
    struct rusage ru {};
    getrusage(RUSAGE_SELF, &ru);
    double load = -1;
    if (std::FILE* f = std::fopen("/proc/loadavg", "r")) {
      if (std::fscanf(f, "%lf", &load) != 1) load = -1;
      std::fclose(f);
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    const double cpu = double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
                       1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
    if (std::FILE* f = std::fopen(rusage_json.c_str(), "w")) {
      fmt::print(f, "{{\"wall_seconds\": {:.3f}, \"cpu_seconds\": {:.3f}, \"maxrss_mb\": {:.3f}, "
                 "\"load_avg\": {:.2f}}}\n", wall, cpu, double(ru.ru_maxrss) / 1024.0, load);
      std::fclose(f);
    }
  }
  return 0;
}

}  // namespace hashcc
