#include "train/trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/camera_models.h"
#include "core/error.h"
#include "core/stats.h"
#include "core/fileio.h"
#include "core/image.h"
#include "core/progress.h"
#include "camera/precondition.h"
#include "kernels/adam.h"
#include "kernels/hash_grid.h"
#include "train/checkpoint.h"
#include "train/minutes_planner.h"
#include "model/render_view.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace hashcc {

// A near-square grid of n rays: round(√n) rows × ⌈n / rows⌉ columns (32 × 32 for 1024).
static int grid_rows_for(int n) { return std::max(1, int(std::lround(std::sqrt(double(n))))); }
static int grid_cols_for(int n) { return (n + grid_rows_for(n) - 1) / grid_rows_for(n); }
int TrainConfig::grid_rows() const { return grid_rows_for(rays); }
int TrainConfig::grid_cols() const { return grid_cols_for(rays); }
// --images-per-step K: validate_train_config requires K | rays, so each image gets rays / K
// (1024 / 4 = 256 → 16 × 16; the step then has K · rows · cols ≈ rays rays, exactly rays
// whenever rays / K is a square, as for the default 1024 and K = 1, 4, 16).
int TrainConfig::step_rows() const { return grid_rows_for(rays / std::max(1, images_per_step)); }
int TrainConfig::step_cols() const { return grid_cols_for(rays / std::max(1, images_per_step)); }

namespace {

// Every file in dir and its subfolders (one level: images*/), with its size and modification
// time, sorted: equal fingerprints mean the loader would read the same bytes.
std::string scene_fingerprint(const std::string& dir) {
  std::vector<std::string> entries;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (it.depth() >= 1) it.disable_recursion_pending();
    std::error_code e2;
    if (!it->is_regular_file(e2)) continue;
    const auto size = it->file_size(e2);
    const auto time = it->last_write_time(e2).time_since_epoch().count();
    entries.push_back(fmt::format("{}\t{}\t{}", it->path().string(), size, time));
  }
  std::sort(entries.begin(), entries.end());
  std::string f;
  for (const std::string& e : entries) f += e + "\n";
  return f;
}

// A plan loads its scene once per stage, and again for each stage's look at the one before
// (--cameras-from): nine loads in the forward recipe. For phone photos each load decodes every
// 12 MP JPEG again (≈ 0.5 s a photo, measured), so the last scene loaded is kept and reused
// while the folder is unchanged (names, sizes, times) and the options are the same. Only a
// small scene is kept (at most 64 MiB of pixels, e.g. 34 photos at the default working size
// take 19 MiB), so a full-size scene is never held twice. The kept scene is shared, not copied:
// the trainers that use it and the cache hold one set of pixels.
std::shared_ptr<const Scene> load_scene_cached(const std::string& dir, const SceneOptions& opt) {
  static std::mutex mutex;
  static std::string key;
  static std::shared_ptr<const Scene> kept;
  const std::lock_guard<std::mutex> lock(mutex);
  const std::string k = fmt::format("{}\n{}\n{}\n{}", dir, opt.images_folder, opt.max_side,
                                    scene_fingerprint(dir));
  if (opt.load_pixels && k == key) return kept;
  auto sc = std::make_shared<const Scene>(load_scene(dir, opt));
  size_t bytes = 0;
  for (const ImageU8& im : sc->images) bytes += im.rgb.size();
  if (opt.load_pixels && bytes <= (size_t(64) << 20)) {
    key = k;
    kept = sc;
  } else {
    key.clear();
    kept.reset();
  }
  return sc;
}

// What --cameras-from needs of an earlier run: its config, its scene (the cached one, shared,
// when it is this run's: a plan's stages) and the camera sections of its checkpoint. Not a
// whole Trainer: opening one held the earlier stage's network, its Adam moments, its
// divergence-guard copy of them and its step buffers next to this run's, and a copy of the
// checkpoint's every section besides.
struct RunCameras {
  TrainConfig cfg;
  std::shared_ptr<const Scene> scene;
  std::vector<float> poses, poses_P0, focal;
};

RunCameras read_run_cameras(const std::string& run) {
  RunCameras r;
  const std::string cfg_path = run + "/config.json";
  r.cfg = train_config_from_json(read_file_bytes(cfg_path, 1 << 20), cfg_path);
  validate_train_config(r.cfg);
  r.scene = load_scene_cached(r.cfg.data, {r.cfg.images_folder, true, r.cfg.max_side});
  HCC_REQUIRE(!r.scene->train.empty(), r.cfg.data, "", "no training images");
  const std::string ck = run + "/checkpoint.bin";
  const std::set<std::string> only = {"poses", "poses.P0", "focal"};
  const Checkpoint c = load_checkpoint(ck, &only);
  const int64_t n = int64_t(r.scene->train.size());
  r.poses = c.floats("poses", ck, 6 * n);
  r.focal = c.floats("focal", ck, 2);
  if (!r.cfg.init_poses.empty()) r.poses_P0 = c.floats("poses.P0", ck, 12 * n);
  return r;
}

}  // namespace

void Trainer::load_scene_and_layout() {
  validate_train_config(cfg_);
  if (cfg_.threads > 0) set_num_threads(cfg_.threads);
  scene_ = load_scene_cached(cfg_.data, {cfg_.images_folder, true, cfg_.max_side});
  HCC_REQUIRE(!scene_->train.empty(), cfg_.data, "", "no training images");
  if (cfg_.images_per_step == 0)
    cfg_.images_per_step = auto_images_per_step(cfg_.rays, int(scene_->train.size()));
  validate_train_config(cfg_, int(scene_->train.size()));
  // A square grid of m × m rays, m = min(width, height), always fits: the hint for tiny photos.
  const int fit = std::min(scene_->width, scene_->height);
  HCC_REQUIRE(cfg_.grid_rows() <= scene_->height && cfg_.grid_cols() <= scene_->width, "--rays", "",
              "a {}x{} ray grid (rows x columns) does not fit {}x{} images", cfg_.grid_rows(),
              cfg_.grid_cols(), scene_->width, scene_->height,
              fmt::format("--rays {} or fewer", int64_t(fit) * fit));
  layout_ = make_layout(cfg_.model);
  build_pyramid();
}

void Trainer::build_pyramid() {
  pyr2_.clear();
  pyr4_.clear();
  if (cfg_.pyramid <= 0) return;
  // Once at start (fresh or resumed run), for the training images only: cost in train/pyramid.h.
  const size_t n = scene_->train.size();
  pyr2_.resize(n);
  pyr4_.resize(n);
  parallel_for(int64_t(n), [&](int64_t i) {
    pyr2_[i] = make_pyramid_level(scene_->images[scene_->train[i]], 2);
    pyr4_[i] = make_pyramid_level(scene_->images[scene_->train[i]], 4);
  });
}

void Trainer::setup_buffers() {
  // The most rays a step can have (a coarse pyramid level may use fewer).
  const int K = cfg_.images_per_step;
  const int R = K * cfg_.step_rows() * cfg_.step_cols(), S = cfg_.samples;
  step_images_.assign(K, 0);
  step_poses_.assign(K, PoseParams<float>{});
  grads_.d_pose.assign(6 * K, 0.f);
  perm_.reserve(scene_->train.size());
  // Full-size index scratch now, so a pyramid level switch never allocates mid-run.
  rsel_.reserve(scene_->height);
  csel_.reserve(scene_->width);
  d_poses_.reserve(6 * scene_->train.size());
  d_net_.assign(layout_.count, 0.f);
  grads_.d_params = d_net_.data();
  px_.assign(2 * R, 0);
  for (std::vector<float>* v : {&ws_.o, &ws_.d, &ws_.d_o, &ws_.d_d}) v->assign(3 * R, 0.f);
  s_.assign(int64_t(R) * S, 0.f);
  target_.assign(3 * R, 0.f);
  good_ = st_;
}

Trainer::Trainer(const TrainConfig& cfg) : cfg_(cfg) {
  load_scene_and_layout();
  const int n = int(scene_->train.size());
  Rng rng(cfg_.seed, 1);
  st_.net.assign(layout_.count, 0.f);
  init_params(st_.net.data(), cfg_.model, layout_, rng);
  st_.poses.assign(6 * n, 0.f);  // formulas.md §1: identity (at the origin, looking down −z)
  st_.focal = {1.f, 1.f};        // formulas.md §1: a = b = 1, fx = W, fy = H
  for (const AdamGroup& g : st_.groups()) {
    g.m.assign(g.value.size(), 0.f);
    g.v.assign(g.value.size(), 0.f);
  }
  // The starting focal; the first source that has one wins:
  //   --focal > the cameras of --cameras-from (a plan's later stages) > --init-poses' focal >
  //   the photos' EXIF lens > --focal-fov, the recipe's prior > fx = W, fy = H.
  // EXIF and the prior assume square pixels (fx = fy). A folder without EXIF (PNG, LLFF) takes
  // exactly the path it took before EXIF was read.
  const bool focal_given = cfg_.focal_fx > 0 || !cfg_.cameras_from.empty() ||
                           (!cfg_.init_poses.empty() && cfg_.init_focal);
  if (scene_->exif_focal > 0 && !focal_given) {
    const double f = scene_->exif_focal;
    st_.focal = {float(std::sqrt(f / scene_->width)), float(std::sqrt(f / scene_->height))};
    focal_source_ = scene_->exif_focal_source;
    init_report_.push_back(fmt::format("focal from the photos' EXIF, {}: fx = fy = {:.2f} px{}",
                                       scene_->exif_focal_source, f,
                                       cfg_.focal_fov > 0 ? fmt::format(" (instead of the "
                                       "{:g}° prior)", cfg_.focal_fov) : ""));
  } else if (cfg_.focal_fov > 0 && !focal_given) {
    const double f = focal_for_fov(scene_->width, cfg_.focal_fov);
    st_.focal = {float(std::sqrt(f / scene_->width)), float(std::sqrt(f / scene_->height))};
    focal_source_ = fmt::format("fov prior {:g} deg", cfg_.focal_fov);
    init_report_.push_back(fmt::format("focal from a {:g}° field of view: fx = fy = {:.2f} px",
                                       cfg_.focal_fov, f));
  }
  if (!cfg_.init_poses.empty()) init_cameras_from_model();
  // (The sources name the flag only: its path is the init_poses / cameras_from key beside.)
  if (!cfg_.init_poses.empty() && cfg_.init_focal) focal_source_ = "--init-poses";
  if (cfg_.focal_fx > 0) {  // --focal: a known focal, a = sqrt(fx/W), b = sqrt(fy/H)
    focal_source_ = "--focal";
    st_.focal = {float(std::sqrt(cfg_.focal_fx / scene_->width)),
                 float(std::sqrt(cfg_.focal_fy / scene_->height))};
    init_report_.push_back(fmt::format("focal given: fx {:.2f} fy {:.2f} px{}", cfg_.focal_fx,
                                       cfg_.focal_fy, focal_frozen() ? " (fixed)" : ""));
  }
  if (!cfg_.cameras_from.empty()) {
    // The earlier run must be of the same scene: the same training images, in the same order.
    const RunCameras src = read_run_cameras(cfg_.cameras_from);  // read-only: the run is left as it is
    HCC_REQUIRE(src.scene->train == scene_->train && src.scene->names == scene_->names,
                "--cameras-from", cfg_.cameras_from, "is a run of another scene",
                "a run of this scene (same images, same size)");
    HCC_REQUIRE(src.scene->width == scene_->width && src.scene->height == scene_->height,
                "--cameras-from", cfg_.cameras_from, "trained at {}x{}, this run at {}x{}",
                src.scene->width, src.scene->height, scene_->width, scene_->height,
                fmt::format("the same working size (its max_side is {}: give --max-side {})",
                            src.cfg.max_side, src.cfg.max_side));
    st_.poses = src.poses;
    st_.poses_P0 = src.poses_P0;
    st_.focal = src.focal;
    focal_source_ = "--cameras-from";
    // The focal as the earlier run rendered with it: a one-focal run (--fx-only) ties fy to fx
    // and leaves its own fy parameter b where it was, so b is set to give fy = fx here.
    if (src.cfg.fx_only && !cfg_.fx_only)
      st_.focal[1] = float(std::sqrt(double(st_.focal[0]) * st_.focal[0] * scene_->width /
                                     scene_->height));
  }
  st_.focal_start = {st_.focal[0], st_.focal[1]};
  if (cfg_.pose_precondition > 0) init_pose_preconditioner();
  setup_buffers();
  if (!cfg_.out.empty()) {
    // The run folder is created only now, after the scene loaded and every setting checked:
    // bad input leaves nothing behind. A fresh run in a folder holding an older run drops the
    // old run's results first, so a crash before our first checkpoint cannot leave our
    // config.json beside another run's checkpoint (which --resume would then load).
    make_dirs(cfg_.out);
    for (const char* stale : {"checkpoint.bin", "checkpoint.bin.tmp", "cameras.json", "preview.png"}) {
      std::error_code ec;
      fs::remove(fs::path(cfg_.out) / stale, ec);
    }
    // "focal_source" is a record for the reader (and `hashcc info --run`), not a setting: the
    // config reader skips it, and a resumed run's focal comes from its checkpoint.
    json cj = json::parse(train_config_json(cfg_));
    cj["focal_source"] = focal_source_;
    write_file_atomic(cfg_.out + "/config.json", cj.dump(2) + "\n");
    write_file_atomic(cfg_.out + "/log.csv",
                      "step,seconds,loss,psnr,psnr_cc,lr_net,lr_pose,lr_focal,fx,fy\n");
  }
}

void Trainer::init_cameras_from_model() {
  const CameraModel m = read_camera_model(cfg_.init_poses);
  const InitPoses ip = init_poses_for_scene(m, *scene_);
  init_report_ = ip.notes;
  int from_model = 0;
  st_.poses_P0.assign(12 * scene_->train.size(), 0.f);
  for (size_t i = 0; i < scene_->train.size(); ++i) {
    const Mat34d& P0 = ip.c2w[scene_->train[i]];
    from_model += ip.from_model[scene_->train[i]];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) st_.poses_P0[12 * i + 4 * r + c] = float(P0(r, c));
  }
  init_report_.insert(init_report_.begin(),
                      fmt::format("--init-poses {} ({}): {} of {} training cameras from the model; "
                                  "scale {}", m.path, m.format, from_model, scene_->train.size(),
                                  ip.scale_source));
  if (cfg_.init_focal) {
    HCC_REQUIRE(ip.has_focal, cfg_.init_poses, "", "holds no focal length",
                "a focal, or --init-focal none");
    // formulas.md §1: fx = a²W, fy = b²H.
    st_.focal = {float(std::sqrt(ip.fx / scene_->width)), float(std::sqrt(ip.fy / scene_->height))};
    init_report_.push_back(fmt::format("focal from the model: fx {:.2f} fy {:.2f} px{}", ip.fx,
                                       ip.fy, focal_frozen() ? " (frozen)" : ""));
  }
}

// --pose-precondition λ: the joint P of every training camera's pose and the learned focal
// parameters, at the starting cameras and focal (camera/precondition.h). Made once: a P that
// changed under Adam's moments would mix their coordinates.
int Trainer::preconditioned_focal_params() const {
  return focal_frozen() ? 0 : cfg_.fx_only ? 1 : 2;
}

void Trainer::init_pose_preconditioner() {
  HCC_REQUIRE(cfg_.ndc, "--pose-precondition", "", "needs NDC (its points fill the NDC box)",
              "a forward-facing scene (NDC on)");
  PreconditionOptions o;
  o.damping = cfg_.pose_precondition;
  const FocalParams<float> ff = focal();
  const FocalParams<double> f{double(ff.a), double(ff.b), ff.fx_only};
  std::vector<PoseParams<double>> poses;
  for (size_t i = 0; i < scene_->train.size(); ++i) poses.push_back(pose_of(int(i)).cast<double>());
  const Eigen::MatrixXd P =
      camera_preconditioner(poses, f, image_size(), preconditioned_focal_params(), o);
  const int64_t D = P.rows();
  st_.cameras_P.resize(D * D);
  for (int64_t r = 0; r < D; ++r)
    for (int64_t c = 0; c < D; ++c) st_.cameras_P[D * r + c] = float(P(r, c));
}

// φ = φ0 + P ψ: Adam sees dL/dψ = P dL/dΦ (P symmetric) and steps ψ from 0 (its step does not
// depend on the value), poses with lr_pose, focal with lr_focal; the cameras move by P Δψ. While
// the focal waits (lr_focal 0: --focal-delay) its rows of the move are dropped, so it stays put;
// the same for the poses.
void Trainer::preconditioned_camera_step(float* d_poses, const float* d_focal, double lr_pose,
                                         double lr_focal, int64_t t) {
  const int n6 = int(st_.poses.size()), m = preconditioned_focal_params(), D = n6 + m;
  const float* P = st_.cameras_P.data();
  auto apply = [&](const std::vector<double>& in, std::vector<double>& out) {
    for (int r = 0; r < D; ++r) {
      double acc = 0;
      for (int c = 0; c < D; ++c) acc += double(P[int64_t(D) * r + c]) * in[c];
      out[r] = acc;
    }
  };
  // Scratch, grown once: cam_g_, cam_step_ of D; cam_psi_, cam_gpsi_ of 6n + 2 (the focal
  // group's two slots even with --fx-only, whose b gets gradient 0 and so step 0).
  cam_g_.assign(D, 0.0);
  cam_step_.assign(D, 0.0);
  cam_psi_.assign(n6 + 2, 0.f);
  cam_gpsi_.assign(n6 + 2, 0.f);
  for (int i = 0; i < n6; ++i) cam_g_[i] = d_poses[i];
  for (int k = 0; k < m; ++k) cam_g_[n6 + k] = d_focal[k];
  apply(cam_g_, cam_step_);  // dL/dψ
  for (int i = 0; i < D; ++i) cam_gpsi_[i] = float(cam_step_[i]);
  adam_step(cam_psi_.data(), cam_gpsi_.data(), st_.poses_m.data(), st_.poses_v.data(), n6,
            lr_pose, t);
  const bool focal_now = m > 0 && lr_focal > 0;
  if (focal_now)
    adam_step(cam_psi_.data() + n6, cam_gpsi_.data() + n6, st_.focal_m.data(),
              st_.focal_v.data(), 2, lr_focal, t);
  for (int i = 0; i < D; ++i) cam_g_[i] = cam_psi_[i];
  apply(cam_g_, cam_step_);  // ΔΦ = P Δψ
  if (lr_pose > 0)  // the poses wait too (--camera-delay): their rows are dropped alike
    for (int i = 0; i < n6; ++i) st_.poses[i] += float(cam_step_[i]);
  if (focal_now)
    for (int k = 0; k < m; ++k) st_.focal[k] += float(cam_step_[n6 + k]);
}

// --refine-poses off: the cameras given (--init-poses, --cameras-from, or a bootstrap's phase 1)
// are held; with the focal held too, the step computes no ray gradient at all (StepOptions::
// need_ray_grads): holding the cameras costs nothing.
bool Trainer::poses_frozen() const { return cfg_.holds_given_poses(); }
bool Trainer::cameras_held_at(int64_t step) const {
  if (poses_frozen() && focal_frozen()) return true;
  return cfg_.hold_cameras_from > 0 &&
         double(step) >= cfg_.hold_cameras_from * double(planned_total());
}

double Trainer::distortion_at(int64_t step) const {
  if (cfg_.distortion_from > 0 && double(step) < cfg_.distortion_from * double(planned_total()))
    return 0;
  return cfg_.distortion;
}

bool Trainer::focal_frozen() const {
  return cfg_.fixed_focal || (poses_frozen() && cfg_.init_focal);
}


Trainer Trainer::open(const std::string& run, double minutes_override,
                      const std::string& data_override) {
  Trainer t;
  std::string cfg_path = run + "/config.json";
  t.cfg_ = train_config_from_json(read_file_bytes(cfg_path, 1 << 20), cfg_path);
  t.cfg_.out = run;
  if (minutes_override >= 0) t.cfg_.minutes = minutes_override;
  if (!data_override.empty()) t.cfg_.data = data_override;
  t.load_scene_and_layout();
  std::string ck = run + "/checkpoint.bin";
  Checkpoint c = load_checkpoint(ck);
  json j;
  try {
    j = json::parse(c.text("state", ck));
  } catch (const json::exception&) {
    throw Error(ck, "state", "not valid JSON");
  }
  TrainState& s = t.st_;
  s.step = j.value("step", int64_t(0));
  s.planned_steps = j.value("planned_steps", int64_t(0));
  s.plan_refined = j.value("plan_refined", false);
  s.elapsed = j.value("elapsed", 0.0);
  s.lr_scale = j.value("lr_scale", 1.0);
  s.diverged = j.value("diverged", 0);
  s.psnr_ema = j.value("psnr_ema", 0.0);          // absent in older checkpoints
  s.camera_start = j.value("camera_start", int64_t(-1));
  s.focal_guarded = j.value("focal_guarded", int64_t(-1));  // absent before the focal guard
  // Each group's size as this run's config and scene define it: a checkpoint of another model
  // or scene is refused by name.
  const int64_t sizes[3] = {t.layout_.count, 6 * int64_t(t.scene_->train.size()), 2};
  int k = 0;
  for (const AdamGroup& g : s.groups()) {
    g.value = c.floats(g.name, ck, sizes[k]);
    g.m = c.floats(std::string(g.name) + ".m", ck, sizes[k]);
    g.v = c.floats(std::string(g.name) + ".v", ck, sizes[k]);
    ++k;
  }
  // The focal the run started from (--focal-guard); a checkpoint from before the guard has none,
  // and its guard then starts from the focal the checkpoint holds.
  s.focal_start = j.contains("focal_start") ? j["focal_start"].get<std::array<float, 2>>()
                                            : std::array<float, 2>{s.focal[0], s.focal[1]};
  if (!t.cfg_.init_poses.empty())
    s.poses_P0 = c.floats("poses.P0", ck, 12 * int64_t(t.scene_->train.size()));
  if (t.cfg_.pose_precondition > 0) {  // made from the starting cameras: kept, not remade
    const int64_t D = 6 * int64_t(t.scene_->train.size()) + t.preconditioned_focal_params();
    s.cameras_P = c.floats("cameras.P", ck, D * D);
  }
  t.setup_buffers();
  return t;
}

Trainer Trainer::resume(const std::string& run, double minutes_override,
                        const std::string& data_override) {
  Trainer t = open(run, minutes_override, data_override);
  const int64_t step = t.st_.step;
  // Keep the log consistent with the checkpoint: drop rows after its step.
  std::string log_path = run + "/log.csv", kept;
  std::ifstream in(log_path);
  std::string line;
  bool header = true;
  while (std::getline(in, line)) {
    if (header) { kept += line + "\n"; header = false; continue; }
    auto comma = line.find(',');
    if (comma == std::string::npos) continue;
    try {
      if (std::stoll(line.substr(0, comma)) <= step) kept += line + "\n";
    } catch (...) {
    }
  }
  if (kept.empty()) kept = "step,seconds,loss,psnr,psnr_cc,lr_net,lr_pose,lr_focal,fx,fy\n";
  write_file_atomic(log_path, kept);
  return t;
}

void Trainer::save_checkpoint_now() {
  if (cfg_.out.empty()) return;
  // Written straight from the state (CheckpointView): no copy of the tables and moments.
  CheckpointView c;
  json j = {{"step", st_.step}, {"planned_steps", st_.planned_steps},
            {"plan_refined", st_.plan_refined}, {"elapsed", st_.elapsed},
            {"lr_scale", st_.lr_scale}, {"diverged", st_.diverged},
            {"psnr_ema", st_.psnr_ema}, {"camera_start", st_.camera_start},
            {"focal_guarded", st_.focal_guarded}, {"focal_start", st_.focal_start}};
  const std::string state = j.dump(), config = train_config_json(cfg_);
  c.put_text("state", state);
  c.put_text("config", config);
  for (const AdamGroup& g : st_.groups()) {
    c.put_floats(g.name, g.value);
    c.put_floats(std::string(g.name) + ".m", g.m);
    c.put_floats(std::string(g.name) + ".v", g.v);
  }
  if (!st_.poses_P0.empty()) c.put_floats("poses.P0", st_.poses_P0);
  if (!st_.cameras_P.empty()) c.put_floats("cameras.P", st_.cameras_P);
  save_checkpoint(cfg_.out + "/checkpoint.bin", c);
}

PoseParams<float> Trainer::pose_of(int i) const {
  PoseParams<float> p;
  const float* v = st_.poses.data() + 6 * i;
  p.r = Vec3<float>(v[0], v[1], v[2]);
  p.t = Vec3<float>(v[3], v[4], v[5]);
  if (!st_.poses_P0.empty()) {
    p.has_P0 = true;
    const float* q = st_.poses_P0.data() + 12 * i;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) p.P0(r, c) = q[4 * r + c];
  }
  return p;
}

FocalParams<float> Trainer::focal() const {
  FocalParams<float> f;
  f.a = st_.focal[0];
  f.b = st_.focal[1];
  f.fx_only = cfg_.fx_only;
  return f;
}

// The focal_start the box is drawn with is saved in the checkpoint (state "focal_start"), so a
// resumed run, and eval/render of a finished one, warp rays exactly as its training did.
NdcWarp Trainer::ndc_warp() const {
  if (!cfg_.ndc) return false;
  if (!cfg_.ndc_fixed_focal) return true;
  const FocalParams<double> s{double(st_.focal_start[0]), double(st_.focal_start[1]), cfg_.fx_only};
  const double k = cfg_.ndc_box_scale;  // 1, or --ndc-box-scale: a box wider (< 1) than the start's
  return NdcWarp(k * focal_fx(s, image_size()), k * focal_fy(s, image_size()));
}

int64_t Trainer::steps_per_epoch() const {
  const int64_t n = int64_t(scene_->train.size()), K = cfg_.images_per_step;
  return (n + K - 1) / K;
}

int64_t Trainer::planned_total() const {
  if (st_.planned_steps > 0) return st_.planned_steps;
  const int64_t n = steps_per_epoch();  // = n_train with one image per step
  if (cfg_.steps > 0) return cfg_.steps;
  if (cfg_.epochs > 0) return cfg_.epochs * n;
  if (cfg_.minutes > 0) return int64_t(1) << 40;  // until planned after the first steps
  return 10000 * n;                                // formulas.md §6: the paper's 10,000 epochs
}

double Trainer::lr_net_at(int64_t s) const {
  return exp_decay_lr(cfg_.lr_net, cfg_.lr_net_end, std::min(s, planned_total()), planned_total());
}
// Cameras learn from a start step on (0 by default): with --camera-delay f it is ⌊f · total⌋,
// with --camera-start-psnr the step after the running train PSNR first reached the threshold.
// Before it their lr is exactly 0; from it the same exponential decay runs compressed into
// [start, total] (still ending at formulas.md §6's values); --camera-warmup N scales the first N steps
// of it by 1/N, 2/N, …, N/N (a linear ramp from the frozen 0).
// Train PSNR of a step's mean squared error (dB; an exact fit reads 120 dB, not infinity).
static double psnr_db(double mse) { return -10.0 * std::log10(std::max(mse, 1e-12)); }

static double camera_lr(double lr0, double lr_end, int64_t s, int64_t total, int64_t start,
                        int64_t warmup) {
  if (start < 0 || s < start) return 0.0;
  double lr = exp_decay_lr(lr0, lr_end, std::min(s, total) - start, std::max<int64_t>(1, total - start));
  if (s - start < warmup) lr *= double(s - start + 1) / double(warmup);
  return lr;
}
int64_t Trainer::camera_start_step() const {
  if (cfg_.camera_start_psnr > 0) return st_.camera_start;
  return int64_t(cfg_.camera_delay * double(planned_total()));
}
double Trainer::lr_pose_at(int64_t s) const {
  return camera_lr(cfg_.lr_pose, cfg_.lr_pose_end, s, planned_total(), camera_start_step(),
                   cfg_.camera_warmup);
}
// --focal-delay f: the focal starts at ⌊f · total⌋ at the earliest, the poses do not wait.
double Trainer::lr_focal_at(int64_t s) const {
  int64_t start = camera_start_step();
  if (start >= 0 && cfg_.focal_delay > 0)
    start = std::max(start, int64_t(cfg_.focal_delay * double(planned_total())));
  return camera_lr(cfg_.lr_focal, cfg_.lr_focal_end, s, planned_total(), start,
                   cfg_.camera_warmup);
}

int Trainer::pyramid_level_at(int64_t step) const {
  return pyramid_level(step, planned_total(), cfg_.pyramid);
}

void Trainer::images_for_step(int64_t step, int* out) const {
  // formulas.md §6: each epoch visits every training image once, in a shuffled order. With K images
  // a step, step j of an epoch takes positions jK … jK + K − 1 of the epoch's permutation,
  // modulo n: an epoch is ⌈n/K⌉ steps, and its last step, when K does not divide n, wraps
  // around to the permutation's first images. The K positions are distinct modulo n (K ≤ n),
  // so a step never sees an image twice. K = 1: step s takes position s mod n of epoch s / n.
  const int n = int(scene_->train.size()), K = cfg_.images_per_step;
  const int64_t spe = steps_per_epoch(), epoch = step / spe;
  std::vector<int>& perm = perm_;  // member: no allocation per step
  perm.resize(n);
  for (int i = 0; i < n; ++i) perm[i] = i;
  Rng rng(cfg_.seed, 0x100000000ULL + uint64_t(epoch));
  for (int i = n - 1; i > 0; --i) std::swap(perm[i], perm[rng.below(uint32_t(i + 1))]);
  const int first = int(step % spe) * K;
  for (int j = 0; j < K; ++j) out[j] = perm[(first + j) % n];
}

StepResult<float> Trainer::step_once() {
  const int K = cfg_.images_per_step, S = cfg_.samples;
  const int H = scene_->height, W = scene_->width;
  StageClock clk(prof_, kStageRays);
  images_for_step(st_.step, step_images_.data());
  // --pyramid: at level s rows and columns come from the lattice {0, s, 2s, …} (train/pyramid.h:
  // full-resolution pixel coordinates, so the camera is untouched). Should the lattice be
  // smaller than the grid (tiny images at level 4), the step uses the whole lattice: fewer
  // rays, and the loss is the mean over the rays used.
  const int lvl = pyramid_level_at(st_.step);
  const int lat_h = (H + lvl - 1) / lvl, lat_w = (W + lvl - 1) / lvl;
  const int rows = std::min(cfg_.step_rows(), lat_h), cols = std::min(cfg_.step_cols(), lat_w);
  const int Rk = rows * cols, R = K * Rk;  // rays per image, per step (image j: [j·Rk, (j+1)·Rk))
  last_R_ = R;

  // 1. per image, a rows × cols grid of distinct random rows and columns (partial Fisher–Yates),
  //    drawn image after image from one stream, then the jitter (K = 1: the paper's order).
  Rng rng(cfg_.seed ^ 0x9E3779B97F4A7C15ULL, uint64_t(st_.step));
  for (int j = 0; j < K; ++j) {
    const int i = step_images_[j];
    const ImageU8& img = scene_->images[scene_->train[i]];
    const PyramidLevel* level = lvl == 4 ? &pyr4_[i] : lvl == 2 ? &pyr2_[i] : nullptr;
    pick_distinct(rng, rsel_, lat_h, rows);  // rsel_, csel_: members, reused across steps
    pick_distinct(rng, csel_, lat_w, cols);
    const std::vector<int>& rsel = rsel_;
    const std::vector<int>& csel = csel_;
    for (int a = 0; a < rows; ++a)
      for (int b = 0; b < cols; ++b) {
        int k = j * Rk + a * cols + b;
        px_[2 * k] = lvl * csel[b];      // u = column (full-resolution pixel)
        px_[2 * k + 1] = lvl * rsel[a];  // v = row
        for (int c = 0; c < 3; ++c)
          target_[3 * k + c] = level ? level->at(rsel[a], csel[b], c) : img.at(rsel[a], csel[b], c);
      }
  }
  // 2. jittered samples (formulas.md §3).
  jitter_samples(rng, s_.data(), R, S);
  // Coarse-to-fine position encoding (off by default), α rising linearly over --c2f of the run:
  // Fourier bands 0 → L; grid levels c2f_start → L (the coarsest levels are on from the start).
  if (cfg_.c2f_end > 0) {
    const double progress =
        std::min(1.0, double(st_.step) / (cfg_.c2f_end * double(planned_total())));
    if (cfg_.model.field == Field::grid) {
      const double L = cfg_.model.gf.grid.levels, a0 = std::min(cfg_.model.gf.c2f_start, L);
      cfg_.model.pos_c2f_alpha = a0 + (L - a0) * progress;
    } else {
      cfg_.model.pos_c2f_alpha = cfg_.model.pos_bands * progress;
    }
  }
  clk.stop();  // camera_step times its own stages
  // 3. the camera, the model, the loss (the mean over all R rays, whichever image they came
  //    from) and every gradient.
  for (int j = 0; j < K; ++j) step_poses_[j] = pose_of(step_images_[j]);
  CameraBatch<float> batch;
  batch.px = px_.data();
  batch.target = target_.data();
  batch.s = s_.data();
  batch.R = R;
  batch.S = S;
  batch.poses = step_poses_.data();
  batch.views = K;
  batch.focal = focal();
  batch.size = image_size();
  batch.ndc = ndc_warp();
  batch.occupancy = occupancy_for_step();
  StepOptions opt;
  opt.chunk_rays = cfg_.chunk_rays;
  opt.stop_cc_to_camera = cfg_.stop_cc_to_camera;
  opt.distortion = distortion_at(st_.step);
  opt.distortion_to_camera = cfg_.distortion_to_camera;
  opt.need_ray_grads = !cameras_held_at(st_.step);
  std::fill(d_net_.begin(), d_net_.end(), 0.f);
  opt.d_params_zero = true;  // just zeroed: the step needs no gradient arena for its first thread
  const StepResult<float> res =
      camera_step(ws_, NetView<float>{st_.net.data(), cfg_.model, layout_}, batch, opt, grads_);
  // 4. guard + Adam.
  apply_update(res, grads_);
  return res;
}

// --occupancy on: uniform samples for the first occupancy_start of the run, then the grid, one
// eighth of its cells re-measured every occupancy_every steps (render/occupancy.h). The first
// step that uses it measures every cell.
const OccupancyGrid* Trainer::occupancy_for_step() {
  if (!cfg_.occupancy) return nullptr;
  if (double(st_.step) < cfg_.occupancy_start * double(planned_total())) return nullptr;
  const uint64_t seed = cfg_.seed ^ (0xA5A5A5A5ULL + uint64_t(st_.step));
  if (!occ_) measure_occupancy(seed);
  else if (st_.step % cfg_.occupancy_every == 0) occ_->update(density_fn(), seed);
  return &*occ_;
}

DensityFn Trainer::density_fn() const {
  return [this](const float* x, int64_t n, float* sigma) {
    model_density(occ_cache_, net(), x, n, sigma);
  };
}

void Trainer::measure_occupancy(uint64_t seed) const {
  OccupancyOptions o;
  o.res = cfg_.occupancy_res;
  o.probes = cfg_.occupancy_probes;
  occ_.emplace(o);
  occ_->update_all(density_fn(), seed);
}

const OccupancyGrid* Trainer::render_occupancy() const {
  if (!cfg_.occupancy) return nullptr;
  if (!occ_) measure_occupancy(cfg_.seed ^ 0x5A5A5A5AULL);
  return &*occ_;
}

// One step's update, by concern: the poses' gradient scattered to its cameras, the divergence
// guard, the grid's decay, Adam on the groups that learn, then the running PSNR and what it
// triggers. False when the guard restored an earlier state instead.
bool Trainer::apply_update(const StepResult<float>& r, const CameraStepGrads<float>& g) {
  scatter_pose_grads(g);
  const bool held = cameras_held_at(st_.step);
  const GroupStep steps[3] = {{g.d_params, lr_net_at(st_.step) * st_.lr_scale, true},
                              {d_poses_.data(), lr_pose_at(st_.step), !poses_frozen() && !held},
                              {g.d_focal, lr_focal_at(st_.step),
                               !focal_frozen() && !held && st_.focal_guarded < 0}};
  if (const char* what = bad_step(r, steps)) {
    restore_good_state(what);
    return false;
  }
  // --grid-decay: its gradient joins the table's data gradient (the loss logged stays the
  // data's). After the guard, which must see the data gradient alone: an empty field's is all 0.
  if (cfg_.grid_decay > 0)
    hashgrid_decay(d_net_.data() + layout_.grid_table, st_.net.data() + layout_.grid_table,
                   cfg_.model.gf.grid, cfg_.grid_decay);
  adam_on_groups(steps, g.d_focal);
  if (steps[2].learns) guard_focal();
  track_psnr(r);
  ++st_.step;
  if (st_.step % 100 == 0) good_ = st_;
  return true;
}

// Poses: one Adam group over every training camera, as NeRF-- does (a camera not in this step
// has a zero gradient; its moments still decay and move it, PyTorch semantics).
void Trainer::scatter_pose_grads(const CameraStepGrads<float>& g) {
  const int K = cfg_.images_per_step;
  d_poses_.assign(st_.poses.size(), 0.f);  // member: same size every step, no allocation
  for (int j = 0; j < K; ++j)  // the K images are distinct: plain copies
    std::copy(g.d_pose.begin() + 6 * j, g.d_pose.begin() + 6 * (j + 1),
              d_poses_.begin() + 6 * step_images_[j]);
}

// What is wrong with this step, or nullptr: a non-finite loss or gradient, or an empty field.
// σ = relu(σ_raw): once a step pushes σ_raw below 0 at every sample, every compositing weight is
// 0, the render is black, and every network gradient is exactly 0 (the relu passes none, the
// colours have no weight), so no later step can bring the density back (seen on fern with
// --c2f 0.5: docs/results/laptop/README.md). A positive loss with an all-zero network gradient
// is exactly that state.
const char* Trainer::bad_step(const StepResult<float>& r, const GroupStep* steps) {
  bool ok = std::isfinite(r.loss);
  int k = 0;
  for (const AdamGroup& group : st_.groups()) {
    const float* grad = steps[k++].grad;
    ok = ok && all_finite(grad, int64_t(group.value.size()));
  }
  if (!ok) return "non-finite loss or gradient";
  if (r.loss > 0 && std::all_of(d_net_.begin(), d_net_.end(), [](float v) { return v == 0.f; }))
    return "empty field (density 0 at every sample, no gradient)";
  return nullptr;
}

// Divergence guard: nothing non-finite reaches the parameters, and an empty field does not train
// on. Restore the last good state, halve the networks' learning rate, and carry on (a few times
// at most).
void Trainer::restore_good_state(const char* what) {
  int diverged = st_.diverged + 1;
  double scale = st_.lr_scale * 0.5;
  int64_t step = st_.step;
  double elapsed = st_.elapsed;
  fmt::print(stderr, "\nhashcc: {} at step {}: restored the state of step {}, networks' "
                     "lr ×{:.3g}\n", what, step, good_.step, scale);
  // The --minutes plan is about the clock, not the parameters: keep it (good_ may predate
  // it: restoring planned_steps = 0 would leave the run unplanned), and let run() refine it
  // once more, since the steps spent since good_ now have to be made again.
  const int64_t planned = st_.planned_steps;
  st_ = good_;
  st_.diverged = diverged;
  st_.lr_scale = scale;
  st_.elapsed = elapsed;
  st_.planned_steps = planned;
  st_.plan_refined = false;
  HCC_REQUIRE(diverged <= 5, "training", "", "diverged {} times (the last: {}); giving up "
              "at step {}. Try a lower --lr-net or another --seed", diverged, what, step);
}

// Adam on each group that learns; --refine-poses off (or held cameras): the cameras are given,
// not learned (no update, moments 0). --pose-precondition: poses and focal in one step through P.
void Trainer::adam_on_groups(const GroupStep* steps, const float* d_focal) {
  const int64_t t = st_.step + 1;  // Adam's bias-correction count
  StageClock clk(prof_, kStageAdam);
  int k = 0;
  for (const AdamGroup& group : st_.groups()) {
    const GroupStep& s = steps[k++];
    if (!s.learns) continue;
    if (!st_.cameras_P.empty() && &group.value == &st_.poses) {  // poses and focal together
      preconditioned_camera_step(d_poses_.data(), d_focal, s.lr,
                                 steps[2].learns ? steps[2].lr : 0.0, t);
      break;
    }
    adam_step(group.value.data(), s.grad, group.m.data(), group.v.data(),
              int64_t(group.value.size()), s.lr, t);
  }
}

// --focal-guard G: the focal must stay within a factor G of where it started, and fx/fy within
// √G of its starting ratio. A focal outside is not a camera any photo was taken with: it is the
// field and the poses pulling the focal along a weak direction (the zoom/depth ambiguity of a
// forward-facing capture; on LLFF horns fy fell from 378 to ~155 px while fx held). The guard
// puts the focal back where it started, clears its Adam moments (their history points the way it
// fell) and holds it for the rest of the run; in a plan, the next stage learns it again from
// there. Checked after every update that moves the focal, so it costs two comparisons a step.
void Trainer::guard_focal() {
  if (cfg_.focal_guard <= 0 || st_.focal_guarded >= 0) return;
  const ImageSize sz = image_size();
  const FocalParams<float> now = focal();
  FocalParams<float> start = now;
  start.a = st_.focal_start[0];
  start.b = st_.focal_start[1];
  const double fx = focal_fx(now, sz), fy = focal_fy(now, sz);
  const double fx0 = focal_fx(start, sz), fy0 = focal_fy(start, sz);
  const double g = cfg_.focal_guard, ratio = (fx / fy) / (fx0 / fy0);
  const auto inside = [](double x, double band) { return x >= 1 / band && x <= band; };
  if (inside(fx / fx0, g) && inside(fy / fy0, g) && inside(ratio, std::sqrt(g))) return;
  fmt::print(stderr, "\nhashcc: focal guard at step {}: fx {:.1f} fy {:.1f} px left the band of "
                     "its start (fx {:.1f} fy {:.1f}, x{:g} each, fx/fy x{:.3g}); put back to the "
                     "start and held for the rest of this run\n", st_.step, fx, fy, fx0, fy0, g,
             std::sqrt(g));
  st_.focal = {st_.focal_start[0], st_.focal_start[1]};
  std::fill(st_.focal_m.begin(), st_.focal_m.end(), 0.f);
  std::fill(st_.focal_v.begin(), st_.focal_v.end(), 0.f);
  st_.focal_guarded = st_.step;
}

// The running train PSNR (of p̃, as logged), tracked in every run; --camera-start-psnr lets the
// cameras learn from the step after it first reaches the threshold. It is state (in the
// checkpoint), so a resumed run triggers at the same step.
void Trainer::track_psnr(const StepResult<float>& r) {
  const double psnr = psnr_db(r.mse);
  st_.psnr_ema = st_.step == 0 ? psnr : kPsnrEma * st_.psnr_ema + (1 - kPsnrEma) * psnr;
  if (cfg_.camera_start_psnr > 0 && st_.camera_start < 0 && st_.psnr_ema >= cfg_.camera_start_psnr)
    st_.camera_start = st_.step + 1;
}

void Trainer::write_cameras_json() const {
  if (cfg_.out.empty()) return;
  // transforms.json convention (instant-ngp, nerfstudio): OpenGL camera-to-world matrices.
  const FocalParams<float> f = focal();
  const ImageSize sz = image_size();
  json frames = json::array();
  for (size_t i = 0; i < scene_->train.size(); ++i) {
    // [Exp(r)|t]·P0 (camera/README.md)
    const Mat34<double> c2w = world_from_camera(pose_of(int(i)).cast<double>());
    json m = json::array();
    for (int r = 0; r < 3; ++r)
      m.push_back({c2w(r, 0), c2w(r, 1), c2w(r, 2), c2w(r, 3)});
    m.push_back({0, 0, 0, 1});
    std::string rel = fs::relative(scene_->image_dir, cfg_.data).string();
    if (rel == ".") rel = "";
    frames.push_back({{"file_path", (rel.empty() ? "" : rel + "/") + scene_->names[scene_->train[i]]},
                      {"transform_matrix", m}});
  }
  json j = {{"camera_model", "PINHOLE"},
            {"fl_x", double(focal_fx(f, sz))}, {"fl_y", double(focal_fy(f, sz))},
            {"cx", sz.W / 2.0}, {"cy", sz.H / 2.0}, {"w", sz.W}, {"h", sz.H},
            {"ndc", cfg_.ndc}, {"frames", frames}};
  write_file_atomic(cfg_.out + "/cameras.json", j.dump(2) + "\n");
}

void Trainer::write_preview(const std::string& path) {
  // A training view at ≤ ~16k pixels: previews must not stall training.
  const ImageSize sz = image_size();
  int stride = 1;
  while (int64_t(sz.W / stride) * (sz.H / stride) > 16384) ++stride;
  // The training grid when it exists (making one here would tie the run to the preview's clock).
  ViewImage v = render_view(ws_.rays, net(), view_camera(pose_of(0)),
                            {cfg_.samples, stride, cfg_.chunk_rays, occ_ ? &*occ_ : nullptr});
  // Side by side: render | ground truth (same stride).
  const ImageU8& gt = scene_->images[scene_->train[0]];
  std::vector<float> sheet(size_t(v.width) * 2 * v.height * 3);
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x)
      for (int c = 0; c < 3; ++c) {
        sheet[(size_t(y) * 2 * v.width + x) * 3 + c] = v.rgb[(size_t(y) * v.width + x) * 3 + c];
        sheet[(size_t(y) * 2 * v.width + v.width + x) * 3 + c] = gt.at(y * stride, x * stride, c);
      }
  write_png_float(path, sheet.data(), 2 * v.width, v.height);
}

// One line of RUN/log.csv for the step just made, and the progress bar's text.
static void report_step(const Trainer& t, const StepResult<float>& r, std::ofstream& log,
                        ProgressBar& bar) {
  const TrainState& st = t.state();
  const TrainConfig& cfg = t.config();
  const double psnr = psnr_db(r.mse), psnr_cc = psnr_db(r.mse_cc);
  const FocalParams<float> f = t.focal();
  const double fx = focal_fx(f, t.image_size()), fy = focal_fy(f, t.image_size());
  if (log.is_open())
    log << fmt::format("{},{:.3f},{:.6g},{:.4f},{:.4f},{:.4g},{:.4g},{:.4g},{:.3f},{:.3f}\n",
                       st.step, st.elapsed, r.loss, psnr, psnr_cc,
                       t.lr_net_at(st.step) * st.lr_scale, t.lr_pose_at(st.step),
                       t.lr_focal_at(st.step), fx, fy)
        << std::flush;  // a whole line per step: a watcher (tail -f, a test) sees step k as it ends
  // The options beyond the paper show their state: the pyramid level the NEXT step trains
  // on (its switches), and whether the cameras still wait for --camera-start-psnr.
  std::string extra;
  if (cfg.pyramid > 0) extra += fmt::format(" level {}", t.pyramid_level_at(st.step));
  if (cfg.camera_start_psnr > 0 && st.camera_start < 0)
    extra += fmt::format(" cameras wait (psnr avg {:.2f} < {:.2f})", st.psnr_ema,
                         cfg.camera_start_psnr);
  bar.update(st.step, fmt::format("epoch {} loss {:.4f} psnr {:.2f}{} fx {:.1f}{}",
                                  st.step / t.steps_per_epoch(), r.loss, psnr,
                                  cfg.model.has_cc() ? fmt::format(" cc {:.2f}", psnr_cc) : "",
                                  fx, extra));
}

// Every --checkpoint-minutes a checkpoint (nothing lost on a crash), every --preview-minutes
// RUN/preview.png; `now` and the last times are the session's seconds.
// (RUN/log.csv needs no flush here: report_step flushes every line.)
static void save_periodically(Trainer& t, double now, double& last_ckpt, double& last_preview) {
  const TrainConfig& cfg = t.config();
  if (now - last_ckpt >= cfg.checkpoint_minutes * 60) {
    t.save_checkpoint_now();
    last_ckpt = now;
  }
  if (!cfg.out.empty() && now - last_preview >= cfg.preview_minutes * 60) {
    t.write_preview(cfg.out + "/preview.png");
    last_preview = now;
  }
}

bool Trainer::run(const std::atomic<bool>* stop,
                  const std::function<void(const Trainer&)>& after_step) {
  Timer session;
  const double budget = cfg_.minutes > 0 ? cfg_.minutes * 60.0 : 1e300;
  const double elapsed0 = st_.elapsed;
  double last_ckpt = 0, last_preview = 0;
  std::ofstream log;
  if (!cfg_.out.empty()) log.open(cfg_.out + "/log.csv", std::ios::app);
  ProgressBar bar("train", cfg_.minutes > 0 && st_.planned_steps == 0 ? 0 : planned_total(),
                  cfg_.progress);
  int64_t session_steps = 0;
  // --minutes: the steps that fit the budget, planned and refined as the run goes.
  std::optional<MinutesPlanner> planner;
  if (cfg_.minutes > 0) planner.emplace(budget, [&session] { return session.seconds(); });
  bool interrupted = false;
  for (;;) {
    if (st_.step >= planned_total()) {
      if (!(planner && planner->extend(st_, session_steps))) break;
      bar.set_total(st_.planned_steps);
    }
    if (stop && stop->load()) { interrupted = true; break; }
    if (st_.elapsed >= budget) break;
    StepResult<float> r = step_once();
    ++session_steps;
    st_.elapsed = elapsed0 + session.seconds();
    if (planner && planner->after_step(st_, session_steps)) bar.set_total(st_.planned_steps);
    report_step(*this, r, log, bar);
    if (after_step) after_step(*this);
    save_periodically(*this, session.seconds(), last_ckpt, last_preview);
  }
  bar.finish();
  save_checkpoint_now();
  write_cameras_json();
  if (!cfg_.out.empty()) write_preview(cfg_.out + "/preview.png");
  return !interrupted;
}

}  // namespace hashcc
