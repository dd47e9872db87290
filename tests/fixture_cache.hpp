// A cache for what a test fixture builds, shared by the processes of one test binary: each ctest
// test is a process of its own, and building the engine tests' six objects (scans, features,
// distance fields) took about 1 s of each test in release and 10-20 s under AddressSanitizer.
#pragma once

#include <filesystem>
#include <string>
#include <system_error>

namespace ts::test {

/// The file under build/test-cache/ that holds `what` for this test binary. The key is the
/// binary's size and modification time, so a rebuilt binary (engine code changed) never reads
/// what an older one wrote; files older binaries left are removed. Empty: no cache (no
/// /proc/self/exe, or no folder to write).
inline std::filesystem::path fixture_cache(const std::string& what, const std::string& extension = ".h5") {
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) return {};
  const auto size = std::filesystem::file_size(exe, ec);
  if (ec) return {};
  const auto mtime = std::filesystem::last_write_time(exe, ec).time_since_epoch().count();
  if (ec) return {};
  const auto dir = std::filesystem::path(TS_BINARY_DIR) / "test-cache";
  std::filesystem::create_directories(dir, ec);
  if (ec) return {};
  const std::string binary = exe.filename().string() + "-";
  const std::string key = binary + std::to_string(size) + "-" + std::to_string(static_cast<unsigned long long>(mtime)) + "-";
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {  // what older binaries left
    const std::string file = e.path().filename().string();
    if (file.starts_with(binary) && !file.starts_with(key)) std::filesystem::remove(e.path(), ec);
  }
  return dir / (key + what + extension);
}

}  // namespace ts::test
