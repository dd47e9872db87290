#include "experiments/cli/cli_common.hpp"

#include "experiments/allocator.hpp"

#include "engine/database/database.hpp"

#include "engine/core.hpp"

#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>

namespace ts::cli {

namespace {
int g_exit_code = 0;
}

void add_common(CLI::App* sub, CommonOptions& o, bool with_json) {
  sub->add_option("--threads", o.threads, "Worker threads (default: all cores)")
      ->check(CLI::Range(0, 4096));
  sub->add_option("--seed", o.seed, "Seed of every random draw (default 1)");
  if (with_json) sub->add_flag("--json", o.json, "Print exactly one JSON object on stdout");
}

int thread_count(const CommonOptions& o) {
  return o.threads > 0 ? o.threads : tbb::info::default_concurrency();
}

void run_command(const CommonOptions& o, const std::function<int()>& body) {
  try {
    tbb::task_arena arena(thread_count(o));
    g_exit_code = arena.execute([&] { return body(); });
  } catch (const ts::Error& e) {
    std::cerr << "touchstone: error: " << e.what() << '\n';
    g_exit_code = 1;
  } catch (const std::exception& e) {
    std::cerr << "touchstone: error: " << e.what() << '\n';
    g_exit_code = 1;
  }
}

int exit_code() { return g_exit_code; }

std::size_t memory_budget_bytes(const std::optional<double>& mb) {
  return static_cast<std::size_t>(std::llround(mb.value_or(kDefaultMemoryBudgetMb) * 1e6));
}

void set_memory_budget(Database& db, const std::optional<double>& mb, const std::string& file,
                       const std::string& option) {
  const std::size_t budget = memory_budget_bytes(mb);
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
  return model + ", " + std::to_string(tbb::info::default_concurrency()) + " cores, " +
         experiments::allocator_name();
}

bool stderr_is_terminal() { return isatty(STDERR_FILENO) == 1; }

}  // namespace ts::cli
