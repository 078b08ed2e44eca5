// Trainer tests: determinism, resume = uninterrupted (bitwise, 1 thread), the divergence
// guard, the run folder, and the end-to-end learning test on the simulated scene.
#include <catch2/catch.hpp>

#include "test/fixtures.h"

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <limits>
#include <thread>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fileio.h"
#include "core/stats.h"
#include "train/checkpoint.h"
#include "train/trainer.h"
#include "tools/simulator.h"

namespace fs = std::filesystem;
using namespace hashcc;

using hashcc::test::sim_scene;

namespace {


TrainConfig tiny_config(const std::string& data, const std::string& out) {
  return test::tiny_train_config(data, out, 12);
}

}  // namespace

TEST_CASE("trainer: same seed, same parameters; resume equals uninterrupted", "[trainer]") {
  std::string data = sim_scene("resume", 6, 40, 30);
  std::string a = (fs::temp_directory_path() / "hashcc_tr_runA").string();
  std::string b = (fs::temp_directory_path() / "hashcc_tr_runB").string();
  fs::remove_all(a);
  fs::remove_all(b);
  int threads = num_threads();
  set_num_threads(1);
  Trainer ta(tiny_config(data, a));
  REQUIRE(ta.run());
  REQUIRE(ta.state().step == 12);
  // B: 5 steps, checkpoint, a fresh process-like resume, then the rest.
  {
    TrainConfig cb = tiny_config(data, b);
    Trainer tb(cb);
    for (int i = 0; i < 5; ++i) tb.step_once();
    tb.save_checkpoint_now();
  }
  Trainer tb = Trainer::resume(b);
  REQUIRE(tb.state().step == 5);
  REQUIRE(tb.run());
  set_num_threads(threads);
  REQUIRE(tb.state().step == 12);
  CHECK(ta.state().net == tb.state().net);        // bitwise
  CHECK(ta.state().poses == tb.state().poses);
  CHECK(ta.state().focal == tb.state().focal);
  CHECK(ta.state().net_m == tb.state().net_m);
  // The run folder.
  for (auto f : {"config.json", "log.csv", "checkpoint.bin", "cameras.json", "preview.png"})
    CHECK(fs::exists(a + "/" + f));
  auto cams = nlohmann::json::parse(read_file_bytes(a + "/cameras.json", 1 << 20));
  CHECK(cams["frames"].size() == ta.scene().train.size());
  CHECK(cams["w"] == 40);
  std::ifstream log(b + "/log.csv");
  int lines = 0;
  for (std::string l; std::getline(log, l);) ++lines;
  CHECK(lines == 1 + 12 - 5);  // header + the steps run() logged after the resume
}

TEST_CASE("trainer: reading a run (eval, --cameras-from) leaves it as it is; only --resume trims its log",
          "[trainer]") {
  // A run whose log goes on past its checkpoint, as after a crash between two checkpoints.
  std::string data = sim_scene("readonly", 6, 40, 30);
  std::string a = (fs::temp_directory_path() / "hashcc_tr_readonly").string();
  fs::remove_all(a);
  int threads = num_threads();
  set_num_threads(1);
  {
    Trainer t(tiny_config(data, a));
    for (int i = 0; i < 3; ++i) t.step_once();
    t.save_checkpoint_now();
  }
  const std::string log_path = a + "/log.csv";
  const std::string before = read_file_bytes(log_path, 1 << 20);
  const std::string past = before +
                           "4,0.1,0.05,13,13,0.001,0.001,0.001,40,40\n"
                           "5,0.2,0.05,13,13,0.001,0.001,0.001,40,40\n";
  write_file_atomic(log_path, past);
  const Trainer opened = Trainer::open(a);
  CHECK(opened.state().step == 3);
  CHECK(read_file_bytes(log_path, 1 << 20) == past);  // byte for byte
  // A run started from its cameras reads it the same way (it used to trim the log, and two runs
  // started from one folder at once raced on the trim's temporary file).
  TrainConfig c = tiny_config(data, a + "_next");
  c.cameras_from = a;
  const Trainer next(c);
  CHECK(next.state().poses == opened.state().poses);
  CHECK(next.state().focal == opened.state().focal);
  CHECK(read_file_bytes(log_path, 1 << 20) == past);
  // --resume continues the run: the rows after the checkpoint's step go.
  const Trainer resumed = Trainer::resume(a);
  set_num_threads(threads);
  const std::string trimmed = read_file_bytes(log_path, 1 << 20);
  CHECK(trimmed == before);
}

TEST_CASE("trainer: the cameras move and the loss falls", "[trainer]") {
  std::string data = sim_scene("learn", 6, 40, 30);
  TrainConfig c = tiny_config(data, "");
  c.steps = 60;
  Trainer t(c);
  // Mean loss over the first and the last epoch: one step's loss depends on its image and
  // rays, so comparing two single steps would test the draw, not the learning.
  const int n = int(t.scene().train.size());
  REQUIRE(12 * n == 60);
  double first = 0, last = 0;
  for (int i = 0; i < n; ++i) first += t.step_once().loss;
  for (int i = 0; i < 10 * n; ++i) t.step_once();
  for (int i = 0; i < n; ++i) last += t.step_once().loss;
  CHECK(last < 0.8 * first);
  double moved = 0;
  for (float v : t.state().poses) moved += std::abs(v);
  CHECK(moved > 0);
  CHECK(t.state().focal[0] != 1.0f);
}

// Where a named tensor (e.g. "rgb.bias") starts in the flat parameter vector.
static int64_t tensor_offset(const Trainer& t, const std::string& name) {
  for (auto& tv : t.layout().tensors)
    if (tv.name == name) return tv.offset;
  FAIL("no tensor " << name);
  return -1;
}

TEST_CASE("trainer: a non-finite loss never reaches the parameters", "[trainer][hard]") {
  std::string data = sim_scene("nan", 6, 40, 30);
  Trainer t(tiny_config(data, ""));
  const std::vector<float> good = t.state().net;
  // A poisoned weight after which nothing can hide it (no ReLU): the colour bias.
  t.mutable_state().net[tensor_offset(t, "rgb.bias")] = std::nanf("");  // every loss is NaN now
  FiniteChecksOff nan_on_purpose;  // the Debug build's kernel asserts would abort here
  auto r = t.step_once();
  CHECK_FALSE(std::isfinite(r.loss));
  CHECK(t.state().net == good);          // restored to the last good state
  CHECK(t.state().lr_scale == 0.5);      // and the networks' lr halved
  CHECK(t.state().step == 0);
  auto r2 = t.step_once();
  CHECK(std::isfinite(r2.loss));
  CHECK(t.state().step == 1);
}

TEST_CASE("trainer: an empty field (density 0 everywhere) is restored, not trained on", "[trainer][hard]") {
  // σ = relu(σ_raw). With σ_raw < 0 at every sample the render is black and every network
  // gradient is exactly 0: without the guard the run would sit there for good (fern,
  // --preset laptop --c2f 0.5, sat there from step 73 until it was stopped at 765 s).
  std::string data = sim_scene("empty", 6, 40, 30);
  Trainer t(tiny_config(data, ""));
  const std::vector<float> good = t.state().net;
  t.mutable_state().net[tensor_offset(t, "density.bias")] = -1e4f;  // σ_raw ≪ 0 at every sample: an empty field
  t.mutable_state().planned_steps = 1234;  // as a --minutes run has after its first steps
  t.mutable_state().plan_refined = true;
  auto r = t.step_once();
  CHECK(std::isfinite(r.loss));
  CHECK(r.loss > 0);                     // the black render is far from the images
  CHECK(t.state().diverged == 1);        // the guard fired
  CHECK(t.state().net == good);          // restored to the last good state
  CHECK(t.state().lr_scale == 0.5);      // and the networks' lr halved
  CHECK(t.state().step == 0);
  CHECK(t.state().planned_steps == 1234);  // the time plan is kept (the last good state's is 0)
  CHECK_FALSE(t.state().plan_refined);     // and refined again: the lost steps must be redone
  t.step_once();                         // a healthy field trains on: the guard stays quiet
  CHECK(t.state().diverged == 1);
  CHECK(t.state().step == 1);
}

TEST_CASE("checkpoint: truncated, foreign and bit-flipped files are clear errors", "[trainer][hard]") {
  Checkpoint c;
  c.put_text("state", "{}");
  std::vector<float> v = {1, 2, 3};
  c.put_floats("net", v);
  std::string bytes = c.serialize();
  REQUIRE(Checkpoint::parse(bytes, "ck").floats("net", "ck", 3) == v);
  REQUIRE_THROWS_WITH(Checkpoint::parse(bytes.substr(0, bytes.size() - 3), "ck"), Catch::Contains("truncated"));
  std::string flipped = bytes;
  flipped[30] ^= 0x10;
  REQUIRE_THROWS_WITH(Checkpoint::parse(flipped, "ck"), Catch::Contains("checksum"));
  std::string version = bytes;
  version[8] = 99;
  REQUIRE_THROWS_WITH(Checkpoint::parse(version, "ck"), Catch::Contains("version 99"));
  REQUIRE_THROWS_WITH(Checkpoint::parse("PK\x03\x04 not a checkpoint at all, a zip file..", "ck"),
                      Catch::Contains("not a hashcc checkpoint"));
  REQUIRE_THROWS_WITH(Checkpoint::parse(bytes, "ck").floats("net", "ck", 4), Catch::Contains("holds 3 values"));
}

TEST_CASE("checkpoint: a file written from views of the state is the serialized file, byte for byte",
          "[trainer]") {
  // Trainer::save_checkpoint_now writes from views (CheckpointView: no copy of the state); the
  // format is Checkpoint::serialize's, sections in name order whatever the order they were put.
  const std::vector<float> net = {1.5f, -0.f, 3e-9f, 7}, m = {0.25f}, empty;
  const std::string state = "{\"step\":3}";
  Checkpoint c;
  c.put_text("state", state);
  c.put_floats("net", net);
  c.put_floats("net.m", m);
  c.put_floats("empty", empty);
  CheckpointView v;
  v.put_floats("net.m", m);
  v.put_floats("empty", empty);
  v.put_floats("net", net);
  v.put_text("state", state);
  const std::string path = (fs::temp_directory_path() / "hashcc_ck_view.bin").string();
  save_checkpoint(path, v);
  const std::string bytes = read_file_bytes(path, 1 << 20);
  CHECK(bytes == c.serialize());
  const Checkpoint back = load_checkpoint(path);
  CHECK(back.sections == c.sections);
  CHECK(back.floats("net", path, 4) == net);
  save_checkpoint(path, c);  // the owning form takes the same path
  CHECK(read_file_bytes(path, 1 << 20) == bytes);
  fs::remove(path);
}

TEST_CASE("checkpoint: a failed write keeps the previous checkpoint", "[trainer][hard]") {
  std::string data = sim_scene("disk", 6, 40, 30);
  std::string out = (fs::temp_directory_path() / "hashcc_tr_disk_run").string();
  fs::remove_all(out);
  Trainer t(tiny_config(data, out));
  t.step_once();
  t.save_checkpoint_now();
  std::string before = read_file_bytes(out + "/checkpoint.bin", 1 << 30);
  t.step_once();
  inject_write_failure_after(1);
  REQUIRE_THROWS_WITH(t.save_checkpoint_now(), Catch::Contains("previous file is kept"));
  CHECK(read_file_bytes(out + "/checkpoint.bin", 1 << 30) == before);
  CHECK_FALSE(fs::exists(out + "/checkpoint.bin.tmp"));
  Trainer r = Trainer::resume(out);
  CHECK(r.state().step == 1);
}

TEST_CASE("trainer: --minutes re-plans when the first plan runs out early, refines once, "
          "uses its budget", "[trainer]") {
  // The failure this pins: steps 2–4 (the plan's clock) ran slow — on a loaded machine — so the
  // plan was short and the run stopped before 10% of its budget, unrefined. Here the slowness
  // is injected (a sleep after steps 1–3, inside the plan's clock), so it happens on every
  // machine: budget 3.6 s, three steps of ≥ 0.8 s, a first plan of 5 or 6 steps. Tiny steps
  // after that take milliseconds. Nothing below compares a duration with a constant other than
  // the budget itself.
  const test::ThreadGuard one_thread(1);  // no OpenMP barriers to stall under load
  std::string data = sim_scene("minutes", 6, 40, 30);
  TrainConfig c = tiny_config(data, "");
  c.steps = 0;
  c.minutes = 0.06;  // 3.6 s
  const double budget = c.minutes * 60;
  Trainer t(c);
  int64_t first_plan = 0;
  double elapsed_at_plan = 0;
  REQUIRE(t.run(nullptr, [&](const Trainer& tr) {
    const TrainState& s = tr.state();
    if (s.step <= 3) std::this_thread::sleep_for(std::chrono::milliseconds(800));
    if (s.step == 4) { first_plan = s.planned_steps; elapsed_at_plan = s.elapsed; }
  }));
  const TrainState& s = t.state();
  INFO("first plan " << first_plan << " steps; ended at step " << s.step << " of "
       << s.planned_steps << ", " << s.elapsed << " s of " << budget);
  REQUIRE(first_plan >= 5);        // planned after step 4: at least one step more
  CHECK(first_plan <= 6);          // the injected slow start did make it short
  CHECK(s.step > first_plan);      // ... and the run went on past it (re-planned)
  CHECK(s.plan_refined);           // the refinement at 10% of the budget happened
  CHECK(s.step <= s.planned_steps);
  // It ended by the clock, or by a plan with less than one step's time left. The step time is
  // the run's own since the plan (what the trainer re-plans from); ×2 absorbs the microseconds
  // between the last step and the trainer's reading of the clock.
  const double per_step = (s.elapsed - elapsed_at_plan) / double(s.step - 4);
  CHECK((s.elapsed >= budget || (s.step == s.planned_steps && budget - s.elapsed < 2 * per_step)));
}

TEST_CASE("trainer: --minutes resumed before the refinement refines in the new session",
          "[trainer]") {
  // A run stopped after its first plan (step 4), before the refinement at 10% of the budget
  // (which also needs 5 steps after the plan): the resumed process starts its own refinement
  // clock (the first one's is gone with the process). Budget 30 s; the resumed session sleeps
  // 0.5 s after each step, so it passes 10% (3 s) after ~6 steps whatever the machine's speed,
  // and is stopped once refined (or, failing, after 12 steps).
  const test::ThreadGuard one_thread(1);  // no OpenMP barriers to stall under load
  std::string data = sim_scene("minutes", 6, 40, 30);
  const std::string out = test::fresh_dir("minutes_resume");
  TrainConfig c = tiny_config(data, out);
  c.steps = 0;
  c.minutes = 0.5;
  {
    Trainer t(c);
    std::atomic<bool> stop{false};
    CHECK_FALSE(t.run(&stop, [&](const Trainer& tr) { if (tr.state().step == 4) stop = true; }));
    REQUIRE(t.state().step == 4);
    REQUIRE(t.state().planned_steps > 4);
    REQUIRE_FALSE(t.state().plan_refined);
  }
  Trainer r = Trainer::resume(out);
  REQUIRE(r.state().step == 4);
  std::atomic<bool> stop{false};
  r.run(&stop, [&](const Trainer& tr) {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    if (tr.state().plan_refined || tr.state().step >= 16) stop = true;
  });
  INFO("resumed run stopped at step " << r.state().step << ", " << r.state().elapsed << " s");
  CHECK(r.state().plan_refined);
  CHECK(r.state().step < 16);
}

TEST_CASE("trainer: --c2f raises alpha linearly over its fraction of the plan, then holds",
          "[trainer]") {
  // docs/training.md: α rises 0 → L (10 bands) over the first fraction F of the run;
  // docs/math/grid_field.md: grid levels from --grid-c2f-start to L. Step i (0-based, the value
  // step_once uses for the step it runs) gets α = a0 + (L − a0)·min(1, i / (F·total)).
  std::string data = sim_scene("c2f", 6, 40, 30);
  for (Field f : {Field::mlp, Field::grid}) {
    DYNAMIC_SECTION("field " << field_name(f)) {
      TrainConfig c = tiny_config(data, "");
      c.steps = 20;
      c.c2f_end = 0.5;  // α reaches L at step 10
      c.model.field = f;
      Trainer t(c);
      std::vector<double> alpha;
      REQUIRE(t.run(nullptr, [&](const Trainer& tr) { alpha.push_back(tr.config().model.pos_c2f_alpha); }));
      REQUIRE(alpha.size() == 20);
      const double L = f == Field::grid ? c.model.gf.grid.levels : c.model.pos_bands;
      const double a0 = f == Field::grid ? c.model.gf.c2f_start : 0.0;
      for (int i = 0; i < 20; ++i) {
        INFO("step " << i);
        CHECK(alpha[i] == Approx(a0 + (L - a0) * std::min(1.0, i / 10.0)).epsilon(1e-12).margin(1e-12));
      }
      CHECK(alpha[0] == a0);
      CHECK(alpha[5] == Approx((a0 + L) / 2));  // half-way through the ramp: half-way in α
    }
  }
}

// all_finite (core/stats.h): the divergence guard's check of every gradient entry a step. One
// non-finite value anywhere — first, last, either side of its 4,096-float block boundary, in a
// partial last block — must be seen; finite extremes (±max, subnormals, −0) must pass.
TEST_CASE("all_finite: one Inf or NaN anywhere is seen; finite extremes pass", "[trainer][hard]") {
  const int64_t n = 3 * 4096 + 17;
  std::vector<float> v(n, 1.f);
  v[5] = std::numeric_limits<float>::max();
  v[6] = -std::numeric_limits<float>::max();
  v[7] = std::numeric_limits<float>::denorm_min();
  v[8] = -0.f;
  CHECK(all_finite(v.data(), n));
  CHECK(all_finite(v.data(), 0));
  for (float bad : {std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                    std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::quiet_NaN()})
    for (int64_t at : {int64_t(0), int64_t(4095), int64_t(4096), int64_t(2 * 4096 + 1), n - 1}) {
      INFO("value " << bad << " at " << at);
      std::vector<float> w = v;
      w[at] = bad;
      CHECK_FALSE(all_finite(w.data(), n));
      CHECK(all_finite(w.data(), at));  // the prefix before it is finite
    }
}
