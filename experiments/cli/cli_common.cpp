#include "experiments/cli/cli_common.hpp"

#include "engine/core.hpp"

#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <unistd.h>

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

bool stderr_is_terminal() { return isatty(STDERR_FILENO) == 1; }

}  // namespace ts::cli
