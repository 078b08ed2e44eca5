// hashcc — the one binary. Subcommands live in tools/cli.cpp so tests can call them in-process.
#include <cstdlib>
#include <cstring>
#include <unistd.h>

#include "tools/cli.h"

int main(int argc, char** argv) {
  // OpenMP threads that finish early spin at the barrier by default. On a laptop where anything
  // else is running, a spinning thread waits for a descheduled one and a step gets ~3× slower
  // (measured: 2 threads 35 s vs 13 s passive, same work, on a loaded 2-core machine). The
  // runtime reads OMP_WAIT_POLICY once at start-up, so set it (unless the user did) and
  // re-execute once. One parallel region per training step keeps the wake-up cost negligible.
  if (!std::getenv("OMP_WAIT_POLICY") && !std::getenv("HASHCC_NO_REEXEC")) {
    setenv("OMP_WAIT_POLICY", "passive", 1);
    setenv("HASHCC_NO_REEXEC", "1", 1);
    execv("/proc/self/exe", argv);  // returns only on failure: then just run as we are
  }
  return hashcc::run_cli(argc, argv);
}
