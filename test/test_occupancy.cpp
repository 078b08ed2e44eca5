// Tests for render/occupancy.h: the occupancy grid (update, decay, dilation, the box) and the
// sampler (all occupied = uniform jitter, samples only in occupied stretches, δ sums, the
// quadrature it buys). Derivation: docs/math/occupancy.md.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/parallel.h"
#include "render/compositor.h"
#include "render/occupancy.h"
#include "test/fixtures.h"
#include "test/gradcheck.h"
#include "train/trainer.h"

using namespace hashcc;
using namespace hashcc::test;

namespace {

// Rays along +z through the NDC box: o = (x, y, −1), d = (0, 0, 2), so the point at s has
// z = −1 + 2s (s = 1 is the far face), and jittered s_in = (k + U)/S.
struct ZRays {
  int64_t R;
  int S;
  std::vector<double> o, d, s_in;
  ZRays(int64_t R_, int S_, uint64_t seed) : R(R_), S(S_), o(3 * R_), d(3 * R_), s_in(R_ * S_) {
    Rng rng(seed);
    for (int64_t r = 0; r < R; ++r) {
      o[3 * r] = rng.uniform(-0.9, 0.9);
      o[3 * r + 1] = rng.uniform(-0.9, 0.9);
      o[3 * r + 2] = -1;
      d[3 * r + 2] = 2;
      for (int k = 0; k < S; ++k) s_in[r * S + k] = (k + rng.uniform()) / S;
    }
  }
};

struct Samples {
  std::vector<double> s, delta;
};

Samples sample(const OccupancyGrid& g, const ZRays& z) {
  Samples out{std::vector<double>(z.R * z.S), std::vector<double>(z.R * z.S)};
  occupancy_samples(out.s.data(), out.delta.data(), g, z.o.data(), z.d.data(), z.s_in.data(), z.R,
                    z.S);
  return out;
}

// A grid whose cells with z index in [z0, z1] hold σ = big, the rest 0 (then dilated).
OccupancyGrid slab_grid(const OccupancyOptions& opt, int z0, int z1, float big = 1e3f) {
  OccupancyGrid g(opt);
  const int G = opt.res;
  auto& sig = g.cell_sigma();
  for (int64_t c = 0; c < int64_t(G) * G * G; ++c) {
    const int iz = int(c / (int64_t(G) * G));
    sig[c] = iz >= z0 && iz <= z1 ? big : 0.f;
  }
  g.rebuild();
  return g;
}

}  // namespace

TEST_CASE("occupancy sampler: every probe occupied and P = S is exactly the uniform jitter",
          "[occupancy]") {
  OccupancyOptions opt;
  opt.probes = 32;
  const OccupancyGrid g(opt);  // fresh: every cell unmeasured, so occupied
  CHECK(g.occupied_fraction() == 1.0);
  const ZRays z(5, 32, 1);
  const Samples sm = sample(g, z);
  double worst = 0;
  for (size_t i = 0; i < sm.s.size(); ++i) hashcc::test::keep_worst(worst, std::abs(sm.s[i] - z.s_in[i]));
  CHECK(report("occupancy s vs uniform jitter", worst, 1e-14) < 1e-14);
  for (int64_t r = 0; r < z.R; ++r)
    for (int k = 0; k < z.S; ++k)
      CHECK(sm.delta[r * z.S + k] == (k + 1 < z.S ? Approx(1.0 / 32).epsilon(1e-14) : Approx(kLastDelta)));
}

TEST_CASE("occupancy sampler: samples only where the probes are occupied; δ sums to the "
          "occupied length", "[occupancy][hard]") {
  OccupancyOptions opt;
  opt.res = 32;
  opt.probes = 128;
  // Cells z ∈ [12, 15] (z from −0.25 to 0; dilated: [11, 16], z ∈ [−0.3125, 0.0625]).
  const OccupancyGrid g = slab_grid(opt, 12, 15);
  const ZRays z(7, 16, 2);
  const Samples sm = sample(g, z);
  const int P = opt.probes;
  for (int64_t r = 0; r < z.R; ++r) {
    double len = 0;
    for (int j = 0; j + 1 < P; ++j) {
      const double sc = (j + 0.5) / P;
      const float x[3] = {float(z.o[3 * r]), float(z.o[3 * r + 1]), float(-1 + 2 * sc)};
      len += g.occupied(x) ? 1.0 / P : 0.0;
    }
    REQUIRE(len > 0);
    CHECK(len < 0.25);  // the slab and its dilation: 6 of 32 cells in z, 3/16 of the ray
    double sum = 0;
    for (int k = 0; k + 1 < z.S; ++k) {
      const double s = sm.s[r * z.S + k];
      const int j = int(s * P);
      const float xc[3] = {float(z.o[3 * r]), float(z.o[3 * r + 1]), float(-1 + 2 * (j + 0.5) / P)};
      CHECK(g.occupied(xc));  // in an occupied probe interval
      if (k > 0) CHECK(s > sm.s[r * z.S + k - 1]);  // increasing
      sum += sm.delta[r * z.S + k];
    }
    CHECK(sum == Approx(len).epsilon(1e-12));
    const double last = sm.s[r * z.S + z.S - 1];
    CHECK(last >= double(P - 1) / P);  // the far interval keeps the last sample
    CHECK(sm.delta[r * z.S + z.S - 1] == kLastDelta);
  }
  SECTION("a ray outside the box samples uniformly (outside counts as occupied)") {
    ZRays out = z;
    for (int64_t r = 0; r < out.R; ++r) out.o[3 * r] = 1.5;
    OccupancyOptions o2 = opt;
    o2.probes = 16;
    const OccupancyGrid g2 = slab_grid(o2, 12, 15);
    const Samples s2 = sample(g2, out);
    for (size_t i = 0; i < s2.s.size(); ++i) CHECK(s2.s[i] == Approx(out.s_in[i]).margin(1e-14));
  }
  SECTION("nothing occupied: the uniform fallback") {
    OccupancyOptions o3 = opt;
    o3.probes = 16;
    const OccupancyGrid g3 = slab_grid(o3, 0, -1);  // no slab
    CHECK(g3.occupied_fraction() == 0.0);
    const Samples s3 = sample(g3, z);
    for (size_t i = 0; i < s3.s.size(); ++i) CHECK(s3.s[i] == Approx(z.s_in[i]).margin(1e-14));
  }
}

TEST_CASE("occupancy sampling integrates a slab better than uniform sampling with as many "
          "samples", "[occupancy]") {
  // σ(s) = 40 on the slab s ∈ [a, b] (the cells z ∈ [12, 15] of a 32³ grid: z ∈ [−0.25, 0)),
  // 0 elsewhere; colour c(s) = (s, 1 − s, 0.5 + 0.5 sin 20s). Reference: 20,000 uniform samples.
  const double a = 0.375, b = 0.5;
  auto sigma = [&](double s) { return s >= a && s < b ? 40.0 : 0.0; };
  auto composite = [&](const std::vector<double>& s, const std::vector<double>* delta, int S) {
    std::vector<double> sg(S), col(3 * S), rgb(3), op(1);
    for (int k = 0; k < S; ++k) {
      sg[k] = sigma(s[k]);
      col[3 * k] = s[k];
      col[3 * k + 1] = 1 - s[k];
      col[3 * k + 2] = 0.5 + 0.5 * std::sin(20 * s[k]);
    }
    composite_forward<double>({rgb.data(), nullptr, nullptr, op.data()},
                              {sg.data(), col.data(), nullptr, s.data(), 1, S,
                               delta ? delta->data() : nullptr});
    return std::vector<double>{rgb[0], rgb[1], rgb[2], op[0]};
  };
  const int Sref = 20000;
  std::vector<double> sref(Sref);
  for (int k = 0; k < Sref; ++k) sref[k] = (k + 0.5) / Sref;
  const std::vector<double> ref = composite(sref, nullptr, Sref);
  REQUIRE(ref[3] > 0.9);  // the slab is nearly opaque: 40 · 0.125 = 5 optical depths

  OccupancyOptions opt;
  opt.res = 32;
  opt.probes = 256;
  const OccupancyGrid g = slab_grid(opt, 12, 15);
  const int S = 16;
  double err_occ = 0, err_uni = 0;
  for (uint64_t seed = 0; seed < 20; ++seed) {
    const ZRays z(1, S, 100 + seed);
    const Samples sm = sample(g, z);
    const auto occ = composite(sm.s, &sm.delta, S);
    const auto uni = composite(z.s_in, nullptr, S);
    for (int i = 0; i < 4; ++i) {
      hashcc::test::keep_worst(err_occ, std::abs(occ[i] - ref[i]));
      hashcc::test::keep_worst(err_uni, std::abs(uni[i] - ref[i]));
    }
  }
  report("occupancy 16 samples: worst error vs 20,000", err_occ, 0);
  report("uniform 16 samples: worst error vs 20,000", err_uni, 0);
  CHECK(err_occ < 0.05);
  CHECK(err_occ < 0.5 * err_uni);
}

TEST_CASE("occupancy grid update: measured cells, dilation, decay, the box", "[occupancy]") {
  OccupancyOptions opt;
  opt.res = 16;
  opt.probes = 64;
  opt.decay = 0.5;
  OccupancyGrid g(opt);
  double level = 100;  // σ of the slab z ∈ [0, 0.25): cells 8 and 9 in z
  const DensityFn slab = [&](const float* x, int64_t n, float* s) {
    for (int64_t i = 0; i < n; ++i) s[i] = x[3 * i + 2] >= 0.f && x[3 * i + 2] < 0.25f ? float(level) : 0.f;
  };
  g.update_all(slab, 7);
  CHECK(g.updates() == opt.parts);
  auto occ = [&](float x, float y, float z) { const float p[3] = {x, y, z}; return g.occupied(p); };
  CHECK(occ(0.1f, 0.2f, 0.1f));     // in the slab
  CHECK(occ(0.1f, 0.2f, -0.1f));    // the dilated cell before it (z cell 7)
  CHECK(occ(0.1f, 0.2f, 0.3f));     // the dilated cell after it (z cell 10)
  CHECK_FALSE(occ(0.1f, 0.2f, -0.5f));
  CHECK_FALSE(occ(0.1f, 0.2f, 0.9f));
  CHECK(occ(1.5f, 0.2f, -0.5f));    // outside the box
  CHECK(g.occupied_fraction() == Approx(4.0 / 16));  // z cells 7..10 of 16
  SECTION("a cell stays occupied while its decayed σ could still be seen, then empties") {
    level = 0;
    // σ·(1/P) ≥ 0.01 ⇔ σ ≥ 0.64: 100 · 0.5^n ≥ 0.64 for n ≤ 7 full rounds.
    for (int round = 0; round < 7; ++round) g.update_all(slab, 8 + round);
    CHECK(occ(0.1f, 0.2f, 0.1f));
    g.update_all(slab, 20);
    CHECK_FALSE(occ(0.1f, 0.2f, 0.1f));
    CHECK(g.occupied_fraction() == 0.0);
  }
  SECTION("one update re-measures one part of the cells only") {
    level = 0;
    g.update(slab, 30);
    int halved = 0, kept = 0;  // the slab's 2 · 16² cells: 1/8 re-measured (decayed to 50)
    for (float v : g.cell_sigma()) {
      halved += v == 50.f;
      kept += v == 100.f;
    }
    CHECK(halved == 64);
    CHECK(kept == 448);
    CHECK(g.occupied_fraction() == Approx(4.0 / 16));  // 50 is still visible
  }
}

TEST_CASE("--occupancy: config keys round-trip, bad settings are refused naming the flag, a run "
          "trains with it", "[occupancy][cli]") {
  TrainConfig c;
  c.occupancy = true;
  c.occupancy_start = 0.25;
  c.occupancy_every = 4;
  c.occupancy_res = 32;
  c.occupancy_probes = 200;
  const TrainConfig d = train_config_from_json(train_config_json(c), "config.json");
  CHECK(d.occupancy);
  CHECK(d.occupancy_start == 0.25);
  CHECK(d.occupancy_every == 4);
  CHECK(d.occupancy_res == 32);
  CHECK(d.occupancy_probes == 200);
  CHECK(train_config_json(d) == train_config_json(c));

  const std::string data = test::sim_scene("cli", 6, 40, 30);
  auto train = [&](const std::string& name, std::vector<std::string> extra) {
    std::vector<std::string> args = {"train", "--data", data, "--out", test::tmp(name, true),
                                     "--steps", "12", "--field", "grid", "--samples", "8",
                                     "--rays", "64", "--no-progress", "--threads", "1"};
    args.insert(args.end(), extra.begin(), extra.end());
    return test::cli(args);
  };
  CHECK(train("occ_noprobes", {"--occupancy", "on", "--occupancy-probes", "4"}) == 2);  // < samples
  CHECK(train("occ_nondc", {"--occupancy", "on", "--no-ndc"}) == 2);
  // A run that samples with the grid from its first step: finite, and its config says so.
  const std::string out = test::tmp("occ_run", true);
  REQUIRE(test::cli({"train", "--data", data, "--out", out, "--steps", "12", "--field", "grid",
                     "--samples", "8", "--rays", "64", "--no-progress", "--threads", "1",
                     "--occupancy", "on", "--occupancy-start", "0", "--occupancy-every", "2",
                     "--occupancy-res", "16", "--occupancy-probes", "32"}) == 0);
  std::ifstream in(out + "/config.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  CHECK(j.at("occupancy").get<bool>());
  CHECK(j.at("occupancy_probes").get<int>() == 32);
  std::ifstream log(out + "/log.csv");
  std::string line, last;
  while (std::getline(log, line)) last = line;
  CHECK(last.rfind("12,", 0) == 0);  // 12 steps logged
  CHECK(last.find("nan") == std::string::npos);
  // Eval (test-pose refinement and renders) and render sample with the grid, measured anew.
  CHECK(test::cli({"eval", "--run", out, "--refine-epochs", "1", "--no-progress", "--threads", "1"}) == 0);
  CHECK(test::cli({"render", "--run", out, "--out", test::tmp("occ_render", true), "--frames", "2",
                   "--no-progress", "--threads", "1"}) == 0);
}
