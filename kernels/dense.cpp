// kernels/dense.cpp — see dense.h for contracts, docs/math/dense.md for the derivations.
#include "kernels/dense.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <type_traits>
#include <utility>
#include <Eigen/Core>

// The hand-written float GEMM (below) is compiled into every AVX2 + FMA build (-DHASHCC_ISA=avx2,
// or native on an AVX2 CPU) with 8-lane vectors, and into every AVX-512 build (-DHASHCC_ISA=avx512,
// or native on an AVX-512 CPU) with 16-lane vectors; the register tile is sized to each ISA's
// register file. The double build (gradient checks) and baseline x86-64 builds use Eigen.
#if defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))
#define HASHCC_DENSE_MICROKERNEL 1
#include <immintrin.h>
#else
#define HASHCC_DENSE_MICROKERNEL 0
#endif

#include "core/buffer.h"
#include "kernels/chunked_for.h"

namespace hashcc {
namespace {

// Rows per GEMM chunk: X chunk 256×128 floats = 128 KiB, Y chunk the same, W 64 KiB — all fit
// in the 1 MiB L2 per core, so the epilogue touches hot data. Fixed (not derived from the thread
// count) so every chunk's arithmetic is identical at any thread count.
constexpr int64_t kChunkRows = 256;
// Elementwise kernels: fixed chunks of this many values (kernels/chunked_for.h); below two
// chunks they run serially, where OpenMP would cost more than it saves.
constexpr int64_t kElemChunk = 1 << 15;

// thread_scratch's tag (core/buffer.h): one chunk of d_y packed in kNR-column panels (the
// micro-kernel's d_W B), per chunk.
struct PanelGTag;

#if HASHCC_DENSE_MICROKERNEL
// ---- the register-blocked GEMM micro-kernel (float) -----------------------------------------
// Every GEMM of a dense layer is written as C (m × n) = A (m × K) · B (K × n), computed in
// register tiles of kMR rows × kNR = 2 vectors of columns. Per k: 2 loads of B, kMR broadcasts
// of A, 2·kMR FMAs — FMA-bound on two FMA pipes with loads to spare. The tile fills the register
// file: 2·kMR accumulators + 2 B vectors + 1 broadcast.
//   AVX2 + FMA (16 ymm):    kMR = 6,  kNR = 16 —  12 accumulators, 15 of 16 registers
//   AVX-512    (32 zmm):    kMR = 14, kNR = 32 —  28 accumulators, 31 of 32 registers
// The three GEMMs:
//   forward   y  = x · Wᵀ : A = x rows,        B = Wᵀ packed in kNR-column panels (zero-padded)
//   backward  dx = g · W  : A = g rows,        B = W  packed in kNR-column panels
//             dWᵀ += xᵀ g : A = x columns,     B = g rows packed per chunk (out % lanes == 0)
// Each element's sum runs k = 0..K−1 in order as one FMA chain from 0, then the bias (forward)
// or the partial (d_W) is added — Eigen's order where Eigen keeps one chain per element, so
// there the results are bitwise Eigen's; Eigen splits some sums over two accumulators, and there
// they differ by rounding (≤ 5e-7 of the scale measured; test/test_dense.cpp "[dense][kernel]").

// The ISA's vector: the few operations the tile needs, so one tile serves both ISAs.
#if defined(__AVX512F__)
struct Simd {
  using F = __m512;
  using Mask = __mmask16;  // one bit a lane
  static constexpr int kLanes = 16;
  static constexpr const char* kName = "AVX-512 micro-kernel, 14x32 tiles (out % 16 == 0)";
  static F zero() { return _mm512_setzero_ps(); }
  static F load(const float* p) { return _mm512_loadu_ps(p); }
  static F bcast(const float* p) { return _mm512_set1_ps(*p); }
  static F fma(F a, F b, F c) { return _mm512_fmadd_ps(a, b, c); }
  static F add(F a, F b) { return _mm512_add_ps(a, b); }
  static F max(F a, F b) { return _mm512_max_ps(a, b); }
  static void store(float* p, F v) { _mm512_storeu_ps(p, v); }
  static Mask mask(int n) {  // lanes [0, n) of one vector, n clamped to [0, 16]
    return n >= kLanes ? Mask(0xFFFF) : n <= 0 ? Mask(0) : Mask((1u << n) - 1);
  }
  static void store(float* p, Mask m, F v) { _mm512_mask_storeu_ps(p, m, v); }
};
constexpr int kMR = 14;
#else
struct Simd {
  using F = __m256;
  using Mask = __m256i;  // all-ones in a stored lane
  static constexpr int kLanes = 8;
  static constexpr const char* kName = "AVX2 micro-kernel, 6x16 tiles (out % 8 == 0)";
  static F zero() { return _mm256_setzero_ps(); }
  static F load(const float* p) { return _mm256_loadu_ps(p); }
  static F bcast(const float* p) { return _mm256_broadcast_ss(p); }
  static F fma(F a, F b, F c) { return _mm256_fmadd_ps(a, b, c); }
  static F add(F a, F b) { return _mm256_add_ps(a, b); }
  static F max(F a, F b) { return _mm256_max_ps(a, b); }
  static void store(float* p, F v) { _mm256_storeu_ps(p, v); }
  static Mask mask(int n) {  // lane j stored when j < n
    return _mm256_cmpgt_epi32(_mm256_set1_epi32(n), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  }
  static void store(float* p, Mask m, F v) { _mm256_maskstore_ps(p, m, v); }
};
constexpr int kMR = 6;
#endif
constexpr int kNR = 2 * Simd::kLanes;

enum class Epi { kStore, kBias, kBiasRelu, kAdd };  // C = acc | acc + b | relu(acc + b) | C + acc

// Columns [0, nc) of a kNR-wide tile are stored (nc < kNR only in a zero-padded last panel).
struct ColMask {
  Simd::Mask m[2];
  bool full;
  explicit ColMask(int nc)
      : m{Simd::mask(nc), Simd::mask(nc - Simd::kLanes)}, full(nc >= kNR) {}
};

// Software prefetch of the next chunk's input while this chunk computes. Without it the
// forward's first pass over a chunk (its first column panel) meets x cold, from L3 or memory,
// and the tiles wait on it; a few 64-byte lines requested after each tile of the chunk's LAST
// panel (prefetcht1: into L2) have the next chunk on its way by the time this one ends, while
// L2 holds only what that panel still reads (small-L2 CPUs: Zen 2/3 have 512 KiB). Measured
// (docs/performance.md, "Chunk size and the forward's prefetch"; AVX2 build, Zen 4, 2 threads):
// the paper step 0.935× of before at a chunk of 64 rays, paired rounds of tools/bench_ab.sh.
struct NextChunk {
  const char* p = nullptr;
  const char* end = nullptr;
  int64_t per_tile = 0;
  NextChunk(const float* next, int64_t floats, int64_t tiles) {
    if (!next || floats <= 0 || tiles <= 0) return;
    p = reinterpret_cast<const char*>(next);
    end = reinterpret_cast<const char*>(next + floats);
    per_tile = ((end - p + 63) / 64 + tiles - 1) / tiles;
  }
  void after_tile() {
    for (int64_t i = 0; i < per_tile && p < end; ++i, p += 64) _mm_prefetch(p, _MM_HINT_T1);
  }
};

// One M × (lanes·NV) tile: A(r, k) = A[r·sam + k·sak], B(k, j) = B[k·ldb + j] (lanes·NV
// readable floats per k), C(r, j) = C[r·ldc + j]; bias (Epi::kBias*) has lanes·NV readable floats.
template <int M, int NV, Epi E>
[[gnu::always_inline]] inline void tile(int K, const float* A, int64_t sam, int64_t sak,
                                        const float* B, int64_t ldb, float* C, int64_t ldc,
                                        const float* bias, const ColMask& cm) {
  constexpr int L = Simd::kLanes;
  Simd::F acc[M][NV];
#pragma GCC unroll 14
  for (int r = 0; r < M; ++r)
#pragma GCC unroll 2
    for (int v = 0; v < NV; ++v) acc[r][v] = Simd::zero();
  for (int k = 0; k < K; ++k) {
    Simd::F b[NV];
#pragma GCC unroll 2
    for (int v = 0; v < NV; ++v) b[v] = Simd::load(B + k * ldb + L * v);
    const float* ak = A + k * sak;
#pragma GCC unroll 14
    for (int r = 0; r < M; ++r) {
      const Simd::F a = Simd::bcast(ak + r * sam);
#pragma GCC unroll 2
      for (int v = 0; v < NV; ++v) acc[r][v] = Simd::fma(a, b[v], acc[r][v]);
    }
  }
#pragma GCC unroll 14
  for (int r = 0; r < M; ++r)
#pragma GCC unroll 2
    for (int v = 0; v < NV; ++v) {
      float* c = C + r * ldc + L * v;
      Simd::F o = acc[r][v];
      if constexpr (E == Epi::kBias || E == Epi::kBiasRelu) o = Simd::add(o, Simd::load(bias + L * v));
      // max(o, +0) returns +0 for NaN and ±0, as the Eigen path's (o > 0 ? o : 0).
      if constexpr (E == Epi::kBiasRelu) o = Simd::max(o, Simd::zero());
      if constexpr (E == Epi::kAdd) o = Simd::add(Simd::load(c), o);
      if (cm.full) Simd::store(c, o);
      else Simd::store(c, cm.m[v], o);
    }
}

// One tile of m = 1..kMR rows (the row count is a template argument of tile): the fold picks
// the instantiation whose M equals m.
template <int NV, Epi E, int... Ms>
void tile_m_of(std::integer_sequence<int, Ms...>, int m, int K, const float* A, int64_t sam,
               int64_t sak, const float* B, int64_t ldb, float* C, int64_t ldc, const float* bias,
               const ColMask& cm) {
  (void)((m == Ms + 1 && (tile<Ms + 1, NV, E>(K, A, sam, sak, B, ldb, C, ldc, bias, cm), true)) ||
         ...);
}
template <int NV, Epi E>
void tile_m(int m, int K, const float* A, int64_t sam, int64_t sak, const float* B, int64_t ldb,
            float* C, int64_t ldc, const float* bias, const ColMask& cm) {
  tile_m_of<NV, E>(std::make_integer_sequence<int, kMR>{}, m, K, A, sam, sak, B, ldb, C, ldc,
                   bias, cm);
}

// The rows [0, m) of one column panel: kMR-row tiles, then one tile of the remaining rows;
// `next` (optional) prefetches after each whole tile.
template <int NV, Epi E>
void panel_rows(int64_t m, int K, const float* A, int64_t sam, int64_t sak, const float* B,
                int64_t ldb, float* C, int64_t ldc, const float* bias, const ColMask& cm,
                NextChunk* next = nullptr) {
  int64_t r = 0;
  for (; r + kMR <= m; r += kMR) {
    tile<kMR, NV, E>(K, A + r * sam, sam, sak, B, ldb, C + r * ldc, ldc, bias, cm);
    if (next) next->after_tile();
  }
  if (r < m)
    tile_m<NV, E>(int(m - r), K, A + r * sam, sam, sak, B, ldb, C + r * ldc, ldc, bias, cm);
}

// Packs the K × n matrix src(k, j) = src[k·sk + j·sj] into ⌈n/kNR⌉ panels of K × kNR floats
// (panel p at dst + p·K·kNR; columns past n are zeros, so every tile reads kNR valid floats).
void pack_panels(float* dst, const float* src, int K, int n, int64_t sk, int64_t sj) {
  const int np = (n + kNR - 1) / kNR;
  for (int p = 0; p < np; ++p) {
    const bool whole = sj == 1 && (p + 1) * kNR <= n;  // kNR contiguous source floats per k
    for (int k = 0; k < K; ++k) {
      float* d = dst + (int64_t(p) * K + k) * kNR;
      const float* sp = src + k * sk + int64_t(p) * kNR * sj;
      if (whole) {
        Simd::store(d, Simd::load(sp));
        Simd::store(d + Simd::kLanes, Simd::load(sp + Simd::kLanes));
        continue;
      }
      for (int j = 0; j < kNR; ++j) d[j] = p * kNR + j < n ? sp[j * sj] : 0.f;
    }
  }
}

// One 256-row chunk of y = x·Wᵀ + b (ReLU when Relu): per kNR-column panel of packed Wᵀ
// (in × kNR floats, ≤ 24 KiB: stays in L1), every kMR-row tile of the chunk, x read in place
// (≤ 191 KiB, in L2). Packing x's chunk into row blocks too measured no faster on AVX2 (the
// pack costs what the contiguous broadcasts save). next_x (next_floats floats; null for the
// last chunk) is the next chunk's x, prefetched during the last panel (NextChunk).
template <bool Relu>
void mk_forward_chunk(float* y, const float* x, const float* Wp, const float* bp, int64_t rows,
                      int in, int out, const float* next_x, int64_t next_floats) {
  constexpr Epi E = Relu ? Epi::kBiasRelu : Epi::kBias;
  const int64_t panels = (out + kNR - 1) / kNR;
  NextChunk next(next_x, next_floats, rows / kMR);  // spread over the last panel's tiles
  for (int p = 0; p < panels; ++p) {
    const ColMask cm(out - p * kNR);
    panel_rows<2, E>(rows, in, x, in, 1, Wp + int64_t(p) * in * kNR, kNR, y + p * kNR, out,
                     bp + p * kNR, cm, p + 1 == panels ? &next : nullptr);
  }
}

// One chunk of the backward's two GEMMs, on the same chunk of g (rows × out, in L2):
// d_x (rows × in) = g · W: per kNR-column panel of packed W (out × kNR), g's rows in place.
// Pt (in × out, the slab's d_Wᵀ partial) += xᵀ · g: A = xᵀ read in place (kMR adjacent columns
// of x per tile: one or two lines per row), B = g packed for this chunk in kNR-column panels
// (rows × kNR); per kMR-column strip of x, every panel of g. Measured against the alternatives
// on AVX2 (1 thread, 256 rows, in = 128, out = 128): g read in place 512 bytes apart — 256 lines
// in 8 of L1's 64 sets — was ~20% slower, and x packed into 6-column blocks too ~20% slower (the
// pack is a strided gather that costs what it saves).
void mk_backward_chunk(float* d_x, float* Pt, const float* g, const float* x, const float* Wp,
                       int64_t rows, int in, int out) {
  if (d_x)
    for (int p = 0; p * kNR < in; ++p) {
      const ColMask cm(in - p * kNR);
      panel_rows<2, Epi::kStore>(rows, out, g, out, 1, Wp + int64_t(p) * out * kNR, kNR,
                                 d_x + p * kNR, in, nullptr, cm);
    }
  if (!Pt) return;
  float* gq = thread_scratch<float, PanelGTag>(size_t((out + kNR - 1) / kNR * kNR) * rows);
  pack_panels(gq, g, int(rows), out, out, 1);  // B(k = n, j = o) = g[n·out + o]
  const ColMask full(kNR);
  const int K = int(rows);
  for (int i0 = 0; i0 < in; i0 += kMR) {
    const int m = std::min(kMR, in - i0);
    for (int q = 0; q * kNR < out; ++q) {
      const float* bq = gq + q * rows * kNR;
      float* c = Pt + int64_t(i0) * out + q * kNR;
      if ((q + 1) * kNR <= out)
        tile_m<2, Epi::kAdd>(m, K, x + i0, 1, in, bq, kNR, c, out, nullptr, full);
      else  // out % kNR == lanes: the first vector of the last (zero-padded) panel
        tile_m<1, Epi::kAdd>(m, K, x + i0, 1, in, bq, kNR, c, out, nullptr, full);
    }
  }
}
#endif  // HASHCC_DENSE_MICROKERNEL

std::atomic<bool> g_force_eigen{false};  // dense_force_eigen(): benchmarks only

// Whether the float layer (in, out) runs the micro-kernel: AVX2 and AVX-512 builds, out a
// multiple of the vector's lanes (8 or 16: the d_W GEMM's tail panel needs whole vectors). The
// narrow heads (out = 1, 3) stay on Eigen.
#if HASHCC_DENSE_MICROKERNEL
constexpr int kMkLanes = Simd::kLanes;
#else
constexpr int kMkLanes = 1;  // unused: HASHCC_DENSE_MICROKERNEL is false
#endif
template <class T>
bool use_microkernel(int out) {
  return HASHCC_DENSE_MICROKERNEL && std::is_same_v<T, float> && out % kMkLanes == 0 &&
         !g_force_eigen.load(std::memory_order_relaxed);
}

static_assert(kDenseBlockRows == kChunkRows);

// The backward's reduction over the batch (d_W, d_b) is split into fixed slabs of kSlabRows rows
// (16 chunks). Each slab writes its own partial; partials are then added in slab order. Fixed
// slabs make d_W and d_b bit-identical at any thread count, and this K-split measured ~300
// GFLOP/s at 2 threads against ~220 for letting Eigen split the (out, in) result.
constexpr int64_t kSlabRows = 16 * kChunkRows;
static_assert(kDenseSlabRows == kSlabRows);

// d_pre = d_y ⊙ [y > 0] over the elements [e0, e1).
template <class T>
void relu_mask(T* d_pre, const T* d_y, const T* y, int64_t e0, int64_t e1) {
  // Branch-free select (d_y read unconditionally, omp simd since d_pre may alias d_y index for
  // index): a branchy scalar loop mispredicts on the random mask and measured 58 ms for
  // 131072×128, longer than the two GEMMs of the layer.
#pragma omp simd
  for (int64_t i = e0; i < e1; ++i) {
    const T gi = d_y[i];
    d_pre[i] = y[i] > T(0) ? gi : T(0);
  }
}

// dense_prepare with the path chosen by the caller (mk: the micro-kernel, when the build has
// one; the Eigen reference entry points pass false).
template <class T>
void prepare_layer(DenseLayer<T>& L, const T* W, const T* b, int in, int out, bool forward,
                   bool backward_dx, bool mk) {
  L.W = W;
  L.b = b;
  L.in = in;
  L.out = out;
  L.mk = mk && HASHCC_DENSE_MICROKERNEL && std::is_same_v<T, float>;
#if HASHCC_DENSE_MICROKERNEL
  if constexpr (std::is_same_v<T, float>) {
    if (!L.mk) return;
    if (forward) {  // Wᵀ in ⌈out/kNR⌉ panels of in × kNR (B(k = i, j = o) = W[o·in + i]), then b
      const int64_t np = (out + kNR - 1) / kNR;
      float* Wp = ensure(L.fwd_pack, size_t(np * kNR * (in + 1)));
      pack_panels(Wp, W, in, out, 1, in);
      float* bp = Wp + np * kNR * in;
      for (int j = 0; j < np * kNR; ++j) bp[j] = j < out ? b[j] : 0.f;
    }
    if (backward_dx)  // W in ⌈in/kNR⌉ panels of out × kNR (B(k = o, j = i) = W[o·in + i])
      pack_panels(ensure(L.dx_pack, size_t((in + kNR - 1) / kNR * kNR) * out), W, out, in, in, 1);
  }
#else
  (void)forward, (void)backward_dx;
#endif
}

}  // namespace

template <class T>
void dense_prepare(DenseLayer<T>& L, const T* W, const T* b, int in, int out, bool forward,
                   bool backward_dx) {
  prepare_layer(L, W, b, in, out, forward, backward_dx, use_microkernel<T>(out));
}

// One chunk: the micro-kernel (float, AVX2/AVX-512), else Eigen's GEMM with the bias/ReLU
// epilogue on the hot chunk.
template <class T>
void dense_forward_block(T* y, const T* x, const DenseLayer<T>& L, int64_t rows, bool relu,
                         const T* next_x, int64_t next_floats) {
  if (rows <= 0) return;
  const int in = L.in, out = L.out;
#if HASHCC_DENSE_MICROKERNEL
  if constexpr (std::is_same_v<T, float>)
    if (L.mk) {
      const float* Wp = L.fwd_pack.data();
      const float* bp = Wp + (out + kNR - 1) / kNR * kNR * in;
      if (relu) mk_forward_chunk<true>(y, x, Wp, bp, rows, in, out, next_x, next_floats);
      else mk_forward_chunk<false>(y, x, Wp, bp, rows, in, out, next_x, next_floats);
      return;
    }
#endif
  (void)next_x, (void)next_floats;
  MapRMu<T> Y(y, rows, out);
  Y.noalias() = CMapRM<T>(x, rows, in) * CMapRM<T>(L.W, out, in).transpose();
  for (int64_t r = 0; r < rows; ++r) {
    T* yr = y + r * out;
    for (int o = 0; o < out; ++o) {
      T v = yr[o] + L.b[o];
      if (relu) v = v > T(0) ? v : T(0);
      yr[o] = v;
    }
  }
}

template <class T>
void dense_grads_begin(DenseGradSlabs<T>& G, const DenseLayer<T>& L, int64_t N, bool has_W,
                       bool has_b) {
  G.slabs = (N + kSlabRows - 1) / kSlabRows;
  G.has_W = has_W;
  G.has_b = has_b;
  const int64_t wsize = int64_t(L.out) * L.in;
  if (has_W) std::fill_n(ensure(G.W, size_t(G.slabs * wsize)), G.slabs * wsize, T(0));
  if (has_b) std::fill_n(ensure(G.b, size_t(G.slabs * L.out)), G.slabs * L.out, 0.0);
}

// Per 256-row chunk, while the chunk of g is in L2: ReLU mask, d_x = g·W, d_W partial += gᵀ·x,
// d_b partial += column sums (in double: 131072-term float sums would drift). The micro-kernel
// keeps its d_W partials transposed (in, out), so that g's rows are read in place; Eigen's are
// (out, in).
template <class T>
void dense_backward_block(T* d_x, DenseGradSlabs<T>* G, int64_t r0, T* d_pre, const T* d_y,
                          const T* y, const T* x, const DenseLayer<T>& L, int64_t rows) {
  if (rows <= 0) return;
  const int in = L.in, out = L.out;
  const int64_t sl = r0 / kSlabRows, wsize = int64_t(out) * in;
  T* P = G && G->has_W ? G->W.data() + sl * wsize : nullptr;
  double* bacc = G && G->has_b ? G->b.data() + sl * out : nullptr;
  if (d_pre) relu_mask(d_pre, d_y, y, 0, rows * out);
  const T* g = d_pre ? d_pre : d_y;  // dL/d(pre-activation) (rows, out)
#if HASHCC_DENSE_MICROKERNEL
  if constexpr (std::is_same_v<T, float>)
    if (L.mk) mk_backward_chunk(d_x, P, g, x, d_x ? L.dx_pack.data() : nullptr, rows, in, out);
#endif
  if (!L.mk) {
    CMapRM<T> Gm(g, rows, out);
    if (d_x) MapRMu<T>(d_x, rows, in).noalias() = Gm * CMapRM<T>(L.W, out, in);
    if (P) MapRMu<T>(P, out, in).noalias() += Gm.transpose() * CMapRM<T>(x, rows, in);
  }
  if (bacc)
    for (int64_t r = 0; r < rows; ++r) {
      const T* gr = g + r * out;
      for (int o = 0; o < out; ++o) bacc[o] += double(gr[o]);
    }
}

// Reduce partials in slab order; each output entry is owned by one thread.
template <class T>
void dense_grads_end(T* d_W, T* d_b, const DenseGradSlabs<T>& G, const DenseLayer<T>& L) {
  const int in = L.in, out = L.out;
  const int64_t nslabs = G.slabs, wsize = int64_t(out) * in;
  const T* pW = G.has_W ? G.W.data() : nullptr;
  if (pW && L.mk)  // partials (in, out): entry (o, i) at i·out + o; one thread per row o of d_W
    parallel_blocks(out, [&](int64_t o0, int64_t o1, int) {
      for (int64_t sl = 0; sl < nslabs; ++sl) {
        const T* p = pW + sl * wsize;
        for (int64_t o = o0; o < o1; ++o)
          for (int i = 0; i < in; ++i) d_W[o * in + i] += p[int64_t(i) * out + o];
      }
    }, 32);
  else if (pW)
    parallel_blocks(wsize, [&](int64_t i0, int64_t i1, int) {
      for (int64_t sl = 0; sl < nslabs; ++sl) {
        const T* p = pW + sl * wsize;
        for (int64_t i = i0; i < i1; ++i) d_W[i] += p[i];
      }
    }, 4096);
  if (G.has_b)
    for (int o = 0; o < out; ++o) {
      double acc = 0;
      for (int64_t sl = 0; sl < nslabs; ++sl) acc += G.b[sl * out + o];
      d_b[o] += T(acc);
    }
}

namespace {

// Y = X·Wᵀ (+ b, then ReLU when Relu) over the batch: the layer packed once per call (out·in
// copies against N·out·in FMAs), then its blocks split over the threads. Mk: the micro-kernel
// when the build has one, else Eigen's GEMM (the reference).
template <class T, bool Relu, bool Mk>
void dense_forward_impl(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out) {
  if (N <= 0) return;
  // Grow-only per calling thread. Named through a reference: inside the lambda, the name of a
  // thread_local would be each worker thread's own (empty) object.
  thread_local DenseLayer<T> layer;
  DenseLayer<T>& L = layer;
  prepare_layer(L, W, b, in, out, true, false, Mk);
  parallel_chunks(N, kChunkRows, [&](int64_t r0, int64_t r1) {
    dense_forward_block(y + r0 * out, x + r0 * in, L, r1 - r0, Relu,
                        r1 < N ? x + r1 * in : nullptr, std::min(kChunkRows, N - r1) * in);
  });
}

// Shared backward. When d_pre != nullptr: d_pre = d_y ⊙ [y > 0] first (ReLU), then use d_pre.
template <class T, bool Mk>
void dense_backward_impl(T* d_x, T* d_W, T* d_b, T* d_pre, const T* d_y, const T* y, const T* x,
                         const T* W, int64_t N, int in, int out) {
  if (N <= 0) return;
  thread_local DenseLayer<T> layer;  // as in dense_forward_impl: used through references
  thread_local DenseGradSlabs<T> slabs;
  DenseLayer<T>& L = layer;
  DenseGradSlabs<T>& G = slabs;
  prepare_layer(L, W, (const T*)nullptr, in, out, false, d_x != nullptr, Mk);
  dense_grads_begin(G, L, N, d_W != nullptr, d_b != nullptr);
  parallel_chunks(N, kSlabRows, [&](int64_t s0, int64_t s1) {
    for (int64_t r0 = s0; r0 < s1; r0 += kChunkRows)
      dense_backward_block(d_x ? d_x + r0 * in : nullptr, &G, r0, d_pre ? d_pre + r0 * out : nullptr,
                           d_y + r0 * out, y ? y + r0 * out : nullptr, x + r0 * in, L,
                           std::min(kChunkRows, s1 - r0));
  });
  dense_grads_end(d_W, d_b, G, L);
}

// f(i) for i in [0, n), in fixed chunks. omp simd: in-place use (y == x, d_x == d_y) is same-index only, so
// vectorising is safe even though the compiler cannot prove the pointers disjoint.
template <class F>
void elementwise(int64_t n, F&& f) {
  parallel_chunks(n, kElemChunk, [&](int64_t b, int64_t e) {
#pragma omp simd
    for (int64_t i = b; i < e; ++i) f(i);
  });
}

}  // namespace

template <class T>
void dense_forward(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out) {
  if (use_microkernel<T>(out)) dense_forward_impl<T, false, true>(y, x, W, b, N, in, out);
  else dense_forward_impl<T, false, false>(y, x, W, b, N, in, out);
}

template <class T>
void dense_relu_forward(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out) {
  if (use_microkernel<T>(out)) dense_forward_impl<T, true, true>(y, x, W, b, N, in, out);
  else dense_forward_impl<T, true, false>(y, x, W, b, N, in, out);
}

template <class T>
void dense_backward(T* d_x, T* d_W, T* d_b, const T* d_y, const T* x, const T* W, int64_t N,
                    int in, int out) {
  dense_relu_backward<T>(d_x, d_W, d_b, nullptr, d_y, nullptr, x, W, N, in, out);
}

template <class T>
void dense_relu_backward(T* d_x, T* d_W, T* d_b, T* d_pre, const T* d_y, const T* y, const T* x,
                         const T* W, int64_t N, int in, int out) {
  if (use_microkernel<T>(out))
    dense_backward_impl<T, true>(d_x, d_W, d_b, d_pre, d_y, y, x, W, N, in, out);
  else dense_backward_impl<T, false>(d_x, d_W, d_b, d_pre, d_y, y, x, W, N, in, out);
}

bool dense_microkernel(int out) { return use_microkernel<float>(out); }
const char* dense_microkernel_name() {
#if HASHCC_DENSE_MICROKERNEL
  return Simd::kName;
#else
  return "none (Eigen's GEMM: no AVX2 + FMA in this build)";
#endif
}
void dense_force_eigen(bool on) { g_force_eigen.store(on); }

std::vector<DenseProbeRow> dense_microkernel_probe(int in, int out, const std::vector<int64_t>& Ns,
                                                   int reps) {
  std::vector<DenseProbeRow> rows;
#if HASHCC_DENSE_MICROKERNEL
  if (!use_microkernel<float>(out) || Ns.empty() || reps < 1) return rows;
  const int64_t Nmax = *std::max_element(Ns.begin(), Ns.end());
  const int64_t np = (out + kNR - 1) / kNR, npi = (in + kNR - 1) / kNR;
  AlignedVec<float> x(Nmax * in), y(Nmax * out), g(Nmax * out), dx(Nmax * in), W(int64_t(out) * in),
      Wp(np * kNR * (in + 1)), WpB(npi * kNR * out), Pt(int64_t(in) * out, 0.f);
  for (size_t i = 0; i < x.size(); ++i) x[i] = float(i % 97) * 1e-3f;
  for (size_t i = 0; i < g.size(); ++i) g[i] = float(i % 91) * 1e-3f - 0.04f;
  for (size_t i = 0; i < W.size(); ++i) W[i] = float(i % 89) * 1e-3f - 0.04f;
  pack_panels(Wp.data(), W.data(), in, out, 1, in);   // the forward's B (Wᵀ panels), as per call
  pack_panels(WpB.data(), W.data(), out, in, in, 1);  // d_x's B (W panels)
  float* bp = Wp.data() + np * kNR * in;
  for (int j = 0; j < np * kNR; ++j) bp[j] = 0.01f * float(j % 7);
  using clock = std::chrono::steady_clock;
  std::vector<std::vector<double>> t(Ns.size() * 3);  // (N, pass) → seconds per rep
  for (int rep = -1; rep < reps; ++rep)                // rep −1: warm-up (scratch, page faults)
    for (size_t k = 0; k < Ns.size(); ++k)
      for (int pass = 0; pass < 3; ++pass) {
        const int64_t N = Ns[k];
        const auto one_pass = [&] {
          for (int64_t r0 = 0; r0 < N; r0 += kChunkRows) {
            const int64_t n = std::min(kChunkRows, N - r0), r1 = r0 + n;
            if (pass == 0)
              mk_forward_chunk<true>(y.data() + r0 * out, x.data() + r0 * in, Wp.data(), bp, n, in,
                                     out, r1 < N ? x.data() + r1 * in : nullptr,
                                     std::min(kChunkRows, N - r1) * in);
            else if (pass == 1)
              mk_backward_chunk(dx.data() + r0 * in, nullptr, g.data() + r0 * out,
                                x.data() + r0 * in, WpB.data(), n, in, out);
            else
              mk_backward_chunk(nullptr, Pt.data(), g.data() + r0 * out, x.data() + r0 * in,
                                nullptr, n, in, out);
          }
        };
        // Two passes back to back, the second timed: its operands are wherever N rows of them
        // stay (L2 for 256 rows), not wherever the last pass over another N left them.
        one_pass();
        const auto t0 = clock::now();
        one_pass();
        if (rep >= 0) t[k * 3 + pass].push_back(std::chrono::duration<double>(clock::now() - t0).count());
      }
  for (size_t k = 0; k < Ns.size(); ++k) {
    const double flop = 2.0 * double(Ns[k]) * in * out;
    double gf[3];
    for (int pass = 0; pass < 3; ++pass) {
      std::vector<double>& v = t[k * 3 + pass];
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      gf[pass] = flop / v[v.size() / 2] * 1e-9;
    }
    rows.push_back({Ns[k], gf[0], gf[1], gf[2]});
  }
#else
  (void)in, (void)out, (void)Ns, (void)reps;
#endif
  return rows;
}

template <class T>
void dense_forward_eigen(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out,
                         bool relu) {
  if (relu) dense_forward_impl<T, true, false>(y, x, W, b, N, in, out);
  else dense_forward_impl<T, false, false>(y, x, W, b, N, in, out);
}

template <class T>
void dense_backward_eigen(T* d_x, T* d_W, T* d_b, T* d_pre, const T* d_y, const T* y, const T* x,
                          const T* W, int64_t N, int in, int out) {
  dense_backward_impl<T, false>(d_x, d_W, d_b, d_pre, d_y, y, x, W, N, in, out);
}

template <class T>
void dense_forward_naive(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out) {
  for (int64_t n = 0; n < N; ++n)
    for (int o = 0; o < out; ++o) {
      T acc = b[o];
      for (int i = 0; i < in; ++i) acc += x[n * in + i] * W[int64_t(o) * in + i];
      y[n * out + o] = acc;
    }
}

template <class T>
void dense_backward_naive(T* d_x, T* d_W, T* d_b, const T* d_y, const T* x, const T* W,
                          int64_t N, int in, int out) {
  for (int64_t n = 0; n < N; ++n) {
    if (d_x)
      for (int i = 0; i < in; ++i) {
        T acc = 0;
        for (int o = 0; o < out; ++o) acc += d_y[n * out + o] * W[int64_t(o) * in + i];
        d_x[n * in + i] = acc;
      }
    for (int o = 0; o < out; ++o) {
      if (d_b) d_b[o] += d_y[n * out + o];
      if (d_W)
        for (int i = 0; i < in; ++i) d_W[int64_t(o) * in + i] += d_y[n * out + o] * x[n * in + i];
    }
  }
}

template <class T>
void relu_forward(T* y, const T* x, int64_t n) {
  elementwise(n, [=](int64_t i) { y[i] = x[i] > T(0) ? x[i] : T(0); });
}
template <class T>
void relu_backward(T* d_x, const T* d_y, const T* y, int64_t n) {
  // y > 0 ⇔ x > 0; the kink x = 0 gets gradient 0 (PyTorch's choice).
  elementwise(n, [=](int64_t i) {
    const T g = d_y[i];  // read unconditionally: a select, not a mispredicted branch
    d_x[i] = y[i] > T(0) ? g : T(0);
  });
}

template <class T>
void sigmoid_forward(T* y, const T* x, int64_t n) {
  // exp of −|x| only: never overflows; for x ≪ 0, e/(1+e) keeps the tiny value's precision.
  elementwise(n, [=](int64_t i) {
    T v = x[i];
    if (v >= T(0)) {
      y[i] = T(1) / (T(1) + std::exp(-v));
    } else {
      T e = std::exp(v);
      y[i] = e / (T(1) + e);
    }
  });
}
template <class T>
void sigmoid_backward(T* d_x, const T* d_y, const T* y, int64_t n) {
  elementwise(n, [=](int64_t i) { d_x[i] = d_y[i] * y[i] * (T(1) - y[i]); });
}

template <class T>
void softplus_forward(T* y, const T* x, int64_t n) {
  // log(1 + eˣ) = max(x, 0) + log1p(e^{−|x|}): exact for both tails, no overflow.
  elementwise(n, [=](int64_t i) {
    T v = x[i];
    y[i] = std::max(v, T(0)) + std::log1p(std::exp(-std::abs(v)));
  });
}
template <class T>
void softplus_backward(T* d_x, const T* d_y, const T* x, int64_t n) {
  // softplus' = sigmoid(x), evaluated with the same sign branch as sigmoid_forward.
  elementwise(n, [=](int64_t i) {
    T v = x[i], s;
    if (v >= T(0)) {
      s = T(1) / (T(1) + std::exp(-v));
    } else {
      T e = std::exp(v);
      s = e / (T(1) + e);
    }
    d_x[i] = d_y[i] * s;
  });
}

template <class T>
void exp_forward(T* y, const T* x, int64_t n) {
  elementwise(n, [=](int64_t i) { y[i] = std::exp(std::min(x[i], T(kExpClampMax))); });
}
template <class T>
void exp_backward(T* d_x, const T* d_y, const T* y, int64_t n) {
  elementwise(n, [=](int64_t i) { d_x[i] = d_y[i] * y[i]; });
}

template <class T>
void concat_forward(T* out, const T* a, const T* b, int64_t N, int A, int B) {
  const int C = A + B;
  parallel_blocks(N, [&](int64_t r0, int64_t r1, int) {
    for (int64_t r = r0; r < r1; ++r) {
      std::copy_n(a + r * A, A, out + r * C);
      std::copy_n(b + r * B, B, out + r * C + A);
    }
  }, 4096);
}
template <class T>
void concat_backward(T* d_a, T* d_b, const T* d_out, int64_t N, int A, int B) {
  const int C = A + B;
  parallel_blocks(N, [&](int64_t r0, int64_t r1, int) {
    for (int64_t r = r0; r < r1; ++r) {
      if (d_a) std::copy_n(d_out + r * C, A, d_a + r * A);
      if (d_b) std::copy_n(d_out + r * C + A, B, d_b + r * B);
    }
  }, 4096);
}

#define HASHCC_DENSE_INSTANTIATE(T)                                                            \
  template void dense_forward<T>(T*, const T*, const T*, const T*, int64_t, int, int);          \
  template void dense_prepare<T>(DenseLayer<T>&, const T*, const T*, int, int, bool, bool);      \
  template void dense_forward_block<T>(T*, const T*, const DenseLayer<T>&, int64_t, bool,        \
                                       const T*, int64_t);                                      \
  template void dense_grads_begin<T>(DenseGradSlabs<T>&, const DenseLayer<T>&, int64_t, bool,    \
                                     bool);                                                     \
  template void dense_backward_block<T>(T*, DenseGradSlabs<T>*, int64_t, T*, const T*, const T*, \
                                        const T*, const DenseLayer<T>&, int64_t);               \
  template void dense_grads_end<T>(T*, T*, const DenseGradSlabs<T>&, const DenseLayer<T>&);      \
  template void dense_relu_forward<T>(T*, const T*, const T*, const T*, int64_t, int, int);     \
  template void dense_forward_naive<T>(T*, const T*, const T*, const T*, int64_t, int, int);    \
  template void dense_backward<T>(T*, T*, T*, const T*, const T*, const T*, int64_t, int, int); \
  template void dense_backward_naive<T>(T*, T*, T*, const T*, const T*, const T*, int64_t, int, \
                                        int);                                                   \
  template void dense_relu_backward<T>(T*, T*, T*, T*, const T*, const T*, const T*, const T*,  \
                                       int64_t, int, int);                                      \
  template void dense_forward_eigen<T>(T*, const T*, const T*, const T*, int64_t, int, int,     \
                                       bool);                                                   \
  template void dense_backward_eigen<T>(T*, T*, T*, T*, const T*, const T*, const T*, const T*, \
                                        int64_t, int, int);                                     \
  template void relu_forward<T>(T*, const T*, int64_t);                                         \
  template void relu_backward<T>(T*, const T*, const T*, int64_t);                              \
  template void sigmoid_forward<T>(T*, const T*, int64_t);                                      \
  template void sigmoid_backward<T>(T*, const T*, const T*, int64_t);                           \
  template void softplus_forward<T>(T*, const T*, int64_t);                                     \
  template void softplus_backward<T>(T*, const T*, const T*, int64_t);                          \
  template void exp_forward<T>(T*, const T*, int64_t);                                          \
  template void exp_backward<T>(T*, const T*, const T*, int64_t);                               \
  template void concat_forward<T>(T*, const T*, const T*, int64_t, int, int);                   \
  template void concat_backward<T>(T*, T*, const T*, int64_t, int, int);

HASHCC_DENSE_INSTANTIATE(float)
HASHCC_DENSE_INSTANTIATE(double)
#undef HASHCC_DENSE_INSTANTIATE

}  // namespace hashcc
