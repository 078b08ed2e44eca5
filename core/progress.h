// core/progress.h — a progress bar (rate, ETA, a status text such as the current loss) that
// redraws in place on a terminal and degrades to one plain line every few seconds otherwise
// (logs, CI). Also a monotonic timer.
#pragma once
#include <chrono>
#include <cstdint>
#include <string>

namespace hashcc {

struct Timer {
  std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  void reset() { t0 = std::chrono::steady_clock::now(); }
};

class ProgressBar {
 public:
  // total ≤ 0: unknown length (no ETA). enabled = false prints nothing.
  ProgressBar(std::string label, int64_t total, bool enabled = true);
  ~ProgressBar();
  void set_total(int64_t total) { total_ = total; }
  // Shows `done` of total plus a free status text; rate-limited (cheap to call every step).
  void update(int64_t done, const std::string& status = "");
  void finish(const std::string& status = "");

 private:
  void draw(bool final);
  std::string label_, status_;
  int64_t total_, done_ = 0;
  bool enabled_, tty_, finished_ = false;
  Timer timer_;
  double last_draw_ = -1e9;
};

}  // namespace hashcc
