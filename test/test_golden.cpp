// `hashcc step` (docs/golden-step.md): one training step from files. The CLI runs
// in-process; its grad.*.npy files are checked against central differences of its loss.npy
// over the same input files, for every committed input folder (test/golden_folders.h: the three
// models, both fields, no NDC, a P0 camera, fx_only, the smooth grid gradient); float agrees
// with double; bad folders exit 2 naming the file and the expected shape; the committed worked
// example reproduces.
#include <catch2/catch.hpp>

#include "test/fixtures.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <unistd.h>

#include "core/error.h"
#include "core/fileio.h"
#include "core/npy.h"
#include "model/golden_step.h"
#include "test/golden_folders.h"
#include "test/gradcheck.h"
#include "test/tolerance_table.h"
#include "test/shared_data.h"
#include "tools/cli.h"

namespace fs = std::filesystem;
using namespace hashcc;
using hashcc::test::rel_err;

namespace {

// Runs the CLI in-process; returns the exit status, and what it printed on stderr in *err.
int cli(std::vector<std::string> args, std::string* err = nullptr) {
  args.insert(args.begin(), "hashcc");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  std::string path = (fs::temp_directory_path() / "hashcc_test_golden_stderr.txt").string();
  std::fflush(stderr);
  int saved = dup(2);
  FILE* f = std::fopen(path.c_str(), "w");
  dup2(fileno(f), 2);
  int rc = run_cli(int(argv.size()), argv.data());
  std::fflush(stderr);
  dup2(saved, 2);
  close(saved);
  std::fclose(f);
  std::ifstream in(path);
  std::string text((std::istreambuf_iterator<char>(in)), {});
  if (err) *err = text;
  else if (!text.empty()) std::fputs(text.c_str(), stderr);
  return rc;
}

ModelConfig tiny_config(Variant v) { return tiny_model_config(v); }

// Difference formulas, step sizes and floors (measured over seeds 0–100 of all three models;
// the loss, ≈ 0.1–0.3, comes at the end of a long chain of double roundings, so its value
// carries ~1e-16 of noise):
//  - 5-point central difference (8(L₊₁ − L₋₁) − (L₊₂ − L₋₂)) / 12h, truncation O(h⁴). The
//    camera needs it: x moves with it and the Fourier bands up to 2⁹ make L⁽³⁾/L′ ~ 1e7, so the
//    plain 3-point formula is off by up to 2e-6 relative at h = 1e-6.
//  - network entries: h = 1e-4, noise ~1e-16/h ≈ 1e-12 absolute (measured ≤ 9e-13). Floor 1e-6
//    of the symmetric relative error |a − n| / max(|a| + |n|, floor): gradients above it are
//    judged relatively at 1e-6; the many tiny ones (deep weights of a small random net,
//    1e-10…1e-7) absolutely, |a − n| < 1e-12, i.e. at the noise.
//  - camera (8 numbers that move every sample of every ray): h = 1e-6, noise ≈ 1e-16/h ≈ 1e-10
//    at worst (measured ≤ 1.5e-11); floor 3e-5 (camera gradients are 1e-6…4e-2; below 3e-5 the
//    check is |a − n| < 3e-11).
//  - ReLU kinks: a move of h can push some of the ~10⁴ ReLU inputs across 0, where the loss is
//    not differentiable. The ReLU pattern is recorded at each evaluation; when one of ±h, ±2h
//    differs from the base, the check uses the 4-point one-sided formula
//    ±(−11L₀ + 18L±₁ − 9L±₂ + 2L±₃) / 6h (truncation O(h³)) on the side whose pattern stays
//    unchanged: a smooth piece containing θ, whose derivative is the analytic gradient. Its
//    coefficients carry ~7× the 5-point formula's noise, so its floor is 7× larger. Only when
//    both sides cross a kink is the entry skipped (≤ 5% of entries).
constexpr double kH = 1e-4, kHCam = 1e-6, kFloor = 1e-6, kFloorCam = 3e-5, kTol = 1e-6;

// The batch (9 rays) is one chunk, so the cache holds every ray for the kink detector.
using test::relu_pattern;

// A pointer to the value of entry i of parameter file t in the inputs.
double* entry(GoldenInputs& in, const GoldenTensor& t, int64_t i) {
  if (t.offset >= 0) return &in.params[t.offset + i];
  if (t.name == "pose_r") return &in.pose_r[i];
  if (t.name == "pose_t") return &in.pose_t[i];
  return &in.focal_ab[i];
}

struct CheckResult {
  double worst = 0, worst_net = 0, worst_cam = 0;  // all, network tensors, the 8 camera numbers
  std::string worst_name;
  int checked = 0, skipped = 0, one_sided = 0;
  double cam_vs_smooth = 0;  // grid_smooth: the camera gradient against the forward's differences
};

// Runs `hashcc step --double` on the input folder in_dir (a committed one, or a copy) and checks
// every grad file. Entries: up to 12 random ones of every tensor (all of a smaller one: the
// camera's 8 numbers always), and for a hash table ("grid.table", "cc.table") also the 4
// largest |gradient| of each level, so the grid's partly-on curriculum level (0 < w_l < 1) and
// the CC's hashed levels are always among them (a level switched off has only zero entries:
// its first entry is checked, and its difference must be 0 too).
// With grid_smooth the camera gradient is the smooth straight-through one, NOT the derivative
// of the forward (docs/math/grid_field.md): the camera is then left out of the check (the
// NumPy reference checks it against its own surrogate, test_reference.cpp) and its distance to
// the forward's differences is returned in cam_vs_smooth.
// `corrupt`, for the negative controls only, edits each file's gradient after it is read (the
// .npy reader itself refuses NaN and inf, so a file cannot carry them to the checker); with it,
// only the finite-difference comparison runs.
using Corrupt = std::function<void(const std::string& file, std::vector<double>& g)>;
CheckResult check_folder(const std::string& in_dir, const std::string& name, const Corrupt& corrupt = {}) {
  const std::string out_dir = test::fresh_dir(name + "_out");
  REQUIRE(cli({"step", "--in", in_dir, "--out", out_dir, "--double"}) == 0);

  // The same inputs, read back from the files the CLI read; the loss is re-evaluated
  // in-process (golden_step<double> is what the CLI runs between reading and writing), which
  // gives access to the ReLU pattern. One perturbed FILE is also run through the CLI below to
  // show both paths give the same loss.npy bit for bit.
  GoldenInputs in = read_golden_inputs(in_dir);
  const ModelLayout L = make_layout(in.model);
  const double loss_file = read_npy_shape(out_dir + "/loss.npy", {}).data[0];
  CameraStepWorkspace<double> ws;
  auto loss = [&] { return golden_step<double>(in, &ws).loss; };
  // The CLI above ran at the suite's thread count; the ~3000 tiny re-evaluations run on one
  // thread (100× faster than waking a team for 72 samples). Thread count changes only the
  // hash-grid scatter's summation order, i.e. rounding.
  const test::ThreadGuard one_thread(1);
  REQUIRE(rel_err(loss(), loss_file) < 1e-15);
  const auto files = golden_parameter_files(L);
  double cam_max = 0;  // the instance must really exercise the camera (σ not all 0)
  for (const auto& t : files) {
    REQUIRE_NOTHROW(read_npy_shape(out_dir + "/grad." + t.name + ".npy", t.shape));
    if (t.offset < 0)
      for (double v : read_npy(out_dir + "/grad." + t.name + ".npy").data) cam_max = std::max(cam_max, std::abs(v));
  }
  CHECK(cam_max > 1e-4);

  // hashcc: the camera's differences hold the CC input fixed (formulas.md §5): feed the run's own
  // sample positions x.npy back as cc_x (the documented test hook). The CLI output with the
  // hook equals the output without it (same positions).
  std::vector<double> x = read_npy(out_dir + "/x.npy").data;

  Rng rng(52, 77);  // the same entries on every run
  CheckResult res;
  const double L0 = loss();
  const auto base = relu_pattern(ws, in.model);
  // L at θ + step for entry p, and whether the ReLU pattern there equals the base one.
  auto eval = [&](double* p, double theta, double step, bool* same) {
    *p = theta + step;
    double l = loss();
    *same = relu_pattern(ws, in.model) == base;
    *p = theta;
    return l;
  };
  const bool smooth = in.model.field == Field::grid && in.model.gf.grid.smooth_dx;
  for (const auto& t : files) {
    const bool camera = t.offset < 0;
    if (camera && in.model.has_cc()) in.cc_x = x;
    const double h = camera ? kHCam : kH, floor = camera ? kFloorCam : kFloor;
    std::vector<double> g = read_npy(out_dir + "/grad." + t.name + ".npy").data;
    if (corrupt) corrupt(t.name, g);
    int64_t n = int64_t(g.size());
    std::vector<int64_t> idx;
    for (int k = 0; k < std::min<int64_t>(n, 12); ++k) idx.push_back(n <= 12 ? k : rng.below(uint32_t(n)));
    if (t.name == "grid.table" || t.name == "cc.table") {
      const int64_t levels = t.shape[0], per = n / levels;
      for (int64_t l = 0; l < levels; ++l) {
        std::vector<int64_t> lv(per);
        for (int64_t j = 0; j < per; ++j) lv[j] = l * per + j;
        std::stable_sort(lv.begin(), lv.end(), [&](int64_t a, int64_t b) { return std::abs(g[a]) > std::abs(g[b]); });
        idx.insert(idx.end(), lv.begin(), lv.begin() + std::min<int64_t>(per, 4));
      }
    }
    for (int64_t i : idx) {
      double* p = entry(in, t, i);
      const double th = *p;
      bool sp, sm, sp2 = false, sm2 = false, s3 = false;
      const double lp = eval(p, th, h, &sp), lm = eval(p, th, -h, &sm);
      const double lp2 = sp ? eval(p, th, 2 * h, &sp2) : 0, lm2 = sm ? eval(p, th, -2 * h, &sm2) : 0;
      double fd;
      ++res.checked;
      const bool central = sp && sm && sp2 && sm2;
      if (central) {
        fd = (8 * (lp - lm) - (lp2 - lm2)) / (12 * h);  // 5-point: truncation O(h⁴)
      } else if (sp && sp2 && (eval(p, th, 3 * h, &s3), s3)) {
        // 4-point one-sided (truncation O(h³)) on the side that keeps the ReLU pattern.
        fd = (-11 * L0 + 18 * lp - 9 * lp2 + 2 * eval(p, th, 3 * h, &s3)) / (6 * h);
        ++res.one_sided;
      } else if (sm && sm2 && (eval(p, th, -3 * h, &s3), s3)) {
        fd = (11 * L0 - 18 * lm + 9 * lm2 - 2 * eval(p, th, -3 * h, &s3)) / (6 * h);
        ++res.one_sided;
      } else {
        ++res.skipped;
        continue;
      }
      // The one-sided coefficients (11, 18, 9, 2)/6h carry ~7× the rounding noise of the
      // 5-point formula's (8, 8, 1, 1)/12h: its floor is 7× larger.
      double e = rel_err(g[i], fd, central ? floor : 7 * floor);  // +inf if g[i] is NaN/inf
      if (camera && smooth && !corrupt) {  // not the forward's derivative: measured, not judged
        test::keep_worst(res.cam_vs_smooth, e);
        --res.checked;
        continue;
      }
      test::keep_worst(camera ? res.worst_cam : res.worst_net, e);
      if (!(e <= res.worst)) {  // a NaN e (were one possible) would win too
        res.worst = e;
        res.worst_name = fmt::format("{}[{}] (analytic {:.6e}, numeric {:.6e}{})", t.name, i, g[i],
                                     fd, central ? "" : ", one-sided");
      }
    }
    in.cc_x.clear();
  }
  if (corrupt) return res;

  // The file path: perturb one entry in the folder, rerun the CLI, compare loss.npy.
  {
    const GoldenTensor& t = files[2];  // trunk.1.weight (mlp), grid.density.0.bias (grid)
    GoldenInputs p = in;
    *entry(p, t, 5) += kH;
    const std::string pin = test::fresh_dir(name + "_pin"), pout = test::fresh_dir(name + "_pout");
    write_golden_inputs(pin, p);
    REQUIRE(cli({"step", "--in", pin, "--out", pout, "--double"}) == 0);
    double lp_file = read_npy_shape(pout + "/loss.npy", {}).data[0];
    GoldenInputs q = in;
    *entry(q, t, 5) += kH;
    CHECK(lp_file == golden_step<double>(q).loss);
  }
  if (in.model.has_cc()) {  // cc_x.npy = x.npy changes nothing at the unperturbed point
    // On a copy: the committed folder is never written to.
    const std::string copy = test::fresh_dir(name + "_hin"), hout = test::fresh_dir(name + "_hout");
    fs::copy(in_dir, copy);
    fs::copy_file(out_dir + "/x.npy", copy + "/cc_x.npy");
    REQUIRE(cli({"step", "--in", copy, "--out", hout, "--double"}) == 0);
    for (const auto& t : files)
      CHECK(read_npy(hout + "/grad." + t.name + ".npy").data ==
            read_npy(out_dir + "/grad." + t.name + ".npy").data);
  }
  return res;
}

}  // namespace

TEST_CASE("hashcc step: the grad-file checker fails a NaN or an inf entry", "[golden][gradcheck]") {
  // Negative control (issue 52): the checker below, with one camera entry (always checked:
  // files of ≤ 12 entries are checked whole) replaced by NaN or +inf after reading, must report
  // an infinite worst error at that entry. golden_sh: the cheapest of the folders.
  const std::string sh = test::repo_root() + "/test/data/golden_sh/in";
  for (double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    DYNAMIC_SECTION("entry set to " << bad) {
      const CheckResult r = check_folder(sh, "negative", [&](const std::string& f, std::vector<double>& g) {
        if (f == "pose_t") g[1] = bad;
      });
      CHECK(r.worst == std::numeric_limits<double>::infinity());
      CHECK_FALSE(r.worst < kTol);
      CHECK_THAT(r.worst_name, Catch::StartsWith("pose_t[1]"));
    }
  }
}

TEST_CASE("hashcc step: the grad-file checker fails a wrong level weight of the curriculum", "[golden][gradcheck]") {
  // Negative control for the grid field's level curriculum: golden_grid has level 2 at
  // w = 1/2 (α = 2.5). Its table gradient scaled by 1/w = 2 (what a backward that forgot the
  // weight would write) must fail the check, and so must one entry of it off by 1e-4 relative.
  const std::string grid = test::repo_root() + "/test/data/golden_grid/in";
  const GoldenInputs gi = read_golden_inputs(grid);
  const int64_t per = gi.model.gf.grid.table_size() * gi.model.gf.grid.features;
  const CheckResult r = check_folder(grid, "negative_level", [&](const std::string& f, std::vector<double>& g) {
    if (f == "grid.table")
      for (int64_t i = 2 * per; i < 3 * per; ++i) g[i] *= 2;
  });
  CHECK_THAT(r.worst_name, Catch::StartsWith("grid.table"));
  CHECK(r.worst > 0.3);  // |2a − a| / (2a + a) = 1/3
  const CheckResult one = check_folder(grid, "negative_one", [&](const std::string& f, std::vector<double>& g) {
    if (f == "grid.table") {
      int64_t big = 2 * per;
      for (int64_t i = 2 * per; i < 3 * per; ++i) if (std::abs(g[i]) > std::abs(g[big])) big = i;
      g[big] *= 1 + 1e-4;
    }
  });
  CHECK_FALSE(one.worst < kTol);
}

TEST_CASE("hashcc step: every grad file matches central differences of loss.npy", "[golden][grad]") {
  // Every committed input folder (test/golden_folders.h), in double, the same tolerance kTol for
  // each (the reasoning is the comment above kH); measured figures: docs/golden-tolerances.md.
  for (const test::GoldenFolder& gf : test::golden_folders()) {
    DYNAMIC_SECTION(gf.name) {
      const std::string in_dir = test::repo_root() + "/test/data/" + gf.name + "/in";
      CheckResult r = check_folder(in_dir, gf.name);
      INFO(gf.name << ": worst relative error " << r.worst << " at " << r.worst_name
                   << "; skipped " << r.skipped << " of " << r.checked << " at ReLU kinks");
      WARN(gf.name << ": worst " << r.worst << " at " << r.worst_name << " (networks " << r.worst_net
                   << ", camera " << r.worst_cam << "), one-sided " << r.one_sided << ", skipped "
                   << r.skipped << "/" << r.checked
                   << (gf.smooth ? fmt::format(", smooth camera vs forward {:.3g}", r.cam_vs_smooth) : ""));
      test::record_tolerance("[golden][grad] network tensors", gf.name, r.worst_net, kTol);
      if (!gf.smooth) test::record_tolerance("[golden][grad] camera", gf.name, r.worst_cam, kTol);
      CHECK(r.worst < kTol);
      CHECK(r.skipped < r.checked / 10);
      if (gf.smooth) {
        // The folder really runs the smooth gradient: the camera's differs from the forward's
        // derivative (measured in the docs' table) by far more than the tolerance.
        test::record_tolerance("[golden][grad] smooth camera vs the forward (must EXCEED)", gf.name,
                               r.cam_vs_smooth, 1e-3);
        CHECK(test::clearly_differs(r.cam_vs_smooth, 1e-3));
      }
    }
  }
}

TEST_CASE("hashcc step: the camera's finite difference needs the CC input held fixed", "[golden][grad]") {
  // Without cc_x the perturbed camera also moves the CC branch's input, which the analytic
  // gradient excludes by design (detach): the difference then disagrees.
  const std::string in_dir = test::fresh_dir("detach_in"), out_dir = test::fresh_dir("detach_out");
  GoldenMakeOptions mo;
  mo.seed = 9;
  write_golden_inputs(in_dir, make_golden_inputs(tiny_config(Variant::hashcc), mo));
  REQUIRE(cli({"step", "--in", in_dir, "--out", out_dir, "--double"}) == 0);
  GoldenInputs in = read_golden_inputs(in_dir);
  std::vector<double> g = read_npy(out_dir + "/grad.pose_t.npy").data;
  double worst = 0;
  for (int i = 0; i < 3; ++i) {
    double keep = in.pose_t[i];
    in.pose_t[i] = keep + kHCam; double lp = golden_step<double>(in).loss;
    in.pose_t[i] = keep - kHCam; double lm = golden_step<double>(in).loss;
    in.pose_t[i] = keep;
    test::keep_worst(worst, rel_err(g[i], (lp - lm) / (2 * kHCam), kFloor));
  }
  INFO("pose_t error with the CC input moving: " << worst);
  WARN("pose_t: relative error with the CC input moving " << worst);
  CHECK(test::clearly_differs(worst, 1e-3));  // a NaN (+inf now) is not a real difference
}

TEST_CASE("hashcc step: float and double runs agree", "[golden][float]") {
  // Float runs the training precision. Measured (seed 21): loss 3e-8 relative, colours, depth,
  // rays and samples 1e-7 (absolute, relative above 1), each gradient tensor 6e-5 of its largest
  // entry (float rounding amplified through eight layers, the compositor's products and the
  // camera chain). Tolerances: 1e-6, 1e-6 and 1e-3.
  for (Variant v : {Variant::nerfmm, Variant::sh, Variant::hashcc}) {
    DYNAMIC_SECTION("model " << variant_name(v)) {
      const std::string name = variant_name(v);
      const std::string in_dir = test::fresh_dir(name + "_fin"), od = test::fresh_dir(name + "_fd"), of = test::fresh_dir(name + "_ff");
      GoldenMakeOptions mo;
      mo.seed = 21;
      GoldenInputs in = make_golden_inputs(tiny_config(v), mo);
      write_golden_inputs(in_dir, in);
      REQUIRE(cli({"step", "--in", in_dir, "--out", od, "--double"}) == 0);
      REQUIRE(cli({"step", "--in", in_dir, "--out", of}) == 0);
      double ld = read_npy(od + "/loss.npy").data[0], lf = read_npy(of + "/loss.npy").data[0];
      CHECK(rel_err(ld, lf) < 1e-6);
      double worst_out = 0;
      std::vector<std::string> outs = {"rgb_main", "depth", "rays_o", "rays_d", "x"};
      if (v == Variant::hashcc) outs.push_back("rgb_cc");
      for (const auto& o : outs) {
        auto a = read_npy(od + "/" + o + ".npy").data, b = read_npy(of + "/" + o + ".npy").data;
        for (size_t i = 0; i < a.size(); ++i) test::keep_worst(worst_out, std::abs(a[i] - b[i]) / (1 + std::abs(a[i])));
      }
      double worst_grad = 0;
      std::string worst_name;
      for (const auto& t : golden_parameter_files(make_layout(in.model))) {
        auto a = read_npy(od + "/grad." + t.name + ".npy").data;
        auto b = read_npy(of + "/grad." + t.name + ".npy").data;
        // max |a − b| / max |a| (the double's scale); +inf when either holds a NaN or inf.
        REQUIRE(a.size() == b.size());
        const double e = test::worst_scaled_diff(b, a);
        if (!(e <= worst_grad)) { worst_grad = e; worst_name = t.name; }
      }
      WARN(name << ": loss rel " << rel_err(ld, lf) << ", outputs " << worst_out
                << ", gradients (per-tensor scaled) " << worst_grad << " in " << worst_name);
      CHECK(worst_out < 1e-6);
      CHECK(worst_grad < 1e-3);
    }
  }
}

TEST_CASE("hashcc step: bad or missing input files exit 2 naming the file and shape", "[golden][io]") {
  const std::string good = test::fresh_dir("bad_src");
  GoldenMakeOptions mo;
  write_golden_inputs(good, make_golden_inputs(tiny_config(Variant::hashcc), mo));
  auto fresh = [&](const std::string& tag) {
    std::string d = test::fresh_dir("bad_" + tag);
    fs::remove_all(d);
    fs::copy(good, d);
    return d;
  };
  struct Case {
    std::string tag;
    std::function<void(const std::string&)> spoil;
    std::vector<std::string> message;  // substrings the one-line error must contain
  };
  const double two[2] = {1, 2};
  std::vector<Case> cases = {
      {"missing", [](const std::string& d) { fs::remove(d + "/trunk.3.bias.npy"); },
       {"trunk.3.bias.npy", "missing", "shape (16,)"}},
      {"shape", [&](const std::string& d) { write_npy(d + "/density.weight.npy", two, {2, 1}); },
       {"density.weight.npy", "has shape (2, 1)", "shape (1, 16)"}},
      {"table", [&](const std::string& d) { write_npy(d + "/cc.table.npy", two, {2}); },
       {"cc.table.npy", "shape (4, 64, 2)"}},
      {"extra", [&](const std::string& d) { write_npy(d + "/trunk.0.weights.npy", two, {2}); },
       {"trunk.0.weights.npy", "unexpected file"}},
      {"truncated", [](const std::string& d) {
         std::string b = read_file_bytes(d + "/pose_r.npy", 1 << 20);
         std::ofstream(d + "/pose_r.npy", std::ios::binary) << b.substr(0, b.size() - 4);
       }, {"pose_r.npy", "truncated", "shape (3,)"}},
      {"rows_dtype", [&](const std::string& d) { write_npy(d + "/rows.npy", two, {2}); },
       {"rows.npy", "int64"}},
      {"rows_range", [&](const std::string& d) {
         int64_t r[2] = {0, 16};
         write_npy_i64(d + "/rows.npy", r, {2});
       }, {"rows.npy", "outside the image"}},
      {"s_shape", [&](const std::string& d) { write_npy(d + "/s.npy", two, {1, 2}); },
       {"s.npy", "shape (9, 8)"}},
      {"config_key", [](const std::string& d) {
         std::string c = read_file_bytes(d + "/config.json", 1 << 20);
         c.replace(c.find("\"cc_levels\""), 11, "\"cc_level\"");
         std::ofstream(d + "/config.json") << c;
       }, {"config.json", "cc_level", "unknown key"}},
      {"config_missing", [](const std::string& d) {
         std::ofstream(d + "/config.json") << R"({"model": "hashcc", "H": 16, "W": 16, "samples": 8, "ndc": true})";
       }, {"config.json", "cc_levels", "missing"}},
      {"grid_key_without_field", [](const std::string& d) {
         std::string c = read_file_bytes(d + "/config.json", 1 << 20);
         c.insert(c.find('{') + 1, "\"grid_levels\": 4, ");
         std::ofstream(d + "/config.json") << c;
       }, {"config.json", "grid_levels", "without \"field\": \"grid\""}},
      {"field_grid_missing_key", [](const std::string& d) {
         std::string c = read_file_bytes(d + "/config.json", 1 << 20);
         c.insert(c.find('{') + 1, "\"field\": \"grid\", ");
         std::ofstream(d + "/config.json") << c;
       }, {"config.json", "grid_levels", "missing"}},
      {"cc_x", [&](const std::string& d) { write_npy(d + "/cc_x.npy", two, {2}); },
       {"cc_x.npy", "shape (72, 3)"}},
  };
  for (const auto& c : cases) {
    DYNAMIC_SECTION("case " << c.tag) {
      std::string d = fresh(c.tag), err;
      c.spoil(d);
      CHECK(cli({"step", "--in", d, "--out", test::fresh_dir("bad_out"), "--double"}, &err) == 2);
      INFO("stderr: " << err);
      for (const auto& m : c.message) CHECK(err.find(m) != std::string::npos);
      CHECK(std::count(err.begin(), err.end(), '\n') == 1);  // one line
    }
  }
  std::string err;
  CHECK(cli({"step", "--in", "/nonexistent/golden", "--out", test::fresh_dir("bad_out")}, &err) == 2);
  CHECK(err.find("/nonexistent/golden") != std::string::npos);
  CHECK(cli({"step", "--out", test::fresh_dir("bad_out")}, &err) == 2);
  CHECK(err.find("--in") != std::string::npos);
}

TEST_CASE("hashcc step: the committed worked example reproduces", "[golden]") {
  // test/data/golden_hashcc/in was written by `hashcc step --make-inputs … --model hashcc
  // --seed 1`, out by `hashcc step --in … --out … --double`. Re-running must give the same
  // numbers up to double rounding (a different compiler, FMA contraction or thread count moves
  // the last bits): relative 1e-10 of each file's largest entry.
  const std::string root = test::repo_root() + "/test/data/golden_hashcc";
  const std::string out = test::fresh_dir("example_out");
  REQUIRE(cli({"step", "--in", root + "/in", "--out", out, "--double"}) == 0);
  int files = 0;
  double worst = 0;
  std::string worst_name;
  for (const auto& e : fs::directory_iterator(root + "/out")) {
    std::string fname = e.path().filename().string();
    INFO(fname);
    REQUIRE(fs::exists(out + "/" + fname));
    NpyArray a = read_npy(e.path().string()), b = read_npy(out + "/" + fname);
    REQUIRE(a.shape == b.shape);
    // max |new − committed| / max |committed|; +inf when either holds a NaN or inf.
    const double rel = test::worst_scaled_diff(b.data, a.data);
    if (!(rel <= worst)) { worst = rel; worst_name = fname; }
    ++files;
  }
  int produced = int(std::distance(fs::directory_iterator(out), fs::directory_iterator{}));
  CHECK(files == produced);
  WARN("worked example: " << files << " files, worst scaled difference " << worst << " in " << worst_name);
  CHECK(worst < 1e-10);
}
