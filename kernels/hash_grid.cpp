// kernels/hash_grid.cpp — multiresolution hash encoding, forward/backward (see hash_grid.h,
// docs/math/hash_grid.md). Optimised kernels first, the plain references at the end.
#include "kernels/hash_grid.h"

#include <immintrin.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <mutex>
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

// How many points ahead the gather and scatter loops prefetch their 8 table rows. The rows of
// a hashed level are random: without a prefetch each point waits for its cache misses in turn;
// with the block's corner rows computed first, the misses of the next few points overlap the
// current one's work.
constexpr int kPrefetchAhead = 8;
// A level's table this small sits in L1/L2 once warm (the CC branch's 2^9 rows: 4 KiB a level),
// and its prefetches would only take issue slots: the loops skip them (`pf`).
constexpr int64_t kPrefetchMinBytes = int64_t(64) << 10;
inline bool prefetch_pays(int64_t table_size, int F, size_t elem) {
  return table_size * F * int64_t(elem) > kPrefetchMinBytes;
}
// Points a block: the kernels locate a block's points at one level (vectorised, below), then
// gather (and scatter) their rows. The block's rows, weights and fractions (8 + 8 + 3 values a
// point, ~20 KiB in float) stay in L1 between the passes. Measured (`hashcc bench --hashgrid`
// with this constant changed, docs/bench/s24_kblock.txt, 2-core Zen 4, AVX-512): 256 the
// fastest or tied; 128 alike or slower; 512 and 1,024 slower by up to 1.5× (their row strides of
// 2–4 KiB put a point's 19 rows in the same few L1 sets).
constexpr int64_t kBlock = 256;

template <class T>
inline void prefetch_rows(const T* base, const uint32_t* idx, int64_t stride, int F, int rw) {
  for (int k = 0; k < 8; ++k) {
    if (rw) __builtin_prefetch(base + int64_t(idx[k * stride]) * F, 1);
    else __builtin_prefetch(base + int64_t(idx[k * stride]) * F, 0);
  }
}

// One level, points [0, m) of a block (m ≤ kBlock), structure of arrays with a row stride of
// kBlock: the clamped positions x0, x1, x2 → the corner rows ic (8 rows: corner k of point i at
// ic[k·kBlock + i]; corner k: bit0 x+1, bit1 y+1, bit2 z+1), the trilinear weights wc (8 rows,
// the same layout; w_k = Π_d (bit_d(k) ? f_d : 1 − f_d)) and the cell fractions fc (3 rows)
// (formulas.md §5). One point a SIMD lane: the loop has no indirect access, so GCC vectorises it
// (16 points a vector in float with AVX-512). The stride is a compile-time constant on purpose:
// with a runtime one GCC cannot prove the rows apart and leaves the loop scalar.
template <class T, bool DENSE>
void locate_block(const T* __restrict x0, const T* __restrict x1, const T* __restrict x2,
                  int64_t m, const LevelT<T>& lv, uint32_t mask, uint32_t* __restrict ic,
                  T* __restrict wc, T* __restrict fc) {
  const T scale = lv.scale;
  const uint32_t r = lv.res, r2 = lv.res2;
  for (int64_t i = 0; i < m; ++i) {
    // +0.5 stagger (tcnn): shifts each level's vertices by half a cell so the levels' cell
    // faces do not all coincide at x = 0. p ≥ 0.5 because x is clamped and scale ≥ 0.
    const T p0 = scale * x0[i] + T(0.5), p1 = scale * x1[i] + T(0.5), p2 = scale * x2[i] + T(0.5);
    // floor(p) as a truncation to int32: the same integer for 0.5 ≤ p < 2^22 + 1, exactly
    // representable back in T; GCC vectorises the conversion, not std::floor or → uint32.
    const int32_t i0 = int32_t(p0), i1 = int32_t(p1), i2 = int32_t(p2);
    const T f0 = p0 - T(i0), f1 = p1 - T(i1), f2 = p2 - T(i2);
    const uint32_t c0 = uint32_t(i0), c1 = uint32_t(i1), c2 = uint32_t(i2);
    fc[i] = f0;
    fc[kBlock + i] = f1;
    fc[2 * kBlock + i] = f2;
    if constexpr (DENSE) {
      // Dense when res³ ≤ 2^T (tcnn): a coarse level fits one-to-one, so no collisions at all.
      // Vertex res (reached when frac(scale) ≥ 0.5 at x = 1) aliases as in tcnn; & mask keeps
      // every index inside the table.
      const uint32_t v = c0 + c1 * r + c2 * r2;
      ic[i] = v & mask;
      ic[kBlock + i] = (v + 1) & mask;
      ic[2 * kBlock + i] = (v + r) & mask;
      ic[3 * kBlock + i] = (v + r + 1) & mask;
      ic[4 * kBlock + i] = (v + r2) & mask;
      ic[5 * kBlock + i] = (v + r2 + 1) & mask;
      ic[6 * kBlock + i] = (v + r2 + r) & mask;
      ic[7 * kBlock + i] = (v + r2 + r + 1) & mask;
    } else {
      // Spatial hash (tcnn): XOR of coordinate·prime in uint32 (wrap-around intended); the
      // table size is 2^T, so "modulo table size" is & mask.
      const uint32_t hx0 = c0, hx1 = c0 + 1u;
      const uint32_t hy0 = c1 * kPrimeY, hy1 = (c1 + 1u) * kPrimeY;
      const uint32_t hz0 = c2 * kPrimeZ, hz1 = (c2 + 1u) * kPrimeZ;
      ic[i] = (hx0 ^ hy0 ^ hz0) & mask;
      ic[kBlock + i] = (hx1 ^ hy0 ^ hz0) & mask;
      ic[2 * kBlock + i] = (hx0 ^ hy1 ^ hz0) & mask;
      ic[3 * kBlock + i] = (hx1 ^ hy1 ^ hz0) & mask;
      ic[4 * kBlock + i] = (hx0 ^ hy0 ^ hz1) & mask;
      ic[5 * kBlock + i] = (hx1 ^ hy0 ^ hz1) & mask;
      ic[6 * kBlock + i] = (hx0 ^ hy1 ^ hz1) & mask;
      ic[7 * kBlock + i] = (hx1 ^ hy1 ^ hz1) & mask;
    }
    // Trilinear weights, each formed as (g_x·g_y)·g_z.
    const T u0 = T(1) - f0, u1 = T(1) - f1, u2 = T(1) - f2;
    wc[i] = u0 * u1 * u2;
    wc[kBlock + i] = f0 * u1 * u2;
    wc[2 * kBlock + i] = u0 * f1 * u2;
    wc[3 * kBlock + i] = f0 * f1 * u2;
    wc[4 * kBlock + i] = u0 * u1 * f2;
    wc[5 * kBlock + i] = f0 * u1 * f2;
    wc[6 * kBlock + i] = u0 * f1 * f2;
    wc[7 * kBlock + i] = f0 * f1 * f2;
  }
}

template <class T>
inline void locate_block_level(const T* xs, int64_t m, const LevelT<T>& lv, uint32_t mask,
                               uint32_t* ic, T* wc, T* fc) {
  if (lv.dense) locate_block<T, true>(xs, xs + kBlock, xs + 2 * kBlock, m, lv, mask, ic, wc, fc);
  else locate_block<T, false>(xs, xs + kBlock, xs + 2 * kBlock, m, lv, mask, ic, wc, fc);
}

// Per-thread scratch of a block (thread_local: a few tens of KiB).
template <class T>
struct BlockScratch {
  std::vector<T> xs, fc, wc, sk;  // clamped x (3, kBlock), fractions (3, ·), weights (8, ·), s_k (8, ·)
  std::vector<T> dx;              // backward: dL/dx (kBlock, 3)
  std::vector<T> gw;              // forward with the Jacobian: its weights (12, kBlock)
  std::vector<uint32_t> ic;       // corner rows (8, kBlock)
  BlockScratch()
      : xs(3 * kBlock), fc(3 * kBlock), wc(8 * kBlock), sk(8 * kBlock), dx(3 * kBlock),
        gw(12 * kBlock), ic(8 * kBlock) {}
};
template <class T>
BlockScratch<T>& block_scratch() {
  static thread_local BlockScratch<T> s;
  return s;
}

// The block's positions, clamped, as (3, kBlock).
template <class T>
inline void load_block(T* xs, const T* x, int64_t m) {
  for (int64_t i = 0; i < m; ++i)
    for (int d = 0; d < 3; ++d) xs[d * kBlock + i] = clamp01(x[i * 3 + d]);
}

// A table row of the production F = 2 as one 2-lane vector (GCC vector extension: 8 bytes in
// float, 16 in double). Lane-wise the same operations as the scalar loops, so the same values.
typedef float Row2f __attribute__((vector_size(8)));
typedef double Row2d __attribute__((vector_size(16)));
template <class T>
using Row2 = std::conditional_t<std::is_same_v<T, float>, Row2f, Row2d>;
template <class T>
inline Row2<T> load_row2(const T* p) {
  Row2<T> r;
  std::memcpy(&r, p, sizeof r);
  return r;
}
template <class T>
inline void store_row2(T* p, Row2<T> r) { std::memcpy(p, &r, sizeof r); }

// Point i's per-axis weights of the position gradient from the cell fractions fc (3 rows of
// stride kBlock); SMOOTH picks them (cfg.smooth_dx). Inlined into loops over i with no indirect
// access, so GCC vectorises them (smooth_weight's polynomials included).
template <class T, bool SMOOTH>
inline void cell_axes(T a[3], T sda[3], const T* __restrict fc, int64_t i, T scale) {
  // a = the per-axis weight of the upper corner and da its derivative: a = f, da = 1
  // (exact), or a = δ(f) = (1 − cos πf)/2, da = (π/2)·sin πf (smooth straight-through:
  // the gradient of the smooth-weight interpolant, which is continuous across faces).
  // sda = scale_l · da: df/dx = scale_l (p = scale_l·x + 0.5).
  for (int d = 0; d < 3; ++d) {
    T da;
    if constexpr (SMOOTH) {
      smooth_weight(fc[d * kBlock + i], a[d], da);
    } else {
      a[d] = fc[d * kBlock + i];
      da = T(1);
    }
    sda[d] = scale * da;
  }
}

// The position gradient of one level's interpolant for point i of a block, from eight corner
// values s_k (rows of stride kBlock: corner k of point i at s[k·kBlock + i]) and the axis weights
// of cell_axes: g_d = scale_l · da_d · Σ_k s_k ∂w_k/∂a_d. With s_k = ⟨dL/dout[l], table[idx_k]⟩
// it is dL/dx (the backward); with s_k = table[idx_k][f] it is ∂out[l·F+f]/∂x (the forward's
// Jacobian). Inlined into loops over i with no indirect access, so GCC vectorises them.
template <class T>
inline void cell_grad(T g[3], const T* __restrict sk, int64_t i, const T a[3], const T sda[3]) {
  const T *s0 = sk, *s1 = sk + kBlock, *s2 = sk + 2 * kBlock, *s3 = sk + 3 * kBlock,
          *s4 = sk + 4 * kBlock, *s5 = sk + 5 * kBlock, *s6 = sk + 6 * kBlock, *s7 = sk + 7 * kBlock;
  // dL/df_d = Σ_k s_k ∂w_k/∂f_d, and ∂w_k/∂f_d is ±(product of the other two axis
  // weights): differences of s along axis d.
  const T ux = T(1) - a[0], uy = T(1) - a[1], uz = T(1) - a[2];
  const T dfx = (s1[i] - s0[i]) * uy * uz + (s3[i] - s2[i]) * a[1] * uz +
                (s5[i] - s4[i]) * uy * a[2] + (s7[i] - s6[i]) * a[1] * a[2];
  const T dfy = (s2[i] - s0[i]) * ux * uz + (s3[i] - s1[i]) * a[0] * uz +
                (s6[i] - s4[i]) * ux * a[2] + (s7[i] - s5[i]) * a[0] * a[2];
  const T dfz = (s4[i] - s0[i]) * ux * uy + (s5[i] - s1[i]) * a[0] * uy +
                (s6[i] - s2[i]) * ux * a[1] + (s7[i] - s3[i]) * a[0] * a[1];
  g[0] = sda[0] * dfx;
  g[1] = sda[1] * dfy;
  g[2] = sda[2] * dfz;
}

// dL/dx of one level for the m points of a block, from the corner sums s_k (sk, (8, m): corner
// k's row, s_k of point i at sk[k·kBlock + i]) and the cell fractions fc (3 rows, stride kBlock):
// dx (m, 3) +=. Arithmetic only (the table was read in the gather pass), one point per SIMD lane.
template <class T, bool SMOOTH>
void level_dx(T* __restrict dx, const T* __restrict sk, const T* __restrict fc, int64_t m,
              T scale) {
  for (int64_t i = 0; i < m; ++i) {
    T a[3], sda[3], g[3];
    cell_axes<T, SMOOTH>(a, sda, fc, i, scale);
    cell_grad(g, sk, i, a, sda);
    dx[i * 3 + 0] += g[0];
    dx[i * 3 + 1] += g[1];
    dx[i * 3 + 2] += g[2];
  }
}

// The corner pairs of the position gradient: along axis d, corner hi = lo + 2^d, and
// ∂out/∂x_d = Σ_q (v[hi_q] − v[lo_q]) · gw[d][q] (cell_grad's sums, expanded).
constexpr int kPairLo[3][4] = {{0, 2, 4, 6}, {0, 1, 4, 5}, {0, 1, 2, 3}};

// The Jacobian's weights of one level for the m points of a block: gw (12 rows of kBlock),
// gw[(d·4 + q)·kBlock + i] = scale_l · da_d · (the product of the other two axes' weights of
// pair q), in cell_grad's order of pairs. Arithmetic only: vectorised like level_dx.
template <class T, bool SMOOTH>
void level_jac_weights(T* __restrict gw, const T* __restrict fc, int64_t m, T scale) {
  for (int64_t i = 0; i < m; ++i) {
    T a[3], sda[3];
    cell_axes<T, SMOOTH>(a, sda, fc, i, scale);
    const T ux = T(1) - a[0], uy = T(1) - a[1], uz = T(1) - a[2];
    const T w[3][4] = {{uy * uz, a[1] * uz, uy * a[2], a[1] * a[2]},
                       {ux * uz, a[0] * uz, ux * a[2], a[0] * a[2]},
                       {ux * uy, a[0] * uy, ux * a[1], a[0] * a[1]}};
    for (int d = 0; d < 3; ++d)
      for (int q = 0; q < 4; ++q) gw[(d * 4 + q) * kBlock + i] = sda[d] * w[d][q];
  }
}

// Which gather the F = 2 float forward uses (hashgrid_set_gather): the mode, and kAuto's choice
// once measured (−1: not yet). tl_force: a calibration's override on its own thread.
std::atomic<int> g_gather_mode{int(GatherMode::kAuto)};
std::atomic<int> g_gather_auto{-1};
thread_local int tl_force = 0;  // 0: none, 1: SIMD, 2: scalar
bool calibrate_gather();
inline bool use_simd_gather() {
  if (tl_force) return tl_force == 1;
  const int m = g_gather_mode.load(std::memory_order_relaxed);
  if (m != int(GatherMode::kAuto)) return m == int(GatherMode::kSimd);
  const int c = g_gather_auto.load(std::memory_order_acquire);
  return c >= 0 ? c == 1 : calibrate_gather();
}

// The forward's gather of one level for the m points of a block, F = 2 in float, one point a
// SIMD lane: a row (2 floats) is one 64-bit element, so one gather instruction loads corner k's
// rows of 8 points (AVX-512; 4 with AVX2), each lane holding a point's (feature 0, feature 1).
// Every lane runs the scalar loop's arithmetic in its order — out = w_0·v_0, then
// out = fma(w_k, v_k, out) for k = 1..7; with the Jacobian, for each axis d,
// J_d = gw_d0·(v_hi − v_lo), then fma over the other 3 corner pairs — so the values are the
// scalar loop's bit for bit (test [hashgrid][simd]). Fewer instructions a point than 8 scalar
// loads and 2-lane FMAs, and a gather's rows are in flight together.
#if defined(__AVX512F__)
struct GatherIsa {  // 8 points a vector: __m512 = 8 rows of 2 floats
  using V = __m512;
  static constexpr int kLanes = 8;
  static V rows(const float* tab, const uint32_t* ic) {
    const __m256i idx = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(ic));
    return _mm512_castsi512_ps(_mm512_mask_i32gather_epi64(
        _mm512_setzero_si512(), 0xFF, idx, reinterpret_cast<const long long*>(tab), 8));
  }
  static V weights(const float* w) {  // 8 weights, each twice (both features of a row)
    const __m512i dup = _mm512_set_epi32(7, 7, 6, 6, 5, 5, 4, 4, 3, 3, 2, 2, 1, 1, 0, 0);
    return _mm512_maskz_permutexvar_ps(0xFFFF, dup, _mm512_maskz_loadu_ps(0x00FF, w));
  }
  static V mul(V a, V b) { return _mm512_mul_ps(a, b); }
  static V fma(V a, V b, V c) { return _mm512_fmadd_ps(a, b, c); }
  static V sub(V a, V b) { return _mm512_sub_ps(a, b); }
  static void store(float* r, V v) { _mm512_storeu_ps(r, v); }
};
#elif defined(__AVX2__) && defined(__FMA__)
struct GatherIsa {  // 4 points a vector: __m256 = 4 rows of 2 floats
  using V = __m256;
  static constexpr int kLanes = 4;
  static V rows(const float* tab, const uint32_t* ic) {
    const __m128i idx = _mm_loadu_si128(reinterpret_cast<const __m128i*>(ic));
    return _mm256_castsi256_ps(_mm256_mask_i32gather_epi64(
        _mm256_setzero_si256(), reinterpret_cast<const long long*>(tab), idx,
        _mm256_set1_epi64x(-1), 8));
  }
  static V weights(const float* w) {
    const __m256i dup = _mm256_set_epi32(3, 3, 2, 2, 1, 1, 0, 0);
    return _mm256_permutevar8x32_ps(_mm256_zextps128_ps256(_mm_loadu_ps(w)), dup);
  }
  static V mul(V a, V b) { return _mm256_mul_ps(a, b); }
  static V fma(V a, V b, V c) { return _mm256_fmadd_ps(a, b, c); }
  static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
  static void store(float* r, V v) { _mm256_storeu_ps(r, v); }
};
#else
struct GatherIsa { static constexpr int kLanes = 0; };  // no gathers: the scalar loop does all
#endif
constexpr int kGatherLanes = GatherIsa::kLanes;

// o: the block's first output row of this level (stride LF floats); J (JAC): the block's first
// Jacobian row of this level (point stride 3·LF, axis stride LF); gw: level_jac_weights'.
// Returns the points it did (a multiple of the lanes); the caller's scalar loop does the rest.
// S is a template parameter (not a plain alias of GatherIsa) so that the discarded branch is
// dependent: in a build without gathers (baseline x86-64, e.g. the sanitizer build) GatherIsa has
// no V, mul or fma, and `if constexpr` only skips the checking of code that depends on a template
// parameter.
template <bool JAC, class S = GatherIsa>
inline int64_t gather_level_f2(float* o, float* J, int64_t LF, const float* tab,
                               const uint32_t* ic, const float* wc, const float* gw, int64_t m,
                               bool pf) {
  if constexpr (S::kLanes == 0) {
    return 0;
  } else {
    using V = typename S::V;
    constexpr int NL = S::kLanes;
    const int64_t n = m - m % NL;
    alignas(64) float r[2 * NL];
    for (int64_t i = 0; i < n; i += NL) {
      if (pf)  // the next vector's rows, as the scalar loop prefetches 8 points ahead
        for (int64_t j = i + NL; j < std::min(m, i + 2 * NL); ++j) prefetch_rows(tab, ic + j, kBlock, 2, 0);
      V v[8];
      V acc;
      for (int k = 0; k < 8; ++k) {
        v[k] = S::rows(tab, ic + k * kBlock + i);
        const V w = S::weights(wc + k * kBlock + i);
        acc = k == 0 ? S::mul(w, v[k]) : S::fma(w, v[k], acc);
      }
      S::store(r, acc);
      for (int p = 0; p < NL; ++p) std::memcpy(o + (i + p) * LF, r + 2 * p, 8);
      if constexpr (JAC)
        for (int d = 0; d < 3; ++d) {
          V g;
          for (int q = 0; q < 4; ++q) {
            const int lo = kPairLo[d][q];
            const V w = S::weights(gw + (d * 4 + q) * kBlock + i);
            const V diff = S::sub(v[lo + (1 << d)], v[lo]);
            g = q == 0 ? S::mul(w, diff) : S::fma(w, diff, g);
          }
          S::store(r, g);
          for (int p = 0; p < NL; ++p) std::memcpy(J + (i + p) * 3 * LF + d * LF, r + 2 * p, 8);
        }
    }
    return n;
  }
}

// FC = compile-time feature count (2 in production) or 0 for "use cfg.features".
// jac (optional, (N, 3, L·F)): the position Jacobian as well (hashgrid_forward): its weights for
// the block in a vectorised pass (level_jac_weights), then, in the gather loop, differences of
// the corner rows the forward has just loaded: 12 differences and FMAs a feature, no second read
// of the table.
// JAC = (jac != null), a compile-time copy of the loops: with the Jacobian's code in the same
// loop behind a runtime test, GCC's code for the plain forward was ~15% slower (bench --hashgrid).
template <class T, int FC, bool JAC>
void forward_block(T* out, T* jac, const T* x, const T* table, int64_t b, int64_t e,
                   const HashGridConfig& cfg, const std::array<LevelT<T>, kMaxLevels>& lvs) {
  const int F = FC > 0 ? FC : cfg.features, L = cfg.levels, LF = L * F;
  const int64_t TS = cfg.table_size();
  const uint32_t mask = uint32_t(TS - 1);
  const bool pf = prefetch_pays(TS, F, sizeof(T));
  BlockScratch<T>& bs = block_scratch<T>();
  T *xs = bs.xs.data(), *fc = bs.fc.data(), *wc = bs.wc.data(), *gw = bs.gw.data();
  uint32_t* ic = bs.ic.data();
  for (int64_t c0 = b; c0 < e; c0 += kBlock) {
    const int64_t m = std::min(kBlock, e - c0);
    load_block(xs, x + c0 * 3, m);
    for (int l = 0; l < L; ++l) {
      const T* tab = table + int64_t(l) * TS * F;
      locate_block_level(xs, m, lvs[l], mask, ic, wc, fc);
      if constexpr (JAC) {
        if (cfg.smooth_dx) level_jac_weights<T, true>(gw, fc, m, lvs[l].scale);
        else level_jac_weights<T, false>(gw, fc, m, lvs[l].scale);
      }
      int64_t i0 = 0;  // the points the SIMD gather has done
      if constexpr (FC == 2 && std::is_same_v<T, float>)
        if (use_simd_gather())
          i0 = gather_level_f2<JAC>(out + c0 * LF + l * 2, JAC ? jac + c0 * 3 * LF + l * 2 : nullptr,
                                    LF, tab, ic, wc, gw, m, pf);
      if (pf) for (int64_t i = i0; i < std::min<int64_t>(m, i0 + kPrefetchAhead); ++i) prefetch_rows(tab, ic + i, kBlock, F, 0);
      for (int64_t i = i0; i < m; ++i) {
        if (pf && i + kPrefetchAhead < m) prefetch_rows(tab, ic + i + kPrefetchAhead, kBlock, F, 0);
        T* o = out + (c0 + i) * LF + l * F;
        if constexpr (FC == 2) {  // a row is one 2-lane vector: one load and one FMA a corner
          Row2<T> acc = {T(0), T(0)};
          if constexpr (!JAC) {
            for (int k = 0; k < 8; ++k)
              acc += wc[k * kBlock + i] * load_row2(tab + int64_t(ic[k * kBlock + i]) * 2);
            store_row2(o, acc);
          } else {
            Row2<T> v[8];
            for (int k = 0; k < 8; ++k) {
              v[k] = load_row2(tab + int64_t(ic[k * kBlock + i]) * 2);
              acc += wc[k * kBlock + i] * v[k];
            }
            store_row2(o, acc);
            T* J = jac + (c0 + i) * 3 * LF + l * 2;
            for (int d = 0; d < 3; ++d) {
              Row2<T> g = {T(0), T(0)};
              for (int q = 0; q < 4; ++q) {
                const int lo = kPairLo[d][q];
                g += gw[(d * 4 + q) * kBlock + i] * (v[lo + (1 << d)] - v[lo]);
              }
              store_row2(J + d * LF, g);
            }
          }
        } else {
          for (int ff = 0; ff < F; ++ff) {
            T acc = 0;
            for (int k = 0; k < 8; ++k) acc += wc[k * kBlock + i] * tab[int64_t(ic[k * kBlock + i]) * F + ff];
            o[ff] = acc;
            if constexpr (JAC)
              for (int d = 0; d < 3; ++d) {
                T g = 0;
                for (int q = 0; q < 4; ++q) {
                  const int lo = kPairLo[d][q];
                  g += gw[(d * 4 + q) * kBlock + i] * (tab[int64_t(ic[(lo + (1 << d)) * kBlock + i]) * F + ff] -
                                                       tab[int64_t(ic[lo * kBlock + i]) * F + ff]);
                }
                jac[(c0 + i) * 3 * LF + d * LF + l * F + ff] = g;
              }
          }
        }
      }
    }
    if constexpr (JAC)  // ∂out/∂x_d = 0 where the clamp is active (as the backward's d_x)
      for (int64_t i = 0; i < m; ++i)
        for (int d = 0; d < 3; ++d)
          if (inside01(x[(c0 + i) * 3 + d]) == T(0))
            std::fill_n(jac + (c0 + i) * 3 * LF + d * LF, LF, T(0));
  }
}

// Scatter dL/dtable into this thread's buffer `gbuf` (L, 2^T, F; null: no table gradient) and,
// when d_x is non-null, write dL/dx for the block's points. Per level and block, three passes:
// locate (vectorised), the gathers (the corner sums s_k, for dL/dx) and the scatter (one point
// after another, in the points' order), then the arithmetic of dL/dx (level_dx, vectorised).
// Split, each indirect loop is short enough for the core to keep many points' cache misses in
// flight, and the arithmetic runs 16 points a vector.
// The scatter of one block at one level: g_tab[ic_k(i)] += wc_k(i) · g(i) for the block's
// points i in order and their corners k in order, g(i) = g_src[i · g_stride + f] (F floats).
// One routine for the fused backward and for the level-parallel scatter
// (hashgrid_scatter_level), so that both add in the same order with the same arithmetic: the
// table gradient is then the same bit for bit whichever of them ran.
template <class T, int FC>
inline void scatter_block_level(T* g_tab, const T* g_src, int64_t g_stride, const uint32_t* ic,
                                const T* wc, int64_t m, int F, bool pf) {
  if (pf) for (int64_t i = 0; i < std::min<int64_t>(m, kPrefetchAhead); ++i) prefetch_rows(g_tab, ic + i, kBlock, F, 1);
  for (int64_t i = 0; i < m; ++i) {
    if (pf && i + kPrefetchAhead < m) prefetch_rows(g_tab, ic + i + kPrefetchAhead, kBlock, F, 1);
    // This point's dL/dout[l] in registers: the scatter below may not alias it (d_out
    // and the gradient table are different arrays, but the compiler cannot know that).
    const T* gsrc = g_src + i * g_stride;
    if constexpr (FC == 2) {  // one 2-lane load, FMA and store a corner
      const Row2<T> g = load_row2(gsrc);
      for (int k = 0; k < 8; ++k) {
        T* row = g_tab + int64_t(ic[k * kBlock + i]) * 2;
        store_row2(row, load_row2(row) + wc[k * kBlock + i] * g);
      }
    } else {
      T g[FC > 0 ? FC : kMaxFeatures];
      for (int ff = 0; ff < F; ++ff) g[ff] = gsrc[ff];
      for (int k = 0; k < 8; ++k) {
        const T w = wc[k * kBlock + i];
        T* row = g_tab + int64_t(ic[k * kBlock + i]) * F;
        for (int ff = 0; ff < F; ++ff) row[ff] += w * g[ff];
      }
    }
  }
}

template <class T, int FC>
void backward_block(T* gbuf, T* d_x, const T* d_out, const T* d_out_x, const T* x, const T* table,
                    int64_t b, int64_t e, const HashGridConfig& cfg,
                    const std::array<LevelT<T>, kMaxLevels>& lvs) {
  const int F = FC > 0 ? FC : cfg.features, L = cfg.levels, LF = L * F;
  const int64_t TS = cfg.table_size();
  const uint32_t mask = uint32_t(TS - 1);
  const bool pf = prefetch_pays(TS, F, sizeof(T));
  BlockScratch<T>& bs = block_scratch<T>();
  T *xs = bs.xs.data(), *dx = bs.dx.data(), *fc = bs.fc.data(), *wc = bs.wc.data(),
    *sk = bs.sk.data();
  uint32_t* ic = bs.ic.data();
  const T* gxall = d_out_x ? d_out_x : d_out;  // dL/dout whose position derivative d_x gets
  for (int64_t c0 = b; c0 < e; c0 += kBlock) {
    const int64_t m = std::min(kBlock, e - c0);
    load_block(xs, x + c0 * 3, m);
    if (d_x) std::fill(dx, dx + m * 3, T(0));
    for (int l = 0; l < L; ++l) {
      const T* tab = table + int64_t(l) * TS * F;
      T* g_tab = gbuf ? gbuf + int64_t(l) * TS * F : nullptr;
      locate_block_level(xs, m, lvs[l], mask, ic, wc, fc);
      if (d_x) {
        // s_k = ⟨dL/dout[l], table[idx_k]⟩ (the table is not the gradient table, so reading
        // it before or after the scatter gives the same values).
        if (pf) for (int64_t i = 0; i < std::min<int64_t>(m, kPrefetchAhead); ++i) prefetch_rows(tab, ic + i, kBlock, F, 0);
        for (int64_t i = 0; i < m; ++i) {
          if (pf && i + kPrefetchAhead < m) prefetch_rows(tab, ic + i + kPrefetchAhead, kBlock, F, 0);
          T gx[FC > 0 ? FC : kMaxFeatures];
          const T* gxsrc = gxall + (c0 + i) * LF + l * F;
          for (int ff = 0; ff < F; ++ff) gx[ff] = gxsrc[ff];
          for (int k = 0; k < 8; ++k) {
            T acc = 0;
            for (int ff = 0; ff < F; ++ff) acc += gx[ff] * tab[int64_t(ic[k * kBlock + i]) * F + ff];
            sk[k * kBlock + i] = acc;
          }
        }
        if (cfg.smooth_dx) level_dx<T, true>(dx, sk, fc, m, lvs[l].scale);
        else level_dx<T, false>(dx, sk, fc, m, lvs[l].scale);
      }
      // dL/dtable[idx_k, f] += w_k · dL/dout[l, f]   (out is linear in the table)
      if (g_tab) scatter_block_level<T, FC>(g_tab, d_out + c0 * LF + l * F, LF, ic, wc, m, F, pf);
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

namespace {
// kAuto's measurement: the plain forward and the one keeping the Jacobian, on 256 points (one
// block: serial, on the calling thread) of the CC branch's grid (16 levels of 2^9 rows, in L1),
// each gather 15 times, alternated; the smaller of the two sums of medians wins. Once a process
// (the first forward that asks), ~2 ms. Either gather gives the same values bit for bit, so the
// choice moves only the time: measured, SIMD is the faster on a Zen 4 (9-25%) and the slower on
// an Ice Lake-SP (the plain forward 1.35x, docs/performance.md).
bool calibrate_gather() {
  static std::mutex mu;
  std::lock_guard<std::mutex> lock(mu);
  if (const int c = g_gather_auto.load(std::memory_order_acquire); c >= 0) return c == 1;
  if (kGatherLanes == 0) {
    g_gather_auto.store(0, std::memory_order_release);
    return false;
  }
  const HashGridConfig cfg{16, 2, 9, 16, 512, true};  // levels, F, log2 T, base, finest, smooth
  const int64_t N = 256, D = cfg.out_dim();
  Rng rng(7);
  std::vector<float> table(cfg.param_count()), x(N * 3), out(N * D), jac(N * 3 * D);
  for (float& v : table) v = float(rng.uniform(-1, 1));
  for (float& v : x) v = float(rng.uniform(0, 1));
  using clock = std::chrono::steady_clock;
  std::vector<double> t[2][2];  // [simd][jac]
  for (int rep = -1; rep < 15; ++rep)
    for (int simd = 1; simd >= 0; --simd)
      for (int j = 0; j < 2; ++j) {
        tl_force = simd ? 1 : 2;
        const auto t0 = clock::now();
        hashgrid_forward(out.data(), x.data(), table.data(), N, cfg, j ? jac.data() : nullptr);
        const double dt = std::chrono::duration<double>(clock::now() - t0).count();
        tl_force = 0;
        if (rep >= 0) t[simd][j].push_back(dt);
      }
  double sum[2] = {0, 0};
  for (int simd = 0; simd < 2; ++simd)
    for (int j = 0; j < 2; ++j) {
      std::vector<double>& v = t[simd][j];
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      sum[simd] += v[v.size() / 2];
    }
  const int c = sum[1] < sum[0] ? 1 : 0;
  g_gather_auto.store(c, std::memory_order_release);
  return c == 1;
}
}  // namespace

void hashgrid_set_gather(GatherMode m) { g_gather_mode.store(int(m), std::memory_order_relaxed); }
bool hashgrid_has_simd_gather() { return kGatherLanes > 0; }
bool hashgrid_simd_gather() { return kGatherLanes > 0 && use_simd_gather(); }

template <class T>
void hashgrid_forward(T* out, const T* x, const T* table, int64_t N, const HashGridConfig& cfg,
                      T* jac) {
  validate(cfg);
  if (N <= 0) return;
  // The gather's choice is made here, before any block runs: its first-call measurement runs
  // forwards of its own, which use this thread's block scratch.
  if constexpr (std::is_same_v<T, float>)
    if (cfg.features == 2) (void)use_simd_gather();
  std::array<LevelT<T>, kMaxLevels> lvs;
  level_table(lvs, cfg);
  parallel_blocks(
      N,
      [&](int64_t b, int64_t e, int) {
        if (cfg.features == 2) {
          if (jac) forward_block<T, 2, true>(out, jac, x, table, b, e, cfg, lvs);
          else forward_block<T, 2, false>(out, jac, x, table, b, e, cfg, lvs);
        } else {
          if (jac) forward_block<T, 0, true>(out, jac, x, table, b, e, cfg, lvs);
          else forward_block<T, 0, false>(out, jac, x, table, b, e, cfg, lvs);
        }
      },
      kMinPerThread);
}

template <class T>
void hashgrid_dx_from_jac(T* d_x, const T* d_out, const T* jac, int64_t N,
                          const HashGridConfig& cfg) {
  validate(cfg);
  const int64_t LF = cfg.out_dim();
  parallel_blocks(
      N,
      [&](int64_t b, int64_t e, int) {
        for (int64_t n = b; n < e; ++n) {
          const T* g = d_out + n * LF;
          const T* J = jac + n * 3 * LF;
          for (int d = 0; d < 3; ++d) {  // a dot product of length L·F: vectorised
            T acc = 0;
            for (int64_t j = 0; j < LF; ++j) acc += g[j] * J[d * LF + j];
            d_x[n * 3 + d] = acc;
          }
        }
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

template <class T>
void hashgrid_scatter_level(T* d_table, const T* d_out_level, const T* x, int64_t N,
                            const HashGridConfig& cfg, int level) {
  validate(cfg);
  HCC_REQUIRE(level >= 0 && level < cfg.levels, "", "hash grid level", "{} (expected 0..{})",
              level, cfg.levels - 1);
  if (N <= 0 || !d_table) return;
  std::array<LevelT<T>, kMaxLevels> lvs;
  level_table(lvs, cfg);
  const int F = cfg.features;
  const int64_t TS = cfg.table_size();
  const uint32_t mask = uint32_t(TS - 1);
  const bool pf = prefetch_pays(TS, F, sizeof(T));
  BlockScratch<T>& bs = block_scratch<T>();
  T *xs = bs.xs.data(), *fc = bs.fc.data(), *wc = bs.wc.data();
  uint32_t* ic = bs.ic.data();
  T* g_tab = d_table + int64_t(level) * TS * F;
  for (int64_t c0 = 0; c0 < N; c0 += kBlock) {  // the fused backward's blocks, in its order
    const int64_t m = std::min(kBlock, N - c0);
    load_block(xs, x + c0 * 3, m);
    locate_block_level(xs, m, lvs[level], mask, ic, wc, fc);
    if (F == 2) scatter_block_level<T, 2>(g_tab, d_out_level + c0 * 2, 2, ic, wc, m, 2, pf);
    else scatter_block_level<T, 0>(g_tab, d_out_level + c0 * F, F, ic, wc, m, F, pf);
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
  template void hashgrid_forward<T>(T*, const T*, const T*, int64_t, const HashGridConfig&, T*); \
  template void hashgrid_dx_from_jac<T>(T*, const T*, const T*, int64_t, const HashGridConfig&);\
  template void hashgrid_backward<T>(T*, T*, const T*, const T*, const T*, int64_t,            \
                                     const HashGridConfig&, HashGridWorkspace<T>&, const T*);  \
  template void hashgrid_scatter_level<T>(T*, const T*, const T*, int64_t, const HashGridConfig&, \
                                          int);                                                 \
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
