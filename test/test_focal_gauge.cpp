// tools/focal_gauge.py, the measure of how far a scene's cameras and points can hide a focal
// error (issue 49; docs/results/scenes/README.md, session 26). Two scenes whose answer is known
// without the tool:
// - a rig that only slides in its image plane (every rotation the identity): a focal f·(1 + ε)
//   is hidden EXACTLY by the scene stretched in depth by (1 + ε) (u = f·X/Z is unchanged when f
//   and Z scale together), so bundle adjustment must reach ~0 px from several px;
// - the built-in scene (cameras turned towards the subject): the turn shows the focal, so the
//   error stays above zero, yet most of it is absorbed.
// And ε = 0 must give 0 before and after. Needs Python with NumPy, as test_scene_table.cpp;
// where none is found the test FAILS with the reason.
#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sys/wait.h>

#include "test/fixtures.h"
#include "test/shared_data.h"

namespace fs = std::filesystem;
using namespace hashcc;

namespace {

// Runs focal_gauge.py on `scene` for the given ε (%); returns its JSON cells.
nlohmann::json gauge(const std::string& py, const fs::path& scene, const std::string& eps,
                     const fs::path& work) {
  const fs::path js = work / "gauge.json", out = work / "gauge.txt";
  const std::string cmd = fmt::format(
      "OPENBLAS_NUM_THREADS=1 '{}' '{}/tools/focal_gauge.py' --eps={} --points-per-view 8 "
      "--iters 40 --json '{}' '{}' >'{}' 2>&1",
      py, test::repo_root(), eps, js.string(), scene.string(), out.string());
  const int rc = std::system(cmd.c_str());
  std::ifstream log(out);
  const std::string text((std::istreambuf_iterator<char>(log)), {});
  INFO(text);
  REQUIRE(WIFEXITED(rc));
  REQUIRE(WEXITSTATUS(rc) == 0);
  std::ifstream in(js);
  return nlohmann::json::parse(in);
}

}  // namespace

TEST_CASE("focal_gauge.py: a sliding rig hides any focal error, a turning one cannot", "[tools]") {
  HASHCC_REQUIRE_PYTHON(py, "tools/focal_gauge.py");
  const fs::path work = test::fresh_dir("focal_gauge");

  SECTION("cameras that only slide in their image plane: the depth takes the whole error") {
    // 9 cameras on a 3 × 3 grid in the image plane, all looking along −z (LLFF columns
    // [down, right, back] = [−y, x, z]), 64 × 48 px, f = 50, near 2, far 10.
    const fs::path scene = work / "slide";
    fs::create_directories(scene);
    const std::string mk = fmt::format(
        "'{}' -c \"import numpy as np; rows = []\n"
        "for i in range(9):\n"
        "    P = np.zeros((3, 5)); P[:, 0] = [0, -1, 0]; P[:, 1] = [1, 0, 0]; P[:, 2] = [0, 0, 1]\n"
        "    P[:, 3] = [0.3 * (i % 3 - 1), 0.2 * (i // 3 - 1), 0]; P[:, 4] = [48, 64, 50]\n"
        "    rows.append(np.concatenate([P.ravel(), [2.0, 10.0]]))\n"
        "np.save('{}', np.array(rows))\"",
        py, (scene / "poses_bounds.npy").string());
    REQUIRE(std::system(mk.c_str()) == 0);
    const auto cells = gauge(py, scene, "0,10", work);
    REQUIRE(cells.size() == 2);
    CHECK(cells[0]["before_px"].get<double>() == 0.0);
    CHECK(cells[0]["after_px"].get<double>() < 1e-9);
    CHECK(cells[1]["before_px"].get<double>() > 0.5);   // the wrong focal, nothing moved
    CHECK(cells[1]["after_px"].get<double>() < 1e-4);   // hidden completely
    CHECK(cells[1]["rel_rot_deg"].get<double>() < 1e-3);  // without turning any camera
  }

  SECTION("the built-in scene's turning cameras: most of the error hidden, not all") {
    const fs::path scene = work / "sim";
    REQUIRE(test::cli({"simulate", "--out", scene.string(), "--views", "12", "--width", "64",
                       "--height", "48"}) == 0);
    const auto cells = gauge(py, scene, "10", work);
    REQUIRE(cells.size() == 1);
    const double before = cells[0]["before_px"].get<double>(), after = cells[0]["after_px"].get<double>();
    CHECK(before > 1.0);
    CHECK(after < before / 10);  // the cameras and points absorb most of it …
    CHECK(after > 1e-3);         // … but the turn still shows the focal
  }
}
