// core/parallel.h — thread-partition helpers over OpenMP, and a deterministic RNG.
//
// Rule (design.md practice 5): parallelise over what you write. parallel_for splits [0, n)
// into contiguous static blocks, so each output element is written by exactly one thread and
// the results do not depend on the thread count (beyond float rounding in reductions, which
// the callers keep in a fixed order).
#pragma once
#include <cmath>
#include <cstdint>
#include <omp.h>

namespace hashcc {

inline int num_threads() { return omp_get_max_threads(); }
inline void set_num_threads(int n) { if (n > 0) omp_set_num_threads(n); }

// Calls fn(begin, end, thread_index) over a static split of [0, n) into at most
// num_threads() contiguous blocks. Serial (no OpenMP overhead) for small n.
template <class Fn>
void parallel_blocks(int64_t n, Fn&& fn, int64_t min_per_thread = 1) {
  if (n <= 0) return;
  int nt = num_threads();
  // Serial when small, single-threaded, or already inside a parallel region (the data-parallel
  // step runs whole chunks per thread; kernels inside it must not fork again).
  if (n < 2 * min_per_thread || nt == 1 || omp_in_parallel()) { fn(int64_t(0), n, 0); return; }
#pragma omp parallel num_threads(nt)
  {
    int t = omp_get_thread_num(), T = omp_get_num_threads();
    int64_t b = n * t / T, e = n * (t + 1) / T;
    if (b < e) fn(b, e, t);
  }
}

// Calls fn(i) for i in [0, n), statically split.
template <class Fn>
void parallel_for(int64_t n, Fn&& fn, int64_t min_per_thread = 1) {
  parallel_blocks(n, [&](int64_t b, int64_t e, int) { for (int64_t i = b; i < e; ++i) fn(i); },
                  min_per_thread);
}

// PCG32 (O'Neill): small, fast, statistically good, and cheap to split into independent
// streams. Per-ray or per-image streams (seed, stream = ray index) make sampling independent
// of how work is split across threads.
struct Rng {
  uint64_t state = 0, inc = 1;
  Rng() : Rng(0) {}
  explicit Rng(uint64_t seed, uint64_t stream = 0) { reseed(seed, stream); }
  void reseed(uint64_t seed, uint64_t stream = 0) {
    state = 0; inc = (stream << 1u) | 1u; next_u32(); state += seed; next_u32();
  }
  uint32_t next_u32() {
    uint64_t old = state;
    state = old * 6364136223846793005ULL + inc;
    uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
    uint32_t rot = uint32_t(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((32 - rot) & 31));
  }
  // Uniform in [0, 1): 24 random bits, exact in float and double.
  double uniform() { return (next_u32() >> 8) * (1.0 / 16777216.0); }
  float uniformf() { return float(uniform()); }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Uniform integer in [0, n) (Lemire's nearly-divisionless method, exact rejection).
  uint32_t below(uint32_t n) {
    uint64_t m = uint64_t(next_u32()) * n;
    uint32_t l = uint32_t(m);
    if (l < n) {
      uint32_t t = (0u - n) % n;
      while (l < t) { m = uint64_t(next_u32()) * n; l = uint32_t(m); }
    }
    return uint32_t(m >> 32);
  }
  double normal() {  // Box–Muller
    double u1 = uniform(), u2 = uniform();
    if (u1 < 1e-300) u1 = 1e-300;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }
};

}  // namespace hashcc
