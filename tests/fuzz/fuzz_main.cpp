// libFuzzer entry point of one target (TS_FUZZ_TARGET, a name of tests/fuzz/targets.cpp).
// Built only by scripts/fuzz (clang, -fsanitize=fuzzer,address,undefined).
#include "fuzz/targets.hpp"

#include <cstdio>
#include <cstdlib>
#include <exception>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const ts::fuzz::Target* target = [] {
    const ts::fuzz::Target* t = ts::fuzz::find_target(TS_FUZZ_TARGET);
    if (!t) {
      std::fprintf(stderr, "no fuzz target named %s\n", TS_FUZZ_TARGET);
      std::abort();
    }
    return t;
  }();
  try {
    (void)target->run({data, size});
  } catch (const std::exception& e) {   // not a ts::Error: a finding
    std::fprintf(stderr, "finding: %s threw %s\n", TS_FUZZ_TARGET, e.what());
    std::abort();
  }
  return 0;
}
