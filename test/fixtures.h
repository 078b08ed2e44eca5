// test/fixtures.h — shared set-ups: temp folders, the CLI in-process, a thread-count guard, a
// tiny simulated scene, a tiny and fast TrainConfig, the ReLU pattern of a step.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <source_location>
#include <fmt/core.h>
#include <string>
#include <vector>

#include "model/camera_step.h"
#include "train/trainer.h"
#include "tools/cli.h"
#include "tools/simulator.h"

namespace hashcc::test {

// A folder for one test under the process's private temp folder (test/main.cpp), named
// "hashcc_<test file>_<name>" after the calling file, so two files may use the same name.
// tmp: the path (clear: whatever is there is removed first); fresh_dir: emptied and created.
inline std::string tmp(const std::string& name, bool clear = false,
                       const std::source_location at = std::source_location::current()) {
  const std::string file = std::filesystem::path(at.file_name()).stem().string();
  const auto d = std::filesystem::temp_directory_path() / fmt::format("hashcc_{}_{}", file, name);
  if (clear) std::filesystem::remove_all(d);
  return d.string();
}
inline std::string fresh_dir(const std::string& name,
                             const std::source_location at = std::source_location::current()) {
  const std::string d = tmp(name, true, at);
  std::filesystem::create_directories(d);
  return d;
}

// The first of $HASHCC_PYTHON, python3 (PATH), /usr/bin/python3 that imports numpy; "" if none.
// For the tests that run the repository's Python tools (tools/install_deps.sh installs NumPy).
inline std::string python_with_numpy() {
  static const std::string found = [] {
    std::vector<std::string> tries;
    if (const char* e = std::getenv("HASHCC_PYTHON")) tries.push_back(e);
    tries.push_back("python3");
    tries.push_back("/usr/bin/python3");
    for (const auto& p : tries)
      if (std::system(fmt::format("'{}' -c 'import numpy' >/dev/null 2>&1", p).c_str()) == 0) return p;
    return std::string();
  }();
  return found;
}

// Runs the CLI in-process as `hashcc args…`; returns its exit status (stderr shows).
inline int cli(std::vector<std::string> args) {
  args.insert(args.begin(), "hashcc");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  return run_cli(int(argv.size()), argv.data());
}

// Sets the thread count for a scope (n > 0) and restores the previous one at its end.
struct ThreadGuard {
  int keep = num_threads();
  ThreadGuard() = default;
  explicit ThreadGuard(int n) { set_num_threads(n); }
  ~ThreadGuard() { set_num_threads(keep); }
};

// The default simulated scene at a small size, written once per test process under the
// (private) temp directory and reused: the folder name holds every setting, so two tests
// asking for different sizes never share a folder.
inline std::string sim_scene(const std::string& name, int views, int w, int h,
                             int supersample = 2) {
  const std::string d = (std::filesystem::temp_directory_path() /
                         fmt::format("hashcc_sim_{}_{}v_{}x{}_ss{}", name, views, w, h, supersample))
                            .string();
  if (std::filesystem::exists(d + "/poses_bounds.npy")) return d;
  SimOptions o;
  o.views = views;
  o.width = w;
  o.height = h;
  o.supersample = supersample;
  write_sim_scene(d, o, false);
  return d;
}

// Width 16, colour width 8, an 8×8 ray grid, 16 samples, no progress bar, no periodic
// checkpoint or preview (final ones only): a step takes milliseconds.
inline TrainConfig tiny_train_config(const std::string& data, const std::string& out,
                                     int64_t steps) {
  TrainConfig c;
  c.data = data;
  c.out = out;
  c.model.width = 16;
  c.model.rgb_width = 8;
  c.rays = 64;
  c.samples = 16;
  c.steps = steps;
  c.progress = false;
  c.checkpoint_minutes = 1e9;
  c.preview_minutes = 1e9;
  return c;
}

// The ReLU pattern of a workspace's last forward (trunk, σ, colour hidden, CC hidden). A
// finite difference whose evaluations change it straddles a kink (design.md practice 8), so
// the whole-step checks skip it. The batch must have run as one chunk on this workspace
// (StepOptions::data_parallel = false or a single chunk), so the cache holds every ray.
template <class T>
std::vector<bool> relu_pattern(const StepWorkspace<T>& ws_, const ModelConfig& cfg) {
  const ModelCache<T>& cache = ws_.chunk.cache;
  std::vector<bool> m;
  const int64_t N = int64_t(cache.R) * cache.S;
  if (cfg.field == Field::grid) {
    // The grid field's kinks: its ReLUs, the exp clamp, and every cell face of every level
    // (the trilinear interpolant is only C⁰ there): the parity of each cell coordinate.
    for (int64_t i = 0; i < N * cfg.gf.hidden; ++i) m.push_back(cache.gdh[i] > 0);
    for (int64_t i = 0; i < N * cfg.gf.rgb_hidden; ++i) m.push_back(cache.hid[i] > 0);
    for (int64_t i = 0; i < N; ++i) m.push_back(cache.gdo[i * (1 + cfg.gf.geo)] < 15);
    for (const HashGridLevel& lv : hashgrid_levels(cfg.gf.grid))
      for (int64_t i = 0; i < N * 3; ++i) {
        const double u = std::clamp(double(cache.gx[i]), 0.0, 1.0);
        m.push_back(int64_t(std::floor(lv.scale * u + 0.5)) & 1);
        m.push_back(cache.gx[i] >= 0 && cache.gx[i] <= 1);
      }
    if (cfg.has_cc())
      for (int64_t i = 0; i < N * cfg.cc_hidden; ++i) m.push_back(cache.cc_h[i] > 0);
    return m;
  }
  for (const auto& h : cache.h)
    for (int64_t i = 0; i < N * cfg.width; ++i) m.push_back(h[i] > 0);
  for (int64_t i = 0; i < N; ++i) m.push_back(cache.sigma_raw[i] > 0);
  for (int64_t i = 0; i < N * cfg.rgb_width; ++i) m.push_back(cache.hid[i] > 0);
  if (cfg.has_cc())
    for (int64_t i = 0; i < N * cfg.cc_hidden; ++i) m.push_back(cache.cc_h[i] > 0);
  return m;
}

template <class T>
std::vector<bool> relu_pattern(const CameraStepWorkspace<T>& ws, const ModelConfig& cfg) {
  return relu_pattern(ws.rays, cfg);
}

}  // namespace hashcc::test
