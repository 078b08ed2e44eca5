// tools/bench_peak.cpp — the FP32 peak `hashcc bench` measures each run against (tools/bench.h):
// an FMA loop of the compiled ISA on every thread, and the nominal peak from the CPU's clock.
#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <immintrin.h>
#include <omp.h>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "core/isa.h"
#include "core/parallel.h"
#include "core/profile.h"
#include "tools/bench.h"

namespace hashcc {

namespace {

// FMA loops: K independent accumulator chains (latency 4 × 2 FMA pipes needs ≥ 8 in flight).
// Each iteration does K vector FMAs = K · lanes · 2 FLOPs. The values converge to c/(1−b), so
// nothing overflows or goes denormal. Returns a sum so the loop cannot be removed.
constexpr int kChains = 12;

__attribute__((target("avx512f"), noinline)) float fma_loop_avx512(int64_t iters, float seed) {
  __m512 a[kChains];
  for (int k = 0; k < kChains; ++k) a[k] = _mm512_set1_ps(seed + 0.01f * k);
  const __m512 b = _mm512_set1_ps(0.9999f), c = _mm512_set1_ps(1e-5f);
  for (int64_t i = 0; i < iters; ++i)
#pragma GCC unroll 12
    for (int k = 0; k < kChains; ++k) a[k] = _mm512_fmadd_ps(a[k], b, c);
  __m512 s = a[0];
  for (int k = 1; k < kChains; ++k) s = _mm512_add_ps(s, a[k]);
  asm volatile("" : "+v"(s));  // the result is "used": the loop cannot be dropped
  return _mm512_reduce_add_ps(s);
}

__attribute__((target("avx2,fma"), noinline)) float fma_loop_avx2(int64_t iters, float seed) {
  __m256 a[kChains];
  for (int k = 0; k < kChains; ++k) a[k] = _mm256_set1_ps(seed + 0.01f * k);
  const __m256 b = _mm256_set1_ps(0.9999f), c = _mm256_set1_ps(1e-5f);
  for (int64_t i = 0; i < iters; ++i)
#pragma GCC unroll 12
    for (int k = 0; k < kChains; ++k) a[k] = _mm256_fmadd_ps(a[k], b, c);
  __m256 s = a[0];
  for (int k = 1; k < kChains; ++k) s = _mm256_add_ps(s, a[k]);
  asm volatile("" : "+v"(s));
  float out[8];
  _mm256_storeu_ps(out, s);
  float r = 0;
  for (float v : out) r += v;
  return r;
}

__attribute__((noinline)) float fma_loop_scalar(int64_t iters, float seed) {
  float a[kChains];
  for (int k = 0; k < kChains; ++k) a[k] = seed + 0.01f * k;
  for (int64_t i = 0; i < iters; ++i)
    for (int k = 0; k < kChains; ++k) a[k] = a[k] * 0.9999f + 1e-5f;
  float r = 0;
  for (float v : a) r += v;
  return r;
}

// Results land here so no FMA loop is ever dead code.
volatile float g_fma_sink = 0;

// The peak loop of the compiled ISA (core/isa.h): what the compiled kernels can reach. The
// start-up guard (core/isa_guard.cpp) has already checked that the CPU runs it.
float fma_loop(int lanes, int64_t iters, float seed) {
  if (lanes == 16) return fma_loop_avx512(iters, seed);
  if (lanes == 8) return fma_loop_avx2(iters, seed);
  return fma_loop_scalar(iters, seed);
}

}  // namespace

PeakMeasure measure_peak(int threads, double seconds) {
  const CompiledIsa isa = compiled_isa();
  PeakMeasure pm;
  pm.threads = threads;
  pm.isa = isa.name;
  auto loop = [&](int64_t iters, float seed) { return fma_loop(isa.lanes, iters, seed); };
  // Calibrate the iteration count on one thread (~20 ms), then run for `seconds`.
  int64_t iters = 1 << 16;
  for (;;) {
    double t0 = thread_cpu_ms();
    g_fma_sink = g_fma_sink + loop(iters, 1.f);
    double dt = thread_cpu_ms() - t0;
    if (dt > 20 || iters > (int64_t(1) << 40)) {
      iters = std::max<int64_t>(1, int64_t(double(iters) * seconds * 1e3 / std::max(dt, 1e-3)));
      break;
    }
    iters *= 4;
  }
  const double flops_per_thread = double(iters) * kChains * isa.lanes * 2.0;
  // Best of 3: the least disturbed repetition.
  for (int rep = 0; rep < 3; ++rep) {
    std::vector<double> cpu(threads, 0);
    const double w0 = bench_wall_s();
#pragma omp parallel num_threads(threads)
    {
      const int t = omp_get_thread_num();
      const double c0 = thread_cpu_ms();
      const float r = loop(iters, 1.f + float(t));
      cpu[t] = thread_cpu_ms() - c0;
      if (r == 12345.f) g_fma_sink = r;  // never true; keeps r (and the loop) alive
    }
    const double wall = bench_wall_s() - w0;
    double g_cpu = 0;
    for (int t = 0; t < threads; ++t) g_cpu += flops_per_thread / (cpu[t] * 1e-3) * 1e-9;
    pm.gflops_cpu = std::max(pm.gflops_cpu, g_cpu);
    pm.gflops_wall = std::max(pm.gflops_wall, flops_per_thread * threads / wall * 1e-9);
  }
  return pm;
}

std::string NominalPeak::how() const {
  return fmt::format("{} cores × {} FMA units × {} lanes ({}) × 2 FLOP/FMA × {:.3f} GHz ({}) = "
                     "{:.1f} GFLOP/s",
                     cores, fma_units, lanes, isa, ghz, clock_source, gflops());
}

NominalPeak nominal_peak(int cores) {
  NominalPeak n;
  const CompiledIsa isa = compiled_isa();
  n.cores = cores;
  n.lanes = isa.lanes;
  n.isa = isa.name;
  // Two FMA pipes per core on every AVX2/AVX-512 x86 core hashcc targets (Haswell+, Zen 1+;
  // some AVX-512 parts have one 512-bit unit: then this is an upper bound).
  n.fma_units = isa.lanes > 1 ? 2 : 1;
  {
    std::ifstream f("/sys/devices/system/cpu/cpu0/cpufreq/cpuinfo_max_freq");
    double khz = 0;
    if (f >> khz && khz > 0) {
      n.ghz = khz * 1e-6;
      n.clock_source = "cpufreq cpuinfo_max_freq";
      return n;
    }
  }
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  double mhz = 0;
  while (std::getline(f, line)) {
    if (line.rfind("model name", 0) == 0) {
      auto at = line.find('@');
      auto g = line.find("GHz");
      if (at != std::string::npos && g != std::string::npos && g > at) {
        n.ghz = std::atof(line.c_str() + at + 1);
        n.clock_source = "/proc/cpuinfo model name";
        return n;
      }
    }
    if (mhz == 0 && line.rfind("cpu MHz", 0) == 0) {
      auto c = line.find(':');
      if (c != std::string::npos) mhz = std::atof(line.c_str() + c + 1);
    }
  }
  n.ghz = mhz * 1e-3;
  n.clock_source = mhz > 0 ? "/proc/cpuinfo cpu MHz (current clock)" : "unknown";
  return n;
}

}  // namespace hashcc
