// core/isa.cpp — see isa.h. Compiled with the build's -march like the rest of the library, so
// the macros below describe the code every kernel was compiled to.
#include "core/isa.h"

#ifndef HASHCC_ISA_OPTION
#define HASHCC_ISA_OPTION "none"
#endif

// What the compiled code may execute, as a constant (no code runs to produce it): the start-up
// guard (core/isa_guard.cpp, built for baseline x86-64) reads it before any of this library's
// code runs. extern "C" so the guard needs no C++ declaration.
extern "C" const unsigned hashcc_isa_required = 0u
#ifdef __AVX__
    | hashcc::kIsaAvx
#endif
#ifdef __AVX2__
    | hashcc::kIsaAvx2
#endif
#ifdef __FMA__
    | hashcc::kIsaFma
#endif
#ifdef __BMI2__
    | hashcc::kIsaBmi2
#endif
#ifdef __F16C__
    | hashcc::kIsaF16c
#endif
#ifdef __AVX512F__
    | hashcc::kIsaAvx512f
#endif
#ifdef __AVX512BW__
    | hashcc::kIsaAvx512bw
#endif
#ifdef __AVX512DQ__
    | hashcc::kIsaAvx512dq
#endif
#ifdef __AVX512VL__
    | hashcc::kIsaAvx512vl
#endif
    ;

namespace hashcc {

CompiledIsa compiled_isa() {
#if defined(__AVX512F__)
  return {"avx512", 16, HASHCC_ISA_OPTION};
#elif defined(__AVX2__) && defined(__FMA__)
  return {"avx2", 8, HASHCC_ISA_OPTION};
#else
  return {"scalar", 1, HASHCC_ISA_OPTION};
#endif
}

unsigned isa_required_bits() { return hashcc_isa_required; }

// The CPU's features, read by core/isa_guard.cpp's baseline-compiled function (linked into every
// executable), so the list of features is written once.
extern "C" unsigned hashcc_baseline_cpu_bits();
unsigned cpu_isa_bits() { return hashcc_baseline_cpu_bits(); }

std::string cpu_isa_name() {
  const unsigned b = cpu_isa_bits();
  if (b & kIsaAvx512f) return "avx512f";
  if ((b & kIsaAvx2) && (b & kIsaFma)) return "avx2+fma";
  return "scalar";
}

std::string isa_bit_names(unsigned bits) {
  static const char* names[] = {"avx", "avx2", "fma", "bmi2", "f16c",
                                "avx512f", "avx512bw", "avx512dq", "avx512vl"};
  std::string s;
  for (unsigned i = 0; i < sizeof(names) / sizeof(names[0]); ++i)
    if (bits & (1u << i)) s += (s.empty() ? "" : " ") + std::string(names[i]);
  return s;
}

}  // namespace hashcc
