#include "tools/bench.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <omp.h>
#include <sstream>
#include <sys/resource.h>
#include <unistd.h>

#include <fmt/core.h>

#include "core/buffer.h"
#include "core/error.h"
#include "core/isa.h"
#include "core/parallel.h"
#include "kernels/dense.h"
#include "train/trainer.h"
#include "tools/simulator.h"

namespace fs = std::filesystem;

namespace hashcc {

double bench_wall_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double bench_cpu_s() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

namespace {

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double pos = q * double(v.size() - 1);
  const size_t lo = size_t(pos), hi = std::min(v.size() - 1, lo + 1);
  return v[lo] + (pos - double(lo)) * (v[hi] - v[lo]);
}

}  // namespace

void read_load_average(double out[3]) {
  out[0] = out[1] = out[2] = 0;
  std::ifstream f("/proc/loadavg");
  f >> out[0] >> out[1] >> out[2];
}

DenseFlops dense_flops_per_step(const ModelConfig& cfg, int64_t N) {
  const ModelLayout L = make_layout(cfg);
  auto fwd = [&](const LayerView& l) { return 2.0 * l.in * l.out * double(N); };
  DenseFlops f;
  if (cfg.field == Field::grid) {
    f.main = fwd(L.gd0) + fwd(L.gd1) + fwd(L.gr0) + fwd(L.gr1);
  } else {
    for (const auto& t : L.trunk) f.main += fwd(t);
    f.main += fwd(L.density) + fwd(L.feature) + fwd(L.rgb_hidden) + fwd(L.rgb);
  }
  if (cfg.has_cc()) f.cc = fwd(L.cc0) + fwd(L.cc1);
  f.main *= 3;  // forward + backward (input and weight gradients: 2 × forward)
  f.cc *= 3;
  return f;
}

double BenchRun::other_ms() const {
  double s = 0;
  for (int i = 0; i < kStageCount; ++i) s += stages.wall_ms[i];
  return ms_mean - s;
}

double BenchReport::peak_gflops() const {
  double best = 0;
  int most = 0;
  for (const auto& p : peaks)
    if (p.threads >= most) { most = p.threads; best = p.gflops_cpu; }
  return best;
}

namespace {

// A variant is a model name, "+grid" for it on the grid field (e.g. hashcc+grid).
ModelConfig model_of(const std::string& v) {
  ModelConfig m;
  const size_t plus = v.find('+');
  m.variant = parse_variant(v.substr(0, plus));
  if (plus != std::string::npos) m.field = parse_field(v.substr(plus + 1));
  return m;
}

// Median, spread and FLOP rates of a run's timed steps.
void summarise_run(BenchRun& r, const TrainConfig& c, double cpu_s,
                   const std::vector<PeakMeasure>& peaks) {
  r.ms_median = percentile(r.ms, 0.5);
  for (double m : r.ms) r.ms_mean += m / r.steps;
  r.ms_min = *std::min_element(r.ms.begin(), r.ms.end());
  r.ms_max = *std::max_element(r.ms.begin(), r.ms.end());
  r.ms_q1 = percentile(r.ms, 0.25);
  r.ms_q3 = percentile(r.ms, 0.75);
  r.cpu_ms_per_step = cpu_s * 1e3 / r.steps;
  const DenseFlops f = dense_flops_per_step(c.model, int64_t(r.rays) * r.samples);
  r.flops_main = f.main;
  r.flops_cc = f.cc;
  const double mlp_wall = r.stages.wall_ms[kStageMlpFwd] + r.stages.wall_ms[kStageMlpBwd];
  const double mlp_cpu = r.stages.cpu_ms[kStageMlpFwd] + r.stages.cpu_ms[kStageMlpBwd];
  r.mlp_gflops = mlp_wall > 0 ? f.main / (mlp_wall * 1e-3) * 1e-9 : 0;
  r.mlp_gflops_cpu = mlp_cpu > 0 ? f.main / (mlp_cpu * 1e-3) * 1e-9 : 0;
  r.step_gflops = (f.main + f.cc) / (r.ms_median * 1e-3) * 1e-9;
  for (const auto& p : peaks) if (p.threads == r.threads) r.peak_gflops = p.gflops_cpu;
  if (r.peak_gflops > 0) {
    r.peak_fraction = r.mlp_gflops / r.peak_gflops;
    r.peak_fraction_cpu = r.mlp_gflops_cpu / r.peak_gflops;
  }
}

// One arm of a same-run comparison: the GEMM path and the distortion loss's λ of its steps.
struct Arm {
  std::string gemm;
  double distortion = 0;
};

// One variant at `nt` threads: warm-up, then timed Trainer::step_once() with the profiler on,
// one BenchRun per arm. The arms alternate step by step, so load changes hit them alike (a
// same-run comparison): GEMM paths on one trainer (dense_force_eigen), distortion values on a
// trainer each (the loss is a training option, fixed at construction).
std::vector<BenchRun> time_variant(const BenchOptions& opt, const TrainConfig& base,
                                   const std::string& v, int nt, double budget_s,
                                   const std::vector<PeakMeasure>& peaks,
                                   const std::vector<Arm>& arms) {
  TrainConfig c = base;
  c.model = model_of(v);
  c.model.width = opt.width;
  c.samples = c.model.field == Field::grid ? opt.grid_samples : opt.samples;
  c.chunk_rays = opt.chunk_rays;
  c.threads = nt;
  c.progress = false;
  c.steps = 1 << 30;
  std::vector<double> lambdas;  // one trainer per distinct λ
  for (const Arm& a : arms)
    if (std::find(lambdas.begin(), lambdas.end(), a.distortion) == lambdas.end())
      lambdas.push_back(a.distortion);
  std::vector<std::unique_ptr<Trainer>> trainers;
  for (double l : lambdas) {
    c.distortion = l;
    trainers.push_back(std::make_unique<Trainer>(c));  // sets the thread count
  }
  const int nm = int(arms.size());
  auto trainer_of = [&](const Arm& a) -> Trainer& {
    return *trainers[std::find(lambdas.begin(), lambdas.end(), a.distortion) - lambdas.begin()];
  };
  const double w0 = bench_wall_s();
  for (int i = 0; i < std::max(1, opt.warmup) * nm; ++i) {
    dense_force_eigen(arms[i % nm].gemm == "eigen");
    trainer_of(arms[i % nm]).step_once();
  }
  const double warm_each = (bench_wall_s() - w0) / (std::max(1, opt.warmup) * nm);
  int steps = opt.steps;
  if (steps <= 0)
    steps = std::clamp(int((budget_s - (bench_wall_s() - w0)) / (nm * std::max(warm_each, 1e-3))), 3, 50);
  std::vector<BenchRun> rs(nm);
  std::vector<StageTimes> sum(nm);
  std::vector<double> cpu(nm, 0.0);
  for (int i = 0; i < steps; ++i)
    for (int m = 0; m < nm; ++m) {
      dense_force_eigen(arms[m].gemm == "eigen");
      Trainer& tr = trainer_of(arms[m]);
      StageTimes st;
      tr.set_stage_times(&st);
      const double c0 = bench_cpu_s(), t0 = bench_wall_s();
      tr.step_once();
      rs[m].ms.push_back((bench_wall_s() - t0) * 1e3);
      cpu[m] += bench_cpu_s() - c0;
      tr.set_stage_times(nullptr);
      sum[m].add_scaled(st, 1.0);
    }
  dense_force_eigen(false);
  for (int m = 0; m < nm; ++m) {
    BenchRun& r = rs[m];
    r.variant = v;
    r.gemm = arms[m].gemm;
    r.distortion = arms[m].distortion;
    r.threads = nt;
    r.rays = c.grid_rows() * c.grid_cols();
    r.samples = c.samples;
    r.chunk_rays = resolve_chunk_rays(c.chunk_rays, c.model, c.samples);
    r.chunk_mib = 4.0 * double(chunk_floats(c.model, r.chunk_rays, c.samples)) / (1 << 20);
    r.width = opt.width;
    r.steps = steps;
    r.stages.add_scaled(sum[m], 1.0 / steps);
    summarise_run(r, c, cpu[m], peaks);
  }
  return rs;
}

// Loss on / off per variant and thread count, on the build's GEMM path.
void distortion_costs(BenchReport& rep) {
  for (const auto& on : rep.runs)
    if (on.distortion > 0 && on.gemm == rep.gemm)
      for (const auto& off : rep.runs)
        if (off.distortion == 0 && off.gemm == rep.gemm && off.variant == on.variant &&
            off.threads == on.threads && off.ms_median > 0)
          rep.distortion_cost.push_back({on.variant, on.threads, on.ms_median / off.ms_median,
                                         on.cpu_ms_per_step / off.cpu_ms_per_step});
}

// hashcc / sh per thread count (wall and CPU), from the runs.
void cc_overheads(BenchReport& rep, const std::vector<int>& threads) {
  for (int nt : threads) {
    const BenchRun *sh = nullptr, *hc = nullptr;
    for (const auto& r : rep.runs)
      if (r.threads == nt && r.gemm == rep.gemm && r.distortion == 0) {
        if (r.variant == "sh") sh = &r;
        if (r.variant == "hashcc") hc = &r;
      }
    if (sh && hc && sh->ms_median > 0) {
      rep.cc_overhead_by_threads.push_back({nt, hc->ms_median / sh->ms_median});
      rep.cc_overhead = hc->ms_median / sh->ms_median;  // threads ascend: ends at the most
      rep.cc_overhead_cpu_by_threads.push_back({nt, hc->cpu_ms_per_step / sh->cpu_ms_per_step});
      rep.cc_overhead_cpu = hc->cpu_ms_per_step / sh->cpu_ms_per_step;
    }
  }
}

// Simulates the bench scene into a temp folder (returned; the caller removes it).
std::string simulate_scene(const TrainConfig& base, const std::function<void(const std::string&)>& say) {
  const std::string dir = (fs::temp_directory_path() / fmt::format("hashcc_bench_{}", getpid())).string();
  SimOptions so;
  so.views = 4;
  so.supersample = 1;
  so.width = std::max(128, base.grid_cols());
  so.height = std::max(96, base.grid_rows());
  say(fmt::format("simulating a {}x{} scene in {}", so.width, so.height, dir));
  write_sim_scene(dir, so, false);
  return dir;
}

}  // namespace

namespace {

// The paper's main network at width 128 (sh / hashcc, spec §4), one chunk of the step: the first
// trunk layer (γ(x): 63 inputs), the six other trunk layers and the feature layer (128), the
// skip layer (128 + 63 = 191), the colour head's hidden layer (128 + 16 SH = 144 → 64). All run
// as Linear + ReLU (the trunk's kernels). The heads with 1 and 3 outputs are < 2% of the FLOPs.
struct DenseShape {
  const char* layer;
  int in, out, count;
};
constexpr DenseShape kPaperShapes[] = {{"trunk0 63->128", 63, 128, 1},
                                       {"trunk 128->128", 128, 128, 7},
                                       {"skip 191->128", 191, 128, 1},
                                       {"colour 144->64", 144, 64, 1}};
// The grid field's layers that the micro-kernel runs (and the CC branch's first, 32 -> 64, the
// density MLP's); their narrow colour heads (64 -> 3) run Eigen's GEMM.
constexpr DenseShape kGridShapes[] = {{"grid d0 32->64", 32, 64, 1},
                                      {"grid d1 64->16", 64, 16, 1},
                                      {"grid r0 31->64", 31, 64, 1}};

// Inside a parallel region: this thread's own layer, `reps` times, each rep Eigen then the
// build's path (forward, then backward with d_pre in place as in training), threads in step
// (barrier per rep). ms[(rep·2 + path)·2 + phase] = this thread's CPU ms.
void time_dense_layer(const DenseShape& sh, int64_t N, int reps, double* ms, uint64_t seed) {
  const int in = sh.in, out = sh.out;
  AlignedVec<float> x(N * in), W(int64_t(out) * in), b(out), y(N * out), g(N * out), dx(N * in),
      dW(int64_t(out) * in, 0.f), db(out, 0.f);
  Rng rng(seed);
  for (auto* v : {&x, &W, &b, &g})
    for (auto& e : *v) e = rng.uniformf() - 0.5f;
  for (int rep = -1; rep < reps; ++rep) {  // rep −1: warm-up (packing buffers, caches)
    for (int path = 0; path < 2; ++path) {
#pragma omp barrier
      const double t0 = thread_cpu_ms();
      if (path == 0) dense_forward_eigen(y.data(), x.data(), W.data(), b.data(), N, in, out, true);
      else dense_relu_forward(y.data(), x.data(), W.data(), b.data(), N, in, out);
      const double t1 = thread_cpu_ms();
      if (path == 0)
        dense_backward_eigen(dx.data(), dW.data(), db.data(), g.data(), g.data(), y.data(),
                             x.data(), W.data(), N, in, out);
      else
        dense_relu_backward(dx.data(), dW.data(), db.data(), g.data(), g.data(), y.data(),
                            x.data(), W.data(), N, in, out);
      const double t2 = thread_cpu_ms();
      if (rep >= 0) {
        ms[(rep * 2 + path) * 2 + 0] = t1 - t0;
        ms[(rep * 2 + path) * 2 + 1] = t2 - t1;
      }
    }
  }
}

// The two rows (eigen, kernel) of one shape at nt threads from every thread's times.
void dense_rows(std::vector<DenseBenchRow>& rows, const DenseShape& sh, int64_t N, int nt,
                int reps, const std::vector<double>& ms, double peak) {
  const double flop = 2.0 * double(N) * sh.in * sh.out;  // forward; backward is twice this
  for (int path = 0; path < 2; ++path) {
    DenseBenchRow r;
    r.path = path == 0 ? "eigen" : "kernel";
    r.layer = sh.layer;
    r.threads = nt;
    r.in = sh.in;
    r.out = sh.out;
    r.count = sh.count;
    r.N = N;
    r.peak_gflops = peak;
    std::vector<double> f_ms, b_ms, f_g, b_g;
    for (int rep = 0; rep < reps; ++rep) {
      double fm = 0, bm = 0, fg = 0, bg = 0;
      for (int t = 0; t < nt; ++t) {
        const double* m = ms.data() + size_t(t) * reps * 4 + (rep * 2 + path) * 2;
        fm += m[0] / nt;
        bm += m[1] / nt;
        fg += flop / (m[0] * 1e-3) * 1e-9;
        bg += 2 * flop / (m[1] * 1e-3) * 1e-9;
      }
      f_ms.push_back(fm), b_ms.push_back(bm), f_g.push_back(fg), b_g.push_back(bg);
    }
    r.fwd_ms = percentile(f_ms, 0.5);
    r.bwd_ms = percentile(b_ms, 0.5);
    r.fwd_gflops = percentile(f_g, 0.5);
    r.bwd_gflops = percentile(b_g, 0.5);
    rows.push_back(r);
  }
}

}  // namespace

std::vector<DenseBenchRow> run_dense_bench(const BenchOptions& opt, const std::vector<int>& threads,
                                           const std::vector<PeakMeasure>& peaks,
                                           const std::function<void(const std::string&)>& log) {
  // The step's chunk for the paper's network (hashcc) at this width and these samples.
  ModelConfig paper = model_of("hashcc");
  paper.width = opt.width;
  const int64_t N = int64_t(resolve_chunk_rays(opt.chunk_rays, paper, opt.samples)) * opt.samples;
  const int reps = std::max(1, opt.dense_reps);
  std::vector<DenseBenchRow> rows;
  for (int nt : threads) {
    double peak = 0;
    for (const auto& p : peaks) if (p.threads == nt) peak = p.gflops_cpu;
    if (log) log(fmt::format("timing the dense layers (N = {}) at {} thread(s)", N, nt));
    // A team of one is not "in parallel" (omp_in_parallel): with more threads configured the
    // kernels would fork inside the timed call. So the thread count is set as the step sets it.
    set_num_threads(nt);
    for (const DenseShape& sh : kPaperShapes) {
      std::vector<double> ms(size_t(nt) * reps * 4, 0.0);
#pragma omp parallel num_threads(nt)
      {
        const int t = omp_get_thread_num();
        time_dense_layer(sh, N, reps, ms.data() + size_t(t) * reps * 4, 100 + t);
      }
      dense_rows(rows, sh, N, nt, reps, ms, peak);
    }
  }
  return rows;
}

void run_bench_dense_probe(int reps) {
  set_num_threads(1);
  const PeakMeasure pk = measure_peak(1);
  const std::vector<int64_t> Ns = {256, 2048, 16384};
  fmt::print("dense micro-kernel probe: {}; compiled ISA {} (this CPU: {}); {}\n", cpu_model(),
             pk.isa, cpu_isa_name(), dense_microkernel_name());
  fmt::print("FP32 FMA peak, 1 thread, measured: {:.1f} GFLOP/s. Each GEMM alone, W packed once, "
             "rows in 256-row chunks, median of {} (the N values interleaved):\n",
             pk.gflops_cpu, reps);
  fmt::print("{:<16} {:>6}  {:>9} {:>6}  {:>9} {:>6}  {:>9} {:>6}\n", "layer", "N", "fwd GF/s",
             "%peak", "d_x GF/s", "%peak", "d_W GF/s", "%peak");
  std::vector<DenseShape> shapes(std::begin(kPaperShapes), std::end(kPaperShapes));
  shapes.insert(shapes.end(), std::begin(kGridShapes), std::end(kGridShapes));
  for (const DenseShape& sh : shapes)
    for (const DenseProbeRow& r : dense_microkernel_probe(sh.in, sh.out, Ns, reps)) {
      const auto pct = [&](double g) { return 100 * g / pk.gflops_cpu; };
      fmt::print("{:<16} {:>6}  {:>9.1f} {:>5.1f}%  {:>9.1f} {:>5.1f}%  {:>9.1f} {:>5.1f}%\n",
                 sh.layer, r.N, r.fwd_gflops, pct(r.fwd_gflops), r.dx_gflops, pct(r.dx_gflops),
                 r.dw_gflops, pct(r.dw_gflops));
    }
  fmt::print("  N = 256: x, y and d_y of the chunk stay in L2 across the repetitions; 16,384: they "
             "stream from L3 or memory, as in a step\n");
}

double dense_network_gflops(const std::vector<DenseBenchRow>& rows, const std::string& path,
                            int threads, int phase) {
  double flop = 0, ms = 0;
  for (const auto& r : rows)
    if (r.path == path && r.threads == threads) {
      const double f = 2.0 * double(r.N) * r.in * r.out * r.count;
      if (phase != 1) flop += f, ms += r.count * r.fwd_ms;
      if (phase != 0) flop += 2 * f, ms += r.count * r.bwd_ms;
    }
  return ms > 0 ? threads * flop / (ms * 1e-3) * 1e-9 : 0;
}

BenchReport run_bench(const BenchOptions& opt, const std::function<void(const std::string&)>& log) {
  auto say = [&](const std::string& s) { if (log) log(s); };
  BenchReport rep;
  const CompiledIsa isa = compiled_isa();
  rep.isa_compiled = isa.name;
  rep.isa_option = isa.option;
  rep.isa_cpu = cpu_isa_name();
  rep.gemm = opt.gemm;
  read_load_average(rep.load_before);
  const int all = std::max(1, num_threads());
  std::vector<int> threads = opt.threads;
  if (threads.empty()) {
    threads.push_back(1);
    if (all > 1) threads.push_back(all);
  }
  for (const auto& v : opt.variants) model_of(v);  // throws on a bad name
  HCC_REQUIRE(opt.rays >= 1 && opt.samples >= 2 && opt.width >= 4, "--rays/--samples/--width", "",
              "{}/{}/{}", opt.rays, opt.samples, opt.width, "rays ≥ 1, samples ≥ 2, width ≥ 4");
  HCC_REQUIRE(opt.distortion >= 0, "--distortion", "", "{}", opt.distortion, "λ ≥ 0");
  rep.nominal = nominal_peak(std::max(1, int(sysconf(_SC_NPROCESSORS_ONLN))));
  for (int nt : threads) {
    say(fmt::format("measuring the {} FMA peak at {} thread(s)", isa.name, nt));
    rep.peaks.push_back(measure_peak(nt));
  }
  if (opt.dense) rep.dense = run_dense_bench(opt, threads, rep.peaks, say);
  std::vector<std::string> gemms = {rep.gemm};
  if (rep.gemm == "both") gemms = {"eigen", "kernel"};
  if (rep.gemm == "both") rep.gemm = "kernel";  // the CC overhead is quoted for the build's path
  std::vector<Arm> arms;
  for (const auto& g : gemms) {
    arms.push_back({g, 0.0});
    if (opt.distortion > 0) arms.push_back({g, opt.distortion});
  }
  if (opt.step) {
    TrainConfig base;
    base.rays = opt.rays;
    const std::string dir = opt.scene_dir.empty() ? simulate_scene(base, say) : opt.scene_dir;
    base.data = dir;
    const int nruns = int(opt.variants.size() * threads.size());
    for (int nt : threads)
      for (const auto& v : opt.variants)
        for (BenchRun& r : time_variant(opt, base, v, nt, opt.budget_seconds / std::max(1, nruns),
                                        rep.peaks, arms)) {
          say(fmt::format("{} ({}{}) at {} thread(s): {} steps, median {:.0f} ms/step", v, r.gemm,
                          r.distortion > 0 ? fmt::format(", distortion {:g}", r.distortion) : "",
                          nt, r.steps, r.ms_median));
          rep.runs.push_back(std::move(r));
        }
    if (opt.scene_dir.empty()) {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  }
  set_num_threads(all);
  cc_overheads(rep, threads);
  distortion_costs(rep);
  read_load_average(rep.load_after);
  return rep;
}

namespace {

// A run's name in the tables: the variant, "+dist" when the distortion loss was on.
std::string run_label(const BenchRun& x) { return x.distortion > 0 ? x.variant + "+dist" : x.variant; }

// The dense-layer GEMM table (`--dense`): per shape and path, GFLOP/s and % of the peak.
std::string dense_table(const BenchReport& r) {
  if (r.dense.empty()) return "";
  const DenseBenchRow& d0 = r.dense.front();
  std::string s = fmt::format("dense layers alone, N = {} rows (one chunk), Linear+ReLU, each "
                              "thread its own layer; GFLOP/s = Σ threads FLOPs / thread CPU time, "
                              "median of the reps; % of the {} peak\n", d0.N, r.isa_compiled);
  s += fmt::format("{:<7} {:>3} {:<15} {:>5} {:>9} {:>6} {:>9} {:>6} {:>9} {:>6}\n", "path", "thr",
                   "layer", "count", "fwd GF/s", "%peak", "bwd GF/s", "%peak", "f+b GF/s", "%peak");
  auto pct = [](double g, double p) { return p > 0 ? 100 * g / p : 0.0; };
  for (const auto& d : r.dense) {
    const double fb = 3 / (1 / d.fwd_gflops + 2 / d.bwd_gflops);
    s += fmt::format("{:<7} {:>3} {:<15} {:>5} {:>9.1f} {:>5.1f}% {:>9.1f} {:>5.1f}% {:>9.1f} "
                     "{:>5.1f}%\n", d.path, d.threads, d.layer, d.count, d.fwd_gflops,
                     pct(d.fwd_gflops, d.peak_gflops), d.bwd_gflops, pct(d.bwd_gflops, d.peak_gflops),
                     fb, pct(fb, d.peak_gflops));
  }
  for (const auto& d : r.dense)
    if (d.path == "kernel" && d.layer == r.dense.front().layer) {
      const double pk = d.peak_gflops;
      for (const char* path : {"eigen", "kernel"}) {
        const double f = dense_network_gflops(r.dense, path, d.threads, 0),
                     b = dense_network_gflops(r.dense, path, d.threads, 1),
                     fb = dense_network_gflops(r.dense, path, d.threads, 2);
        s += fmt::format("{:<7} {:>3} {:<15} {:>5} {:>9.1f} {:>5.1f}% {:>9.1f} {:>5.1f}% {:>9.1f} "
                         "{:>5.1f}%\n", path, d.threads, "network (sum)", "", f, pct(f, pk), b,
                         pct(b, pk), fb, pct(fb, pk));
      }
    }
  return s + "  network: the layers weighted by count (FLOPs and time)\n\n";
}

}  // namespace

std::string bench_table(const BenchReport& r) {
  std::string s;
  s += fmt::format("load average (1/5/15 min): {:.2f} {:.2f} {:.2f} before, {:.2f} {:.2f} {:.2f} "
                   "after on {} cores{}\n",
                   r.load_before[0], r.load_before[1], r.load_before[2], r.load_after[0],
                   r.load_after[1], r.load_after[2], r.nominal.cores,
                   std::max(r.load_before[0], r.load_after[0]) > 0.5 * r.nominal.cores
                       ? "  — LOADED machine: wall times are inflated, compare CPU times"
                       : "");
  s += fmt::format("ISA: compiled for {} (-DHASHCC_ISA={}); this CPU supports {}; dense GEMM: {}\n",
                   r.isa_compiled, r.isa_option, r.isa_cpu,
                   r.gemm == "eigen" ? "Eigen (--gemm eigen)"
                   : r.runs.size() && r.runs.front().gemm == "eigen"
                       ? "both, alternating step by step (--gemm both)"
                   : dense_microkernel(128) ? fmt::format("{}, Eigen otherwise",
                                                          dense_microkernel_name())
                                            : std::string("Eigen"));
  s += fmt::format("FP32 peak of the compiled ISA ({}), measured (FMA loop, 12 chains, per-thread "
                   "CPU time; wall-clock in brackets):\n", r.isa_compiled);
  for (const auto& p : r.peaks)
    s += fmt::format("  {} thread(s), {}: {:.1f} GFLOP/s  [{:.1f} wall]\n", p.threads, p.isa,
                     p.gflops_cpu, p.gflops_wall);
  s += fmt::format("FP32 peak, nominal: {}\n\n", r.nominal.how());
  s += dense_table(r);
  if (r.runs.empty()) return s;
  const BenchRun& r0 = r.runs.front();
  s += fmt::format("step: {} rays × smp samples a ray, width {}; ms per step (wall), CPU ms = "
                   "process CPU time per step (all threads)\n",
                   r0.rays, r0.width);
  s += fmt::format("{:<16} {:<6} {:>3} {:>4} {:>5} {:>9} {:>17} {:>9} {:>9} {:>9} {:>7} {:>15}\n",
                   "variant", "gemm", "thr", "smp", "steps", "median", "min..max", "CPU ms",
                   "GFLOP/s", "GF/s cpu", "% peak", "chunk");
  for (const auto& x : r.runs)
    s += fmt::format("{:<16} {:<6} {:>3} {:>4} {:>5} {:>9.1f} {:>8.1f}..{:<8.1f} {:>9.1f} "
                     "{:>9.1f} {:>9.1f} {:>6.1f}% {:>4} ({:>5.1f} MiB)\n",
                     run_label(x), x.gemm, x.threads, x.samples, x.steps, x.ms_median, x.ms_min, x.ms_max,
                     x.cpu_ms_per_step, x.mlp_gflops, x.mlp_gflops_cpu, 100 * x.peak_fraction,
                     x.chunk_rays, x.chunk_mib);
  s += "  GFLOP/s: main-network dense FLOPs / (mlp_fwd + mlp_bwd) time (wall; cpu: the stages' "
       "thread CPU time); % peak: wall GFLOP/s / measured peak at that thread count; chunk: rays a "
       "chunk (its buffers, MiB a thread)\n\n";
  s += "stages, ms per step (wall-equivalent: mean over threads) and % of the mean step; "
       "[thread CPU ms]\n";
  s += fmt::format("{:<16} {:<6} {:>3}", "variant", "gemm", "thr");
  for (int i = 0; i < kStageCount; ++i) s += fmt::format(" {:>17}", stage_name(i));
  s += fmt::format(" {:>17}\n", "other");
  for (const auto& x : r.runs) {
    s += fmt::format("{:<16} {:<6} {:>3}", run_label(x), x.gemm, x.threads);
    for (int i = 0; i < kStageCount; ++i)
      s += fmt::format(" {:>7.1f} {:>4.1f}% {:>4.0f}", x.stages.wall_ms[i],
                       100 * x.stages.wall_ms[i] / x.ms_mean, x.stages.cpu_ms[i]);
    s += fmt::format(" {:>7.1f} {:>4.1f}%     \n", x.other_ms(), 100 * x.other_ms() / x.ms_mean);
  }
  s += "\n";
  for (size_t i = 0; i < r.cc_overhead_by_threads.size(); ++i)
    s += fmt::format("CC overhead at {} thread(s): hashcc / sh = {:.3f} (median wall), {:.3f} (CPU "
                     "ms per step)\n",
                     r.cc_overhead_by_threads[i].first, r.cc_overhead_by_threads[i].second,
                     r.cc_overhead_cpu_by_threads[i].second);
  for (const auto& d : r.distortion_cost)
    s += fmt::format("distortion loss at {} thread(s), {}: on / off = {:.3f} (median wall), {:.3f} "
                     "(CPU ms per step); alternated step by step, detached from the cameras\n",
                     d.threads, d.variant, d.wall, d.cpu);
  // Speed-up from 1 to the most threads, per variant.
  for (const auto& a : r.runs)
    for (const auto& b : r.runs)
      if (a.variant == b.variant && a.gemm == b.gemm && a.distortion == b.distortion &&
          a.threads == 1 && b.threads > 1)
        s += fmt::format("{} ({}): {} threads {:.2f}× faster than 1 (wall), CPU ms ratio {:.2f}\n",
                         run_label(a), a.gemm, b.threads, a.ms_median / b.ms_median,
                         b.cpu_ms_per_step / a.cpu_ms_per_step);
  return s;
}

std::string bench_json(const BenchReport& r) {
  using nlohmann::json;
  json runs = json::array();
  for (const auto& x : r.runs) {
    json st = json::object(), stc = json::object();
    for (int i = 0; i < kStageCount; ++i) {
      st[stage_name(i)] = x.stages.wall_ms[i];
      stc[stage_name(i)] = x.stages.cpu_ms[i];
    }
    st["other"] = x.other_ms();
    runs.push_back({{"variant", x.variant}, {"gemm", x.gemm}, {"distortion", x.distortion},
                    {"threads", x.threads}, {"rays", x.rays},
                    {"samples", x.samples}, {"width", x.width}, {"steps", x.steps},
                    {"chunk_rays", x.chunk_rays}, {"chunk_mib", x.chunk_mib},
                    {"ms_per_step", x.ms_median}, {"ms_min", x.ms_min}, {"ms_max", x.ms_max},
                    {"ms_q1", x.ms_q1}, {"ms_mean", x.ms_mean}, {"ms_q3", x.ms_q3}, {"ms_all", x.ms},
                    {"cpu_ms_per_step", x.cpu_ms_per_step}, {"stages", st}, {"stages_cpu", stc},
                    {"mlp_flops", x.flops_main}, {"cc_flops", x.flops_cc},
                    {"mlp_gflops", x.mlp_gflops}, {"mlp_gflops_cpu", x.mlp_gflops_cpu},
                    {"step_gflops", x.step_gflops}, {"peak_gflops", x.peak_gflops},
                    {"peak_fraction", x.peak_fraction}, {"peak_fraction_cpu", x.peak_fraction_cpu}});
  }
  json peaks = json::array();
  for (const auto& p : r.peaks)
    peaks.push_back({{"threads", p.threads}, {"isa", p.isa}, {"gflops_cpu", p.gflops_cpu},
                     {"gflops_wall", p.gflops_wall}});
  json dense = json::array();
  for (const auto& d : r.dense)
    dense.push_back({{"path", d.path}, {"layer", d.layer}, {"threads", d.threads}, {"in", d.in},
                     {"out", d.out}, {"count", d.count}, {"N", d.N}, {"fwd_ms", d.fwd_ms},
                     {"bwd_ms", d.bwd_ms}, {"fwd_gflops", d.fwd_gflops},
                     {"bwd_gflops", d.bwd_gflops}, {"peak_gflops", d.peak_gflops}});
  json dnet = json::object();
  for (const auto& d : r.dense)
    if (d.layer == r.dense.front().layer)
      dnet[d.path + "@" + std::to_string(d.threads)] = {
          {"fwd_gflops", dense_network_gflops(r.dense, d.path, d.threads, 0)},
          {"bwd_gflops", dense_network_gflops(r.dense, d.path, d.threads, 1)},
          {"gflops", dense_network_gflops(r.dense, d.path, d.threads, 2)},
          {"peak_gflops", d.peak_gflops}};
  json ccb = json::object();
  for (const auto& [nt, o] : r.cc_overhead_by_threads) ccb[std::to_string(nt)] = o;
  json dist = json::array();
  for (const auto& d : r.distortion_cost)
    dist.push_back({{"variant", d.variant}, {"threads", d.threads}, {"on_over_off_wall", d.wall},
                    {"on_over_off_cpu", d.cpu}});
  json j = {{"isa_compiled", r.isa_compiled},
            {"isa_option", r.isa_option},
            {"isa_cpu", r.isa_cpu},
            {"gemm", r.gemm},
            {"dense", dense},
            {"dense_network", dnet},
            {"peak_gflops", r.peak_gflops()},
            {"peak_nominal_gflops", r.nominal.gflops()},
            {"peak_nominal_how", r.nominal.how()},
            {"peaks", peaks},
            {"cc_overhead", r.cc_overhead},
            {"cc_overhead_by_threads", ccb},
            {"cc_overhead_cpu", r.cc_overhead_cpu},
            {"distortion_cost", dist},
            {"load_average", {r.load_before[0], r.load_before[1], r.load_before[2]}},
            {"load_average_after", {r.load_after[0], r.load_after[1], r.load_after[2]}},
            {"cores", r.nominal.cores},
            {"runs", runs}};
  return j.dump(2) + "\n";
}

}  // namespace hashcc
