#include "core/progress.h"

#include <cstdio>
#include <fmt/core.h>
#include <unistd.h>

namespace hashcc {

namespace {
std::string fmt_time(double s) {
  if (!(s >= 0) || s > 1e7) return "--:--";
  int t = int(s + 0.5);
  if (t >= 3600) return fmt::format("{}:{:02d}:{:02d}", t / 3600, t / 60 % 60, t % 60);
  return fmt::format("{:02d}:{:02d}", t / 60, t % 60);
}
}  // namespace

ProgressBar::ProgressBar(std::string label, int64_t total, bool enabled)
    : label_(std::move(label)), total_(total), enabled_(enabled), tty_(isatty(fileno(stderr))) {}

ProgressBar::~ProgressBar() {
  if (!finished_ && enabled_ && done_ > 0) finish();
}

void ProgressBar::update(int64_t done, const std::string& status) {
  done_ = done;
  status_ = status;
  if (!enabled_) return;
  double now = timer_.seconds();
  double every = tty_ ? 0.1 : 5.0;
  if (now - last_draw_ < every) return;
  last_draw_ = now;
  draw(false);
}

void ProgressBar::finish(const std::string& status) {
  if (!status.empty()) status_ = status;
  if (enabled_ && !finished_) draw(true);
  finished_ = true;
}

void ProgressBar::draw(bool final) {
  double el = timer_.seconds();
  double rate = el > 0 ? done_ / el : 0;
  std::string line;
  if (total_ > 0) {
    double frac = std::min(1.0, double(done_) / total_);
    int width = 24, fill = int(frac * width);
    std::string bar = std::string(fill, '#') + std::string(width - fill, '.');
    double eta = rate > 0 ? (total_ - done_) / rate : -1;
    line = fmt::format("{} [{}] {}/{} {:5.1f}% {:.2f}/s {} elapsed, ETA {}", label_, bar, done_,
                       total_, 100 * frac, rate, fmt_time(el), final ? "00:00" : fmt_time(eta));
  } else {
    line = fmt::format("{} {} done {:.2f}/s {} elapsed", label_, done_, rate, fmt_time(el));
  }
  if (!status_.empty()) line += "  " + status_;
  if (tty_) fmt::print(stderr, "\r\033[K{}{}", line, final ? "\n" : "");
  else fmt::print(stderr, "{}\n", line);
  std::fflush(stderr);
}

}  // namespace hashcc
