// eval/evaluate.cpp — the evaluation pipeline (see evaluate.h and docs/evaluation.md).
#include "eval/evaluate.h"

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <filesystem>
#include <memory>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fileio.h"
#include "core/image.h"
#include "core/parallel.h"
#include "core/progress.h"
#include "eval/lpips.h"
#include "kernels/adam.h"
#include "model/render_view.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace hashcc {

namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;


// NeRF--'s pts_dist_max: the largest distance of a centre from the first one.
double max_distance_from_first(const std::vector<Pose34>& poses) {
  double m = 0;
  for (const auto& p : poses) m = std::max(m, (p.col(3) - poses[0].col(3)).norm());
  return m;
}

std::string file_stem(const std::string& name) { return fs::path(name).stem().string(); }

ImageF to_float(const ImageU8& im) {
  ImageF f(im.height, im.width);
  for (size_t i = 0; i < im.rgb.size(); ++i) f.rgb[i] = im.rgb[i] * (1.0f / 255.0f);
  return f;
}

// Metrics are defined on [0,1] RGB (formulas.md §7); the corrected colour c + Δc is not bounded by a
// sigmoid, so renders are clamped (exactly what the written PNG shows).
ImageF clamp_render(const ViewImage& v) {
  ImageF f(v.height, v.width);
  for (size_t i = 0; i < v.rgb.size(); ++i) f.rgb[i] = std::clamp(v.rgb[i], 0.0f, 1.0f);
  return f;
}

json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
json opt_num(const std::optional<double>& v) { return v ? num(*v) : json(nullptr); }

}  // namespace

TestInit parse_test_init(const std::string& s) {
  if (s == "scale") return TestInit::kScale;
  if (s == "sim3") return TestInit::kSim3;
  if (s == "rig") return TestInit::kRig;
  throw Error("--test-init", "", fmt::format("'{}'", s), "scale, sim3 or rig");
}

const char* test_init_name(TestInit t) {
  return t == TestInit::kSim3 ? "sim3" : t == TestInit::kRig ? "rig" : "scale";
}

std::vector<Pose34> learned_train_c2w(const Trainer& tr) {
  // pose_of composes the learned delta with the image's fixed initial pose P0 (--init-poses):
  // c2w = [Exp(r) | t] · P0 (camera/README.md).
  std::vector<Pose34> out;
  for (size_t i = 0; i < tr.scene().train.size(); ++i) {
    out.push_back(world_from_camera(tr.pose_of(int(i)).cast<double>()));
  }
  return out;
}

std::vector<Pose34> reference_c2w(const Scene& sc, const std::vector<int>& images) {
  std::vector<Pose34> out;
  for (int i : images) out.push_back(sc.ref_c2w.at(size_t(i)));
  return out;
}

TrainPoseReport train_pose_report(const Trainer& tr) {
  TrainPoseReport r;
  const Scene& sc = tr.scene();
  const FocalParams<float> f = tr.focal();
  r.fx = focal_fx(f, tr.image_size());
  r.fy = focal_fy(f, tr.image_size());
  r.has_reference = sc.has_reference;
  if (!sc.has_reference) {
    r.note = "no reference cameras (no poses_bounds.npy): pose error not computed";
    return r;
  }
  r.ref_focal = sc.ref_focal;
  const std::vector<Pose34> learned = learned_train_c2w(tr), ref = reference_c2w(sc, sc.train);
  std::vector<std::string> notes;
  try {
    r.sim3 = align_and_score(learned, ref);
  } catch (const Error& e) {
    notes.push_back("Sim(3) pose error not computed: " + e.problem);
  }
  try {
    r.rig = align_and_score(learned, ref, Alignment::kRotations);
  } catch (const Error& e) {
    notes.push_back("rotation-aligned pose error not computed: " + e.problem);
  }
  try {
    r.relative = relative_rotation_error(learned, ref);
  } catch (const Error& e) {
    notes.push_back("relative rotation error not computed: " + e.problem);
  }
  for (size_t i = 0; i < notes.size(); ++i) r.note += (i ? "; " : "") + notes[i];
  return r;
}

double learned_to_reference_distance_ratio(const Trainer& tr) {
  const Scene& sc = tr.scene();
  HCC_REQUIRE(sc.has_reference, sc.dir, "", "no reference cameras (poses_bounds.npy)");
  const double ref = max_distance_from_first(reference_c2w(sc, sc.train));
  HCC_REQUIRE(ref > 0, sc.dir + "/poses_bounds.npy", "", "all reference training cameras share one "
              "centre: the translation scale of formulas.md §7 is undefined");
  return max_distance_from_first(learned_train_c2w(tr)) / ref;
}

std::vector<PoseParams<float>> test_pose_params(const Trainer& tr, TestInit mode, const Sim3* sim) {
  std::vector<PoseParams<float>> init;
  for (const Pose34& P0 : test_pose_init(tr, mode, sim)) {
    PoseParams<float> q;
    q.has_P0 = true;
    q.P0 = P0.cast<float>();
    init.push_back(q);
  }
  return init;
}

std::vector<Pose34> test_pose_init(const Trainer& tr, TestInit mode, const Sim3* sim) {
  const Scene& sc = tr.scene();
  const std::vector<Pose34> ref = reference_c2w(sc, sc.test);
  std::vector<Pose34> out;
  if (mode == TestInit::kScale) {
    // formulas.md §7 / NeRF-- align_scale_c2b_use_a2b: rotation as is, centre × (learned / reference).
    const double ratio = learned_to_reference_distance_ratio(tr);
    for (Pose34 p : ref) {
      p.col(3) *= ratio;
      out.push_back(p);
    }
    return out;
  }
  HCC_ASSERT(sim != nullptr);
  // x_ref = s R_a x_learned + t_a, R_ref ≈ R_a R_learned; inverted:
  // R = R_aᵀ R_ref, c = R_aᵀ (c_ref − t_a) / s.
  for (const Pose34& p : ref) {
    Pose34 q;
    q.leftCols<3>() = sim->R.transpose() * p.leftCols<3>();
    q.col(3) = sim->R.transpose() * (p.col(3) - sim->t) / sim->s;
    out.push_back(q);
  }
  return out;
}

double refine_lr(int epoch) { return 1e-3 * std::pow(0.5, 1 + std::max(0, epoch) / 200); }

RefineResult refine_test_poses(const Trainer& tr, std::vector<PoseParams<float>> init,
                               const std::vector<int>& images, int epochs, bool progress) {
  std::vector<const ImageU8*> targets;
  for (int i : images) targets.push_back(&tr.scene().images.at(size_t(i)));
  return refine_poses(tr, std::move(init), targets, epochs, progress);
}

RefineResult refine_test_poses(const Trainer& tr, std::vector<PoseParams<float>> init,
                               const std::vector<int>& images, const RefineOptions& ro) {
  std::vector<const ImageU8*> targets;
  for (int i : images) targets.push_back(&tr.scene().images.at(size_t(i)));
  return refine_poses(tr, std::move(init), targets, ro);
}

namespace {

// One refinement step's rays and the CameraBatch that points into them: a rows × cols grid of
// each of `views` images, view k seen through poses[k] with the scene's frozen focal (rays
// [k·rows·cols, (k+1)·rows·cols) of the batch).
struct RefineBatch {
  int rows, cols, views;
  std::vector<int> px, rsel, csel;
  std::vector<float> s, target;
  std::vector<PoseParams<float>> poses;
  CameraBatch<float> batch;

  RefineBatch(const Trainer& tr, int rows_, int cols_, int views_)
      : rows(rows_), cols(cols_), views(views_), px(2 * rows * cols * views),
        s(int64_t(rows) * cols * views * tr.config().samples), target(3 * rows * cols * views),
        poses(views) {
    batch.px = px.data();
    batch.target = target.data();
    batch.s = s.data();
    batch.R = rows * cols * views;
    batch.S = tr.config().samples;
    batch.poses = poses.data();
    batch.views = views;
    batch.focal = tr.focal();  // frozen
    batch.size = tr.image_size();
    batch.ndc = tr.ndc_warp();
    batch.occupancy = tr.render_occupancy();  // --occupancy runs refine as they trained
  }
  RefineBatch(const RefineBatch&) = delete;  // batch points into this object

  // The trainer's recipe (Trainer::step_once): distinct random rows × columns of img, their
  // colours as targets, then jittered samples (jittered during refinement too); into view k's
  // segment of the batch.
  void draw(Rng& rng, const ImageU8& img, int k) {
    const int Rv = rows * cols;
    int* pxk = px.data() + 2 * int64_t(k) * Rv;
    float* tk = target.data() + 3 * int64_t(k) * Rv;
    pick_distinct(rng, rsel, img.height, rows);
    pick_distinct(rng, csel, img.width, cols);
    for (int a = 0; a < rows; ++a)
      for (int b = 0; b < cols; ++b) {
        const int q = a * cols + b;
        pxk[2 * q] = csel[b];
        pxk[2 * q + 1] = rsel[a];
        for (int c = 0; c < 3; ++c) tk[3 * q + c] = img.at(rsel[a], csel[b], c);
      }
    jitter_samples(rng, s.data() + int64_t(k) * Rv * batch.S, Rv, batch.S);
  }
};

// The test poses' [r t] deltas as one Adam group (6 per image) with its moments.
struct RefineGroup {
  std::vector<float> p, m, v, g;

  explicit RefineGroup(const std::vector<PoseParams<float>>& init)
      : p(6 * init.size()), m(p.size(), 0.f), v(p.size(), 0.f), g(p.size(), 0.f) {
    for (size_t k = 0; k < init.size(); ++k)
      for (int j = 0; j < 3; ++j) {
        p[6 * k + j] = init[k].r[j];
        p[6 * k + 3 + j] = init[k].t[j];
      }
  }
  // Image k's pose: its P0 from base, its deltas from the group.
  PoseParams<float> pose(const PoseParams<float>& base, int k) const {
    return pose_from(p, base, k);
  }
  static PoseParams<float> pose_from(const std::vector<float>& p, const PoseParams<float>& base,
                                     int k) {
    PoseParams<float> q = base;
    q.r = Vec3<float>(p[6 * k], p[6 * k + 1], p[6 * k + 2]);
    q.t = Vec3<float>(p[6 * k + 3], p[6 * k + 4], p[6 * k + 5]);
    return q;
  }
  // One Adam step with image k's gradient d_pose (6) and zeros elsewhere, as NeRF--'s eval (one
  // LearnPose, PyTorch semantics: the other images get a zero gradient and their moments still
  // decay). A non-finite loss or gradient makes it a zero-gradient step.
  void step(int k, const float* d_pose, double loss, double lr, int64_t t) {
    bool finite = std::isfinite(loss);
    for (int j = 0; j < 6; ++j) finite = finite && std::isfinite(d_pose[j]);
    std::fill(g.begin(), g.end(), 0.f);
    if (finite) std::copy(d_pose, d_pose + 6, g.begin() + 6 * k);
    adam_step(p.data(), g.data(), m.data(), v.data(), int64_t(p.size()), lr, t);
  }
  // The poses each image will have when its own step of this epoch comes (global steps
  // t0 + 1 … t0 + n, image k's gradient at t0 + 1 + k): image k's deltas after the k steps
  // before its own, in which its gradient is zero. adam_step is elementwise (each value's update
  // reads only its own p, g, m, v), so replaying those steps on a copy with every gradient zero
  // gives image k's values bit for bit; the other images' values of the copy are not used.
  std::vector<float> poses_at_own_step(double lr, int64_t t0, int n) const {
    std::vector<float> cp = p, cm = m, cv = v, zero(p.size(), 0.f), out(p.size());
    for (int k = 0; k < n; ++k) {
      std::copy(cp.begin() + 6 * k, cp.begin() + 6 * k + 6, out.begin() + 6 * k);
      if (k + 1 < n) adam_step(cp.data(), zero.data(), cm.data(), cv.data(), int64_t(cp.size()), lr, t0 + 1 + k);
    }
    return out;
  }
};

// --refine-rays n as a rows × columns grid of exactly n rays: rows = the largest divisor of n
// not above √n (128 → 8 × 16, 1,024 → 32 × 32), so that a view's rays fill whole chunks.
int grid_rows_of(int n) {
  int r = std::max(1, int(std::sqrt(double(n))));
  while (n % r) --r;
  return r;
}
int grid_cols_of(int n) { return n / grid_rows_of(n); }

}  // namespace

WindowEstimate refine_window_estimate(const std::vector<std::vector<float>>& it, int a, int k) {
  const int E = int(it.size()), n = E - a, h = n / 2;
  auto at = [&](int e, int j) { return double(it[size_t(e)][6 * size_t(k) + size_t(j)]); };
  double mean[6], m1[6], m2[6], slope[6];
  const double xm = 0.5 * (a + E - 1);
  double sxx = 0;
  for (int e = a; e < E; ++e) sxx += (e - xm) * (e - xm);
  for (int j = 0; j < 6; ++j) {
    double s = 0, s1 = 0, s2 = 0, sxy = 0;
    for (int e = a; e < E; ++e) {
      s += at(e, j);
      (e < a + h ? s1 : s2) += at(e, j);
      sxy += (e - xm) * at(e, j);
    }
    mean[j] = s / n;
    m1[j] = h > 0 ? s1 / h : mean[j];
    m2[j] = s2 / (n - h);
    slope[j] = sxx > 0 ? sxy / sxx : 0.0;
  }
  auto dist = [](const double* u, const double* v) {
    return std::hypot(u[0] - v[0], u[1] - v[1], u[2] - v[2]) + std::hypot(u[3] - v[3], u[4] - v[4], u[5] - v[5]);
  };
  double var = 0;  // mean squared distance of the iterates from the line
  for (int e = a; e < E; ++e) {
    double pe[6], le[6];
    for (int j = 0; j < 6; ++j) {
      pe[j] = at(e, j);
      le[j] = mean[j] + slope[j] * (e - xm);
    }
    const double d = dist(pe, le);
    var += d * d;
  }
  const double jitter = std::sqrt(var / n), shift = dist(m1, m2);
  WindowEstimate w;
  w.averaged = !(shift > kTrendOverJitter * jitter);
  for (int j = 0; j < 6; ++j)
    w.p[j] = float(w.averaged ? mean[j] : mean[j] + slope[j] * (E - 1 - xm));
  return w;
}

RefineMode parse_refine_mode(const std::string& s) {
  if (s == "adam") return RefineMode::kAdam;
  if (s == "fast") return RefineMode::kFast;
  throw Error("--refine-mode", "", fmt::format("'{}'", s), "adam or fast");
}

const char* refine_mode_name(RefineMode m) { return m == RefineMode::kFast ? "fast" : "adam"; }

int fast_refine_average_from(int epochs) {
  // refine_lr halves every 200 epochs: the last two levels start at 200·(⌈epochs/200⌉ − 2).
  const int levels = (epochs + 199) / 200;
  const int from = std::max(kFastRefineFullEpochs, 200 * (levels - 2));
  return from < epochs ? from : -1;
}

RefineOptions refine_options(const Trainer& tr, const EvalOptions& opt) {
  RefineOptions ro;
  ro.epochs = opt.refine_epochs;
  ro.progress = opt.progress;
  // The spec's mode keeps one step a view, the code path of every published number; the
  // batched step agrees with it only to float rounding (test [refine]), not bit for bit.
  ro.batched = opt.refine_mode == RefineMode::kFast;
  ro.split_chunks = opt.refine_mode == RefineMode::kFast;
  // Fast mode: the run's grid while lr is at its first level (epochs 0–199: the cameras' big
  // moves), the fewer rays for the annealing after it.
  // Then the poses it returns are the mean of the iterates over the last two lr levels: with
  // fewer rays a step each camera jitters about its optimum, and the mean of that jitter is
  // nearer to it than any one iterate (Polyak–Ruppert averaging; docs/evaluation.md §3).
  if (opt.refine_mode == RefineMode::kFast) {
    ro.full_epochs = kFastRefineFullEpochs;
    ro.average_from = fast_refine_average_from(opt.refine_epochs);
  }
  const int rays = opt.refine_rays > 0 ? opt.refine_rays
                   : opt.refine_mode == RefineMode::kFast ? kFastRefineRays : 0;
  if (rays > 0) {
    ro.rows = grid_rows_of(rays);
    ro.cols = grid_cols_of(rays);
  } else {
    ro.rows = tr.config().grid_rows();
    ro.cols = tr.config().grid_cols();
  }
  return ro;
}

RefineResult refine_poses(const Trainer& tr, std::vector<PoseParams<float>> init,
                          const std::vector<const ImageU8*>& images, int epochs, bool progress) {
  RefineOptions ro;
  ro.epochs = epochs;
  ro.progress = progress;
  return refine_poses(tr, std::move(init), images, ro);
}

RefineResult refine_poses(const Trainer& tr, std::vector<PoseParams<float>> init,
                          const std::vector<const ImageU8*>& images, const RefineOptions& ro) {
  const int epochs = ro.epochs;
  HCC_REQUIRE(init.size() == images.size(), "", "refine_poses", "{} poses for {} images",
              init.size(), images.size());
  HCC_REQUIRE(epochs >= 0, "--refine-epochs", "", "{}", epochs, "0 or more");
  const TrainConfig& cfg = tr.config();
  const Scene& sc = tr.scene();
  const int H = sc.height, W = sc.width, n = int(images.size());
  const int rows = ro.rows > 0 ? ro.rows : cfg.grid_rows();
  const int cols = ro.cols > 0 ? ro.cols : cfg.grid_cols();
  HCC_REQUIRE(rows <= H && cols <= W, "--refine-rays", "",
              "a {}x{} ray grid (rows x columns) does not fit {}x{} images", rows, cols, W, H);
  for (int k = 0; k < n; ++k)
    HCC_REQUIRE(images[k]->width == W && images[k]->height == H, "", "refine_poses",
                "target {} is {}x{}, the scene {}x{}", k, images[k]->width, images[k]->height, W, H);
  HCC_REQUIRE(ro.views.empty() || int(ro.views.size()) == n, "", "refine_poses",
              "a view mask of {} for {} views", ro.views.size(), n);
  HCC_REQUIRE(ro.views.empty() || !ro.batched, "", "refine_poses",
              "a view mask needs one step a view (batched off)");
  auto refined = [&](int k) { return ro.views.empty() || ro.views[size_t(k)]; };
  const NetView<float> net{tr.state().net.data(), cfg.model, tr.layout()};  // frozen
  RefineGroup group(init);
  // One ray grid's steps: its batch, chunk and step options. The refinement runs the run's grid
  // for its first ro.full_epochs epochs (fast mode: the first lr level, where the cameras make
  // their big moves), then rows × cols.
  struct Phase {
    int Rv = 0, chunk = 0;
    bool batched = false;
    StepOptions opt;
    std::unique_ptr<RefineBatch> rb;
  };
  auto make_phase = [&](int pr, int pc) {
    Phase ph;
    ph.Rv = pr * pc;
    ph.opt.chunk_rays = cfg.chunk_rays;
    ph.opt.stop_cc_to_camera = cfg.stop_cc_to_camera;
    // The backward forms input gradients only: reading the MLPs' kept activations back beats
    // computing them again here (the same values; docs/performance.md, session 32).
    ph.opt.keep_mlp = true;
    // One step for all n views (ro.batched): each view's rays are whole chunks of the one-view
    // step's size, its loss the mean over its own rays (StepOptions::loss_rays), and Adam's
    // order is kept by poses_at_own_step, so each view's gradient is the one-view step's up to
    // float rounding (measured: losses agree to ~1e-8 relative, not bit for bit; test
    // [refine]). Otherwise (chunks that would straddle two views, or ro.batched off: the spec's
    // mode) one step a view, in order: the code of every published number.
    ph.chunk = std::min(resolve_chunk_rays(cfg.chunk_rays, cfg.model, cfg.samples), ph.Rv);
    ph.batched = ro.batched && n > 1 && ph.Rv % ph.chunk == 0;
    if (ph.batched && ro.split_chunks) {
      // Fast mode: smaller chunks when the views alone would leave a thread idle (a view's
      // rays then span several chunks; its gradient is the same sum in another order).
      while (ph.chunk % 2 == 0 && (int64_t(n) * ph.Rv / ph.chunk) < 2 * num_threads() &&
             ph.chunk > 16)
        ph.chunk /= 2;
    }
    ph.opt.chunk_rays = ph.chunk;
    if (ph.batched) ph.opt.loss_rays = ph.Rv;
    ph.rb = std::make_unique<RefineBatch>(tr, pr, pc, ph.batched ? n : 1);
    return ph;
  };
  const int full_epochs = std::min(epochs, std::max(0, ro.full_epochs));
  Phase reduced = make_phase(rows, cols);
  Phase full = full_epochs > 0 ? make_phase(cfg.grid_rows(), cfg.grid_cols()) : Phase{};
  CameraStepWorkspace<float> ws;
  CameraStepGrads<float> cg;  // d_params = nullptr: the networks are frozen
  RefineResult res;
  const int average_from = ro.average_from >= 0 && ro.average_from < epochs ? ro.average_from : -1;
  Timer timer;
  StageTimes prof;
  // HASHCC_REFINE_PROFILE=1: the step's stage times (CPU ms a step, core/profile.h) on stderr
  // at the end; the 1-thread step's chunks run on ws.rays.chunk (docs/performance.md).
  if (std::getenv("HASHCC_REFINE_PROFILE")) ws.rays.chunk.cache.prof = &prof;
  ProgressBar bar("refine", int64_t(epochs) * n, ro.progress && epochs > 0);
  int64_t t = 0, calls = 0;
  std::vector<double> view_loss(n);
  for (int e = 0; e < epochs; ++e) {
    const double lr = refine_lr(e);
    double sum = 0;
    Phase& ph = e < full_epochs ? full : reduced;
    RefineBatch& rb = *ph.rb;
    const int Rv = ph.Rv;
    if (ph.batched) {
      const std::vector<float> at = group.poses_at_own_step(lr, t, n);
      for (int k = 0; k < n; ++k) {
        Rng rng(cfg.seed ^ 0xD1B54A32D192ED03ULL, uint64_t(e) * uint64_t(n) + uint64_t(k));
        rb.draw(rng, *images[k], k);
        rb.poses[k] = RefineGroup::pose_from(at, init[k], k);
      }
      camera_step(ws, net, rb.batch, ph.opt, cg);
      ++calls;
      // Each view's loss as ray_batch_step forms it: its chunks' sums in order, over its rays.
      const int per_view = Rv / ph.chunk;
      for (int k = 0; k < n; ++k) {
        double se = 0, se_cc = 0;
        for (int c = k * per_view; c < (k + 1) * per_view; ++c) {
          se += ws.rays.sums[c].se;
          se_cc += ws.rays.sums[c].se_cc;
        }
        const double mse = se / (3.0 * Rv), mse_cc = se_cc / (3.0 * Rv);
        view_loss[k] = cfg.model.has_cc() ? mse + mse_cc : mse;
      }
      for (int k = 0; k < n; ++k) {
        group.step(k, cg.d_pose.data() + 6 * k, view_loss[k], lr, ++t);
        sum += view_loss[k];
      }
      bar.update(int64_t(e + 1) * n, fmt::format("epoch {} lr {:.3g} loss {:.4f}", e, lr, sum / n));
    } else {
      for (int k = 0; k < n; ++k) {
        if (!refined(k)) {  // its step, with a zero gradient: the others' moments decay as in a full run
          const float zero[6] = {0, 0, 0, 0, 0, 0};
          group.step(k, zero, 0.0, lr, ++t);
          continue;
        }
        Rng rng(cfg.seed ^ 0xD1B54A32D192ED03ULL, uint64_t(e) * uint64_t(n) + uint64_t(k));
        rb.draw(rng, *images[k], 0);
        rb.poses[0] = group.pose(init[k], k);
        // The trainer's step; cg.d_focal is discarded (the focal is frozen).
        const StepResult<float> sr = camera_step(ws, net, rb.batch, ph.opt, cg);
        ++calls;
        group.step(k, cg.d_pose.data(), sr.loss, lr, ++t);
        sum += sr.loss;
        bar.update(int64_t(e) * n + k + 1, fmt::format("epoch {} lr {:.3g} loss {:.4f}", e, lr, sr.loss));
      }
    }
    res.epoch_loss.push_back(sum / std::max(1, n));
    res.epoch_deltas.push_back(group.p);
  }
  bar.finish();
  res.seconds = timer.seconds();
  res.rays_per_view = reduced.Rv;
  res.full_epochs = full_epochs;
  res.batched = reduced.batched;
  if (ws.rays.chunk.cache.prof) {
    const double steps = std::max<int64_t>(1, calls);
    std::string line = fmt::format("refine profile: {} steps, {:.1f} ms/step wall;", calls,
                                   1e3 * res.seconds / steps);
    for (int st = 0; st < kStageCount; ++st)
      line += fmt::format(" {} {:.2f}", stage_name(st), prof.cpu_ms[st] / steps);
    fmt::print(stderr, "{} (cpu ms/step)\n", line);
  }
  res.average_from = average_from;
  if (average_from >= 0) {
    res.averaged.assign(size_t(n), false);
    for (int k = 0; k < n; ++k) {
      const WindowEstimate w = refine_window_estimate(res.epoch_deltas, average_from, k);
      res.averaged[size_t(k)] = w.averaged;
      std::copy(w.p, w.p + 6, group.p.begin() + 6 * k);
    }
  }
  for (int k = 0; k < n; ++k)
    if (refined(k)) init[k] = group.pose(init[k], k);
  res.poses = std::move(init);
  res.epochs = epochs;
  return res;
}

namespace {

// LPIPS: only with a complete weight folder and images VGG can take; never a made-up number
// (otherwise nullopt and the reason in res.lpips_note).
std::optional<LpipsVgg> load_lpips(const EvalOptions& opt, const Scene& sc, EvalResult& res) {
  std::optional<LpipsVgg> lpips;
  if (opt.lpips_weights.empty()) {
    res.lpips_note = "LPIPS: not computed (no weights)";
  } else {
    HCC_REQUIRE(fs::is_directory(opt.lpips_weights), "--lpips-weights", "",
                "'{}' is not a folder", opt.lpips_weights, "a folder of LPIPS-VGG .npy weights");
    if (lpips_available(opt.lpips_weights)) {
      lpips.emplace(LpipsVgg::load(opt.lpips_weights));
    } else {
      std::string missing;
      for (const auto& f : lpips_vgg_file_names())
        if (!fs::exists(fs::path(opt.lpips_weights) / f)) { missing = f; break; }
      res.lpips_note = fmt::format("LPIPS: not computed (no weights: {} lacks {})",
                                   opt.lpips_weights, missing);
    }
  }
  if (lpips && (sc.width < 16 || sc.height < 16)) {
    lpips.reset();
    res.lpips_note = fmt::format("LPIPS: not computed ({}x{} images; VGG needs 16x16)", sc.width, sc.height);
  }
  return lpips;
}

// The views to score and their cameras: the test views with refined poses when the scene has
// reference cameras (res.pose must be set), else the training views with their learned poses.
void choose_views(const Trainer& tr, const EvalOptions& opt, EvalResult& res,
                  std::vector<int>& images, std::vector<PoseParams<float>>& poses) {
  const Scene& sc = tr.scene();
  if (!sc.has_reference) {
    res.test_views = false;
    images = sc.train;
    for (int i = 0; i < int(images.size()); ++i) poses.push_back(tr.pose_of(i));
    res.mode_note = fmt::format("no reference cameras: training-view reconstruction only ({} "
                                "training views with their learned poses; no test views, no pose "
                                "error)", images.size());
    return;
  }
  images = sc.test;
  const Sim3* sim = nullptr;
  if (opt.test_init == TestInit::kSim3 || opt.test_init == TestInit::kRig) {
    const std::optional<PoseErrors>& a =
        opt.test_init == TestInit::kSim3 ? res.pose.sim3 : res.pose.rig;
    HCC_REQUIRE(a.has_value(), "--test-init", test_init_name(opt.test_init),
                "the train-camera alignment is undefined ({}); use --test-init scale",
                res.pose.note);
    sim = &a->sim;
  } else {
    res.distance_ratio = learned_to_reference_distance_ratio(tr);
  }
  const std::vector<PoseParams<float>> init = test_pose_params(tr, opt.test_init, sim);
  RefineResult rr = refine_test_poses(tr, init, images, refine_options(tr, opt));
  poses = rr.poses;
  // Fast mode: a camera still travelling over the last epochs (its trend taken) is where the
  // 128-ray steps can fall short of the spec's (docs/evaluation.md §3). Those views are refined
  // again in the spec's mode from the same start, alone (RefineOptions::views): they get the
  // spec's poses bit for bit, and a run whose test cameras settle pays nothing.
  if (opt.refine_mode == RefineMode::kFast &&
      std::count(rr.averaged.begin(), rr.averaged.end(), false) > 0) {
    EvalOptions spec = opt;
    spec.refine_mode = RefineMode::kAdam;
    spec.refine_rays = 0;
    RefineOptions ro = refine_options(tr, spec);
    ro.views.assign(rr.averaged.size(), false);
    for (size_t k = 0; k < rr.averaged.size(); ++k) ro.views[k] = !rr.averaged[k];
    const RefineResult again = refine_test_poses(tr, init, images, ro);
    for (size_t k = 0; k < poses.size(); ++k)
      if (ro.views[k]) poses[k] = again.poses[k];
    rr.seconds += again.seconds;
  }
  res.refine_mode = opt.refine_mode;
  res.refine_rays = rr.rays_per_view;
  res.refine_full_epochs = rr.full_epochs;
  res.refine_average_from = rr.average_from;
  res.refine_averaged = rr.averaged;
  res.refine_epochs = rr.epochs;
  res.refine_seconds = rr.seconds;
  res.refine_loss = rr.epoch_loss;
  res.refine_deltas = rr.epoch_deltas;
  res.mode_note = fmt::format("{} test views (every 8th image), poses refined for {} epochs "
                              "(spec: 1000) from their reference poses ({} init)",
                              images.size(), rr.epochs, test_init_name(opt.test_init));
}

// Renders scene image `index` through `pose` and scores it against the image.
EvalImage score_view(StepWorkspace<float>& ws, const Trainer& tr, int index,
                     const PoseParams<float>& pose, const std::optional<LpipsVgg>& lpips,
                     bool shortcuts) {
  const Scene& sc = tr.scene();
  const TrainConfig& cfg = tr.config();
  EvalImage ei;
  ei.scene_index = index;
  ei.name = file_stem(sc.names[size_t(index)]);
  // The test views render in chunks of at least 256 rays (forward only, one view at a time).
  const int chunk = std::max(resolve_chunk_rays(cfg.chunk_rays, tr.net().cfg, cfg.samples), 256);
  ViewOptions vo{cfg.samples, 1, chunk, tr.render_occupancy()};
  vo.shortcuts = shortcuts;  // fast mode: the render shortcuts (docs/render.md)
  ViewImage v = render_view(ws, tr.net(), tr.view_camera(pose), vo);
  ei.render = clamp_render(v);
  ei.gt = to_float(sc.images[size_t(index)]);
  ei.psnr = psnr(ei.render, ei.gt);
  ei.ssim = ssim(ei.render, ei.gt);
  if (lpips) ei.lpips = lpips->distance(ei.render, ei.gt);
  if (pose.has_P0) {
    const Mat34<float> a = world_from_camera(pose);
    ei.refine_rot_deg = so3::angle(so3::exp(Vec3<double>(pose.r.cast<double>()))) * kRadToDeg;
    ei.refine_trans = (a.col(3) - pose.P0.col(3)).cast<double>().norm();
  }
  return ei;
}

}  // namespace

EvalResult evaluate(const Trainer& tr, const EvalOptions& opt) {
  Timer timer;
  HCC_REQUIRE(opt.refine_epochs >= 0, "--refine-epochs", "", "{}", opt.refine_epochs, "0 or more");
  EvalResult res;
  res.test_init = opt.test_init;
  const std::optional<LpipsVgg> lpips = load_lpips(opt, tr.scene(), res);
  res.pose = train_pose_report(tr);
  std::vector<int> images;
  std::vector<PoseParams<float>> poses;
  choose_views(tr, opt, res, images, poses);

  StepWorkspace<float> ws;
  Timer render_timer;
  ProgressBar bar("render", int64_t(images.size()), opt.progress);
  double lp_sum = 0;
  for (size_t k = 0; k < images.size(); ++k) {
    EvalImage ei = score_view(ws, tr, images[k], poses[k], lpips,
                              opt.refine_mode == RefineMode::kFast);
    if (ei.lpips) lp_sum += *ei.lpips;
    res.psnr += ei.psnr / double(images.size());
    res.ssim += ei.ssim / double(images.size());
    res.images.push_back(std::move(ei));
    bar.update(int64_t(k) + 1, res.images.back().name);
  }
  bar.finish();
  if (lpips) res.lpips = lp_sum / double(images.size());
  res.render_seconds = render_timer.seconds();
  res.seconds = timer.seconds();
  return res;
}

std::string eval_metrics_json(const EvalResult& r) {
  const TrainPoseReport& p = r.pose;
  json per_image = json::array();
  for (size_t i = 0; i < r.images.size(); ++i) {
    const auto& im = r.images[i];
    per_image.push_back({{"name", im.name}, {"psnr", num(im.psnr)}, {"ssim", num(im.ssim)},
                         {"lpips", opt_num(im.lpips)}, {"refine_rot_deg", num(im.refine_rot_deg)},
                         {"refine_trans", num(im.refine_trans)}});
    if (i < r.refine_averaged.size())  // fast mode: the window's mean, or (still moving) the
      // spec's refinement of that view alone (choose_views)
      per_image.back()["refine_estimate"] = r.refine_averaged[i] ? "mean" : "spec";
  }
  json j;
  j["mode"] = r.test_views ? "test_views" : "train_views";
  j["note"] = r.mode_note;
  j["psnr"] = num(r.psnr);
  j["ssim"] = num(r.ssim);
  j["lpips"] = opt_num(r.lpips);
  j["lpips_note"] = r.lpips_note;
  j["rot_err_deg"] = p.sim3 ? num(p.sim3->mean_dR_deg) : json(nullptr);
  j["trans_err"] = p.sim3 ? num(p.sim3->mean_dT) : json(nullptr);
  // The same cameras aligned by their rotations (Alignment::kRotations): ΔR is then the
  // rotations' own error, and a gap to rot_err_deg means the centres tilt the Sim(3).
  j["rot_err_deg_rig"] = p.rig ? num(p.rig->mean_dR_deg) : json(nullptr);
  j["trans_err_rig"] = p.rig ? num(p.rig->mean_dT) : json(nullptr);
  j["rel_rot_err_deg"] = p.relative ? num(p.relative->mean_deg) : json(nullptr);
  j["rel_rot_do_nothing_deg"] = p.relative ? num(p.relative->do_nothing_deg) : json(nullptr);
  j["pose_note"] = p.note;
  if (p.sim3) {
    json pc = json::array();
    for (size_t i = 0; i < p.sim3->dR_deg.size(); ++i)
      pc.push_back({{"rot_err_deg", num(p.sim3->dR_deg[i])}, {"trans_err", num(p.sim3->dT[i])}});
    j["per_train_camera"] = pc;
    j["sim3_scale"] = num(p.sim3->sim.s);
  }
  j["focal"] = {{"fx", num(p.fx)}, {"fy", num(p.fy)},
                {"reference", p.has_reference ? num(p.ref_focal) : json(nullptr)}};
  j["test_init"] = r.test_views ? json(test_init_name(r.test_init)) : json(nullptr);
  j["distance_ratio"] = r.test_views && r.test_init == TestInit::kScale ? num(r.distance_ratio) : json(nullptr);
  j["refine_epochs"] = r.refine_epochs;
  j["refine_lr"] = "1e-3 * 0.5^(1 + floor(epoch / 200))";
  j["refine_mode"] = refine_mode_name(r.refine_mode);
  j["refine_rays"] = r.refine_rays;
  j["refine_full_epochs"] = r.refine_full_epochs;
  if (r.refine_average_from >= 0) j["refine_average_from"] = r.refine_average_from;
  j["refine_seconds"] = num(r.refine_seconds);
  j["render_seconds"] = num(r.render_seconds);
  j["refine_loss_first"] = r.refine_loss.empty() ? json(nullptr) : num(r.refine_loss.front());
  j["refine_loss_last"] = r.refine_loss.empty() ? json(nullptr) : num(r.refine_loss.back());
  j["seconds"] = num(r.seconds);
  j["per_image"] = per_image;
  return j.dump(2) + "\n";
}

void write_eval_outputs(const EvalResult& r, const std::string& dir) {
  for (const char* sub : {"renders", "gt", "error"}) make_dirs(dir + "/" + sub);
  for (const auto& im : r.images) {
    write_png_float(dir + "/renders/" + im.name + ".png", im.render.rgb.data(), im.render.W, im.render.H);
    write_png_float(dir + "/gt/" + im.name + ".png", im.gt.rgb.data(), im.gt.W, im.gt.H);
    ImageRGB8 e = error_heatmap(im.render, im.gt);
    write_png(dir + "/error/" + im.name + ".png", e.rgb.data(), e.W, e.H);
  }
  // Contact sheet: one row per image (at most 16), render | ground truth | error.
  const size_t rows = std::min<size_t>(r.images.size(), 16);
  if (rows > 0) {
    const int W = r.images[0].render.W, H = r.images[0].render.H;
    std::vector<uint8_t> sheet(size_t(3 * W) * H * rows * 3, 0);
    auto to8 = [](float x) { return uint8_t(std::lround(std::clamp(x, 0.f, 1.f) * 255.f)); };
    for (size_t k = 0; k < rows; ++k) {
      const EvalImage& im = r.images[k];
      const ImageRGB8 e = error_heatmap(im.render, im.gt);
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
          for (int c = 0; c < 3; ++c) {
            uint8_t* row = sheet.data() + ((k * H + y) * size_t(3 * W)) * 3;
            const size_t src = (size_t(y) * W + x) * 3 + c;
            row[size_t(x) * 3 + c] = to8(im.render.rgb[src]);
            row[size_t(W + x) * 3 + c] = to8(im.gt.rgb[src]);
            row[size_t(2 * W + x) * 3 + c] = e.rgb[src];
          }
    }
    write_png(dir + "/contact_sheet.png", sheet.data(), 3 * W, int(H * rows));
  }
  // The refinement's trajectory: one row an epoch, its mean loss and every test camera's deltas.
  if (!r.refine_loss.empty()) {
    std::string csv = "epoch,lr,loss";
    for (const auto& im : r.images)
      for (const char* c : {"r0", "r1", "r2", "t0", "t1", "t2"}) csv += fmt::format(",{}_{}", im.name, c);
    csv += "\n";
    for (size_t e = 0; e < r.refine_loss.size(); ++e) {
      csv += fmt::format("{},{:.6g},{:.9g}", e, refine_lr(int(e)), r.refine_loss[e]);
      if (e < r.refine_deltas.size())
        for (float v : r.refine_deltas[e]) csv += fmt::format(",{:.9g}", v);
      csv += "\n";
    }
    write_file_atomic(dir + "/refine.csv", csv);
  }
  write_file_atomic(dir + "/metrics.json", eval_metrics_json(r));
}

std::string eval_summary(const EvalResult& r) {
  const TrainPoseReport& p = r.pose;
  std::string s = fmt::format("evaluated {} in {:.1f} s (refinement {:.1f} s, renders {:.1f} s)\n",
                              r.mode_note, r.seconds, r.refine_seconds, r.render_seconds);
  s += fmt::format("  PSNR {:.2f}  SSIM {:.4f}  {}\n", r.psnr, r.ssim,
                   r.lpips ? fmt::format("LPIPS {:.4f}", *r.lpips) : r.lpips_note);
  if (p.sim3)
    s += fmt::format("  train cameras, Sim(3)-aligned: ΔR {:.3f}°  ΔT {:.5f}  (scale {:.4g})\n",
                     p.sim3->mean_dR_deg, p.sim3->mean_dT, p.sim3->sim.s);
  if (p.rig)
    s += fmt::format("  train cameras, aligned by their rotations: ΔR {:.3f}°  ΔT {:.5f}\n",
                     p.rig->mean_dR_deg, p.rig->mean_dT);
  if (p.relative)
    s += fmt::format("  relative rotation error {:.3f}° (do-nothing {:.3f}°, {} pairs)\n",
                     p.relative->mean_deg, p.relative->do_nothing_deg, p.relative->pairs);
  if (!p.note.empty()) s += "  " + p.note + "\n";
  s += fmt::format("  focal: learned fx {:.2f} fy {:.2f}{}\n", p.fx, p.fy,
                   p.has_reference ? fmt::format(", reference {:.2f} px", p.ref_focal) : "");
  if (!r.refine_loss.empty())
    s += fmt::format("  test-pose refinement ({}, {}): loss {:.5f} → {:.5f} over {} epochs{}\n",
                     refine_mode_name(r.refine_mode),
                     // fast mode with no more epochs than its full-grid ones never reaches the
                     // fewer rays: say so rather than name a count no step used
                     r.refine_full_epochs > 0 && r.refine_full_epochs >= r.refine_epochs
                         ? std::string("the run's ray grid every epoch")
                         : fmt::format("{} rays a view a step{}", r.refine_rays,
                                       r.refine_full_epochs > 0 ? fmt::format(" after {} epochs on the run's grid", r.refine_full_epochs) : ""),
                     r.refine_loss.front(), r.refine_loss.back(), r.refine_epochs,
                     r.refine_average_from >= 0
                         ? fmt::format("; poses from epochs {}–{}: their mean, for {} of {} views",
                                       r.refine_average_from, r.refine_epochs - 1,
                                       std::count(r.refine_averaged.begin(), r.refine_averaged.end(), true),
                                       r.refine_averaged.size())
                         : "");
  const auto respec = std::count(r.refine_averaged.begin(), r.refine_averaged.end(), false);
  if (respec > 0)
    s += fmt::format("  note: {} of {} test cameras were still moving over the last epochs: refined again in "
                     "the spec's mode (adam), whose poses they keep (docs/evaluation.md §3)\n",
                     respec, r.refine_averaged.size());
  for (const auto& im : r.images)
    s += fmt::format("    {:<24} PSNR {:6.2f}  SSIM {:.4f}{}{}\n", im.name, im.psnr, im.ssim,
                     im.lpips ? fmt::format("  LPIPS {:.4f}", *im.lpips) : "",
                     r.test_views ? fmt::format("  moved {:.3f}° {:.4f}", im.refine_rot_deg, im.refine_trans) : "");
  return s;
}

}  // namespace hashcc
