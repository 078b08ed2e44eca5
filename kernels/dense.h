// kernels/dense.h — dense layer y = x Wᵀ + b over a batch, activations, concat.
//
// Derivations: docs/math/dense.md (proved by test/test_dense.cpp, "[dense][grad]").
// Gradient-write policy (design practice 4): parameter gradients d_W, d_b are ACCUMULATED (+=;
// the trainer zeroes the gradient arena once per step); activation gradients d_x are WRITTEN (=).
// Threading: the batch is cut into fixed 256-row chunks (independent of the thread count); each
// chunk's GEMM runs serially inside one thread with its bias/ReLU epilogue while the chunk is
// still in L2. The backward's reductions over the batch (d_W, d_b) go to per-slab partials
// (fixed 4096-row slabs, d_b in double) that are added in slab order: no atomics, and results
// are bit-identical at any thread count. Allocation: only GEMM packing buffers (Eigen's; the
// micro-kernel's and the slab partials: grow-only per thread, first call / larger batch only).
#pragma once
#include <cstdint>
#include <vector>

#include "core/buffer.h"
namespace hashcc {

// y (N, out) = x (N, in) · Wᵀ + b.  W (out, in) row-major (PyTorch layout), b (out).
template <class T>
void dense_forward(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out);

// d_x (N, in) written = d_y · W (skipped when d_x == nullptr); d_W (out, in) += d_yᵀ · x;
// d_b (out) += Σ_n d_y. d_W and d_b may be null too: their GEMM / sums are skipped.
template <class T>
void dense_backward(T* d_x, T* d_W, T* d_b, const T* d_y, const T* x, const T* W, int64_t N,
                    int in, int out);

// Fused Linear+ReLU: y (N, out) = relu(x · Wᵀ + b), bias and ReLU applied in the GEMM chunk's
// epilogue (one pass over y while it is hot instead of two cold passes).
template <class T>
void dense_relu_forward(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out);

// Backward of dense_relu_forward. d_y (N, out) is dL/dy of the ReLU OUTPUT y (N, out).
// d_pre (N, out) receives dL/d(pre-activation) = d_y ⊙ [y > 0] (written; may alias d_y, which
// is then overwritten in place — the usual case, it saves a buffer). Then as dense_backward
// with d_pre in place of d_y: d_x (N, in) written (skipped when null), d_W += d_preᵀ x,
// d_b += Σ_n d_pre.
template <class T>
void dense_relu_backward(T* d_x, T* d_W, T* d_b, T* d_pre, const T* d_y, const T* y, const T* x,
                         const T* W, int64_t N, int in, int out);

// ---- One layer, block by block --------------------------------------------------------------
// The four calls above run a layer over the whole batch: every chunk of 256 rows, then return.
// A network of SMALL layers (the grid field's 32 → 64 → 16 and 31 → 64 → 3) is faster the other
// way round, all of its layers on one block of rows, then the next block: each layer's input was
// just written by the layer before and is still in L1/L2, where a batch-wide layer reads it back
// from L3 or memory (docs/performance.md, "The grid field's MLPs block by block"). These are
// the pieces the batch-wide calls are themselves made of, so a network run block by block gives
// the batch-wide calls' results bit for bit:
//   - dense_prepare: the layer's weights, packed once for the micro-kernel (when it takes the
//     layer); `forward` packs Wᵀ and b for dense_forward_block, `backward_dx` packs W for the
//     d_x of dense_backward_block;
//   - dense_forward_block / dense_backward_block: one block of rows ≤ kDenseBlockRows, run by
//     the calling thread; the blocks must be the batch's 256-row chunks (row r0 = 256·k);
//   - DenseGradSlabs: the backward's d_W and d_b partials, one per fixed 4096-row slab
//     (kDenseSlabRows = 16 blocks); dense_grads_begin zeroes them, every block of a slab adds
//     into its slab's partial in row order, dense_grads_end adds the slabs in order into d_W
//     and d_b. So the slabs may run on any threads, each slab's blocks on one.
// Storage is grow-only: a layer object reused every step allocates only on its first use.
constexpr int64_t kDenseBlockRows = 256;
constexpr int64_t kDenseSlabRows = 16 * kDenseBlockRows;

template <class T>
struct DenseLayer {
  const T* W = nullptr;  // (out, in)
  const T* b = nullptr;  // (out)
  int in = 0, out = 0;
  bool mk = false;                // the float micro-kernel runs it (else Eigen's GEMM)
  AlignedVec<float> fwd_pack;     // micro-kernel: Wᵀ in column panels, then b
  AlignedVec<float> dx_pack;      // micro-kernel: W in column panels (d_x = g · W)
};
template <class T>
void dense_prepare(DenseLayer<T>& L, const T* W, const T* b, int in, int out, bool forward,
                   bool backward_dx);
// y (rows, out) = x (rows, in) · Wᵀ + b, ReLU when relu. next_x / next_floats (optional): the
// next block's input, prefetched into L2 while this block computes (no effect on results).
template <class T>
void dense_forward_block(T* y, const T* x, const DenseLayer<T>& L, int64_t rows, bool relu,
                         const T* next_x = nullptr, int64_t next_floats = 0);

template <class T>
struct DenseGradSlabs {
  AlignedVec<T> W;        // (slabs, out, in) on Eigen's path, (slabs, in, out) on the micro-kernel's
  AlignedVec<double> b;   // (slabs, out): d_b's column sums in double
  int64_t slabs = 0;
  bool has_W = false, has_b = false;
};
// Zeroes the partials of a batch of N rows; has_W / has_b say which the backward computes.
template <class T>
void dense_grads_begin(DenseGradSlabs<T>& G, const DenseLayer<T>& L, int64_t N, bool has_W,
                       bool has_b);
// One block of the backward, rows [r0, r0 + rows) of the batch (r0 selects the slab; the
// pointers are the block's own rows). d_pre (optional, may alias d_y): ReLU, d_pre = d_y ⊙
// [y > 0] first, then used as the layer's output gradient. d_x (rows, in) written when non-null;
// G (may be null) receives this block's d_W and d_b terms.
template <class T>
void dense_backward_block(T* d_x, DenseGradSlabs<T>* G, int64_t r0, T* d_pre, const T* d_y,
                          const T* y, const T* x, const DenseLayer<T>& L, int64_t rows);
// d_W += Σ over slabs (in order) of the partials, d_b likewise (each entry by one thread).
template <class T>
void dense_grads_end(T* d_W, T* d_b, const DenseGradSlabs<T>& G, const DenseLayer<T>& L);

// GEMM path. Float layers whose `out` is a multiple of the vector's lanes run a hand-written
// register-blocked micro-kernel: 6×16 tiles with 8-lane vectors in AVX2 + FMA builds
// (-DHASHCC_ISA=avx2, or native on an AVX2 CPU; out % 8 == 0), 14×32 tiles with 16-lane vectors
// in AVX-512 builds (-DHASHCC_ISA=avx512, or native on an AVX-512 CPU; out % 16 == 0): packed
// weights, bias and ReLU fused into the store, d_x and d_W computed on the same chunk of d_y.
// Everything else (double, baseline x86-64 builds, out = 1 or 3) runs Eigen's GEMM, the
// reference. Each sum runs in Eigen's k order: bitwise-equal floats where Eigen keeps one chain
// per element, rounding-level differences where it splits a sum (≤ 5e-7 of the scale,
// "[dense][kernel]").
bool dense_microkernel(int out);  // true when a float layer with `out` outputs uses it
const char* dense_microkernel_name();  // which micro-kernel this build has, for reports
// Forces every float layer onto Eigen's GEMM (process-wide; for `hashcc bench --gemm eigen`,
// which times the whole step both ways in one binary). Off by default.
void dense_force_eigen(bool on);

// `hashcc bench --dense-probe`: the micro-kernel's three GEMMs of one float layer (in, out) —
// forward (with bias and ReLU), d_x, d_W — timed alone at one thread (the calling one), on
// operands packed once, over rows [0, N) in the layers' 256-row chunks. Each N is a working set:
// N = 256 keeps x, y and d_y in L2, N = 16384 streams them from L3 or memory as a step does
// (each timed pass follows an untimed one over the same rows). The N values are interleaved in
// every repetition, so a machine's drift hits them alike. GFLOP/s =
// 2·N·in·out / the median wall time of `reps`. Empty when the build has no micro-kernel or the
// layer does not use it.
struct DenseProbeRow {
  int64_t N = 0;
  double fwd_gflops = 0, dx_gflops = 0, dw_gflops = 0;
};
std::vector<DenseProbeRow> dense_microkernel_probe(int in, int out, const std::vector<int64_t>& Ns,
                                                   int reps);

// The Eigen GEMM path of dense_forward / dense_relu_forward (relu) and of dense_backward /
// dense_relu_backward (d_pre == nullptr: no ReLU), whatever the build: the reference the
// micro-kernel is tested against and `hashcc bench --dense` compares with.
template <class T>
void dense_forward_eigen(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out,
                         bool relu);
template <class T>
void dense_backward_eigen(T* d_x, T* d_W, T* d_b, T* d_pre, const T* d_y, const T* y, const T* x,
                          const T* W, int64_t N, int in, int out);

// Triple-loop references for the tests (same contracts as dense_forward / dense_backward).
template <class T>
void dense_forward_naive(T* y, const T* x, const T* W, const T* b, int64_t N, int in, int out);
template <class T>
void dense_backward_naive(T* d_x, T* d_W, T* d_b, const T* d_y, const T* x, const T* W,
                          int64_t N, int in, int out);

// Elementwise activations over n values; forward may run in place (y == x).
// Backward uses the forward OUTPUT y (relu: y > 0; sigmoid: y(1−y); exp: y), softplus uses x.
// d_x written; may alias d_y.
// Stability (docs/math/dense.md): sigmoid and softplus use the branch on sign(x) so no exp()
// argument is positive — finite and accurate for any finite x (±80, ±100 tested). exp clamps its
// input at kExpClampMax = 80 (exp(80) ≈ 5.5e34 is finite in float with room for the backward's
// d_y·y); the backward d_y·y is then straight-through past the clamp, as instant-ngp's trunc_exp.
inline constexpr double kExpClampMax = 80.0;
template <class T> void relu_forward(T* y, const T* x, int64_t n);
template <class T> void relu_backward(T* d_x, const T* d_y, const T* y, int64_t n);
template <class T> void sigmoid_forward(T* y, const T* x, int64_t n);
template <class T> void sigmoid_backward(T* d_x, const T* d_y, const T* y, int64_t n);
template <class T> void softplus_forward(T* y, const T* x, int64_t n);
template <class T> void softplus_backward(T* d_x, const T* d_y, const T* x, int64_t n);
template <class T> void exp_forward(T* y, const T* x, int64_t n);
template <class T> void exp_backward(T* d_x, const T* d_y, const T* y, int64_t n);

// Row-wise concat: out (N, A+B) = [a (N, A), b (N, B)]; split is its backward
// (d_a (N, A), d_b (N, B) written; either may be null).
template <class T> void concat_forward(T* out, const T* a, const T* b, int64_t N, int A, int B);
template <class T> void concat_backward(T* d_a, T* d_b, const T* d_out, int64_t N, int A, int B);

}  // namespace hashcc
