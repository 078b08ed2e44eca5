// core/profile.h — an optional per-stage profiler for the training step (`hashcc bench`).
//
// A StageTimes* travels with the step (ModelCache::prof, Trainer::set_stage_times). When it is
// null, StageClock does nothing but test the pointer: no clock reads, no cost worth measuring.
// When set, each stage accumulates both steady_clock (wall) time and the calling thread's CPU
// time (CLOCK_THREAD_CPUTIME_ID): on a loaded machine wall time includes the time the thread
// sat descheduled, CPU time does not, so the pair tells a loaded measurement from a slow one.
// In the data-parallel step each thread has its own StageTimes; the step adds their MEAN
// (a wall-equivalent: what one thread spent, as the threads run side by side).
#pragma once
#include <chrono>
#include <ctime>

namespace hashcc {

enum Stage : int {
  kStageRays,        // pixel grid, camera rays + NDC (fwd/bwd), jitter, sampler, normalize
  kStageEncode,      // Fourier γ(x), SH / Fourier of the view direction (fwd/bwd)
  kStageMlpFwd,      // main network forward: trunk, density, feature, colour head
  kStageMlpBwd,      // main network backward (weight and input gradients)
  kStageCC,          // CC branch: hash grid + MLP forward and backward, c + Δc
  kStageCompositor,  // σ = relu, compositor forward/backward, the loss
  kStageAdam,        // the three Adam updates
  kStageCount
};

inline const char* stage_name(int s) {
  static const char* names[kStageCount] = {"rays+ndc", "encodings", "mlp_fwd", "mlp_bwd",
                                           "cc", "compositor", "adam"};
  return names[s];
}

inline double thread_cpu_ms() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

struct StageTimes {
  double wall_ms[kStageCount] = {};
  double cpu_ms[kStageCount] = {};
  void clear() { *this = StageTimes{}; }
  // this += w · o
  void add_scaled(const StageTimes& o, double w) {
    for (int s = 0; s < kStageCount; ++s) {
      wall_ms[s] += w * o.wall_ms[s];
      cpu_ms[s] += w * o.cpu_ms[s];
    }
  }
};

// Times consecutive stages of one thread: StageClock c(prof, kStageEncode); …; c.to(kStageMlpFwd);
// …; the time up to to() / destruction goes to the current stage. No-op when prof is null.
class StageClock {
 public:
  StageClock(StageTimes* prof, int stage) : p_(prof), s_(stage) {
    if (p_) start();
  }
  ~StageClock() { stop(); }
  void to(int stage) {
    if (!p_) return;
    stop();
    s_ = stage;
    start();
  }
  void stop() {
    if (!p_ || s_ < 0) return;
    p_->wall_ms[s_] +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - w0_).count();
    p_->cpu_ms[s_] += thread_cpu_ms() - c0_;
    s_ = -1;
  }
  StageClock(const StageClock&) = delete;
  StageClock& operator=(const StageClock&) = delete;

 private:
  void start() {
    w0_ = std::chrono::steady_clock::now();
    c0_ = thread_cpu_ms();
  }
  StageTimes* p_;
  int s_;
  std::chrono::steady_clock::time_point w0_{};
  double c0_ = 0;
};

}  // namespace hashcc
