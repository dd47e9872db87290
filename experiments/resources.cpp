#include "experiments/resources.hpp"

#include "engine/core.hpp"
#include "engine/database/database.hpp"
#include "experiments/allocator.hpp"

#include <tbb/info.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>

namespace ts::experiments {

void set_memory_budget(Database& db, const std::optional<double>& mb, const std::string& file,
                       const std::string& option) {
  const auto budget = static_cast<std::size_t>(std::llround(mb.value_or(kDefaultMemoryBudgetMb) * 1e6));
  if (mb && budget > 0 && db.size() > 0) {
    std::size_t largest = 0;
    for (std::size_t i = 1; i < db.size(); ++i)
      if (db.info(i).fine_points > db.info(largest).fine_points) largest = i;
    const std::size_t need = memory_bytes(*db.geometry(largest));
    if (budget < need) {
      char text[256];
      std::snprintf(text, sizeof text,
                    "a memory budget of %.1f MB cannot hold one object: '%s' needs %.1f MB",
                    double(budget) / 1e6, db.info(largest).name.c_str(), double(need) / 1e6);
      throw Error(text, file, option);
    }
  }
  db.set_memory_budget(budget);
}

double physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page > 0 ? static_cast<double>(pages) * static_cast<double>(page) : 0.0;
}

std::string machine_description() {
  std::string model = "unknown CPU";
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) {
      auto pos = line.find(':');
      if (pos != std::string::npos) model = line.substr(pos + 2);
      break;
    }
  }
  return model + ", " + std::to_string(tbb::info::default_concurrency()) + " cores, " + allocator_name();
}

}  // namespace ts::experiments
