// core/buffer.h — aligned storage and Eigen views over it.
//
// Activations live in buffers allocated once per batch size and reused every step
// (performance.md: a step must never allocate). Batches are row-major: (N, C) means N rows
// of C contiguous values.
#pragma once
#include <Eigen/Core>
#include <cstddef>
#include <vector>

namespace hashcc {

template <class T>
using AlignedVec = std::vector<T, Eigen::aligned_allocator<T>>;

template <class T>
using MatRM = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
template <class T>
using MapRM = Eigen::Map<MatRM<T>, Eigen::Aligned16>;
template <class T>
using CMapRM = Eigen::Map<const MatRM<T>, Eigen::Unaligned>;
template <class T>
using MapRMu = Eigen::Map<MatRM<T>, Eigen::Unaligned>;

// Grow-only resize: keeps capacity so a reused buffer never reallocates for a smaller batch.
template <class T>
inline T* ensure(AlignedVec<T>& v, size_t n) {
  if (v.size() < n) v.resize(n);
  return v.data();
}

// Grow-only scratch of the calling thread, one buffer per Tag type (each thread that calls it has
// its own; a kernel run by several threads gets one buffer a thread): allocated on the first call
// and when a larger n appears, never per step.
template <class T, class Tag>
inline T* thread_scratch(size_t n) {
  thread_local AlignedVec<T> buf;
  return ensure(buf, n);
}

}  // namespace hashcc
