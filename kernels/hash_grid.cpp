// kernels/hash_grid.cpp — multiresolution hash encoding, forward/backward (see hash_grid.h,
// docs/math/hash_grid.md). Optimised kernels first, the plain references at the end.
#include "kernels/hash_grid.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <type_traits>
#include <vector>

#include "core/error.h"

namespace hashcc {
namespace {

// tiny-cuda-nn's spatial-hash primes; the x prime is 1 so the coherent axis stays coherent.
constexpr uint32_t kPrimeY = 2654435761u, kPrimeZ = 805459861u;
// Stack arrays of per-level geometry; far beyond any sensible config (the spec uses 16).
constexpr int kMaxLevels = 64;
constexpr int kMaxFeatures = 64;  // a point's dL/dout[l] is copied to a stack array (backward)
// Points per inner chunk: the level loop runs outside the points of a chunk, so one level's
// table (and scatter buffer) is reused by all the chunk's points before the next level evicts
// it. A step's model call is ≤ 64 rays × 64 samples = 4096 points, so one chunk covers the call:
// hashcc bench (hashcc+grid, 1 thread, Zen 3) measured step CPU 340 ms at 256 points a chunk,
// 333 at 1024, 267 at 4096 (the hashed levels' 2^15-row tables are re-read from L3 at every
// level of every chunk, so the fewer chunks the better).
constexpr int64_t kChunk = 4096;
// Per-thread scratch of a chunk (thread_local: ~0.3 MB, too big for an OpenMP worker's stack).
template <class T>
struct ChunkScratch {
  std::vector<T> xc, dx, fc;      // clamped x, dL/dx, one level's cell fractions (kChunk, 3)
  std::vector<uint32_t> ic;       // one level's corner rows (kChunk, 8)
  std::vector<T> sk;              // backward: one level's s_k = ⟨dL/dout, row_k⟩ (8, kChunk)
  ChunkScratch() : xc(kChunk * 3), dx(kChunk * 3), fc(kChunk * 3), ic(kChunk * 8), sk(kChunk * 8) {}
};
template <class T>
ChunkScratch<T>& chunk_scratch() {
  static thread_local ChunkScratch<T> s;
  return s;
}
// Below this many points per thread the OpenMP fork costs more than it saves.
constexpr int64_t kMinPerThread = 1024;

void validate(const HashGridConfig& c) {
  HCC_REQUIRE(c.levels >= 1 && c.levels <= kMaxLevels, "", "hash grid levels",
              "{} levels (expected 1..{})", c.levels, kMaxLevels);
  HCC_REQUIRE(c.features >= 1 && c.features <= kMaxFeatures, "", "hash grid features",
              "{} features (expected 1..{})", c.features, kMaxFeatures);
  HCC_REQUIRE(c.log2_table >= 0 && c.log2_table <= 30, "", "hash grid log2_table",
              "{} (expected 0..30)", c.log2_table);
  // scale_l ≥ 0 keeps p = scale·x + 0.5 ≥ 0.5, so corners are non-negative integers.
  HCC_REQUIRE(std::isfinite(c.base_res) && c.base_res >= 1 && std::isfinite(c.max_res) &&
                  c.max_res >= 1 && c.max_res <= (1 << 22),
              "", "hash grid resolution", "base {} max {} (expected 1 <= both <= 2^22)",
              c.base_res, c.max_res);
}

// Clamp to [0,1]; NaN compares false both ways and lands on 0, so no input can index outside.
template <class T>
inline T clamp01(T v) { return v > T(0) ? (v < T(1) ? v : T(1)) : T(0); }

// d clamp/dx: 1 inside [0,1] (one-sided at the ends), 0 where the clamp is active.
template <class T>
inline T inside01(T v) { return (v >= T(0) && v <= T(1)) ? T(1) : T(0); }

template <class T>
struct LevelT {
  T scale;
  uint32_t res, res2;
  bool dense;
};

template <class T>
void level_table(std::array<LevelT<T>, kMaxLevels>& out, const HashGridConfig& cfg) {
  for (int l = 0; l < cfg.levels; ++l) {
    HashGridLevel lv = hashgrid_level(cfg, l);
    // Only dense levels use res in the index; res² ≤ 2^T there, so uint32 cannot overflow.
    out[l] = {T(lv.scale), uint32_t(lv.res), uint32_t(lv.dense ? lv.res * lv.res : 0), lv.dense};
  }
}

// One point at one level: the 8 table rows of its cell (corner k: bit0 x+1, bit1 y+1,
// bit2 z+1) and the fractional position inside the cell (formulas.md §5).
template <class T>
inline void locate(const T* xc, const LevelT<T>& lv, uint32_t mask, uint32_t idx[8], T f[3]) {
  uint32_t c[3];
  for (int d = 0; d < 3; ++d) {
    // +0.5 stagger (tcnn): shifts each level's vertices by half a cell so the levels' cell
    // faces do not all coincide at x = 0.
    T p = lv.scale * xc[d] + T(0.5);
    T fl = std::floor(p);
    f[d] = p - fl;
    c[d] = uint32_t(fl);  // p ≥ 0.5 because x is clamped and scale ≥ 0
  }
  if (lv.dense) {
    // Dense when res³ ≤ 2^T (tcnn): a coarse level fits one-to-one, so no collisions at all.
    // Vertex res (reached when frac(scale) ≥ 0.5 at x = 1) aliases as in tcnn; & mask keeps
    // every index inside the table.
    const uint32_t r = lv.res, r2 = lv.res2;
    const uint32_t i0 = c[0] + c[1] * r + c[2] * r2;
    const uint32_t off[8] = {0, 1, r, r + 1, r2, r2 + 1, r2 + r, r2 + r + 1};
    for (int k = 0; k < 8; ++k) idx[k] = (i0 + off[k]) & mask;
  } else {
    // Spatial hash (tcnn): XOR of coordinate·prime in uint32 (wrap-around intended); the
    // table size is 2^T, so "modulo table size" is & mask.
    const uint32_t hx[2] = {c[0], c[0] + 1u};
    const uint32_t hy[2] = {c[1] * kPrimeY, (c[1] + 1u) * kPrimeY};
    const uint32_t hz[2] = {c[2] * kPrimeZ, (c[2] + 1u) * kPrimeZ};
    for (int k = 0; k < 8; ++k) idx[k] = (hx[k & 1] ^ hy[(k >> 1) & 1] ^ hz[k >> 2]) & mask;
  }
}

// Trilinear weights w_k = Π_d (bit_d(k) ? f_d : 1 − f_d).
template <class T>
inline void weights(const T f[3], T w[8]) {
  const T gx[2] = {T(1) - f[0], f[0]}, gy[2] = {T(1) - f[1], f[1]}, gz[2] = {T(1) - f[2], f[2]};
  for (int k = 0; k < 8; ++k) w[k] = gx[k & 1] * gy[(k >> 1) & 1] * gz[k >> 2];
}

// δ(f) = (1 − cos πf)/2 and δ'(f) = (π/2)·sin πf for f ∈ [0, 1] (smooth straight-through
// weights). Float: polynomials in u = π(f − ½) ∈ [−π/2, π/2] (sin πf = cos u, cos πf = −sin u;
// Taylor to u¹² / u¹¹, error < 1e-7), 96 of them a point per 16 levels would cost more than
// the rest of the backward through libm; double: libm, so the gradient checks see exact values.
template <class T>
inline void smooth_weight(T f, T& a, T& da) {
  if constexpr (std::is_same_v<T, float>) {
    const float u = float(M_PI) * (f - 0.5f), u2 = u * u;
    const float sin_u =
        u * (1.f + u2 * (-1.f / 6 + u2 * (1.f / 120 + u2 * (-1.f / 5040 + u2 * (1.f / 362880 +
                                                                              u2 * (-1.f / 39916800))))));
    const float cos_u =
        1.f + u2 * (-0.5f + u2 * (1.f / 24 + u2 * (-1.f / 720 + u2 * (1.f / 40320 +
                                                                      u2 * (-1.f / 3628800 + u2 * (1.f / 479001600))))));
    a = (1.f + sin_u) * 0.5f;     // (1 − cos πf)/2 with cos πf = −sin u
    da = float(M_PI / 2) * cos_u;  // (π/2)·sin πf with sin πf = cos u
  } else {
    a = (T(1) - std::cos(T(M_PI) * f)) * T(0.5);
    da = T(M_PI / 2) * std::sin(T(M_PI) * f);
  }
}

// How many points ahead the accumulation loops prefetch their 8 table rows. The rows of a
// hashed level are random: without a prefetch each point waits for its cache misses in turn
// (perf: the scatter's stores were ~50% of the grid field's step); with the chunk's corner
// indices computed first, the misses of the next few points overlap the current one's work.
constexpr int kPrefetchAhead = 8;

// One level's corner rows and fractions for the m points of a chunk (locate, point by point).
template <class T>
inline void locate_chunk(const T* xc, int64_t m, const LevelT<T>& lv, uint32_t mask,
                         uint32_t* idx, T* f) {
  for (int64_t i = 0; i < m; ++i) locate(xc + i * 3, lv, mask, idx + i * 8, f + i * 3);
}

template <class T>
inline void prefetch_rows(const T* base, const uint32_t* idx, int F, int rw) {
  for (int k = 0; k < 8; ++k) {
    if (rw) __builtin_prefetch(base + int64_t(idx[k]) * F, 1);
    else __builtin_prefetch(base + int64_t(idx[k]) * F, 0);
  }
}

// FC = compile-time feature count (2 in production) or 0 for "use cfg.features".
template <class T, int FC>
void forward_block(T* out, const T* x, const T* table, int64_t b, int64_t e,
                   const HashGridConfig& cfg, const std::array<LevelT<T>, kMaxLevels>& lvs) {
  const int F = FC > 0 ? FC : cfg.features, L = cfg.levels, LF = L * F;
  const int64_t TS = cfg.table_size();
  const uint32_t mask = uint32_t(TS - 1);
  ChunkScratch<T>& cs = chunk_scratch<T>();
  T *xc = cs.xc.data(), *fc = cs.fc.data();
  uint32_t* ic = cs.ic.data();
  for (int64_t c0 = b; c0 < e; c0 += kChunk) {
    const int64_t m = std::min(kChunk, e - c0);
    for (int64_t i = 0; i < m * 3; ++i) xc[i] = clamp01(x[c0 * 3 + i]);
    for (int l = 0; l < L; ++l) {  // level-major: one level's 2^T·F table stays in cache
      const LevelT<T>& lv = lvs[l];
      const T* tab = table + int64_t(l) * TS * F;
      locate_chunk(xc, m, lv, mask, ic, fc);
      for (int64_t i = 0; i < std::min<int64_t>(m, kPrefetchAhead); ++i) prefetch_rows(tab, ic + i * 8, F, 0);
      for (int64_t i = 0; i < m; ++i) {
        if (i + kPrefetchAhead < m) prefetch_rows(tab, ic + (i + kPrefetchAhead) * 8, F, 0);
        const uint32_t* idx = ic + i * 8;
        T w[8];
        weights(fc + i * 3, w);
        T* o = out + (c0 + i) * LF + l * F;
        for (int ff = 0; ff < F; ++ff) {
          T acc = 0;
          for (int k = 0; k < 8; ++k) acc += w[k] * tab[int64_t(idx[k]) * F + ff];
          o[ff] = acc;
        }
      }
    }
  }
}

// dL/dx of one level for the m points of a chunk, from the corner sums s_k (sk, (8, m): corner
// k's row, s_k of point i at sk[k·m + i]) and the cell fractions fc (m, 3): dx (m, 3) +=.
// Arithmetic only (the table was read in the gather pass), one point per SIMD lane: GCC
// vectorises the loop (the polynomials of smooth_weight included), which the gather loop, with
// its indirect loads, cannot be. SMOOTH picks the weights (cfg.smooth_dx). Every point computes
// exactly what the one-loop kernel did, in the same order (bitwise the same dL/dx).
template <class T, bool SMOOTH>
void level_dx(T* __restrict dx, const T* __restrict sk, const T* __restrict fc, int64_t m,
              T scale) {
  const T *s0 = sk, *s1 = sk + m, *s2 = sk + 2 * m, *s3 = sk + 3 * m, *s4 = sk + 4 * m,
          *s5 = sk + 5 * m, *s6 = sk + 6 * m, *s7 = sk + 7 * m;
  for (int64_t i = 0; i < m; ++i) {
    // dL/df_d = Σ_k s_k ∂w_k/∂f_d, and ∂w_k/∂f_d is ±(product of the other two axis
    // weights): differences of s along axis d.
    // a = the per-axis weight of the upper corner and da its derivative: a = f, da = 1
    // (exact), or a = δ(f) = (1 − cos πf)/2, da = (π/2)·sin πf (smooth straight-through:
    // the gradient of the smooth-weight interpolant, which is continuous across faces).
    T a[3], da[3];
    for (int d = 0; d < 3; ++d) {
      if constexpr (SMOOTH) {
        smooth_weight(fc[i * 3 + d], a[d], da[d]);
      } else {
        a[d] = fc[i * 3 + d];
        da[d] = T(1);
      }
    }
    const T ux = T(1) - a[0], uy = T(1) - a[1], uz = T(1) - a[2];
    const T dfx = (s1[i] - s0[i]) * uy * uz + (s3[i] - s2[i]) * a[1] * uz +
                  (s5[i] - s4[i]) * uy * a[2] + (s7[i] - s6[i]) * a[1] * a[2];
    const T dfy = (s2[i] - s0[i]) * ux * uz + (s3[i] - s1[i]) * a[0] * uz +
                  (s6[i] - s4[i]) * ux * a[2] + (s7[i] - s5[i]) * a[0] * a[2];
    const T dfz = (s4[i] - s0[i]) * ux * uy + (s5[i] - s1[i]) * a[0] * uy +
                  (s6[i] - s2[i]) * ux * a[1] + (s7[i] - s3[i]) * a[0] * a[1];
    // df/dx = scale_l (p = scale_l·x + 0.5)
    dx[i * 3 + 0] += scale * da[0] * dfx;
    dx[i * 3 + 1] += scale * da[1] * dfy;
    dx[i * 3 + 2] += scale * da[2] * dfz;
  }
}

// Scatter dL/dtable into this thread's buffer `gbuf` (L, 2^T, F; null: no table gradient) and,
// when d_x is non-null, write dL/dx for the block's points. Per level two passes over a chunk's
// points: the gather pass (the table rows: the scatter and, for dL/dx, the corner sums s_k) and
// the arithmetic pass (level_dx). Split, the gather loop is short enough for the core to keep
// many points' cache misses in flight, and the arithmetic runs 16 points a vector: the eval's
// test-pose refinement (positions only) measured the backward 3× faster (docs/performance.md).
template <class T, int FC>
void backward_block(T* gbuf, T* d_x, const T* d_out, const T* d_out_x, const T* x, const T* table,
                    int64_t b, int64_t e, const HashGridConfig& cfg,
                    const std::array<LevelT<T>, kMaxLevels>& lvs) {
  const int F = FC > 0 ? FC : cfg.features, L = cfg.levels, LF = L * F;
  const int64_t TS = cfg.table_size();
  const uint32_t mask = uint32_t(TS - 1);
  ChunkScratch<T>& cs = chunk_scratch<T>();
  T *xc = cs.xc.data(), *dx = cs.dx.data(), *fc = cs.fc.data(), *sk = cs.sk.data();
  uint32_t* ic = cs.ic.data();
  for (int64_t c0 = b; c0 < e; c0 += kChunk) {
    const int64_t m = std::min(kChunk, e - c0);
    for (int64_t i = 0; i < m * 3; ++i) xc[i] = clamp01(x[c0 * 3 + i]);
    if (d_x) std::fill(dx, dx + m * 3, T(0));
    for (int l = 0; l < L; ++l) {
      const LevelT<T>& lv = lvs[l];
      const T* tab = table + int64_t(l) * TS * F;
      T* g_tab = gbuf ? gbuf + int64_t(l) * TS * F : nullptr;
      locate_chunk(xc, m, lv, mask, ic, fc);
      auto prefetch = [&](int64_t i) {
        if (g_tab) prefetch_rows(g_tab, ic + i * 8, F, 1);
        if (d_x) prefetch_rows(tab, ic + i * 8, F, 0);
      };
      for (int64_t i = 0; i < std::min<int64_t>(m, kPrefetchAhead); ++i) prefetch(i);
      for (int64_t i = 0; i < m; ++i) {
        if (i + kPrefetchAhead < m) prefetch(i + kPrefetchAhead);
        const uint32_t* idx = ic + i * 8;
        // s_k = ⟨dL/dout[l], table[idx_k]⟩ for dL/dx (level_dx below), read BEFORE the
        // scatter (the table is not the gradient table, so the order does not change the
        // values); dL/dout is d_out_x's when given (the losses that reach the positions).
        if (d_x) {
          T gx[FC > 0 ? FC : kMaxFeatures];
          const T* gxsrc = (d_out_x ? d_out_x : d_out) + (c0 + i) * LF + l * F;
          for (int ff = 0; ff < F; ++ff) gx[ff] = gxsrc[ff];
          for (int k = 0; k < 8; ++k) {
            T acc = 0;
            for (int ff = 0; ff < F; ++ff) acc += gx[ff] * tab[int64_t(idx[k]) * F + ff];
            sk[k * m + i] = acc;
          }
        }
        // dL/dtable[idx_k, f] += w_k · dL/dout[l, f]   (out is linear in the table)
        if (g_tab) {
          T w[8];
          weights(fc + i * 3, w);
          // This point's dL/dout[l] in registers: the scatter below may not alias it (d_out
          // and the gradient table are different arrays, but the compiler cannot know that).
          T g[FC > 0 ? FC : kMaxFeatures];
          const T* gsrc = d_out + (c0 + i) * LF + l * F;
          for (int ff = 0; ff < F; ++ff) g[ff] = gsrc[ff];
          for (int k = 0; k < 8; ++k)
            for (int ff = 0; ff < F; ++ff) g_tab[int64_t(idx[k]) * F + ff] += w[k] * g[ff];
        }
      }
      if (d_x) {
        if (cfg.smooth_dx) level_dx<T, true>(dx, sk, fc, m, lv.scale);
        else level_dx<T, false>(dx, sk, fc, m, lv.scale);
      }
    }
    if (d_x)  // activation gradient: written (=); zero where the clamp was active
      for (int64_t i = 0; i < m * 3; ++i) d_x[c0 * 3 + i] = dx[i] * inside01(x[c0 * 3 + i]);
  }
}

}  // namespace

HashGridLevel hashgrid_level(const HashGridConfig& cfg, int level) {
  validate(cfg);
  HCC_REQUIRE(level >= 0 && level < cfg.levels, "", "hash grid level", "{} (expected 0..{})",
              level, cfg.levels - 1);
  // b = exp((ln N_max − ln N_min)/(L−1)); a single level has no growth (b = 1).
  const double log_b =
      cfg.levels > 1 ? (std::log(cfg.max_res) - std::log(cfg.base_res)) / (cfg.levels - 1) : 0.0;
  double scale = cfg.base_res * std::exp(log_b * level) - 1.0;
  // Rounding noise in b^l must not push ceil() over an integer: N_max = 512 gives scale 511
  // and res 512 at the finest level, exactly as the real-number formula (and tcnn's float) do.
  const double r = std::round(scale);
  if (std::abs(scale - r) <= 1e-9 * std::max(1.0, r)) scale = r;
  const int64_t res = int64_t(std::ceil(scale)) + 1;
  const bool dense = res * res * res <= cfg.table_size();
  return {scale, res, dense};
}

std::vector<HashGridLevel> hashgrid_levels(const HashGridConfig& cfg) {
  std::vector<HashGridLevel> v;
  for (int l = 0; l < cfg.levels; ++l) v.push_back(hashgrid_level(cfg, l));
  return v;
}

uint32_t hashgrid_vertex_index(uint32_t cx, uint32_t cy, uint32_t cz, const HashGridLevel& lv,
                               int64_t table_size) {
  uint32_t i;
  if (lv.dense) {
    const uint32_t r = uint32_t(lv.res);
    i = cx + cy * r + cz * r * r;
  } else {
    i = cx ^ (cy * kPrimeY) ^ (cz * kPrimeZ);
  }
  return uint32_t(uint64_t(i) % uint64_t(table_size));
}

template <class T>
void hashgrid_init_table(T* table, const HashGridConfig& cfg, Rng& rng) {
  const int64_t n = cfg.param_count();
  for (int64_t i = 0; i < n; ++i) table[i] = T(rng.uniform(-1e-4, 1e-4));  // formulas.md §5
}

template <class T>
void hashgrid_forward(T* out, const T* x, const T* table, int64_t N, const HashGridConfig& cfg) {
  validate(cfg);
  if (N <= 0) return;
  std::array<LevelT<T>, kMaxLevels> lvs;
  level_table(lvs, cfg);
  parallel_blocks(
      N,
      [&](int64_t b, int64_t e, int) {
        if (cfg.features == 2) forward_block<T, 2>(out, x, table, b, e, cfg, lvs);
        else forward_block<T, 0>(out, x, table, b, e, cfg, lvs);
      },
      kMinPerThread);
}

template <class T>
void hashgrid_backward(T* d_table, T* d_x, const T* d_out, const T* x, const T* table, int64_t N,
                       const HashGridConfig& cfg, HashGridWorkspace<T>& ws, const T* d_out_x) {
  validate(cfg);
  if (N <= 0 || (!d_table && !d_x)) return;
  std::array<LevelT<T>, kMaxLevels> lvs;
  level_table(lvs, cfg);
  // Points [b, e) scattered into gbuf (null: no table gradient), F = 2 specialised.
  const auto block = [&](T* gbuf, int64_t b, int64_t e) {
    if (cfg.features == 2) backward_block<T, 2>(gbuf, d_x, d_out, d_out_x, x, table, b, e, cfg, lvs);
    else backward_block<T, 0>(gbuf, d_x, d_out, d_out_x, x, table, b, e, cfg, lvs);
  };
  const int nt = std::max(1, num_threads());
  const bool par = nt > 1 && N >= 2 * kMinPerThread && !omp_in_parallel();
  if (!par) {
    // One thread (or inside the step's data-parallel region, whose d_table is already this
    // thread's own arena): scatter straight into d_table. No scratch to zero and reduce, which
    // for a large table (the grid field's 2^15+ entries a level) would cost more than the scatter.
    block(d_table, 0, N);
    return;
  }
  if (!d_table) {  // positions only (frozen tables): each thread its own points, no scatter
    parallel_blocks(N, [&](int64_t b, int64_t e, int) { block(nullptr, b, e); }, kMinPerThread);
    return;
  }
  if (int(ws.per_thread.size()) < nt) ws.per_thread.resize(nt);  // grow-only
  const int64_t P = cfg.param_count();
#pragma omp parallel num_threads(nt) if (par)
  {
    const int t = omp_get_thread_num(), TT = omp_get_num_threads();
    std::vector<T>& buf = ws.per_thread[t];
    if (int64_t(buf.size()) < P) buf.resize(P);  // grow-only, first touched by its thread
    std::fill(buf.begin(), buf.begin() + P, T(0));
    const int64_t b = N * t / TT, e = N * (t + 1) / TT;
    if (b < e) block(buf.data(), b, e);
#pragma omp barrier
    // Fixed-order reduction, split over entries (each thread writes its own slice of
    // d_table): d_table[i] += buf_0[i] + buf_1[i] + … — no atomics, deterministic.
    const int64_t rb = P * t / TT, re = P * (t + 1) / TT;
    for (int64_t i = rb; i < re; ++i) {
      T acc = ws.per_thread[0][i];
      for (int u = 1; u < TT; ++u) acc += ws.per_thread[u][i];
      d_table[i] += acc;
    }
  }
}

// ---- plain references: no chunking, no threads, index via hashgrid_vertex_index ----

// The naive kernels' cell lookup: clamp (NaN → 0), p = scale·x + 0.5, corner and fraction.
template <class T>
void naive_cell(uint32_t c[3], T fr[3], const T* x, const HashGridLevel& lv) {
  for (int d = 0; d < 3; ++d) {
    T v = x[d];
    v = std::isnan(v) ? T(0) : std::clamp(v, T(0), T(1));
    T p = T(lv.scale) * v + T(0.5);
    c[d] = uint32_t(std::floor(p));
    fr[d] = p - std::floor(p);
  }
}

template <class T>
void hashgrid_forward_naive(T* out, const T* x, const T* table, int64_t N,
                            const HashGridConfig& cfg) {
  const int L = cfg.levels, F = cfg.features;
  const int64_t TS = cfg.table_size();
  for (int64_t n = 0; n < N; ++n) {
    for (int l = 0; l < L; ++l) {
      const HashGridLevel lv = hashgrid_level(cfg, l);
      uint32_t c[3];
      T fr[3];
      naive_cell(c, fr, x + n * 3, lv);
      for (int f = 0; f < F; ++f) out[n * L * F + l * F + f] = 0;
      for (int k = 0; k < 8; ++k) {
        const int i = k & 1, j = (k >> 1) & 1, q = k >> 2;
        const T w = (i ? fr[0] : 1 - fr[0]) * (j ? fr[1] : 1 - fr[1]) * (q ? fr[2] : 1 - fr[2]);
        const uint32_t e = hashgrid_vertex_index(c[0] + i, c[1] + j, c[2] + q, lv, TS);
        for (int f = 0; f < F; ++f)
          out[n * L * F + l * F + f] += w * table[(int64_t(l) * TS + e) * F + f];
      }
    }
  }
}

template <class T>
void hashgrid_backward_naive(T* d_table, T* d_x, const T* d_out, const T* x, const T* table,
                             int64_t N, const HashGridConfig& cfg, const T* d_out_x) {
  if (!d_out_x) d_out_x = d_out;
  const int L = cfg.levels, F = cfg.features;
  const int64_t TS = cfg.table_size();
  for (int64_t n = 0; n < N; ++n) {
    T dx[3] = {0, 0, 0};
    for (int l = 0; l < L; ++l) {
      const HashGridLevel lv = hashgrid_level(cfg, l);
      uint32_t c[3];
      T fr[3];
      naive_cell(c, fr, x + n * 3, lv);
      for (int k = 0; k < 8; ++k) {
        const int b[3] = {k & 1, (k >> 1) & 1, k >> 2};
        T wa[3], dwa[3];  // per-axis weight of the gradient's interpolant and its derivative
        T wf = 1;         // the forward's (always trilinear) weight, for the table gradient
        for (int d = 0; d < 3; ++d) {
          wf *= b[d] ? fr[d] : 1 - fr[d];
          if (cfg.smooth_dx) {  // δ(f) = (1 − cos πf)/2; δ(1 − f) = 1 − δ(f)
            const T sm = (1 - std::cos(T(M_PI) * fr[d])) / 2, dsm = T(M_PI / 2) * std::sin(T(M_PI) * fr[d]);
            wa[d] = b[d] ? sm : 1 - sm;
            dwa[d] = b[d] ? dsm : -dsm;
          } else {
            wa[d] = b[d] ? fr[d] : 1 - fr[d];
            dwa[d] = b[d] ? T(1) : T(-1);
          }
        }
        const T w = wf;
        const uint32_t e = hashgrid_vertex_index(c[0] + b[0], c[1] + b[1], c[2] + b[2], lv, TS);
        for (int f = 0; f < F; ++f) {
          const T g = d_out[n * L * F + l * F + f], gx = d_out_x[n * L * F + l * F + f];
          const T tv = table[(int64_t(l) * TS + e) * F + f];
          d_table[(int64_t(l) * TS + e) * F + f] += w * g;
          dx[0] += T(lv.scale) * dwa[0] * wa[1] * wa[2] * gx * tv;
          dx[1] += T(lv.scale) * wa[0] * dwa[1] * wa[2] * gx * tv;
          dx[2] += T(lv.scale) * wa[0] * wa[1] * dwa[2] * gx * tv;
        }
      }
    }
    if (d_x)
      for (int d = 0; d < 3; ++d) {
        const T v = x[n * 3 + d];
        d_x[n * 3 + d] = (v >= 0 && v <= 1) ? dx[d] : T(0);
      }
  }
}

template <class T>
double hashgrid_decay(T* d_table, const T* table, const HashGridConfig& cfg, double lambda) {
  const int64_t per_level = cfg.table_size() * cfg.features;
  const double c = lambda / double(per_level);  // λ · mean over a level
  double r = 0;
  for (int l = 0; l < cfg.levels; ++l) {
    const T* t = table + int64_t(l) * per_level;
    T* g = d_table + int64_t(l) * per_level;
    double sq = 0;
    for (int64_t i = 0; i < per_level; ++i) {
      sq += double(t[i]) * double(t[i]);
      g[i] += T(2 * c) * t[i];
    }
    r += c * sq;
  }
  return r;
}

#define HASHCC_INSTANTIATE(T)                                                                   \
  template void hashgrid_forward<T>(T*, const T*, const T*, int64_t, const HashGridConfig&);   \
  template void hashgrid_backward<T>(T*, T*, const T*, const T*, const T*, int64_t,            \
                                     const HashGridConfig&, HashGridWorkspace<T>&, const T*);  \
  template void hashgrid_init_table<T>(T*, const HashGridConfig&, Rng&);                       \
  template double hashgrid_decay<T>(T*, const T*, const HashGridConfig&, double);              \
  template void hashgrid_forward_naive<T>(T*, const T*, const T*, int64_t,                     \
                                          const HashGridConfig&);                              \
  template void hashgrid_backward_naive<T>(T*, T*, const T*, const T*, const T*, int64_t,      \
                                           const HashGridConfig&, const T*);
HASHCC_INSTANTIATE(float)
HASHCC_INSTANTIATE(double)
#undef HASHCC_INSTANTIATE

}  // namespace hashcc
