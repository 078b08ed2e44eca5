// core/error.h — the one error type of hashcc.
//
// Every failure that a user can cause (a bad file, a bad flag, a bad value) is thrown as
// hashcc::Error, carrying WHERE (file, and a field/line inside it), WHAT was found and WHAT
// was expected. The CLI prints it on one line and exits with status 2; nothing else is caught.
#pragma once
#include <stdexcept>
#include <string>
#include <fmt/args.h>
#include <fmt/format.h>
#include <string_view>
#include <vector>

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

namespace hashcc::detail {
// Number of {} replacement fields in a format string ({{ and }} are literal braces).
inline int count_fields(std::string_view f) {
  int n = 0;
  for (size_t i = 0; i < f.size(); ++i) {
    if (f[i] == '{') {
      if (i + 1 < f.size() && f[i + 1] == '{') { ++i; continue; }
      ++n;
    }
  }
  return n;
}
// HCC_REQUIRE's error: the format string's fields take the first arguments; ONE argument more
// than there are fields is the "expected …" hint.
template <class... A>
::hashcc::Error make_error(std::string file, std::string field, std::string_view f, A&&... a) {
  constexpr int n = int(sizeof...(A));
  const int fields = count_fields(f);
  const bool has_expected = n > 0 && n == fields + 1;
  fmt::dynamic_format_arg_store<fmt::format_context> store;
  std::string expected;
  int i = 0;
  auto take = [&](auto&& v) {
    if (has_expected && i == n - 1) expected = fmt::format("{}", v);
    else store.push_back(v);
    ++i;
  };
  (take(a), ...);
  (void)take;  // unused when the message has no arguments
  std::string problem;
  try {
    problem = fmt::vformat(f, store);
  } catch (const fmt::format_error&) {
    problem = std::string(f);
  }
  return ::hashcc::Error(std::move(file), std::move(field), std::move(problem), std::move(expected));
}
}  // namespace hashcc::detail

// HCC_REQUIRE(cond, file, field, fmt, args... [, expected]) — input validation that throws
// hashcc::Error. One argument beyond the format's {} fields is the "expected …" hint.
#define HCC_REQUIRE(cond, file, field, ...)                                           \
  do {                                                                                \
    if (!(cond)) throw ::hashcc::detail::make_error((file), (field), __VA_ARGS__);    \
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
