#include "experiments/allocator.hpp"

#include <malloc.h>
#include <tbb/scalable_allocator.h>

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

}  // namespace ts::experiments
