// tools/bench.h — `hashcc bench`: the time of one full training step and where it goes.
//
// A run = one variant at one thread count: a Trainer on the built-in simulated scene (written
// to a temp folder), warm-up steps (the first allocates and warms caches), then timed
// Trainer::step_once() calls — the whole step: pixels, camera + NDC, jitter, every forward and
// backward, the camera backward, the guard and the three Adam updates. Each timed step runs
// with the stage profiler (core/profile.h) on.
//
// FLOPs count only the dense layers, from the ModelLayout: forward 2·in·out per point per
// layer; backward 2× forward (input and weight gradients of every layer, the first trunk
// layer's input gradient included since positions depend on the cameras).
#pragma once
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/profile.h"
#include "model/model.h"

namespace hashcc {

// The FP32 peak of the COMPILED instruction set (core/isa.h), measured: an FMA loop (AVX-512,
// AVX2+FMA or scalar: the widest the build was compiled for, so an avx2 build on an AVX-512 CPU
// divides by the AVX2 peak) with 12 independent accumulators per thread, on `threads` threads.
// gflops_cpu divides each thread's FLOPs by its own CPU time (what the cores do while they
// run — robust on a loaded machine); gflops_wall divides the total by the wall time.
struct PeakMeasure {
  int threads = 1;
  double gflops_cpu = 0, gflops_wall = 0;
  std::string isa;  // the compiled ISA: "avx512", "avx2" or "scalar"
};
PeakMeasure measure_peak(int threads, double seconds = 0.3);

// Nominal peak = cores × FMA units × SIMD lanes × 2 × clock, with how each term was found.
struct NominalPeak {
  int cores = 1, fma_units = 2, lanes = 1;
  double ghz = 0;
  std::string clock_source, isa;
  double gflops() const { return cores * fma_units * lanes * 2.0 * ghz; }
  std::string how() const;  // "2 cores × 2 FMA units × 8 lanes (avx2) × 2 × 2.450 GHz (…)"
};
NominalPeak nominal_peak(int cores);

// Dense-layer FLOPs per step for N = rays·samples points: {main network, CC MLP}, forward +
// backward (= 3 × forward).
struct DenseFlops { double main = 0, cc = 0; };
DenseFlops dense_flops_per_step(const ModelConfig& cfg, int64_t N);

struct BenchOptions {
  std::vector<std::string> variants = {"nerfmm", "sh", "hashcc"};
  std::vector<int> threads;  // empty: {1, all}
  int rays = 1024, samples = 128, width = 128, chunk_rays = 0;  // 0 = auto (model/step.h)
  // Samples per ray of the NAME+grid variants: the grid field's training default (32, train's
  // `--field grid` defaults), so a grid row is the step that field trains with.
  int grid_samples = 32;
  int steps = 0;             // timed steps per run; 0 = as many as fit the time budget (≥ 3)
  int warmup = 1;            // untimed steps first (the first allocates and warms caches)
  double budget_seconds = 50;  // whole bench, when steps == 0
  std::string scene_dir;     // "" = simulate into a temp folder (removed afterwards)
  bool step = true;          // time the training step per variant
  bool dense = false;        // also time the dense layers' GEMMs alone (run_dense_bench)
  int dense_reps = 15;       // repetitions of each dense shape (the median is reported)
  std::string gemm = "kernel";  // steps on: "kernel" (the build's path), "eigen" (forced with
                                // dense_force_eigen) or "both" (alternating step by step)
  // --distortion λ > 0: each variant is also timed with the distortion loss on (StepOptions::
  // distortion, detached from the cameras as in training), on a second trainer alternating step
  // by step with the first (off): the loss's cost as a same-run ratio.
  double distortion = 0;
};

// One dense layer shape timed alone: N = chunk_rays · samples rows (one chunk of the
// data-parallel step), each thread running its own layer on its own buffers at once, as in a
// training step. GFLOP/s = Σ over threads of FLOPs / that thread's CPU time (median over reps).
struct DenseBenchRow {
  std::string path;                // "kernel" (dense_*: the build's path) or "eigen"
  std::string layer;               // e.g. "trunk 128→128"
  int threads = 1, in = 0, out = 0, count = 1;  // count: how many such layers the network has
  int64_t N = 0;
  double fwd_ms = 0, bwd_ms = 0;   // median per-thread CPU ms (mean over threads) per call
  double fwd_gflops = 0, bwd_gflops = 0, peak_gflops = 0;
};

struct BenchRun {
  std::string variant;
  std::string gemm = "kernel";     // "kernel" (the build's path) or "eigen" (forced)
  double distortion = 0;           // the distortion loss's λ of these steps (0: off)
  int threads = 1, rays = 0, samples = 0, width = 0, steps = 0;
  int chunk_rays = 0;              // rays a chunk (the automatic chunk resolved: model/step.h)
  double chunk_mib = 0;            // one chunk's buffers, MiB a thread (chunk_floats)
  std::vector<double> ms;          // wall ms of each timed step
  double ms_median = 0, ms_min = 0, ms_max = 0, ms_q1 = 0, ms_q3 = 0;
  double ms_mean = 0;              // the stages are means too: their % are of this
  double cpu_ms_per_step = 0;      // process CPU time per step (all threads)
  StageTimes stages;               // per step (mean over the timed steps)
  double flops_main = 0, flops_cc = 0;  // dense FLOPs per step
  double mlp_gflops = 0;           // main-network FLOPs / (mlp_fwd + mlp_bwd) wall time
  double mlp_gflops_cpu = 0;       // same over the stages' CPU time
  double step_gflops = 0;          // all dense FLOPs / median step time
  double peak_gflops = 0;          // measured peak at this thread count (CPU-time based)
  double peak_fraction = 0, peak_fraction_cpu = 0;  // mlp_gflops(_cpu) / peak_gflops
  double other_ms() const;         // mean step − Σ stages (wall): glue, reductions, imbalance
};

// Times each of the paper's dense layer shapes (DenseBenchRow) on both GEMM paths, interleaved
// rep by rep, at each thread count; the peaks give each row's peak_gflops.
std::vector<DenseBenchRow> run_dense_bench(const BenchOptions& opt, const std::vector<int>& threads,
                                           const std::vector<PeakMeasure>& peaks,
                                           const std::function<void(const std::string&)>& log);
// The main network's dense layers as a whole on one path at one thread count: Σ count · FLOPs
// over Σ count · time, forward (phase 0), backward (1) or both (2). 0 when nothing was timed.
double dense_network_gflops(const std::vector<DenseBenchRow>& rows, const std::string& path,
                            int threads, int phase);

struct BenchReport {
  std::string isa_compiled, isa_option, isa_cpu;  // core/isa.h
  std::string gemm = "kernel";     // the steps' GEMM path: "kernel" or "eigen" ("both": kernel)
  std::vector<BenchRun> runs;
  std::vector<DenseBenchRow> dense;
  std::vector<PeakMeasure> peaks;  // one per thread count used
  NominalPeak nominal;
  double load_before[3] = {0, 0, 0}, load_after[3] = {0, 0, 0};
  double cc_overhead = 0;          // hashcc ms / sh ms (median wall) at the most threads timed
  double cc_overhead_cpu = 0;      // the same with CPU ms per step (robust on a loaded machine)
  std::vector<std::pair<int, double>> cc_overhead_by_threads, cc_overhead_cpu_by_threads;
  // With BenchOptions::distortion: per variant and thread count, loss on / off (median wall and
  // CPU ms per step), from the alternated runs.
  struct Ratio { std::string variant; int threads = 1; double wall = 0, cpu = 0; };
  std::vector<Ratio> distortion_cost;
  double peak_gflops() const;      // measured at the most threads
};

// The benches' clocks: steady wall time and this process's CPU time (user + system), seconds.
double bench_wall_s();
double bench_cpu_s();

// Reads /proc/loadavg (1, 5, 15 minutes); zeros when unavailable.
void read_load_average(double out[3]);

// Runs every variant × thread count. log(line) reports progress (may be empty).
BenchReport run_bench(const BenchOptions& opt, const std::function<void(const std::string&)>& log = {});

// `hashcc bench --render` (tools/bench_render.cpp): one frame of a grid-field run (its first
// training camera; run empty: a freshly initialised grid field, 504x378), exact and with the
// render shortcuts, at each sample count and thread count, against the training step's rate.
struct BenchRenderOptions {
  std::string run;                  // run folder; "" = a fresh field
  std::vector<int> samples = {32, 64};
  std::vector<int> threads;         // default 1 and 2
  int frames = 3;                   // timed frames per row (median), after one warm-up frame
  std::vector<double> skip_sigmas;  // also the shortcuts with an empty-space grid of each σ_min
  int skip_res = 64;                // its cells per axis
  int skip_passes = 2;              // jittered points a cell
};
void run_bench_render(const BenchRenderOptions& o);

// `hashcc bench --memory` (tools/bench_memory.cpp): per working-set size and thread count, the
// latency of dependent loads (pointer chase), the throughput of independent random 8-byte row
// loads and read-modify-writes (the hash grid's gathers and scatter-adds) and the streaming read
// and write bandwidth; the grid step's roofline reads them (tools/grid_roofline.py).
struct BenchMemoryOptions {
  std::vector<int64_t> sizes;      // working sets in bytes (multiples of 64); empty: 16 KiB … 256 MiB
  std::vector<int> threads;        // default 1 and all
  double seconds = 0.04;           // per repetition of a probe (best of 3)
  std::string json;                // also write the rows here ("" = no)
};
void run_bench_memory(const BenchMemoryOptions& o);

// `hashcc bench --hashgrid` (tools/bench_hashgrid.cpp): the hash encoding's forward, training
// backward and frozen-table backward alone, per table size and thread count, in ms a step and ns
// a point a level.
struct BenchHashGridOptions {
  std::vector<int> log2_tables = {15, 17};  // the bench step's table and the default plan's last
  std::vector<int> threads;                 // default 1 and 2
  int rays = 256, samples = 32;             // points a call: one automatic chunk of the bench step
  int calls = 4;                            // calls a step (4 × 8,192 = the bench step's 32,768)
  int reps = 30;                            // timed repetitions (median), after one warm-up
  uint64_t seed = 7;
};
struct BenchHashGridRow {
  int log2_table, threads;
  double ms_forward, ms_backward, ms_backward_dx;  // medians, ms a step
  double sum_out_dx, sum_table;                    // checksums (see tools/bench_hashgrid.cpp)
  // The path that keeps the forward's position Jacobian: forward + Jacobian, the scatter alone
  // (d_x null), dL/dx from the Jacobian; medians, ms a step. dx_rel_diff: max |d_x − d_x(gather)|
  // over max |d_x(gather)| (the two paths sum in another order).
  double ms_forward_jac = 0, ms_scatter = 0, ms_dx_jac = 0, dx_rel_diff = 0;
  double ms_forward_scalar = 0, ms_forward_jac_scalar = 0;  // the SIMD gather off
};
std::vector<BenchHashGridRow> run_bench_hashgrid(const BenchHashGridOptions& o);  // also prints

// `hashcc bench --dense-probe`: the dense micro-kernel's three GEMMs per paper layer shape at one
// thread, on working sets from L2-resident (256 rows) to a step's streaming one (16,384), against
// the measured FMA peak (dense_microkernel_probe, kernels/dense.h). Prints the table.
void run_bench_dense_probe(int reps);
// "model name (family F, model M)" of /proc/cpuinfo's first processor.
std::string cpu_model();

// The human-readable table and the JSON object (`--json`).
std::string bench_table(const BenchReport& r);
std::string bench_json(const BenchReport& r);

}  // namespace hashcc
