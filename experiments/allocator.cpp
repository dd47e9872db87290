#include "experiments/allocator.hpp"

#include <malloc.h>
#include <tbb/scalable_allocator.h>

#include <sys/mman.h>
#include <unistd.h>

#include <chrono>
#include <fstream>

namespace ts::experiments {

std::string allocator_name() {
  // libtbbmalloc_proxy, when the program was linked with it, replaces malloc from the start; it
  // shows in the process's mappings.
  static const std::string name = [] {
    std::ifstream maps("/proc/self/maps");
    for (std::string line; std::getline(maps, line);)
      if (line.find("libtbbmalloc_proxy") != std::string::npos) return std::string("tbbmalloc");
    return std::string("glibc malloc");
  }();
  return name;
}

void release_free_memory() {
  if (allocator_name() == "tbbmalloc")
    scalable_allocation_command(TBBMALLOC_CLEAN_ALL_BUFFERS, nullptr);
  else
    malloc_trim(0);
}

double first_touch_ms_per_mb(std::size_t mb) {
  if (mb == 0) return 0.0;
  const std::size_t bytes = mb << 20;
  const auto page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  const auto start = std::chrono::steady_clock::now();
  void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) return -1.0;
  auto* bytes_p = static_cast<volatile unsigned char*>(p);
  for (std::size_t o = 0; o < bytes; o += page) bytes_p[o] = 1;
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  munmap(p, bytes);
  return 1e3 * s / static_cast<double>(mb);
}

}  // namespace ts::experiments
