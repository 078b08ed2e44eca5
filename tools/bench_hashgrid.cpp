// tools/bench_hashgrid.cpp — `hashcc bench --hashgrid`: the hash encoding's three kernels alone
// (kernels/hash_grid.h), the grid field's largest stage: the forward (8 row gathers a point a
// level), the training backward (the corner sums for dL/dx and the scatter-add into the table's
// gradient) and eval's frozen-table backward (dL/dx only). Points come as the grid field sees
// them: R rays × S samples, each ray a straight line through [0,1]³ from near (z = 0) to far
// (z = 1) with a small slant, samples jittered in their strata, rays in random order (a training
// step's random pixels). The table is the grid field's (16 levels × 2 features, base 16, finest
// 512, the smooth position gradient) at each --hashgrid-log2 size; d_out is uniform in ±0.5.
//
// Per table size and thread count: the median over --hashgrid-reps repetitions of one "step"
// (--hashgrid-calls kernel calls of R·S points each, as a training step calls the field once a
// chunk of rays), in ms and in ns a point a level (the step's time / (points × levels)), and two
// checksums: the sum of the forward's outputs and the positions' gradients (the same at any thread
// count: every point is computed alone) and the sum of the table's gradient (at 2 threads two
// arenas are added, so its rounding may differ). Both change when a kernel's arithmetic does.
// A second line per row times the path the grid field takes when the camera learns: the forward
// keeping its position Jacobian (`fwd+jac`), the scatter alone (`scatter`) and dL/dx from the
// Jacobian (`dx(jac)`); training = fwd+jac + scatter + dx(jac) against forward + bwd tab+dx,
// eval's frozen field = fwd+jac + dx(jac) against forward + bwd dx only; `max rel diff` compares
// its d_x with the gather's. A third line (`fwd scalar`, `+jac`) times both forwards again with
// the SIMD gather switched off (hashgrid_set_gather(kScalar)) and counts the entries whose bits
// differ from the SIMD forwards' (0 expected). Timings only: nothing is asserted (the kernels' tests are
// test/test_hash_grid.cpp). To compare two builds, run both alternately (tools/bench_ab.sh).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include <fmt/core.h>

#include "core/isa.h"
#include "core/parallel.h"
#include "kernels/hash_grid.h"
#include "tools/bench.h"

namespace hashcc {

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

std::vector<BenchHashGridRow> run_bench_hashgrid(const BenchHashGridOptions& o) {
  std::vector<BenchHashGridRow> rows;
  const std::vector<int> threads = o.threads.empty() ? std::vector<int>{1, 2} : o.threads;
  // The rows time the SIMD gather (where the build has one), then the scalar loop, whatever the
  // default (kAuto) would pick on this CPU; it is printed at the end.
  const bool simd = hashgrid_has_simd_gather();
  hashgrid_set_gather(GatherMode::kAuto);
  const bool auto_simd = hashgrid_simd_gather();
  hashgrid_set_gather(simd ? GatherMode::kSimd : GatherMode::kScalar);
  const int64_t N = int64_t(o.rays) * o.samples;
  // The points of every call, fixed by the seed (the same for every table size and build).
  Rng rng(o.seed);
  std::vector<std::vector<float>> xs(o.calls), d_out(o.calls);
  for (int c = 0; c < o.calls; ++c) {
    xs[c].resize(N * 3);
    for (int r = 0; r < o.rays; ++r) {
      const double x0 = rng.uniform(0.1, 0.9), y0 = rng.uniform(0.1, 0.9);
      const double sx = rng.uniform(-0.05, 0.05), sy = rng.uniform(-0.05, 0.05);
      for (int s = 0; s < o.samples; ++s) {
        const double z = (s + rng.uniform(0.0, 1.0)) / o.samples;
        float* p = xs[c].data() + (int64_t(r) * o.samples + s) * 3;
        p[0] = float(x0 + sx * z);
        p[1] = float(y0 + sy * z);
        p[2] = float(z);
      }
    }
  }
  fmt::print("hash grid kernels alone: {} call(s) a step of {} rays x {} samples = {} points; "
             "16 levels x 2 features, base 16, finest 512, smooth position gradient; ISA {}\n",
             o.calls, o.rays, o.samples, N, compiled_isa().name);
  fmt::print("{:>5} {:>4} {:>10} {:>8} {:>13} {:>8} {:>13} {:>8}  {:>16} {:>16}\n", "log2T", "thr",
             "forward", "ns/pt·l", "bwd tab+dx", "ns/pt·l", "bwd dx only", "ns/pt·l",
             "sum out + d_x", "sum d_table");
  for (int log2 : o.log2_tables) {
    HashGridConfig cfg;
    cfg.levels = 16;
    cfg.features = 2;
    cfg.log2_table = log2;
    cfg.base_res = 16;
    cfg.max_res = 512;
    cfg.smooth_dx = true;
    std::vector<float> table(cfg.param_count()), d_table(cfg.param_count());
    Rng trng(o.seed + 1);
    // Entries of a trained table's size (±0.1), not the ±1e-4 start: the checksum then moves with
    // any change of the arithmetic.
    for (float& v : table) v = float(trng.uniform(-0.1, 0.1));
    for (int c = 0; c < o.calls; ++c) {
      d_out[c].resize(N * cfg.out_dim());
      for (float& v : d_out[c]) v = float(trng.uniform(-0.5, 0.5));
    }
    std::vector<std::vector<float>> out(o.calls, std::vector<float>(N * cfg.out_dim())),
        d_x(o.calls, std::vector<float>(N * 3)), d_xj(o.calls, std::vector<float>(N * 3)),
        jac(o.calls, std::vector<float>(N * 3 * cfg.out_dim())),
        out_s(o.calls, std::vector<float>(N * cfg.out_dim())),
        jac_s(o.calls, std::vector<float>(N * 3 * cfg.out_dim()));
    for (int t : threads) {
      set_num_threads(t);
      HashGridWorkspace<float> ws;
      std::vector<double> tf, tb, tx, tfj, ts, txj, tfs, tfjs;
      for (int rep = 0; rep <= o.reps; ++rep) {  // rep 0: warm-up, not timed
        double t0 = bench_wall_s();
        for (int c = 0; c < o.calls; ++c)
          hashgrid_forward(out[c].data(), xs[c].data(), table.data(), N, cfg);
        const double f = 1e3 * (bench_wall_s() - t0);
        std::fill(d_table.begin(), d_table.end(), 0.f);
        t0 = bench_wall_s();
        for (int c = 0; c < o.calls; ++c)
          hashgrid_backward(d_table.data(), d_x[c].data(), d_out[c].data(), xs[c].data(),
                            table.data(), N, cfg, ws);
        const double b = 1e3 * (bench_wall_s() - t0);
        t0 = bench_wall_s();
        for (int c = 0; c < o.calls; ++c)
          hashgrid_backward<float>(nullptr, d_x[c].data(), d_out[c].data(), xs[c].data(),
                                   table.data(), N, cfg, ws);
        const double x = 1e3 * (bench_wall_s() - t0);
        t0 = bench_wall_s();
        for (int c = 0; c < o.calls; ++c)
          hashgrid_forward(out[c].data(), xs[c].data(), table.data(), N, cfg, jac[c].data());
        const double fj = 1e3 * (bench_wall_s() - t0);
        t0 = bench_wall_s();
        for (int c = 0; c < o.calls; ++c)
          hashgrid_backward<float>(d_table.data(), nullptr, d_out[c].data(), xs[c].data(),
                                   table.data(), N, cfg, ws);
        const double sc = 1e3 * (bench_wall_s() - t0);
        t0 = bench_wall_s();
        for (int c = 0; c < o.calls; ++c)
          hashgrid_dx_from_jac(d_xj[c].data(), d_out[c].data(), jac[c].data(), N, cfg);
        const double xj = 1e3 * (bench_wall_s() - t0);
        // The forward again with the SIMD gather off (the scalar loop), into out_s.
        hashgrid_set_gather(GatherMode::kScalar);
        t0 = bench_wall_s();
        for (int c = 0; c < o.calls; ++c)
          hashgrid_forward(out_s[c].data(), xs[c].data(), table.data(), N, cfg);
        const double fs = 1e3 * (bench_wall_s() - t0);
        t0 = bench_wall_s();
        for (int c = 0; c < o.calls; ++c)
          hashgrid_forward(out_s[c].data(), xs[c].data(), table.data(), N, cfg, jac_s[c].data());
        const double fjs = 1e3 * (bench_wall_s() - t0);
        hashgrid_set_gather(simd ? GatherMode::kSimd : GatherMode::kScalar);
        if (rep > 0) {
          tfs.push_back(fs);
          tfjs.push_back(fjs);
          tf.push_back(f);
          tb.push_back(b);
          tx.push_back(x);
          tfj.push_back(fj);
          ts.push_back(sc);
          txj.push_back(xj);
        }
      }
      // d_table now holds reps + 1 steps of scatter-only gradient on top of the timed step's:
      // recompute the checksum's single step.
      std::fill(d_table.begin(), d_table.end(), 0.f);
      for (int c = 0; c < o.calls; ++c)
        hashgrid_backward(d_table.data(), d_x[c].data(), d_out[c].data(), xs[c].data(),
                          table.data(), N, cfg, ws);
      BenchHashGridRow row{log2, t, median(tf), median(tb), median(tx), 0.0, 0.0};
      row.ms_forward_jac = median(tfj);
      row.ms_scatter = median(ts);
      row.ms_dx_jac = median(txj);
      double dmax = 0, emax = 0;
      for (int c = 0; c < o.calls; ++c)
        for (int64_t i = 0; i < N * 3; ++i) {
          dmax = std::max(dmax, std::abs(double(d_x[c][i])));
          emax = std::max(emax, std::abs(double(d_xj[c][i]) - double(d_x[c][i])));
        }
      row.dx_rel_diff = dmax > 0 ? emax / dmax : 0.0;
      for (int c = 0; c < o.calls; ++c) {
        for (float v : out[c]) row.sum_out_dx += v;
        for (float v : d_x[c]) row.sum_out_dx += v;
      }
      for (float v : d_table) row.sum_table += v;
      const double per = 1e6 / (double(N) * o.calls * cfg.levels);  // ms → ns a point a level
      fmt::print("{:>5} {:>4} {:>7.2f} ms {:>8.2f} {:>10.2f} ms {:>8.2f} {:>10.2f} ms {:>8.2f}  {:>16.9g} {:>16.9g}\n",
                 log2, t, row.ms_forward, row.ms_forward * per, row.ms_backward,
                 row.ms_backward * per, row.ms_backward_dx, row.ms_backward_dx * per,
                 row.sum_out_dx, row.sum_table);
      fmt::print("{:>10} {:>7.2f} ms {:>8.2f} {:>7} {:>7.2f} ms {:>8.2f} {:>7} {:>7.2f} ms {:>8.2f}  "
                 "max rel diff {:.2g}\n",
                 "fwd+jac", row.ms_forward_jac, row.ms_forward_jac * per, "scatter",
                 row.ms_scatter, row.ms_scatter * per, "dx(jac)", row.ms_dx_jac,
                 row.ms_dx_jac * per, row.dx_rel_diff);
      // Entries whose bits differ between the SIMD and the scalar gather, over every call.
      auto bits_differ = [&](const std::vector<std::vector<float>>& a,
                             const std::vector<std::vector<float>>& b) {
        int64_t n = 0;
        for (int c = 0; c < o.calls; ++c)
          for (size_t i = 0; i < a[c].size(); ++i)
            n += std::memcmp(&a[c][i], &b[c][i], sizeof(float)) != 0;
        return n;
      };
      const int64_t differ = bits_differ(out, out_s) + bits_differ(jac, jac_s);
      row.ms_forward_scalar = median(tfs);
      row.ms_forward_jac_scalar = median(tfjs);
      fmt::print("{:>10} {:>7.2f} ms {:>8.2f} {:>7} {:>7.2f} ms {:>8.2f}  (the gathers {}; "
                 "{} of {} outputs' and Jacobian entries' bits differ)\n",
                 "fwd scalar", row.ms_forward_scalar, row.ms_forward_scalar * per, "+jac",
                 row.ms_forward_jac_scalar, row.ms_forward_jac_scalar * per,
                 simd ? "SIMD on the lines above, scalar here"
                      : "scalar everywhere: no SIMD gather in this build",
                 differ, int64_t(o.calls) * N * cfg.out_dim() * 4);
      rows.push_back(row);
    }
  }
  hashgrid_set_gather(GatherMode::kAuto);
  fmt::print("the default gather (measured once a process, kernels/hash_grid.h): {} on this CPU\n",
             auto_simd ? "SIMD" : "scalar");
  return rows;
}

}  // namespace hashcc
