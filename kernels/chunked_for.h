// kernels/chunked_for.h — thread split over FIXED chunks, for bit-identical results at any
// thread count.
//
// Why not parallel_for: GCC contracts a*b + c into FMA where it sees fit (C++ defaults to
// -ffp-contract=fast), and it decides separately for every compiled copy of a loop: the SIMD
// main body, the scalar remainder, and each call site the body is inlined into (parallel_blocks
// calls fn both outside and inside the OpenMP region). So the same item could round differently
// at 1 and 2 threads (seen in sh_backward). Here (1) chunk boundaries do not depend on the thread
// count, and (2) every chunk runs through ONE out-of-line copy of the body (run_chunk), so each
// item is computed by the same instructions every time.
#pragma once
#include <algorithm>
#include <cmath>  // core/parallel.h uses std::sqrt/log/cos but includes <cmath> only after its body
#include <cstdint>

#include "core/parallel.h"

namespace hashcc {
namespace detail {
template <class Fn>
[[gnu::noinline]] void run_chunk(Fn& fn, int64_t begin, int64_t end) { fn(begin, end); }
}  // namespace detail

// Calls fn(begin, end) for the chunks [k·chunk, min(n, (k+1)·chunk)) of [0, n); the chunks are
// statically split over the threads (serial when there is only one chunk).
template <class Fn>
void parallel_chunks(int64_t n, int64_t chunk, Fn&& fn) {
  if (n <= 0) return;
  const int64_t nchunks = (n + chunk - 1) / chunk;
  parallel_blocks(nchunks, [&](int64_t c0, int64_t c1, int) {
    for (int64_t c = c0; c < c1; ++c) detail::run_chunk(fn, c * chunk, std::min(n, (c + 1) * chunk));
  });
}

}  // namespace hashcc
