// Fuzz targets: every reader of outside data, fed arbitrary bytes. Each target writes the bytes
// where its reader expects a file (a temporary path of this process) and reads it. A reader may
// accept the input or refuse it with ts::Error; anything else is a finding: a crash, a sanitizer report,
// an exception of another type (it propagates out of Target::run), an allocation beyond the
// fuzzer's limit.
//
// The same functions serve the libFuzzer executables (tests/fuzz/fuzz_main.cpp, built by
// scripts/fuzz) and the regular test suite, which replays every seed and every past finding
// (tests/fuzz/corpus/<target>/) through them.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace ts::fuzz {

struct Target {
  std::string name;          ///< "pcd", "ply", ...; also the corpus folder's name
  std::string reads;         ///< what it reads, for scripts/fuzz --list
  /// Read the bytes: true when the reader accepted them, false when it refused them with
  /// ts::Error. Any other exception propagates (a finding).
  bool (*run)(std::span<const std::uint8_t> bytes);
};

/// Every target, in a fixed order.
const std::vector<Target>& targets();
/// The target of this name, or nullptr.
const Target* find_target(const std::string& name);

}  // namespace ts::fuzz
