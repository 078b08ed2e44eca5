// render/occupancy.h — occupancy-guided sampling: fewer full samples per ray (issue 22, item 4).
//
// Uniform sampling spends most of a ray's S samples where the field is empty. An occupancy grid
// (G³ cells over the NDC box [-1, 1]³, the domain of the grid field) remembers, per cell, a
// decayed maximum of the field's density σ; a cell is "occupied" when that maximum could make a
// probe interval visible (σ·(1/P) ≥ threshold), dilated by one cell so that cameras and surfaces
// that move a little between updates still find their samples. The sampler then places the S
// samples of a ray inside the occupied stretches of its s ∈ [0, 1) only:
//
//   P probe intervals [j/P, (j+1)/P), j < P − 1, each occupied or not (the cell at its centre
//   x = o + s·d; a point outside the box counts as occupied). L = their occupied length.
//   Samples k < S − 1 take the jittered strata u_k = (k + U_k)/(S − 1) of the occupied length:
//   s_k = the point at occupied length u_k·L, and each stands for δ_k = L/(S − 1) of it.
//   The last sample keeps the far interval [(P−1)/P, 1) (NDC s = 1 is infinity) with δ = 1e10,
//   as uniform sampling's last sample does (formulas.md §3).
//
// With every interval occupied and P = S this is exactly the uniform jitter s_k = (k + U_k)/S
// (test "[occupancy] all occupied = uniform"); a ray with nothing occupied falls back to that.
// The samples' positions are constants of the step: the camera's gradient still flows through
// x = o + s·d, and the occupancy flags are piecewise constant in (o, d). Empty stretches get no
// samples and so no gradient; a cell whose density grows is seen at the next update, gets
// samples again, and is trained like any other (Müller et al. 2022, Instant-NGP §4).
//
// Tests: test/test_occupancy.cpp ("[occupancy]"). Math: docs/math/occupancy.md.
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

namespace hashcc {

struct OccupancyOptions {
  int res = 64;               // cells per axis over [-1, 1]³
  int probes = 128;           // P: probe intervals per ray
  double threshold = 0.01;    // occupied when max σ · (1/P) ≥ threshold (opacity ≈ 1%)
  double decay = 0.95;        // per update, a cell's remembered σ is max(decay·old, new)
  int parts = 8;              // an update re-measures every parts-th cell (round robin)
};

// σ at n points x (n, 3) in NDC → sigma (n), σ ≥ 0.
using DensityFn = std::function<void(const float* x, int64_t n, float* sigma)>;

class OccupancyGrid {
 public:
  explicit OccupancyGrid(const OccupancyOptions& opt = {});
  const OccupancyOptions& options() const { return opt_; }
  // Re-measures one part of the cells (cell c with c % parts == updates % parts) at a jittered
  // point inside each (the jitter comes from `seed`), then rebuilds the dilated flags.
  // Before the first full round every cell counts as occupied (its σ starts at +∞).
  void update(const DensityFn& density, uint64_t seed);
  // All parts at once (start of a resumed run, or a test).
  void update_all(const DensityFn& density, uint64_t seed);
  // Is the NDC point x occupied? Outside the box: yes.
  bool occupied(const float* x) const;
  // Fraction of cells occupied (after dilation).
  double occupied_fraction() const;
  int64_t updates() const { return updates_; }
  // Direct access for tests: a cell's remembered σ, then rebuild().
  std::vector<float>& cell_sigma() { return sigma_; }
  void rebuild();

 private:
  OccupancyOptions opt_;
  std::vector<float> sigma_;     // G³ remembered σ
  std::vector<uint8_t> occ_;     // G³ flags after dilation
  int64_t updates_ = 0;
};

// The sampler: s_out, delta_out (R, S) from the rays (o, d) (R, 3) and the uniform jitter
// s_in (R, S) (jitter_samples: s_k = (k + U_k)/S). S ≥ 2. Deterministic; rays in parallel.
template <class T>
void occupancy_samples(T* s_out, T* delta_out, const OccupancyGrid& grid, const T* o, const T* d,
                       const T* s_in, int64_t R, int S);

}  // namespace hashcc
