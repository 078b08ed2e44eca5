// core/error.h — the one error type of hashcc.
//
// Every failure that a user can cause (a bad file, a bad flag, a bad value) is thrown as
// hashcc::Error, carrying WHERE (file, and a field/line inside it), WHAT was found and WHAT
// was expected. The CLI prints it on one line and exits with status 2; nothing else is caught.
#pragma once
#include <stdexcept>
#include <string>
#include <fmt/format.h>

namespace hashcc {

struct Error : std::runtime_error {
  std::string file;      // the file or flag at fault ("" when none applies)
  std::string field;     // a field, line or key inside it ("" when none applies)
  std::string problem;   // what was found / what is wrong
  std::string expected;  // what was expected ("" when obvious)

  Error(std::string file_, std::string field_, std::string problem_, std::string expected_ = {})
      : std::runtime_error(format(file_, field_, problem_, expected_)),
        file(std::move(file_)), field(std::move(field_)),
        problem(std::move(problem_)), expected(std::move(expected_)) {}

  static std::string format(const std::string& file, const std::string& field,
                            const std::string& problem, const std::string& expected) {
    std::string s;
    if (!file.empty()) s += file;
    if (!field.empty()) s += (s.empty() ? "" : ": ") + field;
    s += (s.empty() ? "" : ": ") + problem;
    if (!expected.empty()) s += " (expected " + expected + ")";
    return s;
  }
};

}  // namespace hashcc

// HCC_REQUIRE(cond, file, field, fmt, args...) — input validation that throws hashcc::Error.
#define HCC_REQUIRE(cond, file, field, ...)                                  \
  do {                                                                       \
    if (!(cond)) throw ::hashcc::Error((file), (field), fmt::format(__VA_ARGS__)); \
  } while (0)

// HCC_ASSERT(cond) — internal invariants (a bug, not bad input): abort with location.
#define HCC_ASSERT(cond)                                                             \
  do {                                                                               \
    if (!(cond)) {                                                                   \
      fmt::print(stderr, "hashcc: internal error: {} at {}:{}\n", #cond, __FILE__, __LINE__); \
      std::abort();                                                                  \
    }                                                                                \
  } while (0)

// HCC_DEBUG_FINITE(ptr, n, "kernel") — in the Debug/sanitizer build (HASHCC_CHECK_FINITE, set by
// -DHASHCC_SANITIZE=ON) aborts with the kernel's name when any of the n outputs at ptr is NaN or
// ±Inf; compiles to nothing otherwise. Called after every kernel in model/model.cpp and
// model/step.cpp. Tests that feed non-finite values on purpose (the divergence guard) turn it
// off for their scope with hashcc::FiniteChecksOff.
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
namespace hashcc {
inline std::atomic<int>& finite_checks_off_depth() {
  static std::atomic<int> depth{0};
  return depth;
}
struct FiniteChecksOff {
  FiniteChecksOff() { ++finite_checks_off_depth(); }
  ~FiniteChecksOff() { --finite_checks_off_depth(); }
  FiniteChecksOff(const FiniteChecksOff&) = delete;
  FiniteChecksOff& operator=(const FiniteChecksOff&) = delete;
};
template <class T>
void debug_check_finite(const T* p, int64_t n, const char* kernel, const char* file, int line) {
  if (!p || finite_checks_off_depth().load(std::memory_order_relaxed) > 0) return;
  for (int64_t i = 0; i < n; ++i)
    if (!std::isfinite(p[i])) {
      fmt::print(stderr, "hashcc: internal error: non-finite output {} at element {} of {} after "
                         "{} ({}:{})\n", double(p[i]), i, n, kernel, file, line);
      std::abort();
    }
}
}  // namespace hashcc
#ifdef HASHCC_CHECK_FINITE
#define HCC_DEBUG_FINITE(ptr, n, kernel) \
  ::hashcc::debug_check_finite((ptr), int64_t(n), (kernel), __FILE__, __LINE__)
#else
#define HCC_DEBUG_FINITE(ptr, n, kernel) ((void)0)
#endif
