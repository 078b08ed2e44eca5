// core/isa.h — the instruction set this build was compiled for, beside the one the CPU has.
//
// `-DHASHCC_ISA=native|avx2|avx512` (CMakeLists.txt) picks -march for the Release build. What
// the compiler then enabled is read from its own macros (__AVX2__, __FMA__, __AVX512F__), so the
// answer is right for any flags. core/isa_guard.cpp refuses, at start-up, to run a binary on a
// CPU that lacks the features in kIsaRequired (one line on stderr, exit status 1).
#pragma once
#include <string>

namespace hashcc {

// Feature bits of kIsaRequired (and of cpu_isa_bits()).
enum IsaBit : unsigned {
  kIsaAvx = 1u << 0,
  kIsaAvx2 = 1u << 1,
  kIsaFma = 1u << 2,
  kIsaBmi2 = 1u << 3,
  kIsaF16c = 1u << 4,
  kIsaAvx512f = 1u << 5,
  kIsaAvx512bw = 1u << 6,
  kIsaAvx512dq = 1u << 7,
  kIsaAvx512vl = 1u << 8,
};

// The SIMD path the compiled code uses: "avx512" (AVX-512F, 16 float lanes), "avx2" (AVX2 + FMA,
// 8 lanes) or "scalar" (SSE2 baseline; the FMA peak loop is then scalar). Compile-time.
struct CompiledIsa {
  const char* name;    // "avx512", "avx2" or "scalar"
  int lanes;           // float lanes of the FMA peak loop for this path: 16, 8 or 1
  const char* option;  // the HASHCC_ISA CMake option: "native", "avx2", "avx512", or "none"
};
CompiledIsa compiled_isa();

// The features the compiled code needs (a mask of IsaBit), and what this CPU has.
unsigned isa_required_bits();
unsigned cpu_isa_bits();
// "avx512f" / "avx2+fma" / "scalar": the widest FMA path this CPU can run.
std::string cpu_isa_name();
// Names of the bits in `bits`, space-separated ("avx2 fma avx512f").
std::string isa_bit_names(unsigned bits);

}  // namespace hashcc
