// The simulator's capture effects (the "zoo", issue 49): each switch does what it says, and a
// default SimOptions is still the built-in scene.
#include <catch2/catch.hpp>
#include <cmath>

#include "core/error.h"
#include "core/llff.h"
#include "tools/simulator.h"
#include "test/fixtures.h"

using namespace hashcc;

namespace {
double angle_deg(const Eigen::Matrix3d& R) {
  return std::acos(std::clamp((R.trace() - 1) / 2, -1.0, 1.0)) * 180 / M_PI;
}
double mean_pairwise_rotation_deg(const std::vector<SimCamera>& rig) {
  double sum = 0;
  int n = 0;
  for (size_t i = 0; i < rig.size(); ++i)
    for (size_t j = i + 1; j < rig.size(); ++j, ++n)
      sum += angle_deg(rig[i].c2w.leftCols<3>().transpose() * rig[j].c2w.leftCols<3>());
  return sum / n;
}
}  // namespace

TEST_CASE("zoo: --fov sets the focal; 0 keeps the built-in 0.8 x width", "[simulate][zoo]") {
  SimOptions o;
  o.width = 100;
  CHECK(o.focal_px() == Approx(80).epsilon(1e-12));
  o.fov_deg = 90;  // tan(45°) = 1: the focal is half the width
  CHECK(o.focal_px() == Approx(50).epsilon(1e-12));
  o.fov_deg = 40;
  CHECK(2 * std::atan(0.5 * o.width / o.focal_px()) * 180 / M_PI == Approx(40).epsilon(1e-12));
  // The written scene carries it: the loader reads the same focal back.
  o.width = 40;
  o.height = 30;
  o.views = 9;
  o.supersample = 1;
  const std::string d = test::fresh_dir("zoo_fov");
  write_sim_scene(d, o, false);
  CHECK(load_scene(d).ref_focal == Approx(o.focal_px()).epsilon(1e-9));
}

TEST_CASE("zoo: a sweep walks an arc left to right, every camera turned to the focus point",
          "[simulate][zoo]") {
  SimOptions o;
  o.sweep = true;
  o.views = 31;
  o.sweep_deg = 24;
  o.rot_jitter_deg = 0;  // the arc alone: each camera looks exactly at the focus
  const auto rig = make_sim_rig(o);
  const Eigen::Vector3d focus(0, 0, -o.focus_depth);
  for (size_t i = 0; i < rig.size(); ++i) {
    const Eigen::Vector3d c = rig[i].c2w.col(3), back = rig[i].c2w.col(2);
    // The optical axis (−back) points at the focus, up to the centre's vertical wander.
    const Eigen::Vector3d to_focus = (focus - c).normalized();
    CHECK(std::acos(std::clamp(-back.dot(to_focus), -1.0, 1.0)) * 180 / M_PI < 0.5);
    // Left to right: the arc advances 0.8° a view and each view's place on it jitters by 0.5°
    // (a hand), so neighbours may swap but four views on the order holds.
    if (i >= 4) CHECK(c.x() > rig[i - 4].c2w(0, 3));
  }
  // The yaw spread is the arc's: first to last ≈ sweep_deg, pairwise mean ≈ sweep_deg / 3.
  const double ends = angle_deg(rig.front().c2w.leftCols<3>().transpose() *
                                rig.back().c2w.leftCols<3>());
  CHECK(ends == Approx(24).margin(2.5));
  CHECK(mean_pairwise_rotation_deg(rig) == Approx(8).margin(1.5));
  // A wider arc turns the cameras more: the switch is what sets the rotation spread.
  o.sweep_deg = 48;
  CHECK(mean_pairwise_rotation_deg(make_sim_rig(o)) > 1.7 * 8);
}

TEST_CASE("zoo: the backdrop's depth sets the far bound; the near subject stays", "[simulate][zoo]") {
  SimOptions o;
  o.width = 48;
  o.height = 36;
  o.views = 9;
  o.supersample = 1;
  const std::string near_dir = test::fresh_dir("zoo_back8"), far_dir = test::fresh_dir("zoo_back40");
  write_sim_scene(near_dir, o, false);
  o.backdrop_depth = 40;
  write_sim_scene(far_dir, o, false);
  const Scene a = load_scene(near_dir), b = load_scene(far_dir);
  // Bounds are in raw world units before the loader's scaling: compare far/near ratios.
  const auto ratio = [](const Scene& s) {
    return *std::max_element(s.far.begin(), s.far.end()) /
           *std::min_element(s.near.begin(), s.near.end());
  };
  CHECK(ratio(a) < 7);
  CHECK(ratio(b) > 3 * ratio(a));
}

TEST_CASE("zoo: out-of-range switches are refused, naming the flag", "[simulate][zoo][hard]") {
  SimOptions o;
  o.width = 16;
  o.height = 12;
  o.views = 3;
  const std::string d = test::fresh_dir("zoo_bad");
  SimOptions bad = o;
  bad.fov_deg = 170;
  CHECK_THROWS_WITH(write_sim_scene(d, bad, false), Catch::Contains("--fov"));
  bad = o;
  bad.backdrop_depth = 5;  // in front of the objects
  CHECK_THROWS_WITH(write_sim_scene(d, bad, false), Catch::Contains("--backdrop-depth"));
  bad = o;
  bad.sweep_deg = 0;
  CHECK_THROWS_WITH(write_sim_scene(d, bad, false), Catch::Contains("--sweep"));
}
