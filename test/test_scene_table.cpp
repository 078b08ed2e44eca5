// tools/scene_table.py, the script that writes issue 49's scene table from run folders: what it
// counts must be what the runs trained. A made-up run folder (no training: the files a plan
// writes, with known numbers) whose stage 1 tried two alternatives (a plan's "try": RUN/stage1/
// try1, try2, each with its own log) and then trained stage 2 and the last stage (RUN itself).
// Before session 23 the script crashed on such a run (it looked for RUN/stage1/camera_error.csv).
//
// Needs a Python with NumPy, like test_reference.cpp (tools/install_deps.sh installs it); where
// none is found the test FAILS with the reason rather than passing silently.
#include <catch2/catch.hpp>

#include "test/fixtures.h"
#include "test/shared_data.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <sys/wait.h>

namespace fs = std::filesystem;
using namespace hashcc;

namespace {

void write(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

// A log.csv whose last row is (step, seconds); the columns are hashcc train's.
std::string log_csv(int steps, double seconds) {
  return fmt::format("step,seconds,loss,psnr,psnr_cc,lr_net,lr_pose,lr_focal,fx,fy\n"
                     "1,0.1,0.1,10,10,0.01,0.001,0.001,50,50\n"
                     "{},{},0.01,20,20,0.001,0.0001,0.0001,50,50\n",
                     steps, seconds);
}

// A camera_error.csv: first row (step 0) and last row given as (rel_rot, sim3_dR, fx).
std::string camera_csv(double rel0, double rel, double dR, double fx) {
  return fmt::format("step,seconds,rel_rot_deg,sim3_dR_deg,sim3_dT,fx,fy,ref_focal\n"
                     "0,0.0,{},,,50,50,50\n"
                     "100,1.0,{},{},0.01,{},{},50\n",
                     rel0, rel, dR, fx, fx);
}

// The table.csv row of the one run, as column → text.
std::map<std::string, std::string> table_row(const std::string& csv_path) {
  std::ifstream in(csv_path);
  std::string header, row;
  std::getline(in, header);
  std::getline(in, row);
  std::map<std::string, std::string> out;
  std::stringstream hs(header), rs(row);
  std::string k, v;
  while (std::getline(hs, k, ',')) {
    std::getline(rs, v, ',');
    out[k] = v;
  }
  return out;
}

}  // namespace

TEST_CASE("scene_table.py: a stage that tried alternatives counts every alternative", "[tools]") {
  HASHCC_REQUIRE_PYTHON(py, "tools/scene_table.py");
  const fs::path root = test::fresh_dir("runs");
  const fs::path run = root / "plain_s0";
  // The scene folder need not exist: the do-nothing Sim(3) column is then empty.
  write(run / "config.json", R"({"data": "no_such_scene/plain", "seed": 0, "threads": 1})");
  write(run / "stage1" / "try1" / "log.csv", log_csv(250, 10.0));
  write(run / "stage1" / "try1" / "camera_error.csv", camera_csv(7.25, 3.0, 9.0, 61.5));
  write(run / "stage1" / "try2" / "log.csv", log_csv(250, 12.0));
  write(run / "stage1" / "try2" / "camera_error.csv", camera_csv(7.25, 2.0, 8.0, 45.7));
  write(run / "stage2" / "log.csv", log_csv(100, 5.0));
  write(run / "log.csv", log_csv(400, 33.0));
  // The last stage's cameras: relative rotation 0.5 (do-nothing from try1's first row: 7.25).
  write(run / "camera_error.csv", camera_csv(0.9, 0.5, 2.5, 52.5));

  SECTION("a run without eval: the cameras from camera_error.csv") {
    const std::string cmd = fmt::format("'{}' '{}/tools/scene_table.py' '{}' --write '{}' >'{}' 2>&1",
                                        py, test::repo_root(), root.string(),
                                        (root / "table").string(), (root / "out.txt").string());
    const int rc = std::system(cmd.c_str());
    std::ifstream log(root / "out.txt");
    const std::string text((std::istreambuf_iterator<char>(log)), {});
    INFO(text);
    REQUIRE(WIFEXITED(rc));
    REQUIRE(WEXITSTATUS(rc) == 0);
    auto row = table_row((root / "table" / "table.csv").string());
    CHECK(row["steps"] == "1000");  // 250 + 250 + 100 + 400: both alternatives ran
    CHECK(std::stod(row["minutes"]) == Approx(60.0 / 60).margin(0.05));  // 10 + 12 + 5 + 33 s
    CHECK(std::stod(row["rel_rot_deg"]) == Approx(0.5));
    CHECK(std::stod(row["rel_rot_do_nothing_deg"]) == Approx(7.25));
    CHECK(std::stod(row["sim3_dR_deg"]) == Approx(2.5));
    CHECK(std::stod(row["fx_err_pct"]) == Approx(5.0));  // 52.5 against 50
    CHECK(row["psnr"].empty());
  }
}
