// Tests of kernels/adam (PyTorch Adam semantics; derivation in docs/math/adam.md).
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <cstdio>
#include <vector>

#include "core/parallel.h"
#include "kernels/adam.h"
#include "test/gradcheck.h"

using namespace hashcc;
using hashcc::test::random_vec;

namespace {
// Textbook Adam (Kingma & Ba with PyTorch's eps placement), written independently.
void adam_reference(std::vector<double>& p, const std::vector<double>& g, std::vector<double>& m,
                    std::vector<double>& v, double lr, int t, double b1 = 0.9, double b2 = 0.999,
                    double eps = 1e-8) {
  for (size_t i = 0; i < p.size(); ++i) {
    m[i] = b1 * m[i] + (1 - b1) * g[i];
    v[i] = b2 * v[i] + (1 - b2) * g[i] * g[i];
    const double mhat = m[i] / (1 - std::pow(b1, t)), vhat = v[i] / (1 - std::pow(b2, t));
    p[i] -= lr * mhat / (std::sqrt(vhat) + eps);
  }
}
// Worst symmetric relative error; a NaN or inf entry counts as an infinite error (keep_worst,
// test/gradcheck.h), so an optimiser step that writes NaN cannot pass as "equal".
double max_rel(const std::vector<double>& a, const std::vector<double>& b) {
  double w = 0;
  for (size_t i = 0; i < a.size(); ++i)
    hashcc::test::keep_worst(w, hashcc::test::rel_err(a[i], b[i], 1e-300));
  return w;
}
}  // namespace

TEST_CASE("adam one step equals the hand-computed scalar", "[adam][exact]") {
  // t = 1, p = 1, g = 0.5, m = v = 0, lr = 0.1:
  //   m = 0.1·0.5 = 0.05, v = 0.001·0.25 = 2.5e-4, m̂ = 0.05/0.1 = 0.5, v̂ = 2.5e-4/0.001 = 0.25,
  //   p = 1 − 0.1·0.5/(0.5 + 1e-8) = 1 − 0.05/0.50000001 = 0.9000000019999999…
  double p = 1, g = 0.5, m = 0, v = 0;
  adam_step(&p, &g, &m, &v, 1, 0.1, 1);
  CHECK(m == Approx(0.05).epsilon(1e-15));
  CHECK(v == Approx(2.5e-4).epsilon(1e-15));
  CHECK(p == Approx(0.900000002).epsilon(1e-15));
  CHECK(std::abs(p - 0.9000000019999999600) < 1e-15);

  // t = 3 from a non-zero state: p = 2, g = −1, m = 0.2, v = 0.04, lr = 0.01:
  //   m = 0.18 − 0.1 = 0.08, v = 0.03996 + 0.001 = 0.04096,
  //   m̂ = 0.08/(1 − 0.729) = 0.08/0.271, v̂ = 0.04096/(1 − 0.997002999) = 0.04096/0.002997001,
  //   p = 2 − 0.01·m̂/(sqrt(v̂) + 1e-8).
  p = 2; g = -1; m = 0.2; v = 0.04;
  adam_step(&p, &g, &m, &v, 1, 0.01, 3);
  const double mh = 0.08 / 0.271, vh = 0.04096 / 0.002997001;
  CHECK(m == Approx(0.08).epsilon(1e-14));
  CHECK(v == Approx(0.04096).epsilon(1e-14));
  CHECK(p == Approx(2 - 0.01 * mh / (std::sqrt(vh) + 1e-8)).epsilon(1e-14));
}

TEST_CASE("adam several steps match the reference implementation; threads agree bitwise",
          "[adam][exact]") {
  int keep = num_threads();
  for (size_t n : {size_t(37), size_t(100000)}) {  // 100k > 2·32k: parallel at 2 threads
    Rng rng(13);
    auto p0 = random_vec(n, rng, -1, 1);
    std::vector<std::vector<double>> grads;
    for (int s = 0; s < 12; ++s) grads.push_back(random_vec(n, rng, -2, 2));
    std::vector<double> results[2];
    for (int threads : {1, 2}) {
      set_num_threads(threads);
      std::vector<double> p = p0, m(n, 0.0), v(n, 0.0), pr = p0, mr(n, 0.0), vr(n, 0.0);
      for (int t = 1; t <= 12; ++t) {
        const double lr = exp_decay_lr(1e-2, 1e-4, t - 1, 12);
        adam_step(p.data(), grads[t - 1].data(), m.data(), v.data(), int64_t(n), lr, t);
        adam_reference(pr, grads[t - 1], mr, vr, lr, t);
      }
      const double e = std::max({max_rel(p, pr), max_rel(m, mr), max_rel(v, vr)});
      HCC_TEST_PRINTF("[adam][exact] n=%zu %d thr: 12 steps vs reference, worst rel %.1e (tol 1e-12)\n",
                  n, threads, e);
      CHECK(e < 1e-12);
      CHECK(max_rel(p, p0) > 1e-3);  // parameters really moved
      results[threads - 1] = p;
    }
    CHECK(results[0] == results[1]);
  }
  set_num_threads(keep);
}

TEST_CASE("adam float agrees with double", "[adam][float]") {
  const size_t n = 5000;
  Rng rng(17);
  auto p0 = random_vec(n, rng, -1, 1);
  std::vector<double> pd = p0, md(n, 0.0), vd(n, 0.0);
  std::vector<float> pf(p0.begin(), p0.end()), mf(n, 0.f), vf(n, 0.f);
  for (int t = 1; t <= 20; ++t) {
    auto g = random_vec(n, rng, -1, 1);
    std::vector<float> gf(g.begin(), g.end());
    std::vector<double> gd(gf.begin(), gf.end());
    adam_step(pd.data(), gd.data(), md.data(), vd.data(), int64_t(n), 1e-3, t);
    adam_step(pf.data(), gf.data(), mf.data(), vf.data(), int64_t(n), 1e-3, t);
  }
  // Compare the update (p − p0), which is what float rounding could distort.
  double worst = 0, den = 0;
  for (size_t i = 0; i < n; ++i) {
    const double ud = pd[i] - double(float(p0[i])), uf = double(pf[i]) - double(float(p0[i]));
    hashcc::test::keep_worst(worst, std::abs(ud - uf));
    den = std::max(den, std::abs(ud));
  }
  HCC_TEST_PRINTF("[adam][float] 20 steps: max |Δupdate| / max |update| = %.1e (tol 1e-4)\n",
              worst / den);
  CHECK(den > 1e-3);
  CHECK(worst / den < 1e-4);
}

TEST_CASE("adam hard cases: zero gradient, sign-like first step, huge t, empty group",
          "[adam][hard]") {
  // Zero gradient from a zero state leaves p unchanged (0 / (0 + eps) = 0), no NaN.
  double p = 0.3, g = 0, m = 0, v = 0;
  adam_step(&p, &g, &m, &v, 1, 1e-3, 1);
  CHECK(p == 0.3);
  // First step moves by lr·sign(g)·|g|/(|g| + eps) regardless of the gradient's scale.
  for (double gg : {3.0, -3.0, 1e-3, -1e6}) {
    double q = 1, mm = 0, vv = 0;
    adam_step(&q, &gg, &mm, &vv, 1, 1e-2, 1);
    CHECK(q == Approx(1 - 1e-2 * gg / (std::abs(gg) + 1e-8)).epsilon(1e-14));
  }
  // Large step counts: bias corrections → 1, finite.
  double q = 1, gg = 0.5, mm = 0.1, vv = 0.01;
  adam_step(&q, &gg, &mm, &vv, 1, 1e-3, 1000000);
  CHECK(std::isfinite(q));
  CHECK(q == Approx(1 - 1e-3 * 0.14 / (std::sqrt(0.01 * 0.999 + 0.001 * 0.25) + 1e-8)).epsilon(1e-12));
  // Empty group: nothing read or written.
  adam_step<float>(nullptr, nullptr, nullptr, nullptr, 0, 1e-3, 1);
  // t is 1-based: 0 is a caller bug reported as an Error.
  CHECK_THROWS(adam_step(&q, &gg, &mm, &vv, 1, 1e-3, 0));
}

TEST_CASE("exp_decay_lr endpoints, midpoint and the NeRF-- per-epoch factor", "[adam][exact]") {
  CHECK(exp_decay_lr(1e-3, 1e-5, 0, 1000) == 1e-3);     // exact start
  CHECK(exp_decay_lr(1e-3, 1e-5, 1000, 1000) == 1e-5);  // exact end
  CHECK(exp_decay_lr(1e-3, 1e-5, 500, 1000) == Approx(1e-4).epsilon(1e-12));  // geometric mean
  CHECK(exp_decay_lr(1e-3, 1e-8, 250, 1000) == Approx(1e-3 * std::pow(1e-5, 0.25)).epsilon(1e-12));
  CHECK(exp_decay_lr(1e-3, 1e-5, 5000, 1000) == 1e-5);  // overshoot stays at the end value
  CHECK(exp_decay_lr(1e-3, 1e-5, 7, 0) == 1e-5);
  // formulas.md §6: NeRF-- multiplies the network lr by 0.9954 every 10 of 10,000 epochs; the
  // schedule over the plan reproduces that factor to 0.001%.
  CHECK(exp_decay_lr(1e-3, 1e-5, 10, 10000) / 1e-3 == Approx(0.9954).epsilon(1e-5));
  // Monotone decreasing.
  double prev = 1;
  for (int s = 0; s <= 100; ++s) {
    double lr = exp_decay_lr(1e-3, 1e-5, s, 100);
    CHECK(lr < prev);
    prev = lr;
  }
}

// Why a short camera-less run needs a higher camera lr floor (test/test_e2e.cpp): a
// camera's gradient is non-zero only on the steps that draw its image. With one image per
// step and n training images, Adam's moments decay between visits, and a camera with a
// steady gradient moves ≈ 0.24 lr per step for n = 17 (1 lr per step when every step has a
// gradient, 0.45 with a gradient every 5th step as --images-per-step 4 gives with 17 images).
//
// Closed form (steady state, bias corrections → 1): with |g| = 1 every n-th step, the moments
// right after a gradient are periodic fixed points of m ← β1^n m + (1 − β1), v ← β2^n v + (1 − β2):
//   M = (1 − β1)/(1 − β1^n),   V = (1 − β2)/(1 − β2^n),
// j steps later m = β1^j M, v = β2^j V, and the step moves lr·β1^j M/(√(β2^j V) + ε). The travel
// per step, averaged over a period, is
//   τ(n) = (1/n) Σ_{j=0}^{n−1} β1^j M / (√(β2^j V) + ε)   (≈ (M/√V)(1 − q^n)/(n(1 − q)), q = β1/√β2).
// The test runs Adam past its transient (β2^t < 1e-8) and compares the travel over whole
// periods with τ(n); the numbers the docs quote are τ rounded.
namespace {
double adam_travel_closed_form(int n) {
  const double b1 = 0.9, b2 = 0.999, eps = 1e-8;
  const double M = (1 - b1) / (1 - std::pow(b1, n)), V = (1 - b2) / (1 - std::pow(b2, n));
  double sum = 0;
  for (int j = 0; j < n; ++j) sum += std::pow(b1, j) * M / (std::sqrt(std::pow(b2, j) * V) + eps);
  return sum / n;
}
}  // namespace

TEST_CASE("adam travel with a gradient every n-th step: simulation = closed form", "[adam][exact]") {
  auto travel_per_step = [](int n) {
    double p = 0, m = 0, v = 0;
    const int warm = 20000 - 20000 % n, periods = 50;  // β2^20000 = 2e-9: transient gone
    double p_warm = 0;
    for (int t = 1; t <= warm + periods * n; ++t) {
      const double g = (t % n == 0) ? -1.0 : 0.0;  // descent moves p upwards
      adam_step(&p, &g, &m, &v, 1, 1.0, t);
      if (t == warm) p_warm = p;
    }
    return (p - p_warm) / (periods * n);
  };
  for (int n : {1, 5, 8, 17}) {
    const double sim = travel_per_step(n), closed = adam_travel_closed_form(n);
    INFO("every " << n << "th step: simulated " << sim << ", closed form " << closed);
    // The residual bias correction (β2^t ≤ 2e-9) and rounding over 20,000 steps: 1e-7.
    CHECK(sim == Approx(closed).epsilon(1e-7));
  }
  // The values quoted in the docs (every step, --images-per-step 4 with 17 images, n = 8, 17).
  CHECK(adam_travel_closed_form(1) == Approx(1.0).epsilon(1e-7));
  CHECK(adam_travel_closed_form(5) == Approx(0.447).margin(5e-4));
  CHECK(adam_travel_closed_form(8) == Approx(0.353).margin(5e-4));
  CHECK(adam_travel_closed_form(17) == Approx(0.242).margin(5e-4));
}

TEST_CASE("adam: the step comparison fails a NaN or an inf entry (negative control)", "[adam][exact]") {
  // max_rel is the checker of the exact-step tests above: a step that wrote one NaN or +inf
  // parameter must read as an infinite error, not as the worst of the finite entries.
  Rng rng(52);
  auto g = random_vec(9, rng, -2, 2);
  std::vector<double> p = random_vec(9, rng), m(9, 0.0), v(9, 0.0);
  std::vector<double> pr = p, mr = m, vr = v;
  adam_step(p.data(), g.data(), m.data(), v.data(), 9, 1e-2, 1);
  adam_reference(pr, g, mr, vr, 1e-2, 1);
  CHECK(max_rel(p, pr) < 1e-12);  // positive control
  for (double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    INFO("one entry set to " << bad);
    std::vector<double> q = p;
    q[4] = bad;
    CHECK(max_rel(q, pr) == std::numeric_limits<double>::infinity());
    CHECK(max_rel(pr, q) == std::numeric_limits<double>::infinity());
  }
}
