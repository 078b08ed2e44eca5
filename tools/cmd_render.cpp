// tools/cmd_render.cpp — `hashcc render`: novel views of a trained run along a camera path
// (LLFF spiral from the learned cameras, the training cameras, or the test images' reference
// cameras). Per frame: colour PNG, expected NDC depth (float EXR + colour-mapped PNG), opacity
// PNG; then a contact sheet and poses.json. Formulas: docs/render.md.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fileio.h"
#include "core/image.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "outputs/paths.h"
#include "model/render_view.h"
#include "train/trainer.h"
#include "tools/cli.h"
#include "tools/run_report.h"
#include "tools/video.h"

namespace hashcc {

namespace {

struct RenderOptions {
  std::string run, out, path = "spiral";
  int frames = 120;
  double scale = 1;
  int sheet_frames = 30;  // at most this many frames (evenly spaced) on the contact sheet
  int threads = 0;
  bool progress = true;
  std::string video;  // --video FILE.mp4 (tools/video.h)
  int fps = 30;
  bool exact = false;  // --exact: every sample of every ray (no render shortcuts)
};

// Turbo colour map (Mikhailov 2019), polynomial fit; x in [0, 1].
void turbo(double x, float* rgb) {
  x = std::clamp(x, 0.0, 1.0);
  const double r = 0.13572138 + x * (4.61539260 + x * (-42.66032258 + x * (132.13108234 + x * (-152.94239396 + x * 59.28637943))));
  const double g = 0.09140261 + x * (2.19418839 + x * (4.84296658 + x * (-14.18503333 + x * (4.27729857 + x * 2.82956604))));
  const double b = 0.10667330 + x * (12.64194608 + x * (-60.58204836 + x * (110.36276771 + x * (-89.90310912 + x * 27.34824973))));
  rgb[0] = float(std::clamp(r, 0.0, 1.0));
  rgb[1] = float(std::clamp(g, 0.0, 1.0));
  rgb[2] = float(std::clamp(b, 0.0, 1.0));
}

// Depth image for eyes: s̄ = Σws/Σw mapped over [lo, hi], near = warm (turbo 1), black where
// nothing was hit (opacity < 0.05).
std::vector<float> depth_colours(const ViewImage& v, double lo, double hi) {
  std::vector<float> out(size_t(v.width) * v.height * 3, 0.f);
  for (size_t k = 0; k < size_t(v.width) * v.height; ++k) {
    if (!(v.opacity[k] >= 0.05f)) continue;
    const double s = v.depth[k] / v.opacity[k];
    turbo(1.0 - (s - lo) / std::max(hi - lo, 1e-9), &out[3 * k]);
  }
  return out;
}

// Box-filter downscale by an integer factor (thumbnails).
std::vector<float> shrink(const std::vector<float>& rgb, int w, int h, int f, int* ow, int* oh) {
  *ow = std::max(1, w / f);
  *oh = std::max(1, h / f);
  std::vector<float> out(size_t(*ow) * *oh * 3, 0.f);
  for (int y = 0; y < *oh; ++y)
    for (int x = 0; x < *ow; ++x)
      for (int c = 0; c < 3; ++c) {
        double acc = 0;
        int n = 0;
        for (int dy = 0; dy < f && y * f + dy < h; ++dy)
          for (int dx = 0; dx < f && x * f + dx < w; ++dx, ++n)
            acc += rgb[(size_t(y * f + dy) * w + (x * f + dx)) * 3 + c];
        out[(size_t(y) * *ow + x) * 3 + c] = float(acc / std::max(n, 1));
      }
  return out;
}

// Grid of thumbnails (colour row over depth row per frame), 2-pixel white gutters.
void write_contact_sheet(const std::string& path, const std::vector<std::vector<float>>& colour,
                         const std::vector<std::vector<float>>& depth, int w, int h) {
  const int n = int(colour.size());
  if (n == 0) return;
  const int f = std::max(1, int(std::ceil(w / 192.0)));  // thumbnails ≤ 192 px wide
  int tw, th;
  shrink(colour[0], w, h, f, &tw, &th);
  const int cols = std::min(n, 6), rows = (n + cols - 1) / cols, g = 2;
  const int SW = cols * (tw + g) + g, SH = rows * (2 * th + 2 * g) + g;
  std::vector<float> sheet(size_t(SW) * SH * 3, 1.f);
  for (int i = 0; i < n; ++i) {
    const int x0 = g + (i % cols) * (tw + g), y0 = g + (i / cols) * (2 * th + 2 * g);
    for (int part = 0; part < 2; ++part) {
      int a, b;
      std::vector<float> t = shrink(part == 0 ? colour[i] : depth[i], w, h, f, &a, &b);
      for (int y = 0; y < th; ++y)
        for (int x = 0; x < tw; ++x)
          for (int c = 0; c < 3; ++c)
            sheet[(size_t(y0 + part * (th + g) + y) * SW + x0 + x) * 3 + c] =
                t[(size_t(y) * tw + x) * 3 + c];
    }
  }
  write_png_float(path, sheet.data(), SW, SH);
}

// The cameras to render (--path, at most --frames unless spiral) and what poses.json says about
// them. The spiral's focus comes from the rendered depth of the training views, whose range
// then fixes the depth colours (*have_range).
std::vector<Mat34d> camera_path(const Trainer& tr, const RenderOptions& o, nlohmann::json& info,
                                double s_range[2], bool* have_range) {
  std::vector<Mat34d> path;
  if (o.path == "spiral") {
    // Focus from the rendered depth of the training views (LLFF close/far bounds).
    const std::vector<double> z = training_view_depths(tr, 4096, 0.5, s_range);
    *have_range = true;
    const double close = 0.9 * percentile(z, 1), inf = 5.0 * percentile(z, 99);
    SpiralOptions so;
    so.frames = o.frames;
    SpiralInfo si;
    path = spiral_path(training_c2w(tr), close, inf, so, &si);
    info["spiral"] = {{"close_depth", close}, {"inf_depth", inf}, {"focus", si.focus},
                      {"radii", {si.radii.x(), si.radii.y(), si.radii.z()}},
                      {"rotations", so.rotations}, {"zrate", so.zrate}};
    fmt::print("spiral: {} frames, focus {:.3f} (close {:.3f}, inf {:.3f}), radii {:.4f} {:.4f} "
               "{:.4f}\n", path.size(), si.focus, close, inf, si.radii.x(), si.radii.y(),
               si.radii.z());
  } else if (o.path == "train") {
    path = training_c2w(tr);
  } else if (o.path == "test") {
    std::string method;
    path = test_c2w_in_learned_frame(tr, &method);
    info["test_pose_method"] = method;
    fmt::print("test cameras: {}\n", method);
  } else {
    throw Error("--path", "", fmt::format("'{}'", o.path), "spiral, train or test");
  }
  if (o.path != "spiral" && o.frames > 0 && o.frames < int(path.size())) path.resize(o.frames);
  return path;
}

// A fixed colour range for the whole sequence, from its first frame: the 1st and 99th
// percentiles of s̄ where the opacity is at least 0.5 (unchanged when no pixel is).
void depth_range_of(const ViewImage& v, double s_range[2]) {
  std::vector<double> s;
  for (size_t k = 0; k < v.depth.size(); ++k)
    if (v.opacity[k] >= 0.5f) s.push_back(v.depth[k] / v.opacity[k]);
  if (!s.empty()) { s_range[0] = percentile(s, 1); s_range[1] = percentile(s, 99); }
}

// STEM_rgb.png, STEM_depth.exr, STEM_depth.png, STEM_opacity.png of one frame; returns the
// depth colours (for the contact sheet).
std::vector<float> write_frame(const std::string& stem, const ViewImage& v, const double s_range[2]) {
  write_png_float(stem + "_rgb.png", v.rgb.data(), v.width, v.height);
  write_exr(stem + "_depth.exr", v.depth.data(), v.width, v.height, 1);
  std::vector<float> dc = depth_colours(v, s_range[0], s_range[1]);
  write_png_float(stem + "_depth.png", dc.data(), v.width, v.height);
  std::vector<float> op(v.opacity.size() * 3);
  for (size_t k = 0; k < v.opacity.size(); ++k) op[3 * k] = op[3 * k + 1] = op[3 * k + 2] = v.opacity[k];
  write_png_float(stem + "_opacity.png", op.data(), v.width, v.height);
  return dc;
}

// poses.json's entry of frame i: its camera-to-world as a 4×4 matrix.
nlohmann::json frame_json(int i, const Mat34d& c2w) {
  nlohmann::json m = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) m.push_back({c2w(r, 0), c2w(r, 1), c2w(r, 2), c2w(r, 3)});
  m.push_back({0, 0, 0, 1});
  return {{"frame", i}, {"transform_matrix", m}};
}

void run_render(const RenderOptions& o) {
  HCC_REQUIRE(o.scale > 0 && o.scale <= 8, "--scale", "", "{} (expected 0 < scale ≤ 8)", o.scale);
  const std::string ffmpeg = o.video.empty() ? "" : require_ffmpeg(o.video);  // before any frame
  Trainer tr = Trainer::open(o.run);  // sets the run's thread count: --threads after it
  if (o.threads > 0) set_num_threads(o.threads);
  const TrainConfig& cfg = tr.config();
  const ImageSize full = tr.image_size();
  // Render at ImageSize{W·s, H·s} with the same a, b: fx = a²·(W·s), cx = W·s/2 — the
  // intrinsics of the scaled image (docs/render.md).
  const ImageSize sz{int(std::lround(full.W * o.scale)), int(std::lround(full.H * o.scale))};
  HCC_REQUIRE(sz.W >= 1 && sz.H >= 1, "--scale", "", "{} gives a {}x{} image", o.scale, sz.W, sz.H);

  nlohmann::json info = {{"run", o.run}, {"path", o.path}, {"width", sz.W}, {"height", sz.H},
                         {"scale", o.scale}, {"ndc", cfg.ndc}};
  double s_range[2] = {0, 1};
  bool have_range = false;
  const std::vector<Mat34d> path = camera_path(tr, o, info, s_range, &have_range);

  make_dirs(o.out);
  StepWorkspace<float> ws;
  const int n = int(path.size());
  const int sheet_every = std::max(1, (n + o.sheet_frames - 1) / std::max(1, o.sheet_frames));
  std::vector<std::vector<float>> sheet_rgb, sheet_depth;
  nlohmann::json frames = nlohmann::json::array();
  ProgressBar bar("render", n, o.progress);
  Timer timer;
  for (int i = 0; i < n; ++i) {
    const PoseParams<float> pose = pose_params_from_c2w(path[i]);
    ViewCamera cam = tr.view_camera(pose);
    cam.size = sz;  // --scale: the same focal parameters a, b at the output size
    ViewOptions vo{cfg.samples, 1, cfg.chunk_rays, tr.render_occupancy()};
    vo.shortcuts = !o.exact;  // docs/render.md, "Render shortcuts"
    ViewImage v = render_view(ws, tr.net(), cam, vo);
    if (!have_range) {
      depth_range_of(v, s_range);
      have_range = true;
    }
    std::vector<float> dc = write_frame(fmt::format("{}/{:04d}", o.out, i), v, s_range);
    if (i % sheet_every == 0) {
      sheet_rgb.push_back(v.rgb);
      sheet_depth.push_back(std::move(dc));
    }
    frames.push_back(frame_json(i, path[i]));
    bar.update(i + 1, fmt::format("{:.2f} s/frame", timer.seconds() / (i + 1)));
  }
  bar.finish();
  write_contact_sheet(o.out + "/contact_sheet.png", sheet_rgb, sheet_depth, sz.W, sz.H);
  info["depth_png_range_s"] = {s_range[0], s_range[1]};
  info["fl_x"] = focal_fx(tr.focal(), sz);
  info["fl_y"] = focal_fy(tr.focal(), sz);
  info["cx"] = sz.W / 2.0;
  info["cy"] = sz.H / 2.0;
  info["frames"] = frames;
  write_file_atomic(o.out + "/poses.json", info.dump(2) + "\n");
  fmt::print("rendered {} frames of {}x{} in {:.1f} s → {}/NNNN_{{rgb,depth,opacity}}.png, "
             "NNNN_depth.exr, contact_sheet.png, poses.json\n",
             n, sz.W, sz.H, timer.seconds(), o.out);
  if (!o.video.empty()) {
    encode_video(ffmpeg, o.out, o.fps, o.video);
    fmt::print("video: {} ({} frames at {} fps)\n", o.video, n, o.fps);
  }
  // The run's report shows this folder's frames (tools/run_report.h).
  remember_render_dir(o.run, o.out);
  record_command(o.run, command_args());
  refresh_run_report(o.run, o.out);
}

}  // namespace

void add_render_command(CLI::App& app, std::function<void()>& run) {
  auto* sub = app.add_subcommand("render", "render novel views of a trained run (spiral, "
                                           "training or test cameras): colour, depth, opacity");
  auto o = std::make_shared<RenderOptions>();
  sub->add_option("--run", o->run, "run folder (from hashcc train)")->required();
  sub->add_option("--out", o->out, "output folder for the frames")->required();
  sub->add_option("--path", o->path, "camera path: spiral | train | test")->capture_default_str()
      ->check(CLI::IsMember({"spiral", "train", "test"}));
  sub->add_option("--frames", o->frames, "spiral frames (train/test: at most this many; 0 = all)")
      ->capture_default_str()->check(CLI::Range(0, 100000));
  sub->add_option("--scale", o->scale, "image size as a fraction of the training size")
      ->capture_default_str()->check(CLI::Range(1e-3, 8.0));
  sub->add_option("--sheet-frames", o->sheet_frames, "frames on the contact sheet (evenly spaced)")
      ->capture_default_str()->check(CLI::Range(1, 1000));
  sub->add_option("--threads", o->threads, "threads (default: all cores)")->check(CLI::Range(1, 1024));
  sub->add_option("--video", o->video, "also encode the colour frames as FILE.mp4 (H.264) with "
                  "ffmpeg, which must be on the PATH (checked before rendering)");
  sub->add_option("--fps", o->fps, "frames per second of --video")->capture_default_str()
      ->check(CLI::Range(1, 240));
  sub->add_flag("!--no-progress", o->progress, "plain output only");
  sub->add_flag("--exact", o->exact, "every sample of every ray: no early ray termination, no "
                "colour for weightless samples (grid field; docs/render.md)");
  sub->callback([&run, o, sub] {
    RenderOptions opts = *o;
    if (opts.path == "spiral" && opts.frames == 0) opts.frames = 120;
    if (opts.path != "spiral" && !sub->count("--frames")) opts.frames = 0;
    run = [opts] { run_render(opts); };
  });
}

}  // namespace hashcc
