// render/occupancy.cpp — see occupancy.h; the sampler's derivation in docs/math/occupancy.md.
#include "render/occupancy.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "kernels/chunked_for.h"
#include "render/compositor.h"

namespace hashcc {
namespace {

constexpr int kMaxProbes = 1024;
constexpr int64_t kRayChunk = 64;       // rays per fixed chunk (kernels/chunked_for.h)
constexpr int64_t kDensityBatch = 16384;  // points per density call of an update

// splitmix64: a counter-based stream, so a cell's jitter depends on (seed, cell) only.
uint64_t mix(uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
double unit(uint64_t z) { return double(z >> 11) * 0x1.0p-53; }  // [0, 1)

}  // namespace

OccupancyGrid::OccupancyGrid(const OccupancyOptions& opt) : opt_(opt) {
  // Ranges are validated where the options are read (train/train_config.cpp).
  HCC_ASSERT(opt.res >= 1 && opt.res <= 512);
  HCC_ASSERT(opt.probes >= 2 && opt.probes <= kMaxProbes);
  HCC_ASSERT(opt.parts >= 1 && opt.decay >= 0 && opt.decay <= 1);
  const int64_t n = int64_t(opt.res) * opt.res * opt.res;
  sigma_.assign(n, std::numeric_limits<float>::infinity());  // unmeasured = occupied
  occ_.assign(n, 1);
}

void OccupancyGrid::update(const DensityFn& density, uint64_t seed) {
  const int G = opt_.res;
  const int64_t n = int64_t(G) * G * G;
  const int part = int(updates_ % opt_.parts);
  std::vector<int64_t> cells;
  cells.reserve(n / opt_.parts + 1);
  for (int64_t c = part; c < n; c += opt_.parts) cells.push_back(c);
  std::vector<float> x, sig;
  for (size_t b = 0; b < cells.size(); b += kDensityBatch) {
    const int64_t m = std::min<int64_t>(kDensityBatch, int64_t(cells.size() - b));
    x.resize(3 * m);
    sig.resize(m);
    for (int64_t i = 0; i < m; ++i) {
      const int64_t c = cells[b + i];
      const int64_t idx[3] = {c % G, (c / G) % G, c / (int64_t(G) * G)};
      uint64_t h = mix(seed ^ mix(uint64_t(c)));
      for (int a = 0; a < 3; ++a) {  // a jittered point inside the cell, NDC [-1, 1]
        h = mix(h);
        x[3 * i + a] = float(-1.0 + 2.0 * (double(idx[a]) + unit(h)) / G);
      }
    }
    density(x.data(), m, sig.data());
    for (int64_t i = 0; i < m; ++i) {
      float& s = sigma_[cells[b + i]];
      const float v = std::max(sig[i], 0.0f);
      s = std::isinf(s) ? v : std::max(float(opt_.decay) * s, v);
    }
  }
  ++updates_;
  rebuild();
}

void OccupancyGrid::update_all(const DensityFn& density, uint64_t seed) {
  for (int p = 0; p < opt_.parts; ++p) update(density, seed + uint64_t(p));
}

void OccupancyGrid::rebuild() {
  const int G = opt_.res;
  const int64_t n = int64_t(G) * G * G;
  // Raw flags: σ·(1/P) ≥ threshold (an unmeasured cell, σ = +∞, is occupied).
  const double min_sigma = opt_.threshold * opt_.probes;
  std::vector<uint8_t> a(n), b(n);
  for (int64_t c = 0; c < n; ++c) a[c] = double(sigma_[c]) >= min_sigma;
  // Dilation by one cell: an OR over the 3×3×3 neighbourhood, one axis at a time.
  const int64_t stride[3] = {1, G, int64_t(G) * G};
  uint8_t* src = a.data();
  uint8_t* dst = b.data();
  for (int ax = 0; ax < 3; ++ax) {
    for (int64_t c = 0; c < n; ++c) {
      const int64_t i = (c / stride[ax]) % G;
      uint8_t v = src[c];
      if (i > 0) v |= src[c - stride[ax]];
      if (i + 1 < G) v |= src[c + stride[ax]];
      dst[c] = v;
    }
    std::swap(src, dst);
  }
  occ_.assign(src, src + n);
}

bool OccupancyGrid::occupied(const float* x) const {
  const int G = opt_.res;
  int64_t idx[3];
  for (int a = 0; a < 3; ++a) {
    if (!(x[a] >= -1.0f && x[a] <= 1.0f)) return true;  // outside the box (or NaN)
    idx[a] = std::min<int64_t>(G - 1, int64_t((double(x[a]) + 1.0) * 0.5 * G));
  }
  return occ_[idx[0] + G * (idx[1] + int64_t(G) * idx[2])] != 0;
}

double OccupancyGrid::occupied_fraction() const {
  int64_t k = 0;
  for (uint8_t v : occ_) k += v;
  return occ_.empty() ? 0.0 : double(k) / double(occ_.size());
}

template <class T>
void occupancy_samples(T* s_out, T* delta_out, const OccupancyGrid& grid, const T* o, const T* d,
                       const T* s_in, int64_t R, int S) {
  HCC_ASSERT(S >= 2);
  const int P = grid.options().probes;
  parallel_chunks(R, kRayChunk, [&](int64_t r0, int64_t r1) {
    uint8_t flag[kMaxProbes];
    for (int64_t r = r0; r < r1; ++r) {
      const T* orr = o + 3 * r;
      const T* dr = d + 3 * r;
      // Probe intervals j < P − 1: occupied if the cell at the interval's centre is.
      int cnt = 0;
      for (int j = 0; j + 1 < P; ++j) {
        const double sc = (j + 0.5) / P;
        const float x[3] = {float(orr[0] + sc * dr[0]), float(orr[1] + sc * dr[1]),
                            float(orr[2] + sc * dr[2])};
        flag[j] = grid.occupied(x);
        cnt += flag[j];
      }
      if (cnt == 0) {  // nothing occupied: uniform
        std::fill(flag, flag + P - 1, uint8_t(1));
        cnt = P - 1;
      }
      const T* si = s_in + r * S;
      T* so = s_out + r * S;
      T* dl = delta_out + r * S;
      const double len = double(cnt) / P;  // L, the occupied length
      const double top = std::nextafter(double(cnt), 0.0);
      int j = 0;
      double cum = 0;  // occupied intervals wholly before interval j
      for (int k = 0; k + 1 < S; ++k) {
        // u_k = (k + U_k)/(S − 1) from s_in = (k + U_k)/S; m = u_k · cnt in interval units.
        const double m = std::min(double(si[k]) * S / (S - 1) * cnt, top);
        while (j + 1 < P - 1 && (!flag[j] || m >= cum + 1)) {
          if (flag[j]) cum += 1;
          ++j;
        }
        so[k] = T((j + (m - cum)) / P);
        dl[k] = T(len / (S - 1));
      }
      const double U = std::clamp(double(si[S - 1]) * S - (S - 1), 0.0, 1.0);
      so[S - 1] = T((P - 1 + U) / P);  // the far interval: its sample absorbs what is left
      dl[S - 1] = T(kLastDelta);
    }
  });
}

template void occupancy_samples<float>(float*, float*, const OccupancyGrid&, const float*,
                                       const float*, const float*, int64_t, int);
template void occupancy_samples<double>(double*, double*, const OccupancyGrid&, const double*,
                                        const double*, const double*, int64_t, int);

}  // namespace hashcc
