// tools/cmd_export.cpp — `hashcc export`: the learned cameras as a COLMAP text model and a
// coloured point cloud (PLY) from the expected depth of the training views, both in the learned
// world frame (the frame of cameras.json). Conventions: docs/render.md.
#include <CLI/CLI.hpp>
#include <fmt/core.h>

#include "core/error.h"
#include "core/parallel.h"
#include "outputs/export.h"
#include "outputs/paths.h"
#include "train/trainer.h"
#include "tools/cli.h"

namespace hashcc {

namespace {

struct ExportOptions {
  std::string run, colmap, ply;
  double opacity_threshold = 0.5;
  int stride = 4;
  bool points = true;  // fill points3D.txt with the cloud
  int threads = 0;
  bool progress = true;
};

void run_export(const ExportOptions& o) {
  HCC_REQUIRE(!o.colmap.empty() || !o.ply.empty(), "--colmap/--ply", "", "neither given",
              "at least one output");
  Trainer tr = Trainer::open(o.run);  // sets the run's thread count: --threads after it
  if (o.threads > 0) set_num_threads(o.threads);
  const Scene& sc = tr.scene();
  PointCloud cloud;
  const bool need_cloud = !o.ply.empty() || (!o.colmap.empty() && o.points);
  if (need_cloud) {
    cloud = training_point_cloud(tr, o.stride, o.opacity_threshold, o.progress);
    HCC_REQUIRE(cloud.size() > 0 || o.ply.empty(), "--opacity-threshold", "",
                "no pixel of any training view has opacity ≥ {}", o.opacity_threshold);
  }
  if (!o.ply.empty()) {
    write_ply(o.ply, cloud);
    fmt::print("point cloud: {} points (stride {}, opacity ≥ {}) → {}\n", cloud.size(), o.stride,
               o.opacity_threshold, o.ply);
  }
  if (!o.colmap.empty()) {
    std::vector<std::string> names;
    for (int j : sc.train) names.push_back(sc.names[j]);
    const ColmapCamera cam = colmap_camera(tr.focal(), tr.image_size());
    write_colmap_text(o.colmap, cam, training_c2w(tr), names, o.points ? &cloud : nullptr);
    fmt::print("COLMAP text model: 1 PINHOLE camera (fx {:.3f} fy {:.3f} cx {} cy {}), {} images, "
               "{} points → {}/{{cameras,images,points3D}}.txt\n",
               cam.fx, cam.fy, cam.cx, cam.cy, names.size(), o.points ? cloud.size() : 0,
               o.colmap);
  }
}

}  // namespace

void add_export_command(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("export", "export the learned cameras (COLMAP text model) and a "
                                           "coloured point cloud (PLY) of a trained run");
  auto o = std::make_shared<ExportOptions>();
  sub->add_option("--run", o->run, "run folder (from hashcc train)")->required();
  sub->add_option("--colmap", o->colmap, "write cameras.txt, images.txt, points3D.txt here");
  sub->add_option("--ply", o->ply, "write the point cloud to this .ply file");
  sub->add_option("--opacity-threshold", o->opacity_threshold,
                  "keep pixels whose rendered opacity Σw is at least this")
      ->capture_default_str()->check(CLI::Range(0.0, 1.0));
  sub->add_option("--stride", o->stride, "use every K-th pixel in x and y")
      ->capture_default_str()->check(CLI::Range(1, 4096));
  sub->add_flag("!--no-points", o->points, "COLMAP: leave points3D.txt empty (header only)");
  sub->add_option("--threads", o->threads, "threads (default: all cores)")->check(CLI::Range(1, 1024));
  sub->add_flag("!--no-progress", o->progress, "plain output only");
  sub->callback([&run, o] {
    ExportOptions opts = *o;
    run = [opts] { run_export(opts); };
  });
}

}  // namespace hashcc
