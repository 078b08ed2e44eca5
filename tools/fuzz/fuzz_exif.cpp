// libFuzzer target 'exif' (see tools/fuzz/targets.h and tools/fuzz.sh).
#include "tools/fuzz/targets.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  hashcc::fuzz::exif(std::string(reinterpret_cast<const char*>(data), size));
  return 0;
}
