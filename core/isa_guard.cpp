// core/isa_guard.cpp — refuse to start on a CPU without the ISA the binary was compiled for.
//
// A Release build with -DHASHCC_ISA=avx512 (or native, on an AVX-512 machine) started on an
// AVX2 laptop would otherwise die with SIGILL at some arbitrary instruction. This file is built
// for baseline x86-64 (CMakeLists.txt sets -march=x86-64 on it, whatever HASHCC_ISA says) and
// linked into every executable; its check runs as a priority-101 constructor, before any C++
// static initialiser of the (ISA-compiled) library, and before main. It reads only a constant
// (hashcc_isa_required, core/isa.cpp) and libgcc's CPU model, so it executes no ISA-specific
// instruction. hashcc::cpu_isa_bits() (core/isa.cpp, compiled with the build's -march) reads
// the CPU through hashcc_baseline_cpu_bits() below, so the feature list is written once.
#include <cstdio>
#include <unistd.h>

#include "core/isa.h"

extern "C" const unsigned hashcc_isa_required;

extern "C" unsigned hashcc_baseline_cpu_bits() {
  using namespace hashcc;
  __builtin_cpu_init();
  unsigned b = 0;
  if (__builtin_cpu_supports("avx")) b |= kIsaAvx;
  if (__builtin_cpu_supports("avx2")) b |= kIsaAvx2;
  if (__builtin_cpu_supports("fma")) b |= kIsaFma;
  if (__builtin_cpu_supports("bmi2")) b |= kIsaBmi2;
  if (__builtin_cpu_supports("f16c")) b |= kIsaF16c;
  if (__builtin_cpu_supports("avx512f")) b |= kIsaAvx512f;
  if (__builtin_cpu_supports("avx512bw")) b |= kIsaAvx512bw;
  if (__builtin_cpu_supports("avx512dq")) b |= kIsaAvx512dq;
  if (__builtin_cpu_supports("avx512vl")) b |= kIsaAvx512vl;
  return b;
}

namespace {

__attribute__((constructor(101))) void hashcc_isa_guard() {
  const unsigned missing = hashcc_isa_required & ~hashcc_baseline_cpu_bits();
  if (!missing) return;
  static const char* names[] = {"avx", "avx2", "fma", "bmi2", "f16c",
                                "avx512f", "avx512bw", "avx512dq", "avx512vl"};
  char list[128] = "";
  int len = 0;
  for (unsigned i = 0; i < sizeof(names) / sizeof(names[0]); ++i)
    if ((missing & (1u << i)) && len < int(sizeof(list)) - 16)
      len += std::snprintf(list + len, sizeof(list) - len, "%s%s", len ? " " : "", names[i]);
  std::fprintf(stderr, "hashcc: this binary was compiled for an instruction set this CPU lacks "
               "(missing: %s); rebuild with -DHASHCC_ISA=avx2 or -DHASHCC_ISA=native\n", list);
  _exit(1);
}

}  // namespace
