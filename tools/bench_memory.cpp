// tools/bench_memory.cpp — `hashcc bench --memory`: the latency and bandwidth of each level of
// the memory hierarchy, measured, for the grid step's roofline (docs/performance.md, "The grid
// step's roofline"). Per working-set size (16 KiB … 256 MiB, i.e. L1d, L2, L3 and DRAM on the
// project's machine) and thread count, five probes, each on every thread at once (its own
// buffer), each the best of 3 repetitions of ~40 ms:
//
//   chase    dependent loads: p = next[p] over a random cycle of the buffer's cache lines
//            (Sattolo's algorithm), one load a line: the load-to-use LATENCY, ns a load
//   gather   independent random 8-byte loads (2 floats, a hash-grid row of F = 2) at indices
//            read from a 32,768-entry index array (128 KiB, the hash kernel's corner-index
//            chunk), 8 accumulators: the THROUGHPUT of the forward's gathers, ns a row
//   scatter  the same indices, row += value (read-modify-write of 2 floats): the backward's
//            scatter-add into the gradient table, ns a row
//   read     sequential vector loads over the buffer, summed: streaming READ bandwidth, GB/s
//   write    sequential vector stores over the buffer: streaming WRITE bandwidth, GB/s
//
// The vector width is the compiled ISA's (AVX-512 / AVX2 / scalar), as the peak's. Nothing here
// is asserted; the numbers go to the table and (--json) to a file that tools/grid_roofline.py
// reads.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <immintrin.h>
#include <memory>
#include <nlohmann/json.hpp>
#include <omp.h>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "core/error.h"
#include "core/fileio.h"
#include "core/isa.h"
#include "core/parallel.h"
#include "tools/bench.h"

namespace hashcc {

namespace {

// 64-byte aligned, page-touched buffer of n bytes (n a multiple of 64).
struct Buf {
  float* p = nullptr;
  explicit Buf(int64_t n) {
    p = static_cast<float*>(std::aligned_alloc(64, size_t(n)));
    HCC_REQUIRE(p != nullptr, "", "bench --memory", "{} bytes", n, "allocation failed");
    std::memset(p, 0, size_t(n));
  }
  ~Buf() { std::free(p); }
  Buf(const Buf&) = delete;
  Buf& operator=(const Buf&) = delete;
};

uint64_t splitmix(uint64_t& s) {
  uint64_t z = (s += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// One cycle through all n lines in random order (Sattolo): line i's first word holds the next.
void make_chase(uint32_t* words, int64_t lines, uint64_t seed) {
  std::vector<uint32_t> perm(static_cast<size_t>(lines));
  for (int64_t i = 0; i < lines; ++i) perm[size_t(i)] = uint32_t(i);
  for (int64_t i = lines - 1; i > 0; --i) {
    const int64_t j = int64_t(splitmix(seed) % uint64_t(i));  // j < i: a single cycle
    std::swap(perm[size_t(i)], perm[size_t(j)]);
  }
  for (int64_t i = 0; i < lines; ++i) words[int64_t(perm[size_t(i)]) * 16] = perm[size_t((i + 1) % lines)];
}

// Continues the chase from `p` (a line on the cycle) and returns where it stopped. Each call
// starts where the last one ended: were every call to start at 0, the compiler may treat the
// call as pure, compute it once and scale by the repetitions (a first version measured 4e-17 ns).
__attribute__((noinline)) uint32_t chase(const uint32_t* words, int64_t loads, uint32_t p) {
  for (int64_t i = 0; i < loads; ++i) {
    p = words[int64_t(p) * 16];
    asm volatile("" : "+r"(p));  // one dependent load per iteration, nothing folded
  }
  return p;
}

constexpr int64_t kIdx = 32768;  // the hash kernel's chunk: 4,096 points × 8 corners

__attribute__((noinline)) float gather(const float* tab, const uint32_t* idx, int64_t reps) {
  float a[8][2] = {};
  for (int64_t r = 0; r < reps; ++r)
    for (int64_t i = 0; i < kIdx; i += 8)
#pragma GCC unroll 8
      for (int k = 0; k < 8; ++k) {
        const float* row = tab + 2 * int64_t(idx[i + k]);
        a[k][0] += row[0];
        a[k][1] += row[1];
      }
  float s = 0;
  for (auto& v : a) s += v[0] + v[1];
  return s;
}

__attribute__((noinline)) void scatter(float* tab, const uint32_t* idx, int64_t reps) {
  for (int64_t r = 0; r < reps; ++r)
    for (int64_t i = 0; i < kIdx; ++i) {
      float* row = tab + 2 * int64_t(idx[i]);
      row[0] += 1e-30f;
      row[1] += 1e-30f;
    }
}

// Streaming loads / stores of n floats (n a multiple of 64), the compiled ISA's vectors.
__attribute__((noinline)) float stream_read(const float* p, int64_t n, int64_t reps) {
#if defined(__AVX512F__)
  __m512 a0 = _mm512_setzero_ps(), a1 = a0, a2 = a0, a3 = a0;
  for (int64_t r = 0; r < reps; ++r)
    for (int64_t i = 0; i < n; i += 64) {
      a0 = _mm512_add_ps(a0, _mm512_load_ps(p + i));
      a1 = _mm512_add_ps(a1, _mm512_load_ps(p + i + 16));
      a2 = _mm512_add_ps(a2, _mm512_load_ps(p + i + 32));
      a3 = _mm512_add_ps(a3, _mm512_load_ps(p + i + 48));
    }
  return _mm512_reduce_add_ps(_mm512_add_ps(_mm512_add_ps(a0, a1), _mm512_add_ps(a2, a3)));
#elif defined(__AVX2__)
  __m256 a[8];
  for (auto& v : a) v = _mm256_setzero_ps();
  for (int64_t r = 0; r < reps; ++r)
    for (int64_t i = 0; i < n; i += 64)
      for (int k = 0; k < 8; ++k) a[k] = _mm256_add_ps(a[k], _mm256_load_ps(p + i + 8 * k));
  float out[8], s = 0;
  for (int k = 1; k < 8; ++k) a[0] = _mm256_add_ps(a[0], a[k]);
  _mm256_storeu_ps(out, a[0]);
  for (float v : out) s += v;
  return s;
#else
  float a[16] = {};
  for (int64_t r = 0; r < reps; ++r)
    for (int64_t i = 0; i < n; i += 16)
      for (int k = 0; k < 16; ++k) a[k] += p[i + k];
  float s = 0;
  for (float v : a) s += v;
  return s;
#endif
}

__attribute__((noinline)) void stream_write(float* p, int64_t n, int64_t reps, float v) {
#if defined(__AVX512F__)
  const __m512 x = _mm512_set1_ps(v);
  for (int64_t r = 0; r < reps; ++r)
    for (int64_t i = 0; i < n; i += 16) _mm512_store_ps(p + i, x);
#elif defined(__AVX2__)
  const __m256 x = _mm256_set1_ps(v);
  for (int64_t r = 0; r < reps; ++r)
    for (int64_t i = 0; i < n; i += 8) _mm256_store_ps(p + i, x);
#else
  for (int64_t r = 0; r < reps; ++r)
    for (int64_t i = 0; i < n; ++i) p[i] = v;
#endif
  asm volatile("" ::"r"(p) : "memory");
}

volatile float g_sink = 0;

// Runs fn(reps) on `threads` threads at once (each its own state, made by make(t)), calibrating
// reps on thread 0 to ~target seconds; best of 3. Returns the mean over threads of each
// thread's seconds per rep (the best repetition).
template <class Make>
double time_probe(int threads, double target, const Make& make) {
  // Each thread's probe: a callable (reps) → void, built once (buffers, index arrays).
  std::vector<std::function<void(int64_t)>> probes(static_cast<size_t>(threads));
#pragma omp parallel num_threads(threads)
  probes[size_t(omp_get_thread_num())] = make(omp_get_thread_num());  // first touch by its thread
  int64_t reps = 1;
  for (;;) {
    const double t0 = bench_wall_s();
    probes[0](reps);
    const double dt = bench_wall_s() - t0;
    if (dt > 0.01 || reps > (int64_t(1) << 40)) {
      reps = std::max<int64_t>(1, int64_t(double(reps) * target / std::max(dt, 1e-6)));
      break;
    }
    reps *= 4;
  }
  double best = 1e300;
  for (int rep = 0; rep < 3; ++rep) {
    std::vector<double> sec(size_t(threads), 0);
#pragma omp parallel num_threads(threads)
    {
      const int t = omp_get_thread_num();
      probes[size_t(t)](1);  // warm: the buffer back in its cache level
#pragma omp barrier
      const double t0 = bench_wall_s();
      probes[size_t(t)](reps);
      sec[size_t(t)] = bench_wall_s() - t0;
    }
    double mean = 0;
    for (double s : sec) mean += s / threads;
    best = std::min(best, mean / double(reps));
  }
  return best;
}

struct CacheLevel { int level = 0; std::string type; int64_t bytes = 0; std::string shared; };

std::vector<CacheLevel> read_caches() {
  std::vector<CacheLevel> v;
  for (int i = 0; i < 8; ++i) {
    const std::string d = fmt::format("/sys/devices/system/cpu/cpu0/cache/index{}/", i);
    std::ifstream lv(d + "level"), ty(d + "type"), sz(d + "size"), sh(d + "shared_cpu_list");
    CacheLevel c;
    std::string size;
    if (!(lv >> c.level) || !(ty >> c.type) || !(sz >> size)) break;
    sh >> c.shared;
    int64_t n = std::atoll(size.c_str());
    if (size.back() == 'K') n <<= 10;
    if (size.back() == 'M') n <<= 20;
    c.bytes = n;
    v.push_back(c);
  }
  return v;
}

}  // namespace

// "model name (family F, model M)" of /proc/cpuinfo's first processor (bench.h).
std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  std::string line, name = "?", fam = "?", model = "?";
  while (std::getline(f, line)) {
    auto val = [&] { auto c = line.find(':'); return c == std::string::npos ? std::string() : line.substr(c + 2); };
    if (name == "?" && line.rfind("model name", 0) == 0) name = val();
    else if (fam == "?" && line.rfind("cpu family", 0) == 0) fam = val();
    else if (model == "?" && line.rfind("model\t", 0) == 0) model = val();
  }
  return fmt::format("{} (family {}, model {})", name, fam, model);
}

void run_bench_memory(const BenchMemoryOptions& o) {
  std::vector<int> threads = o.threads;
  const int all = std::max(1, num_threads());
  if (threads.empty()) {
    threads.push_back(1);
    if (all > 1) threads.push_back(all);
  }
  std::vector<int64_t> sizes = o.sizes;
  if (sizes.empty())
    for (int64_t kib : {16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192, 16384, 32768, 65536, 262144})
      sizes.push_back(kib << 10);
  double load0[3], load1[3];
  read_load_average(load0);
  const CompiledIsa isa = compiled_isa();
  const auto caches = read_caches();
  std::string cache_line;
  for (const auto& c : caches)
    cache_line += fmt::format("{}L{} {} {} KiB (cpus {})", cache_line.empty() ? "" : ", ", c.level,
                              c.type, c.bytes >> 10, c.shared);
  fmt::print("memory probes: {}; compiled ISA {} (this CPU: {}); caches: {}\n", cpu_model(), isa.name,
             cpu_isa_name(), cache_line);
  fmt::print("load average {:.2f} {:.2f} {:.2f} before{}\n", load0[0], load0[1], load0[2],
             load0[0] > 0.5 ? "  — LOADED machine: these figures measure the contention too" : "");
  fmt::print("{:>3} {:>10} {:>10} {:>11} {:>12} {:>10} {:>10}   (per thread; GB/s: all threads)\n",
             "thr", "size KiB", "chase ns", "gather ns", "scatter ns", "read GB/s", "write GB/s");
  nlohmann::json rows = nlohmann::json::array();
  const double target = o.seconds;
  for (int nt : threads)
    for (int64_t bytes : sizes) {
      const int64_t floats = bytes / 4, lines = bytes / 64, rows_ = bytes / 8;
      // chase: ns a dependent load
      const double t_chase = time_probe(nt, target, [&](int t) {
        auto b = std::make_shared<Buf>(bytes);
        make_chase(reinterpret_cast<uint32_t*>(b->p), lines, 0x1234 + uint64_t(t));
        const int64_t loads = std::max<int64_t>(lines, 4096);
        return std::function<void(int64_t)>([b, loads](int64_t reps) {
          uint32_t p = 0;
          for (int64_t r = 0; r < reps; ++r) p = chase(reinterpret_cast<const uint32_t*>(b->p), loads, p);
          if (p == 0xFFFFFFFFu) g_sink = 1;
        });
      }) / double(std::max<int64_t>(lines, 4096));
      auto make_idx = [&](int t) {
        auto idx = std::make_shared<std::vector<uint32_t>>(size_t(kIdx));
        uint64_t s = 0xABCD + uint64_t(t);
        for (auto& i : *idx) i = uint32_t(splitmix(s) % uint64_t(rows_));
        return idx;
      };
      const double t_gather = time_probe(nt, target, [&](int t) {
        auto b = std::make_shared<Buf>(bytes);
        auto idx = make_idx(t);
        return std::function<void(int64_t)>([b, idx](int64_t reps) {
          const float s = gather(b->p, idx->data(), reps);
          if (s == 12345.f) g_sink = s;
        });
      }) / double(kIdx);
      const double t_scatter = time_probe(nt, target, [&](int t) {
        auto b = std::make_shared<Buf>(bytes);
        auto idx = make_idx(t);
        return std::function<void(int64_t)>([b, idx](int64_t reps) { scatter(b->p, idx->data(), reps); });
      }) / double(kIdx);
      const double t_read = time_probe(nt, target, [&](int) {
        auto b = std::make_shared<Buf>(bytes);
        return std::function<void(int64_t)>([b, floats](int64_t reps) {
          const float s = stream_read(b->p, floats, reps);
          if (s == 12345.f) g_sink = s;
        });
      });
      const double t_write = time_probe(nt, target, [&](int) {
        auto b = std::make_shared<Buf>(bytes);
        return std::function<void(int64_t)>([b, floats](int64_t reps) { stream_write(b->p, floats, reps, 1.f); });
      });
      const double read_gbs = nt * double(bytes) / t_read * 1e-9, write_gbs = nt * double(bytes) / t_write * 1e-9;
      fmt::print("{:>3} {:>10} {:>10.2f} {:>11.3f} {:>12.3f} {:>10.1f} {:>10.1f}\n", nt, bytes >> 10,
                 t_chase * 1e9, t_gather * 1e9, t_scatter * 1e9, read_gbs, write_gbs);
      rows.push_back({{"threads", nt}, {"bytes", bytes}, {"chase_ns", t_chase * 1e9},
                      {"gather_ns", t_gather * 1e9}, {"scatter_ns", t_scatter * 1e9},
                      {"read_gbs", read_gbs}, {"write_gbs", write_gbs}});
    }
  read_load_average(load1);
  fmt::print("load average {:.2f} {:.2f} {:.2f} after\n", load1[0], load1[1], load1[2]);
  fmt::print("  chase: dependent loads, one a random cache line (latency); gather / scatter: "
             "independent random 8-byte rows (2 floats) read / read-modify-written, indices from a "
             "128 KiB array (throughput); read / write: streaming vectors of the compiled ISA\n");
  if (!o.json.empty()) {
    nlohmann::json caches_j = nlohmann::json::array();
    for (const auto& c : caches)
      caches_j.push_back({{"level", c.level}, {"type", c.type}, {"bytes", c.bytes}, {"shared_cpu_list", c.shared}});
    nlohmann::json j = {{"cpu_model", cpu_model()}, {"isa_compiled", isa.name}, {"isa_cpu", cpu_isa_name()},
                        {"caches", caches_j}, {"load_average", {load0[0], load0[1], load0[2]}},
                        {"load_average_after", {load1[0], load1[1], load1[2]}},
                        {"seconds_per_probe", target}, {"rows", rows}};
    write_file_atomic(o.json, j.dump(1) + "\n");
    fmt::print("wrote {}\n", o.json);
  }
}

}  // namespace hashcc
