#include "experiments/cli/cli_common.hpp"

#include "engine/core.hpp"

#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <iostream>
#include <limits>
#include <string>
#include <tuple>
#include <vector>

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

namespace {

/// Levenshtein distance: what "the nearest valid flag" means.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = up;
    }
  }
  return row[b.size()];
}

/// The long flags of a (sub)command, its option groups' included; `shown` only those its help
/// shows (a hidden alias is taken, never suggested).
void long_flags(const CLI::App* app, std::vector<std::string>& out, bool shown = false) {
  for (const CLI::Option* o : app->get_options())
    if (!shown || !o->get_group().empty())
      for (const auto& name : o->get_lnames()) out.push_back("--" + name);
  for (const CLI::App* group : app->get_subcommands([](const CLI::App* a) { return a->get_name().empty(); }))
    long_flags(group, out, shown);
}

/// A flag the command line gives that its subcommand does not know, as one usage error naming
/// the nearest valid flag; empty when every flag is known. Looked for before CLI11 parses, so
/// that a misspelt flag is named rather than the required one it misses (`--dbb` is "did you
/// mean --db?", not "--db is required"). Tokens after `--` are not flags.
std::string unknown_flag(const CLI::App& app, int argc, char** argv) {
  const CLI::App* current = &app;
  std::string path = "touchstone";
  for (int i = 1; i < argc; ++i) {
    const std::string token = argv[i];
    if (token == "--") break;
    if (token.rfind("--", 0) != 0) {
      const auto subs = current->get_subcommands(
          [&](const CLI::App* a) { return !a->get_name().empty() && a->check_name(token); });
      if (!subs.empty()) {
        current = subs.front();
        path += " " + token;
      } else if (current->get_require_subcommand_min() > 0) {
        return {};   // a misspelt subcommand: CLI11 names it, not the flags after it
      }
      continue;
    }
    if (current->get_allow_extras()) continue;
    const std::string flag = token.substr(0, token.find('='));
    std::vector<std::string> flags;
    long_flags(current, flags);
    if (std::find(flags.begin(), flags.end(), flag) != flags.end()) continue;
    std::string nearest;
    std::size_t best = std::numeric_limits<std::size_t>::max();
    flags.clear();
    long_flags(current, flags, true);
    for (const auto& f : flags) {
      // A flag cut short (`--thr`, `--run`) is as near as one letter off.
      const std::size_t d = f.rfind(flag, 0) == 0 ? 1 : edit_distance(flag, f);
      if (d < best) best = d, nearest = f;
    }
    const std::size_t near_enough = std::max<std::size_t>(2, flag.size() / 3);
    std::string message = "touchstone: error: unknown flag " + flag + " for `" + path + "`";
    if (!nearest.empty() && best <= near_enough) message += " (did you mean " + nearest + "?)";
    return message + "; `" + path + " --help` lists its flags";
  }
  return {};
}

}  // namespace

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
  if (const std::string unknown = unknown_flag(app, argc, argv); !unknown.empty()) {
    std::cerr << unknown << '\n';
    return 2;
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
