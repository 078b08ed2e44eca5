// kernels/hash_grid.h — multiresolution hash encoding (spec §5, tiny-cuda-nn). CONTRACT.
#pragma once
#include <cstdint>
#include <vector>
namespace hashcc {

struct HashGridConfig {
  int levels = 16;       // L
  int features = 2;      // F per level
  int log2_table = 9;    // table size 2^T per level
  double base_res = 16;  // N_min
  double max_res = 512;  // N_max (spec default 512)
  int out_dim() const { return levels * features; }
  int64_t table_size() const { return int64_t(1) << log2_table; }
  int64_t param_count() const { return int64_t(levels) * table_size() * features; }
};

// Per-thread scatter buffers for the backward (no atomics; reduced in fixed order).
template <class T>
struct HashGridWorkspace { std::vector<std::vector<T>> per_thread; };

// out (N, L·F) level-major; x (N, 3), clamped to [0,1]; table (L, 2^T, F).
template <class T>
void hashgrid_forward(T* out, const T* x, const T* table, int64_t N, const HashGridConfig& cfg);

// d_table (L, 2^T, F) accumulated (+=). d_x (N, 3) written only when non-null (the CC branch
// passes nullptr: its input is detached).
template <class T>
void hashgrid_backward(T* d_table, T* d_x, const T* d_out, const T* x, const T* table, int64_t N,
                       const HashGridConfig& cfg, HashGridWorkspace<T>& ws);

}  // namespace hashcc
