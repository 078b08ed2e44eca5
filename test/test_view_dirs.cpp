// `--view-dirs off`: the colour does not depend on the viewing direction (SH degree 1, a
// constant basis value). Checked where it matters: the model's colour is the same for any
// direction, no gradient reaches the direction (so none reaches the camera through it), and
// the CLI writes it into the run's config and refuses it where it has no meaning.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "model/model.h"
#include "test/fixtures.h"
#include "test/gradcheck.h"

using namespace hashcc;

namespace {

// Colours and the direction gradient of one random batch for the given directions.
struct Probe {
  std::vector<double> color, d_dir, d_x;
};

Probe probe(const ModelConfig& cfg, const std::vector<double>& dir) {
  const ModelLayout L = make_layout(cfg);
  std::vector<double> p(L.count);
  Rng rng(7, 0);
  init_params(p.data(), cfg, L, rng);
  const int R = 3, S = 5, N = R * S;
  const std::vector<double> x = test::random_vec(N * 3, rng, -0.9, 0.9);
  ModelCache<double> c;
  c.reserve(cfg, R, S);
  const NetView<double> net{p.data(), cfg, L};
  const ModelIn<double> in{x.data(), dir.data(), x.data(), R, S};
  model_forward(c, net, in);
  Probe out;
  out.color.assign(c.color.data(), c.color.data() + N * 3);
  const std::vector<double> d_sigma = test::random_vec(N, rng);
  const std::vector<double> d_color = test::random_vec(N * 3, rng);
  const std::vector<double> d_dcolor = test::random_vec(N * 3, rng);
  out.d_dir.assign(R * 3, 1.0);  // written by the backward: a stale value would show
  out.d_x.assign(N * 3, 0.0);
  model_backward<double>({nullptr, out.d_x.data(), out.d_dir.data()},
                         {d_sigma.data(), d_color.data(), cfg.has_cc() ? d_dcolor.data() : nullptr},
                         c, net, in);
  return out;
}

std::vector<double> unit_dirs(double tilt) {
  std::vector<double> d;
  for (int r = 0; r < 3; ++r) {
    const double a = tilt * (r + 1), v[3] = {std::sin(a), 0.3 * tilt, std::cos(a)};
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (double e : v) d.push_back(e / n);
  }
  return d;
}

}  // namespace

TEST_CASE("--view-dirs off: colour independent of the direction, zero direction gradient",
          "[model][viewdirs]") {
  for (Variant v : {Variant::sh, Variant::hashcc})
    for (Field f : {Field::mlp, Field::grid}) {
      CAPTURE(variant_name(v), field_name(f));
      ModelConfig cfg = tiny_model_config(v, f);
      // Degree 4 (the default): the colour does move with the direction — the probe can fail.
      const Probe a4 = probe(cfg, unit_dirs(0.1)), b4 = probe(cfg, unit_dirs(0.7));
      CHECK(a4.color != b4.color);
      double any = 0;
      for (double g : a4.d_dir) any = std::max(any, std::abs(g));
      CHECK(any > 0);
      cfg.sh_degree = 1;
      const Probe a = probe(cfg, unit_dirs(0.1)), b = probe(cfg, unit_dirs(0.7));
      CHECK(a.color == b.color);  // bitwise: the direction enters only through a constant
      for (double g : a.d_dir) CHECK(g == 0.0);
      CHECK(a.d_x == b.d_x);      // the position gradient does not see the direction either
    }
}

TEST_CASE("--view-dirs off: in the run's config; refused with nerfmm", "[cli][viewdirs]") {
  const std::string data = test::sim_scene("cli", 6, 40, 30);
  const std::string out = test::tmp("viewdirs_run", true);
  REQUIRE(test::cli({"train", "--data", data, "--out", out, "--steps", "2", "--width", "16",
                     "--samples", "8", "--rays", "64", "--view-dirs", "off", "--no-progress",
                     "--threads", "1", "--preset", "paper"}) == 0);
  std::ifstream in(out + "/config.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  CHECK(j.at("sh_degree").get<int>() == 1);
  CHECK(test::cli({"train", "--data", data, "--out", test::tmp("viewdirs_nerfmm", true),
                   "--steps", "2", "--model", "nerfmm", "--view-dirs", "off"}) == 2);
}
