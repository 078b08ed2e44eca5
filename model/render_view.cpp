#include "model/render_view.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <omp.h>

#include "core/error.h"
#include "core/parallel.h"
#include "kernels/dense.h"
#include "kernels/sh.h"
#include "model/grid_field.h"
#include "model/layers.h"
#include "render/compositor.h"
#include "render/sampler.h"

namespace hashcc {

namespace {

// One thread's buffers of the marched render (grow-only).
struct MarchBuffers {
  AlignedVec<float> x, u, dir_enc, px, gx, genc, gdo, rgb_in, color, ccx, ccenc, dcol;
  // The three two-layer MLPs (density gd0 → gd1, colour gr0 → gr1, CC cc0 → cc1), packed once
  // a march block, each run a 256-point block at a time with its hidden layer in `hidden`
  // (kernels/dense.h: the batch-wide layers' results bit for bit, the hidden layer in L1/L2).
  DenseLayer<float> lay[6];
  AlignedVec<float> hidden;
  std::vector<double> T, acc;     // per ray: transmittance, [rgb 3, rgb2 3, depth, opacity]
  std::vector<uint8_t> active;
  std::vector<int> pt_ray, pt_k;  // per marched point: its ray, its sample index
  std::vector<int> pt_e;          // per marched point: its row in the density buffers, −1: skipped
  std::vector<double> pt_w;       // per marched point: its weight (−1: not reached)
  std::vector<int> col_pt;        // points that get a colour
};

// The rays [r0, r0 + R) of a marched render on one thread (serial kernels).
void march_block(MarchBuffers& b, const NetView<float>& net, const float* o, const float* d,
                 const float* s, int R, int S, const RayOutputs<float>& out, double t_min,
                 double w_min, const OccupancyGrid* skip, RenderStats& st) {
  const ModelConfig& cfg = net.cfg;
  const ModelLayout& L = net.L;
  const GridFieldConfig& g = cfg.gf;
  const float* p = net.params;
  const int LF = g.grid.out_dim(), G = g.geo, E = cfg.dir_dim();
  const bool cc = cfg.has_cc();
  const int B = kMarchBlock;
  const int64_t NB = int64_t(R) * B;  // at most this many points a block
  // All sample positions, as the full render forms them (render/sampler.h), and the directions.
  ensure(b.x, int64_t(R) * S * 3);
  ensure(b.u, int64_t(R) * 3);
  ensure(b.dir_enc, int64_t(R) * E);
  std::vector<float> s_all(size_t(R) * S);
  for (int r = 0; r < R; ++r) std::memcpy(s_all.data() + size_t(r) * S, s, sizeof(float) * S);
  sample_points_forward(b.x.data(), o, d, s_all.data(), R, S);
  normalize3_forward(b.u.data(), d, R);
  layers::encode_dir(b.dir_enc.data(), b.u.data(), R, cfg);
  for (AlignedVec<float>* v : {&b.px, &b.gx}) ensure(*v, NB * 3);
  ensure(b.genc, NB * LF);
  ensure(b.gdo, NB * (1 + G));
  ensure(b.rgb_in, NB * (G + E));
  ensure(b.color, NB * 3);
  if (cc) {
    ensure(b.ccx, NB * 3);
    ensure(b.ccenc, NB * cfg.cc.out_dim());
    ensure(b.dcol, NB * 3);
  }
  const LayerView* views[6] = {&L.gd0, &L.gd1, &L.gr0, &L.gr1, &L.cc0, &L.cc1};
  for (int k = 0; k < (cc ? 6 : 4); ++k)
    dense_prepare(b.lay[k], p + views[k]->w, p + views[k]->b, views[k]->in, views[k]->out, true,
                  false);
  float* hidden = ensure(b.hidden, size_t(kDenseBlockRows) *
                                       std::max({g.hidden, g.rgb_hidden, cc ? cfg.cc_hidden : 0}));
  // y (n, l1.out) = l1(relu(l0(x))) over n rows (x: n × l0.in), a 256-row block at a time.
  const auto mlp2 = [&](float* y, const float* x, int64_t n, const DenseLayer<float>& l0,
                        const DenseLayer<float>& l1) {
    for (int64_t r0 = 0; r0 < n; r0 += kDenseBlockRows) {
      const int64_t rows = std::min(kDenseBlockRows, n - r0);
      dense_forward_block(hidden, x + r0 * l0.in, l0, rows, true);
      dense_forward_block(y + r0 * l1.out, hidden, l1, rows, false);
    }
  };
  b.T.assign(R, 1.0);
  b.acc.assign(size_t(R) * 8, 0.0);
  b.active.assign(R, 1);
  float lw[64];
  const bool levels_weighted = cfg.pos_c2f_alpha >= 0;
  if (levels_weighted) c2f_band_weights(lw, g.grid.levels, cfg.pos_c2f_alpha);
  const float zmax = float(kGridMaxLogDensity);
  for (int k0 = 0; k0 < S; k0 += B) {
    const int nb = std::min(B, S - k0);
    // The block's points: nb samples of every ray still marching.
    b.pt_ray.clear();
    b.pt_k.clear();
    for (int r = 0; r < R; ++r)
      if (b.active[r])
        for (int k = k0; k < k0 + nb; ++k) {
          b.pt_ray.push_back(r);
          b.pt_k.push_back(k);
        }
    const int64_t M = int64_t(b.pt_ray.size());
    if (M == 0) break;
    // The points whose density is evaluated (NE of them, rows 0…NE−1 of px and the density
    // buffers): all, or with an empty-space grid the occupied ones; a skipped point has σ = 0.
    b.pt_e.resize(M);
    int64_t NE = 0;
    for (int64_t m = 0; m < M; ++m) {
      const float* xm = b.x.data() + (int64_t(b.pt_ray[m]) * S + b.pt_k[m]) * 3;
      if (skip && !skip->occupied(xm)) {
        b.pt_e[m] = -1;
        continue;
      }
      b.pt_e[m] = int(NE);
      std::memcpy(b.px.data() + 3 * NE, xm, sizeof(float) * 3);
      ++NE;
    }
    st.density += NE;
    // Density: the grid field's forward up to σ (grid_field_forward, the same kernels).
    for (int64_t i = 0; i < NE * 3; ++i) b.gx[i] = (b.px[i] + 1.0f) * 0.5f;
    hashgrid_forward(b.genc.data(), b.gx.data(), p + L.grid_table, NE, g.grid);
    if (levels_weighted)
      for (int64_t e = 0; e < NE; ++e)
        for (int l = 0; l < g.grid.levels; ++l)
          for (int f = 0; f < g.grid.features; ++f) b.genc[e * LF + l * g.grid.features + f] *= lw[l];
    mlp2(b.gdo.data(), b.genc.data(), NE, b.lay[0], b.lay[1]);
    // Composite in sample order (render/compositor.cpp's recursion, in double); a ray stops
    // once T < t_min; a sample whose weight is below w_min gets no colour.
    b.pt_w.assign(M, -1.0);
    b.col_pt.clear();
    for (int64_t m0 = 0; m0 < M; m0 += nb) {
      const int r = b.pt_ray[m0];
      double Ti = b.T[r];
      double* acc = b.acc.data() + 8 * size_t(r);
      for (int j = 0; j < nb; ++j) {
        const int64_t m = m0 + j;
        const int k = b.pt_k[m];
        const int e = b.pt_e[m];
        // σ_raw = exp(min(z, 15)); σ = relu(σ_raw); a skipped (empty) point: σ = 0
        const float sr = e >= 0 ? std::exp(std::min(b.gdo[int64_t(e) * (1 + G)], zmax)) : 0.f;
        const float sigma = sr > 0.f ? sr : 0.f;
        const double delta = k + 1 < S ? double(s[k + 1]) - double(s[k]) : kLastDelta;
        const double x = double(sigma) * delta;
        const double alpha = -std::expm1(-x), q = std::exp(-x) + kTransmittanceEps;
        const double w = Ti * alpha;
        acc[6] += w * double(s[k]);
        acc[7] += w;
        b.pt_w[m] = w;
        if (w >= w_min && e >= 0) b.col_pt.push_back(int(m));
        Ti *= q;
        if (Ti < t_min) {
          b.active[r] = 0;
          break;
        }
      }
      b.T[r] = Ti;
    }
    // Colour of the samples that carry weight: the colour MLP and the CC branch on them alone.
    const int64_t C = int64_t(b.col_pt.size());
    st.colour += C;
    if (C == 0) continue;
    for (int64_t c = 0; c < C; ++c) {
      const int64_t m = b.col_pt[c], e = b.pt_e[m];
      float* row = b.rgb_in.data() + c * (G + E);
      std::memcpy(row, b.gdo.data() + e * (1 + G) + 1, sizeof(float) * G);
      std::memcpy(row + G, b.dir_enc.data() + int64_t(b.pt_ray[m]) * E, sizeof(float) * E);
    }
    mlp2(b.color.data(), b.rgb_in.data(), C, b.lay[2], b.lay[3]);
    sigmoid_forward(b.color.data(), b.color.data(), C * 3);
    if (cc) {
      for (int64_t c = 0; c < C; ++c)
        for (int a = 0; a < 3; ++a) {
          const float v = (b.px[3 * int64_t(b.pt_e[b.col_pt[c]]) + a] + 1.0f) * 0.5f;
          b.ccx[3 * c + a] = v < 0.f ? 0.f : (v > 1.f ? 1.f : v);
        }
      hashgrid_forward(b.ccenc.data(), b.ccx.data(), p + L.cc_table, C, cfg.cc);
      mlp2(b.dcol.data(), b.ccenc.data(), C, b.lay[4], b.lay[5]);
    }
    for (int64_t c = 0; c < C; ++c) {  // col_pt is in ray order, each ray's samples in order
      const int64_t m = b.col_pt[c];
      const double w = b.pt_w[m];
      double* acc = b.acc.data() + 8 * size_t(b.pt_ray[m]);
      const float* col = b.color.data() + 3 * c;
      for (int a = 0; a < 3; ++a) acc[a] += w * double(col[a]);
      if (cc)
        for (int a = 0; a < 3; ++a) acc[3 + a] += w * double(col[a] + b.dcol[3 * c + a]);
    }
  }
  for (int r = 0; r < R; ++r) {
    const double* acc = b.acc.data() + 8 * size_t(r);
    for (int a = 0; a < 3; ++a) {
      if (out.rgb) out.rgb[3 * r + a] = float(acc[a]);
      if (out.rgb_cc) out.rgb_cc[3 * r + a] = float(cc ? acc[3 + a] : acc[a]);
    }
    if (out.depth) out.depth[r] = float(acc[6]);
    if (out.opacity) out.opacity[r] = float(acc[7]);
  }
  st.samples += int64_t(R) * S;
}

}  // namespace

OccupancyGrid empty_space_grid(const NetView<float>& net, int res, double sigma_min, int passes,
                               uint64_t seed) {
  HCC_REQUIRE(res >= 1 && res <= 512 && sigma_min > 0 && passes >= 1, "", "empty-space grid",
              "res {} sigma_min {} passes {}", res, sigma_min, passes,
              "res 1..512, sigma_min > 0, passes >= 1");
  OccupancyOptions o;
  o.res = res;
  o.probes = 2;                    // occupied when σ·(1/probes) ≥ threshold, i.e. σ ≥ sigma_min
  o.threshold = sigma_min / o.probes;
  o.decay = 1.0;                   // a cell keeps the largest σ of its passes
  o.parts = 1;
  OccupancyGrid grid(o);
  ModelCache<float> cache;
  const DensityFn density = [&](const float* x, int64_t n, float* sigma) {
    model_density(cache, net, x, n, sigma);
  };
  for (int p = 0; p < passes; ++p) grid.update(density, seed + uint64_t(p) * 0x9E3779B97F4A7C15ull);
  return grid;
}

bool render_shortcuts_apply(const ModelConfig& cfg, const ViewOptions& opt) {
  return opt.shortcuts && cfg.field == Field::grid && !opt.occupancy;
}

void render_rays_marched(const NetView<float>& net, const float* o, const float* d, const float* s,
                         int R, int S, const RayOutputs<float>& out, double t_min, double w_min,
                         RenderStats* stats, const OccupancyGrid* skip) {
  HCC_ASSERT(net.cfg.field == Field::grid);
  constexpr int kBlockRays = 256;  // rays a task: ≤ 2,048 points a march block
  const int nblocks = (R + kBlockRays - 1) / kBlockRays;
  const int nt = std::max(1, std::min(num_threads(), nblocks));
  std::vector<MarchBuffers> bufs(nt);
  std::vector<RenderStats> st(nt);
  auto block = [&](int t, int blk) {
    const int r0 = blk * kBlockRays, Rb = std::min(kBlockRays, R - r0);
    const RayOutputs<float> ob{out.rgb ? out.rgb + 3 * int64_t(r0) : nullptr,
                               out.rgb_cc ? out.rgb_cc + 3 * int64_t(r0) : nullptr,
                               out.depth ? out.depth + r0 : nullptr,
                               out.opacity ? out.opacity + r0 : nullptr};
    march_block(bufs[t], net, o + 3 * int64_t(r0), d + 3 * int64_t(r0), s, Rb, S, ob, t_min, w_min,
                skip, st[t]);
  };
  if (nt <= 1) {
    for (int blk = 0; blk < nblocks; ++blk) block(0, blk);
  } else {
    // Rays stop at different depths: blocks handed out dynamically (each block's numbers do
    // not depend on which thread renders it).
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
    for (int blk = 0; blk < nblocks; ++blk) block(omp_get_thread_num(), blk);
  }
  if (stats)
    for (const RenderStats& x : st) {
      stats->samples += x.samples;
      stats->density += x.density;
      stats->colour += x.colour;
    }
}

ViewImage render_view(StepWorkspace<float>& ws, const NetView<float>& net, const ViewCamera& cam,
                      const ViewOptions& opt, RenderStats* stats) {
  const PoseParams<float>& pose = cam.pose;
  const FocalParams<float>& focal = cam.focal;
  const ImageSize size = cam.size;
  const NdcWarp ndc = cam.ndc;
  const int S = opt.samples, stride = std::max(1, opt.stride);
  const int chunk_rays = resolve_chunk_rays(opt.chunk_rays, net.cfg, S);
  ViewImage img;
  img.width = (size.W + stride - 1) / stride;
  img.height = (size.H + stride - 1) / stride;
  const int64_t total = int64_t(img.width) * img.height;
  img.rgb.resize(total * 3);
  img.depth.resize(total);
  img.opacity.resize(total);
  // One chunk a thread per call: ray_batch_render then runs the chunks side by side, each thread
  // with serial kernels, as a training step does (one chunk a call would fork every kernel).
  // The shortcuts' march takes 8,192 rays a call (its own blocks over the threads) and one row
  // of sample positions for all of them.
  const bool marched = render_shortcuts_apply(net.cfg, opt);
  const int block = marched ? 8192 : std::min(kMaxChunkRays, chunk_rays * std::max(1, num_threads()));
  std::vector<int> px(2 * block);
  std::vector<float> o(3 * block), d(3 * block), s(int64_t(marched ? 1 : block) * S);
  // formulas.md §3: s_i = i/S for final renders; with an occupancy grid, the strata's centres
  // (k + ½)/S, which occupancy_samples moves into each ray's occupied stretches (s_occ, delta).
  for (int i = 0; i < S; ++i) s[i] = opt.occupancy ? (i + 0.5f) / S : float(i) / S;
  if (!marched)
    for (int r = 1; r < block; ++r) std::copy(s.begin(), s.begin() + S, s.begin() + int64_t(r) * S);
  std::vector<float> s_occ, delta;
  if (opt.occupancy) {
    s_occ.resize(s.size());
    delta.resize(s.size());
  }
  for (int64_t r0 = 0; r0 < total; r0 += block) {
    const int R = int(std::min<int64_t>(block, total - r0));
    for (int r = 0; r < R; ++r) {
      int64_t k = r0 + r;
      px[2 * r] = int(k % img.width) * stride;      // u (column)
      px[2 * r + 1] = int(k / img.width) * stride;  // v (row)
    }
    camera_rays_forward(o.data(), d.data(), px.data(), R, pose, focal, size, ndc);
    RayBatch<float> rays{o.data(), d.data(), s.data(), nullptr, R, S};
    if (opt.occupancy) {
      occupancy_samples(s_occ.data(), delta.data(), *opt.occupancy, o.data(), d.data(), s.data(),
                        R, S);
      rays.s = s_occ.data();
      rays.delta = delta.data();
    }
    if (marched) {
      render_rays_marched(net, o.data(), d.data(), s.data(), R, S,
                          {nullptr, img.rgb.data() + 3 * r0, img.depth.data() + r0,
                           img.opacity.data() + r0},
                          opt.t_min, opt.w_min_total / S, stats, opt.skip);
      continue;
    }
    ray_batch_render(ws, net, rays,
                     chunk_rays, {nullptr, img.rgb.data() + 3 * r0, img.depth.data() + r0,
                                  img.opacity.data() + r0});
    if (stats) {
      stats->samples += int64_t(R) * S;
      stats->density += int64_t(R) * S;
      stats->colour += int64_t(R) * S;
    }
  }
  return img;
}

}  // namespace hashcc
