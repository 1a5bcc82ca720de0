// One libFuzzer executable per target: ARREG_FUZZ_TARGET names it (CMake sets
// it per executable). Built only with -DARREG_FUZZ=ON and clang (scripts/fuzz).
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "core/log.h"
#include "fuzz/fuzz_entries.h"

// With ARREG_FUZZ_SEEDS=DIR set, the executable writes its target's seed corpus
// into DIR and exits (scripts/fuzz does this before fuzzing).
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  arreg::SetLogLevel(
      arreg::LogLevel::kSilent);  // readers' warnings would flood the fuzzer's output
  if (const char* dir = std::getenv("ARREG_FUZZ_SEEDS")) {
    const int n = arreg::fuzz::WriteSeeds(arreg::fuzz::FindTarget(ARREG_FUZZ_TARGET), dir);
    std::printf("%d seed file(s) written to %s\n", n, dir);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const arreg::fuzz::Target& target = arreg::fuzz::FindTarget(ARREG_FUZZ_TARGET);
  arreg::fuzz::RunOne(target, data, size);
  return 0;
}
