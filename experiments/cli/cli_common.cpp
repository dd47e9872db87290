#include "experiments/cli/cli_common.hpp"

#include "engine/core.hpp"

#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <iostream>
#include <string>
#include <tuple>

namespace ts::cli {

namespace {
int g_exit_code = 0;
}

void add_common(CLI::App* sub, CommonOptions& o, unsigned offered) {
  auto* threads = sub->add_option("--threads", o.threads, "Worker threads (default: all cores)")
                      ->check(CLI::Range(0, 4096));
  auto* seed = sub->add_option("--seed", o.seed, "Seed of every random draw (default 1)");
  // Not offered: hidden from the help and the reference, taken with a note (nothing changes).
  const std::string command = "touchstone " + (sub->get_parent() && !sub->get_parent()->get_name().empty() &&
                                                       sub->get_parent()->get_parent()
                                                   ? sub->get_parent()->get_name() + " "
                                                   : std::string()) +
                              sub->get_name();
  for (auto [opt, flag, name] : {std::tuple{threads, kThreads, "--threads"}, std::tuple{seed, kSeed, "--seed"}}) {
    if (offered & flag) continue;
    opt->group("");
    opt->each([name = std::string(name), command](const std::string&) {
      std::cerr << "touchstone: note: " << name << " changes nothing in `" << command << "` (ignored)\n";
    });
  }
  if (offered & kJson) sub->add_flag("--json", o.json, "Print exactly one JSON object on stdout");
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

int run_touchstone(int argc, char** argv, const char* version) {
  g_exit_code = 0;
  CLI::App app{"touchstone: tactile object recognition and 6-DOF localization"};
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "Help for every subcommand");
  app.set_version_flag("--version", std::string("touchstone ") + version);
  register_db(app);
  register_tactile(app);
  register_recognize(app);
  register_experiment(app);
  register_catalogue(app);
  register_stress(app);
  register_params(app);
  if (argc == 2 && std::string(argv[1]) == "--help-reference") {   // not in --help: a tool's input
    print_reference(app);
    return 0;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);  // prints help or "error message + usage hint"
    return rc == 0 ? 0 : 2;      // usage errors exit 2
  }
  return exit_code();
}

bool stderr_is_terminal() { return isatty(STDERR_FILENO) == 1; }

}  // namespace ts::cli
