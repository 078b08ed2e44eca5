// The bench's untimed parts: no allocation inside a training step (a counting global operator
// new, enabled only around the measured steps), the dense-FLOP count against
// performance.md's hand count, and the bench's report/JSON shape. Nothing here is timed.
#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <malloc.h>
#include <new>
#include <nlohmann/json.hpp>

#include "train/trainer.h"
#include "tools/bench.h"
#include "test/fixtures.h"
#include "test/shared_data.h"
#include "tools/simulator.h"

namespace {
// Counting allocator: replaces the global operator new for this (one) test binary. Counting is
// off unless g_count_allocs is set, so every other test is unaffected.
std::atomic<bool> g_count_allocs{false};
std::atomic<long> g_allocs{0};
std::atomic<int64_t> g_alloc_bytes{0};  // bytes asked for while counting (not net of frees)
void* counted(std::size_t n) {
  if (g_count_allocs.load(std::memory_order_relaxed)) {
    g_allocs.fetch_add(1);
    g_alloc_bytes.fetch_add(int64_t(n));
  }
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* counted_aligned(std::size_t n, std::align_val_t a) {
  if (g_count_allocs.load(std::memory_order_relaxed)) {
    g_allocs.fetch_add(1);
    g_alloc_bytes.fetch_add(int64_t(n));
  }
  std::size_t al = std::max(sizeof(void*), std::size_t(a));
  void* p = nullptr;
  if (posix_memalign(&p, al, n ? n : 1) == 0) return p;
  throw std::bad_alloc();
}
}  // namespace

void* operator new(std::size_t n) { return counted(n); }
void* operator new[](std::size_t n) { return counted(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try { return counted(n); } catch (...) { return nullptr; }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try { return counted(n); } catch (...) { return nullptr; }
}
void* operator new(std::size_t n, std::align_val_t a) { return counted_aligned(n, a); }
void* operator new[](std::size_t n, std::align_val_t a) { return counted_aligned(n, a); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

namespace fs = std::filesystem;
using namespace hashcc;

namespace {
std::string bench_scene() { return test::sim_scene("bench", 4, 40, 30, 1); }
// sh and hashcc, 1 thread, 2 timed steps of a tiny step on the bench scene.
BenchOptions tiny_bench() {
  BenchOptions o;
  o.variants = {"sh", "hashcc"};
  o.threads = {1};
  o.rays = 64;
  o.samples = 8;
  o.width = 16;
  o.chunk_rays = 16;
  o.steps = 2;
  o.warmup = 1;
  o.scene_dir = bench_scene();
  return o;
}
}  // namespace

TEST_CASE("bench: Trainer::step_once allocates nothing after two warm-up steps", "[bench]") {
  const std::string data = bench_scene();
  for (const char* v : {"nerfmm", "sh", "hashcc"}) {
    // chunk 16 unprofiled and profiled, then the automatic chunk (0)
    for (auto [chunk, profiled] : {std::pair{16, false}, std::pair{16, true}, std::pair{0, false}}) {
      TrainConfig c;
      c.data = data;
      c.model.variant = parse_variant(v);
      c.model.width = 16;
      c.model.rgb_width = 8;
      c.rays = 64;
      c.samples = 16;
      c.chunk_rays = chunk;  // 16: 4 chunks, the data-parallel path when threads > 1
      c.steps = 100;
      c.progress = false;
      Trainer t(c);
      StageTimes st;
      if (profiled) t.set_stage_times(&st);
      t.step_once();
      t.step_once();
      g_allocs = 0;
      g_count_allocs = true;
      for (int i = 0; i < 3; ++i) t.step_once();
      g_count_allocs = false;
      INFO(v << (profiled ? " (profiled)" : "") << ", chunk " << chunk << ": operator new calls in 3 steps");
      CHECK(g_allocs.load() == 0);
    }
  }
}

TEST_CASE("bench: the options beyond the paper allocate nothing either", "[bench][trainer]") {
  // K = 2 images a step, the pyramid switching levels 4 → 2 → 1 inside the counted steps
  // (steps 0–1 at level 4, 2–4 at level 2, then 1), the PSNR-gated camera warm-up, the
  // distortion loss (its weights buffers and the detached second backward for the cameras).
  const std::string data = bench_scene();
  TrainConfig c = test::tiny_train_config(data, "", 10);
  c.chunk_rays = 16;
  c.distortion = 0.01;
  c.images_per_step = 2;
  c.pyramid = 0.5;
  c.camera_start_psnr = 10;
  c.camera_warmup = 2;
  Trainer t(c);
  t.step_once();
  t.step_once();
  REQUIRE(t.pyramid_level_at(2) == 2);
  g_allocs = 0;
  g_count_allocs = true;
  for (int i = 0; i < 5; ++i) t.step_once();
  g_count_allocs = false;
  CHECK(t.pyramid_level_at(t.state().step - 1) == 1);
  CHECK(g_allocs.load() == 0);
}

TEST_CASE("bench: dense FLOPs per step match the hand count", "[bench]") {
  // performance.md: multiply-adds per point, forward: sh 156,736; nerfmm 157,440; CC MLP 2,240.
  ModelConfig m;
  const int64_t N = 1024 * 128;
  m.variant = Variant::sh;
  CHECK(dense_flops_per_step(m, N).main == 3.0 * 2 * 156736 * N);
  CHECK(dense_flops_per_step(m, N).cc == 0);
  m.variant = Variant::nerfmm;
  CHECK(dense_flops_per_step(m, N).main == 3.0 * 2 * 157440 * N);
  m.variant = Variant::hashcc;
  CHECK(dense_flops_per_step(m, N).cc == 3.0 * 2 * 2240 * N);
  // The grid field (math/grid_field.md, performance.md's roofline): 32·64 + 64·16 + 31·64 + 64·3
  // = 5,248 a point with SH-4; the bench's grid step (1,024 rays × 32 samples): 1,031,798,784.
  m.variant = Variant::sh;
  m.field = Field::grid;
  CHECK(dense_flops_per_step(m, 1024 * 32).main == 3.0 * 2 * 5248 * 1024 * 32);
  CHECK(dense_flops_per_step(m, 1024 * 32).main == 1031798784.0);
}

TEST_CASE("bench: a tiny run fills every field of the report and the JSON", "[bench]") {
  BenchReport r = run_bench(tiny_bench());
  REQUIRE(r.runs.size() == 2);
  for (const auto& x : r.runs) {
    CHECK(x.steps == 2);
    CHECK(x.ms.size() == 2);
    CHECK(x.ms_min <= x.ms_median);
    CHECK(x.ms_median <= x.ms_max);
    // Each timed step took a positive, finite wall time (a clock never started reads 0, one
    // never stopped reads huge, a bad subtraction negative), and the mean is theirs.
    double sum = 0;
    for (double ms : x.ms) {
      CHECK(std::isfinite(ms));
      CHECK(ms > 0);
      CHECK(ms < 60e3);  // two tiny steps: well under a minute each
      sum += ms;
    }
    CHECK(x.ms_mean == Approx(sum / double(x.ms.size())).epsilon(1e-12));
    CHECK(x.ms_min == *std::min_element(x.ms.begin(), x.ms.end()));
    CHECK(x.ms_max == *std::max_element(x.ms.begin(), x.ms.end()));
    // A derived figure agrees with the times it is derived from: the MLP's GFLOP/s is the
    // main network's FLOPs over the forward + backward stages' wall time.
    const double mlp_ms = x.stages.wall_ms[kStageMlpFwd] + x.stages.wall_ms[kStageMlpBwd];
    CHECK(x.mlp_gflops == Approx(x.flops_main / (mlp_ms * 1e-3) * 1e-9).epsilon(1e-9));
    CHECK(mlp_ms < x.ms_mean * (1 + 1e-6));  // a part of the step, not more
    // The stages are disjoint parts of each timed step (one thread here): their sum cannot
    // exceed the step's wall time, i.e. other_ms() ≥ 0 up to the clock's rounding (a stage
    // timed twice, or a clock left running across steps, breaks it); and every stage this
    // step runs took some time (a stage never timed reads 0).
    CHECK(x.other_ms() >= -1e-6 * x.ms_mean);
    for (int s : {kStageRays, kStageEncode, kStageMlpFwd, kStageMlpBwd, kStageCompositor, kStageAdam}) {
      INFO("stage " << stage_name(s));
      CHECK(x.stages.wall_ms[s] > 0);
    }
    CHECK(x.flops_main > 0);
    CHECK(x.chunk_rays == 16);  // as set (tiny_bench)
    CHECK(x.chunk_mib > 0);
  }
  CHECK(r.runs[0].stages.wall_ms[kStageCC] == 0);  // sh has no CC branch
  CHECK(r.runs[1].stages.wall_ms[kStageCC] > 0);
  CHECK(r.cc_overhead > 0);
  CHECK(r.nominal.gflops() > 0);
  auto j = nlohmann::json::parse(bench_json(r));
  for (const char* k : {"peak_gflops", "peak_nominal_gflops", "cc_overhead", "load_average", "runs"})
    CHECK(j.contains(k));
  for (const auto& run : j["runs"])
    for (const char* k : {"variant", "threads", "ms_per_step", "ms_min", "ms_max", "cpu_ms_per_step",
                          "stages", "mlp_gflops", "peak_fraction", "chunk_rays", "chunk_mib"})
      CHECK(run.contains(k));
  CHECK(j["runs"][0]["stages"].contains("encodings"));
  CHECK(!bench_table(r).empty());
}

TEST_CASE("bench: --distortion times each variant with the loss on, alternated with it off", "[bench]") {
  BenchOptions o = tiny_bench();
  o.distortion = 0.01;
  BenchReport r = run_bench(o);
  REQUIRE(r.runs.size() == 4);  // per variant: off, on
  for (int i = 0; i < 4; ++i) {
    CHECK(r.runs[i].distortion == (i % 2 ? 0.01 : 0.0));
    CHECK(r.runs[i].variant == (i < 2 ? "sh" : "hashcc"));
    CHECK(r.runs[i].steps == 2);
  }
  REQUIRE(r.distortion_cost.size() == 2);
  CHECK(r.distortion_cost[0].variant == "sh");
  CHECK(r.distortion_cost[0].wall > 0);
  CHECK(r.distortion_cost[1].cpu > 0);
  // The CC overhead still compares the runs without the loss.
  REQUIRE(r.cc_overhead_by_threads.size() == 1);
  CHECK(r.cc_overhead == r.runs[2].ms_median / r.runs[0].ms_median);
  auto j = nlohmann::json::parse(bench_json(r));
  CHECK(j["runs"][1]["distortion"] == 0.01);
  CHECK(j["distortion_cost"].size() == 2);
  CHECK(bench_table(r).find("sh+dist") != std::string::npos);
  o.distortion = -1;
  CHECK_THROWS_WITH(run_bench(o), Catch::Contains("--distortion"));
}

namespace {
// A grid-field run whose parameters (a 2^14 table: 2 MiB of floats) outweigh everything else a
// tiny step holds, so a parameter-sized buffer shows in the bytes allocated.
TrainConfig big_table_run(const std::string& data, const std::string& out, int64_t steps) {
  TrainConfig c = test::tiny_train_config(data, out, steps);
  c.model.field = Field::grid;
  c.model.gf.grid.log2_table = 14;
  c.rays = 64;
  c.samples = 8;
  return c;
}
// Bytes allocated (operator new, not net of frees) while f runs.
template <class F> int64_t bytes_allocated(F&& f) {
  g_alloc_bytes = 0;
  g_count_allocs = true;
  f();
  g_count_allocs = false;
  return g_alloc_bytes.load();
}
}  // namespace

TEST_CASE("memory: --cameras-from reads the earlier run's cameras, not a whole second trainer",
          "[bench][trainer]") {
  // Issue 51's 300 MiB: a stage used to open the stage before as a Trainer (its network, Adam
  // moments, divergence-guard copy, gradient and buffers, and a copy of every checkpoint
  // section): about 13 parameter-sized buffers allocated beside the new stage's own. Now only the
  // checkpoint file's bytes (3: network and moments) pass through, and its camera sections.
  const std::string data = bench_scene();
  const std::string out = test::tmp("bench_mem_camfrom", true);
  {
    Trainer first(big_table_run(data, out + "/stage1", 2));
    first.run();
  }
  const int64_t P = int64_t(sizeof(float)) * make_layout(big_table_run(data, "", 1).model).count;
  REQUIRE(P > (int64_t(2) << 20));
  TrainConfig fresh = big_table_run(data, out + "/fresh", 2);
  TrainConfig next = big_table_run(data, out + "/stage2", 2);
  next.cameras_from = out + "/stage1";
  { Trainer warm(fresh); }  // the scene is in the cache from here on, for both
  const int64_t b_fresh = bytes_allocated([&] { Trainer t(fresh); });
  const int64_t b_next = bytes_allocated([&] { Trainer t(next); });
  INFO("bytes allocated: fresh " << b_fresh << ", from cameras " << b_next << ", parameters " << P);
  CHECK(b_next - b_fresh < 4 * P);
  CHECK(b_next - b_fresh > 2 * P);  // the checkpoint file is read whole (it is checksummed)
}

TEST_CASE("memory: at 2 threads a step holds one parameter-sized gradient arena, thread 1's",
          "[bench][trainer]") {
  // The data-parallel step's thread 0 adds into the trainer's gradient, zeroed before each step
  // (StepOptions::d_params_zero), instead of into an arena of its own: at 2 threads the first
  // step adds one parameter-sized arena to the heap, not two. The arenas are AlignedVecs (Eigen
  // allocates them with malloc, not operator new), so this counts the heap malloc reports (its
  // main arena: the step sizes its buffers on the calling thread, before the parallel region).
#if defined(__SANITIZE_ADDRESS__)
  HASHCC_SKIP("AddressSanitizer's allocator: mallinfo2 does not see its heap (the Release suite runs this)");
#endif
  const auto heap_in_use = [] {
    const struct mallinfo2 mi = mallinfo2();
    return int64_t(mi.uordblks) + int64_t(mi.hblkhd);  // small blocks in use + mmapped ones
  };
  const std::string data = bench_scene();
  TrainConfig c = big_table_run(data, "", 5);
  c.threads = 2;
  c.chunk_rays = 16;  // 4 chunks: the data-parallel path
  Trainer t(c);
  REQUIRE(num_threads() == 2);
  const int64_t P = int64_t(sizeof(float)) * t.layout().count;
  const int64_t before = heap_in_use();
  t.step_once();
  const int64_t grown = heap_in_use() - before;
  INFO("heap grown by the first step: " << grown << " bytes, parameters " << P);
  CHECK(grown > P);
  CHECK(grown < 2 * P);
}

TEST_CASE("bench --memory: each probe fills its row of the JSON (tiny sizes, nothing asserted on time)",
          "[bench]") {
  BenchMemoryOptions o;
  o.sizes = {16 << 10, 64 << 10};
  o.threads = {1};
  o.seconds = 0.001;
  o.json = test::fresh_dir("memory") + "/memory.json";
  run_bench_memory(o);
  std::ifstream f(o.json);
  const auto j = nlohmann::json::parse(f);
  REQUIRE(j["rows"].size() == 2);
  CHECK(j["rows"][0]["bytes"] == 16 << 10);
  CHECK(j["rows"][1]["bytes"] == 64 << 10);
  for (const auto& r : j["rows"]) {
    CHECK(r["threads"] == 1);
    for (const char* k : {"chase_ns", "gather_ns", "scatter_ns", "read_gbs", "write_gbs"}) {
      CHECK(std::isfinite(r[k].get<double>()));
      CHECK(r[k].get<double>() > 0);
    }
    // A dependent load takes ≥ 3 cycles on any CPU (≥ 0.5 ns at 6 GHz); load only makes it
    // slower. Below 0.1 ns the chase was folded away by the compiler (a first version: 4e-17 ns).
    CHECK(r["chase_ns"].get<double>() > 0.1);
  }
  for (const char* k : {"cpu_model", "isa_compiled", "caches", "load_average", "seconds_per_probe"})
    CHECK(j.contains(k));
}

TEST_CASE("bench --hashgrid: a row per table size and thread count; the outputs' checksum is the "
          "same at 1 and 2 threads (tiny sizes, nothing asserted on time)", "[bench]") {
  test::ThreadGuard guard;
  BenchHashGridOptions o;
  o.log2_tables = {9, 12};
  o.threads = {1, 2};
  o.rays = 64;
  o.samples = 40;  // 2,560 points a call: above the kernels' 2 × 1,024 threading threshold
  o.calls = 2;
  o.reps = 1;
  const std::vector<BenchHashGridRow> rows = run_bench_hashgrid(o);
  REQUIRE(rows.size() == 4);
  for (const BenchHashGridRow& r : rows) {
    CHECK(r.ms_forward > 0);
    CHECK(r.ms_backward > 0);
    CHECK(r.ms_backward_dx > 0);
    CHECK(std::isfinite(r.sum_out_dx));
    CHECK(std::abs(r.sum_out_dx) > 0);
    CHECK(std::abs(r.sum_table) > 0);
  }
  for (int k : {0, 2}) {  // (log2 9: 1 thread, 2 threads), (log2 12: …)
    INFO("log2 table " << rows[k].log2_table);
    CHECK(rows[k].sum_out_dx == rows[k + 1].sum_out_dx);  // every point computed alone
    CHECK(std::abs(rows[k].sum_table - rows[k + 1].sum_table) <= 1e-5 * std::abs(rows[k].sum_table));
  }
  CHECK(rows[0].sum_out_dx != rows[2].sum_out_dx);  // the table size reaches the outputs
}
