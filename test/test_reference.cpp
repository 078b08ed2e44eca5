// An independent reference of the assembled step (issue 24): tools/reference_step.py, NumPy in
// float64, written from docs/formulas.md and docs/golden-step.md rather than from the C++, runs
// the committed golden inputs (test/golden_folders.h: nerfmm, sh, hashcc, the grid field, no
// NDC, a P0 camera, fx_only, the smooth grid gradient) and must agree with `hashcc step
// --double` on every forward output and the loss to 1e-9, on the camera gradient (its own
// finite differences) to 1e-6, and on every network tensor's gradient (its own differences on a
// random subset of entries, issue 52) to 1e-5. The finite-difference checks of
// test_golden.cpp prove each backward against the engine's own forward; this one proves the
// forward itself (concat orders, loss normalisation, Δc before compositing, NDC, hash indexing,
// the level curriculum) against a second implementation. A check of the initialisation
// (formulas.md §4) rides along.
//
// Where no Python with NumPy is found the tests FAIL, with the reason (Catch2 v2 has no skip):
// tools/install_deps.sh installs python3-numpy, so a machine set up by the project has it, and
// a silent pass would hide that the forward pass went unchecked.
#include <catch2/catch.hpp>

#include "test/fixtures.h"
#include "test/golden_folders.h"
#include "test/gradcheck.h"
#include "test/tolerance_table.h"
#include "test/shared_data.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sys/wait.h>

#include "core/npy.h"
#include "model/golden_step.h"

namespace fs = std::filesystem;
using namespace hashcc;

namespace {

// The repository read (test/shared_data.h: the one built from, or a clone under test).
const std::string kSource = hashcc::test::repo_root();
const std::string kScript = kSource + "/tools/reference_step.py";

using test::python_with_numpy;  // test/fixtures.h

// Runs the script with args; returns its exit status and its output (stdout + stderr) in *text.
int run_script(const std::string& args, std::string* text) {
  const std::string log = test::tmp("reference_log.txt");
  const std::string cmd = fmt::format("'{}' '{}' {} >'{}' 2>&1", python_with_numpy(), kScript, args, log);
  const int rc = std::system(cmd.c_str());
  std::ifstream in(log);
  text->assign((std::istreambuf_iterator<char>(in)), {});
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

#define REQUIRE_NUMPY()                                                                       \
  if (python_with_numpy().empty())                                                            \
    FAIL("no Python with NumPy (tried $HASHCC_PYTHON, python3, /usr/bin/python3): the "       \
         "independent reference of the step did NOT run. Install python3-numpy "              \
         "(tools/install_deps.sh does), or set HASHCC_PYTHON.")

// max |a − b| / max |a| over one file (the scale of docs/golden-step.md's comparison); +inf
// when either side holds a NaN or an inf (test/gradcheck.h: NaN must never look like 0).
double scaled_diff(const std::vector<double>& a, const std::vector<double>& b) {
  REQUIRE(a.size() == b.size());
  return test::worst_scaled_diff(b, a);
}

// The camera gradient's error, hashcc's ga against the reference's gb: per entry
// |a − n| / max(|a|, |n|, 1e-2·(largest |ga|)), worst over the 8; +inf if any is not finite.
double camera_error(const std::vector<double>& ga, const std::vector<double>& gb) {
  REQUIRE(ga.size() == gb.size());
  double big = 0, worst = 0;
  for (double v : ga) big = std::max(big, std::abs(v));
  for (size_t i = 0; i < ga.size(); ++i)
    test::keep_worst(worst, std::abs(ga[i] - gb[i]) /
                                std::max({std::abs(ga[i]), std::abs(gb[i]), 1e-2 * big}));
  return test::as_error(worst);
}

// A network tensor's gradient, hashcc's ga at the reference's entries against the reference's
// differences gb: per entry the symmetric relative error |a − n| / max(|a| + |n|, 1e-6), worst
// over the entries; +inf if any is not finite.
double param_error(const std::vector<double>& ga, const std::vector<double>& gb) {
  REQUIRE(ga.size() == gb.size());
  double worst = 0;
  for (size_t i = 0; i < ga.size(); ++i) test::keep_worst(worst, test::rel_err(ga[i], gb[i], 1e-6));
  return worst;
}

}  // namespace

TEST_CASE("NumPy reference: forward outputs, loss and every gradient agree with hashcc step",
          "[golden][reference]") {
  REQUIRE_NUMPY();
  // Tolerances. Forward (rays, samples, colours, depth) and loss: both sides are float64
  // evaluations of the same formulas in a different order (hashcc's Fourier bands come from the
  // double-angle recurrence, ~1e-13 off at band 9); measured ≤ 1e-15, so 1e-9 leaves room for
  // another compiler or BLAS while a convention error (a swapped concat, a mean over R·C instead
  // of R·C·3, Δc after compositing) moves them by 1e-3 or more. Camera gradient: the script's
  // 5-point differences at h = 1e-5 (truncation ~1e-8 relative, rounding ~2e-12 absolute; at
  // 1e-6 near a kink: ~2e-11) against hashcc's analytic one, per entry
  // |a − n| / max(|a|, |n|, 1e-2·(largest camera entry)): the floor keeps the entries 100× below
  // the largest (~3e-5) from being judged relatively at the differences' rounding. Measured
  // figures: docs/golden-tolerances.md (generated).
  // Network tensors: the script's 5-point differences at h = 1e-4 (1e-5 near a kink) of a loss
  // that rounds at ~1e-17: noise ≲ 3e-12 absolute. Per entry the symmetric relative error with
  // floor 1e-6 (param_error): relative above 1e-6, absolute (≲ 1e-11) below — many weights of a
  // small random net have gradients of 1e-10…1e-7. 1e-5 leaves a factor of a few over the
  // noise at the floor; a convention error (a transposed weight, a missing level weight, a
  // wrong mean) is off by O(1).
  constexpr double kTolForward = 1e-9, kTolCamera = 1e-6, kTolParam = 1e-5;
  for (const test::GoldenFolder& gf : test::golden_folders()) {
    const std::string name = gf.name;
    DYNAMIC_SECTION(name) {
      const std::string in = kSource + "/test/data/" + name + "/in";
      const std::string ours = test::fresh_dir(std::string(name) + "_hcc");
      const std::string ref = test::fresh_dir(std::string(name) + "_ref");
      REQUIRE(test::cli({"step", "--in", in, "--out", ours, "--double"}) == 0);
      std::string text;
      const int rc = run_script("--in '" + in + "' --out '" + ref + "'", &text);
      INFO("reference_step.py said:\n" << text);
      REQUIRE(rc == 0);
      CHECK(text.find(", 0 skipped |") != std::string::npos);  // every camera entry differenced
      if (const auto np = text.find("| NumPy "); np != std::string::npos)
        test::record_tolerance_note("The NumPy reference ran with " + text.substr(np + 2, text.find('\n', np) - np - 2) + ".");
      // Network tensors: the script's subset, its size and seed, and how many it had to skip
      // (both sides of an entry at a kink): at most 5%.
      std::smatch m;
      REQUIRE(std::regex_search(text, m, std::regex(R"(parameter differences: (\d+) entries of (\d+) tensors \(up to (\d+) a tensor, numpy default_rng seed (\d+)\):.* (\d+) skipped)")));
      CHECK(std::stoi(m[5]) * 20 <= std::stoi(m[1]));
      test::record_tolerance_note(fmt::format("Network-tensor subset of the NumPy reference: up to {} entries a tensor, numpy.random.default_rng({}).", std::string(m[3]), std::string(m[4])));

      const GoldenInputs gi = read_golden_inputs(in);
      std::vector<std::string> forward = {"rgb_main", "depth", "rays_o", "rays_d", "x"};
      if (gi.model.has_cc()) forward.push_back("rgb_cc");
      double worst_fwd = 0;
      std::string worst_name;
      for (const auto& f : forward) {
        const NpyArray a = read_npy(ours + "/" + f + ".npy"), b = read_npy(ref + "/" + f + ".npy");
        REQUIRE(a.shape == b.shape);
        const double e = scaled_diff(a.data, b.data);
        if (e >= worst_fwd) { worst_fwd = e; worst_name = f; }  // e is +inf, never NaN
      }
      const double la = read_npy(ours + "/loss.npy").data[0], lb = read_npy(ref + "/loss.npy").data[0];
      const double loss_err = test::as_error(std::abs(la - lb) / std::abs(la));

      std::vector<double> ga, gb;
      for (const char* f : {"grad.pose_r", "grad.pose_t", "grad.focal_ab"}) {
        for (double v : read_npy(ours + "/" + f + ".npy").data) ga.push_back(v);
        for (double v : read_npy(ref + "/" + f + ".npy").data) gb.push_back(v);
      }
      REQUIRE(ga.size() == 8);
      REQUIRE(gb.size() == 8);
      double big = 0;
      for (double v : ga) big = std::max(big, std::abs(v));
      CHECK(big > 1e-4);  // the instance really moves the loss with the camera
      const double worst_cam = camera_error(ga, gb);

      // Network tensors: every one has the reference's fd.X.idx.npy and fd.X.npy.
      double worst_param = 0, largest = 0;
      std::string worst_tensor;
      int entries = 0;
      std::vector<double> all_a, all_b;
      for (const auto& t : golden_parameter_files(make_layout(gi.model))) {
        if (t.offset < 0) continue;  // the camera, above
        INFO(t.name);
        REQUIRE(fs::exists(ref + "/fd." + t.name + ".npy"));
        const std::vector<double> idx = read_npy(ref + "/fd." + t.name + ".idx.npy").data;
        const std::vector<double> gb = read_npy(ref + "/fd." + t.name + ".npy").data;
        const std::vector<double> g = read_npy(ours + "/grad." + t.name + ".npy").data;
        std::vector<double> ga;
        for (double i : idx) {
          REQUIRE((i >= 0 && i < double(g.size())));
          ga.push_back(g[size_t(i)]);
        }
        const double e = param_error(ga, gb);
        if (!(e <= worst_param)) { worst_param = e; worst_tensor = t.name; }
        for (double v : ga) largest = std::max(largest, std::abs(v));
        all_a.insert(all_a.end(), ga.begin(), ga.end());
        all_b.insert(all_b.end(), gb.begin(), gb.end());
        entries += int(ga.size());
      }
      CHECK(entries >= 60);       // the subset is really there (8 a tensor, or all)
      CHECK(largest > 1e-3);      // and carries real gradients
      // The check can fail here: the largest checked entry 1e-3 off must exceed the tolerance.
      {
        size_t k = 0;
        for (size_t i = 0; i < all_a.size(); ++i) if (std::abs(all_a[i]) > std::abs(all_a[k])) k = i;
        std::vector<double> off = all_a;
        off[k] *= 1 + 1e-3;
        CHECK_FALSE(param_error(off, all_b) <= kTolParam);
      }
      WARN(name << ": loss " << la << ", forward worst " << worst_fwd << " (" << worst_name
                << "), loss " << loss_err << ", camera gradient " << worst_cam
                << ", network gradients " << worst_param << " (" << worst_tensor << ", " << entries
                << " entries)");
      test::record_tolerance("[golden][reference] forward outputs", name, worst_fwd, kTolForward);
      test::record_tolerance("[golden][reference] loss", name, loss_err, kTolForward);
      test::record_tolerance("[golden][reference] camera gradient", name, worst_cam, kTolCamera);
      test::record_tolerance("[golden][reference] network gradients (subset)", name, worst_param, kTolParam);
      CHECK(worst_fwd <= kTolForward);
      CHECK(loss_err <= kTolForward);
      CHECK(worst_cam <= kTolCamera);
      CHECK(worst_param <= kTolParam);
    }
  }
}

TEST_CASE("NumPy reference: its error measures fail a NaN or an inf entry", "[golden][reference][exact]") {
  // Negative controls (issue 52): one NaN or +inf entry on either side must give an infinite
  // error, which fails every tolerance above; std::max(worst, NaN) alone would report 0 here.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<double> good = {0.3, -0.2, 1e-3, 0.05, -0.4, 0.1, 2e-4, 0.7};
  std::vector<double> near = good;
  near[5] += 1e-9;  // the positive control: a tiny real difference is measured, finite
  CHECK(scaled_diff(good, good) == 0);
  CHECK(camera_error(good, good) == 0);
  CHECK(scaled_diff(good, near) == Approx(1e-9 / 0.7).epsilon(1e-6));
  CHECK(camera_error(good, near) == Approx(1e-9 / 0.1).epsilon(1e-6));
  CHECK(param_error(good, good) == 0);
  CHECK(param_error(good, near) == Approx(1e-9 / 0.2).epsilon(1e-6));
  for (double v : {nan, inf}) {
    INFO("bad entry " << v);
    std::vector<double> bad = good;
    bad[3] = v;
    CHECK(scaled_diff(good, bad) == inf);
    CHECK(scaled_diff(bad, good) == inf);
    CHECK(camera_error(good, bad) == inf);
    CHECK(camera_error(bad, good) == inf);
    CHECK(param_error(good, bad) == inf);
    CHECK(param_error(bad, good) == inf);
  }
}

TEST_CASE("NumPy reference: the committed golden inputs exercise what they should", "[golden][reference]") {
  // A reference comparison only proves something about the parts the inputs use: each folder
  // must be the model and field its name says, and the grid one must run the level curriculum
  // with a level partly on, so its weights (not just 0 and 1) are compared.
  // The four of issue 52 likewise: no NDC, a P0 (not the identity), fx_only, grid_smooth.
  for (const test::GoldenFolder& w : test::golden_folders()) {
    INFO(w.name);
    const GoldenInputs gi = read_golden_inputs(kSource + "/test/data/" + w.name + "/in");
    CHECK(gi.model.variant == w.variant);
    CHECK(gi.model.field == w.field);
    const double a = gi.model.pos_c2f_alpha;
    CHECK((a >= 0) == w.c2f);
    if (w.c2f) CHECK(a - std::floor(a) > 0.1);  // a band / level partly on
    CHECK(gi.ndc == w.ndc);
    CHECK(gi.fx_only == w.fx_only);
    CHECK(gi.has_P0 == w.p0);
    if (w.p0) {
      double off = 0;  // P0 moves the camera: rotation and centre off the identity
      for (int i = 0; i < 12; ++i) off = std::max(off, std::abs(gi.P0[i] - (i % 5 == 0 ? 1.0 : 0.0)));
      CHECK(off > 0.05);
    }
    CHECK((gi.model.field == Field::grid && gi.model.gf.grid.smooth_dx) == w.smooth);
  }
}

TEST_CASE("NumPy reference: init_params follows formulas.md §4 (and the check can fail)",
          "[golden][reference][init]") {
  REQUIRE_NUMPY();
  // Fresh inputs from make_golden_inputs → init_params (the CC and grid tables are rescaled by
  // the golden maker, so only the dense layers and the two special biases are judged here).
  for (Field f : {Field::mlp, Field::grid})
    for (Variant v : {Variant::nerfmm, Variant::sh, Variant::hashcc}) {
      DYNAMIC_SECTION(variant_name(v) << " " << field_name(f)) {
        const std::string d = test::fresh_dir("init_in");
        GoldenMakeOptions mo;
        mo.seed = 5;
        write_golden_inputs(d, make_golden_inputs(tiny_model_config(v, f), mo));
        std::string text;
        CHECK(run_script("--in '" + d + "' --check-init", &text) == 0);
        INFO(text);
        CHECK(text.find("init: ok") != std::string::npos);
        // Negative control: a density bias of 0 (or a zero rgb.0 weight for the grid) must fail.
        GoldenInputs bad = read_golden_inputs(d);
        const ModelLayout L = make_layout(bad.model);
        if (f == Field::mlp) bad.params[L.density.b] = 0;
        else std::fill_n(bad.params.begin() + L.gr0.w, int64_t(L.gr0.in) * L.gr0.out, 0.0);
        write_golden_inputs(d, bad);
        CHECK(run_script("--in '" + d + "' --check-init", &text) == 1);
        CHECK(text.find("init: FAILED") != std::string::npos);
      }
    }
}
