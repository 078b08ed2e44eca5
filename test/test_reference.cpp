// An independent reference of the assembled step (issue 24): tools/reference_step.py, NumPy in
// float64, written from docs/formulas.md and docs/golden-step.md rather than from the C++, runs
// the committed golden inputs (test/data/golden_*/in: nerfmm, sh, hashcc, and the grid field)
// and must agree with `hashcc step --double` on every forward output and the loss to 1e-9, and
// on the camera gradient (its own finite differences) to 1e-6. The finite-difference checks of
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
#include "test/gradcheck.h"
#include "test/shared_data.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sys/wait.h>

#include "core/npy.h"
#include "model/golden_step.h"

namespace fs = std::filesystem;
using namespace hashcc;

namespace {

// The repository read (test/shared_data.h: the one built from, or a clone under test).
const std::string kSource = hashcc::test::repo_root();
const std::string kScript = kSource + "/tools/reference_step.py";

// The first of $HASHCC_PYTHON, python3 (PATH), /usr/bin/python3 that imports numpy; "" if none.
std::string python_with_numpy() {
  static const std::string found = [] {
    std::vector<std::string> tries;
    if (const char* e = std::getenv("HASHCC_PYTHON")) tries.push_back(e);
    tries.push_back("python3");
    tries.push_back("/usr/bin/python3");
    for (const auto& p : tries)
      if (std::system(fmt::format("'{}' -c 'import numpy' >/dev/null 2>&1", p).c_str()) == 0) return p;
    return std::string();
  }();
  return found;
}

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

}  // namespace

TEST_CASE("NumPy reference: forward outputs, loss and camera gradient agree with hashcc step",
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
  // ≤ 1.6e-7 (grid field, then nerfmm 1.4e-7).
  constexpr double kTolForward = 1e-9, kTolCamera = 1e-6;
  for (const char* name : {"golden_nerfmm", "golden_sh", "golden_hashcc", "golden_grid"}) {
    DYNAMIC_SECTION(name) {
      const std::string in = kSource + "/test/data/" + name + "/in";
      const std::string ours = test::fresh_dir(std::string(name) + "_hcc");
      const std::string ref = test::fresh_dir(std::string(name) + "_ref");
      REQUIRE(test::cli({"step", "--in", in, "--out", ours, "--double"}) == 0);
      std::string text;
      const int rc = run_script("--in '" + in + "' --out '" + ref + "'", &text);
      INFO("reference_step.py said:\n" << text);
      REQUIRE(rc == 0);
      CHECK(text.find("0 skipped") != std::string::npos);  // every camera entry differenced

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
      WARN(name << ": loss " << la << ", forward worst " << worst_fwd << " (" << worst_name
                << "), loss " << loss_err << ", camera gradient " << worst_cam);
      CHECK(worst_fwd <= kTolForward);
      CHECK(loss_err <= kTolForward);
      CHECK(worst_cam <= kTolCamera);
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
  for (double v : {nan, inf}) {
    INFO("bad entry " << v);
    std::vector<double> bad = good;
    bad[3] = v;
    CHECK(scaled_diff(good, bad) == inf);
    CHECK(scaled_diff(bad, good) == inf);
    CHECK(camera_error(good, bad) == inf);
    CHECK(camera_error(bad, good) == inf);
  }
}

TEST_CASE("NumPy reference: the committed golden inputs exercise what they should", "[golden][reference]") {
  // A reference comparison only proves something about the parts the inputs use: each folder
  // must be the model and field its name says, and the grid one must run the level curriculum
  // with a level partly on, so its weights (not just 0 and 1) are compared.
  struct Want { const char* dir; Variant v; Field f; bool c2f; };
  for (const Want& w : {Want{"golden_nerfmm", Variant::nerfmm, Field::mlp, true},
                        Want{"golden_sh", Variant::sh, Field::mlp, false},
                        Want{"golden_hashcc", Variant::hashcc, Field::mlp, false},
                        Want{"golden_grid", Variant::hashcc, Field::grid, true}}) {
    INFO(w.dir);
    const GoldenInputs gi = read_golden_inputs(kSource + "/test/data/" + w.dir + "/in");
    CHECK(gi.model.variant == w.v);
    CHECK(gi.model.field == w.f);
    const double a = gi.model.pos_c2f_alpha;
    CHECK((a >= 0) == w.c2f);
    if (w.c2f) CHECK(a - std::floor(a) > 0.1);  // a band / level partly on
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
