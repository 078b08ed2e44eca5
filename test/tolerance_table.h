// test/tolerance_table.h — the generated tolerance table (issue 52).
#pragma once
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace hashcc::test {

// The generated tolerance table (issue 52): with HASHCC_TOLERANCE_TABLE=PATH set, every
// record_tolerance call adds a row "check | subject | measured worst | tolerance" and rewrites
// PATH as a Markdown table whose header names the CPU (/proc/cpuinfo), the ISA this binary was
// compiled for and the compiler, so the figures the docs quote are the ones a run produced
// (docs/golden-tolerances.md, linked from docs/golden-step.md; the command is in its header).
// record_tolerance_note adds a line under the header (e.g. the NumPy version). Unset: nothing.
inline std::string compiled_isa() {
  std::string s;
#if defined(__AVX512F__)
  s += "AVX-512F ";
#endif
#if defined(__AVX2__)
  s += "AVX2 ";
#endif
#if defined(__FMA__)
  s += "FMA ";
#endif
#if defined(__aarch64__)
  s += "AArch64 NEON ";
#endif
  if (s.empty()) s = "baseline (no AVX2/FMA) ";
  s.pop_back();
  return s;
}
// "model name (family F model M; runtime avx512f avx2 fma)" from /proc/cpuinfo: the model name
// alone can be as vague as "AMD EPYC" on a VM (family 25 model 17 is Zen 4).
inline std::string cpu_model() {
  std::FILE* f = std::fopen("/proc/cpuinfo", "r");
  if (!f) return "unknown CPU";
  char line[8192];
  std::string name = "unknown CPU", family, model, flags;
  auto value = [](const std::string& l) {
    std::string v = l.substr(l.find(':') + 1);
    while (!v.empty() && (v.front() == ' ' || v.front() == '\t')) v.erase(v.begin());
    while (!v.empty() && (v.back() == '\n' || v.back() == ' ')) v.pop_back();
    return v;
  };
  while (std::fgets(line, sizeof line, f)) {
    const std::string l = line;
    if (l.find(':') == std::string::npos) continue;
    if (l.rfind("model name", 0) == 0 && name == "unknown CPU") name = value(l);
    else if (l.rfind("cpu family", 0) == 0 && family.empty()) family = value(l);
    else if (l.rfind("model\t", 0) == 0 && model.empty()) model = value(l);
    else if (l.rfind("flags", 0) == 0 && flags.empty()) {
      const std::string v = " " + value(l) + " ";
      for (const char* fl : {"avx512f", "avx2", "fma"})
        if (v.find(std::string(" ") + fl + " ") != std::string::npos) flags += std::string(flags.empty() ? "" : " ") + fl;
    }
  }
  std::fclose(f);
  return name + " (family " + family + " model " + model + "; runtime " + (flags.empty() ? "none of avx512f/avx2/fma" : flags) + ")";
}
struct ToleranceTable {
  std::vector<std::string> notes, rows;
  static ToleranceTable& get() {
    static ToleranceTable t;
    return t;
  }
  void write() const {
    const char* path = std::getenv("HASHCC_TOLERANCE_TABLE");
    if (!path || !*path) return;
    std::FILE* f = std::fopen(path, "w");
    if (!f) return;
    std::fprintf(f,
                 "# Measured worst errors against their tolerances (generated)\n\n"
                 "Written by the test binary, not by hand:\n\n"
                 "    HASHCC_TOLERANCE_TABLE=docs/golden-tolerances.md OMP_NUM_THREADS=2 \\\n"
                 "      build/hashcc_tests \"[golden][grad],[golden][reference],[model][grad][c2f]\" --order decl\n\n"
                 "CPU: %s. Compiled for: %s (compiler %s, %s build). Each tolerance's reason is the\n"
                 "comment above it in the test named in the first column.\n\n",
                 cpu_model().c_str(), compiled_isa().c_str(), __VERSION__,
#ifdef NDEBUG
                 "optimised"
#else
                 "debug"
#endif
    );
    for (const auto& n : notes) std::fprintf(f, "%s\n", n.c_str());
    if (!notes.empty()) std::fprintf(f, "\n");
    std::fprintf(f, "| check | subject | measured worst | tolerance |\n|---|---|---|---|\n");
    for (const auto& r : rows) std::fprintf(f, "%s\n", r.c_str());
    std::fclose(f);
  }
};
inline void record_tolerance(const std::string& check, const std::string& subject, double measured,
                             double tol) {
  if (!std::getenv("HASHCC_TOLERANCE_TABLE")) return;
  char m[64], t[64];
  std::snprintf(m, sizeof m, "%.2e", measured);
  std::snprintf(t, sizeof t, "%.0e", tol);
  ToleranceTable::get().rows.push_back("| " + check + " | " + subject + " | " + m + " | " + t + " |");
  ToleranceTable::get().write();
}
inline void record_tolerance_note(const std::string& note) {
  if (!std::getenv("HASHCC_TOLERANCE_TABLE")) return;
  auto& n = ToleranceTable::get().notes;
  if (std::find(n.begin(), n.end(), note) == n.end()) n.push_back(note);
  ToleranceTable::get().write();
}

}  // namespace hashcc::test
