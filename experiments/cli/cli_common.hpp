// What every `touchstone` subcommand shares: --threads, --seed, --json, the error format and
// the caller-owned task arena. See docs/command-line.md and the interface contract.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <functional>
#include <string>

namespace ts::cli {

struct CommonOptions {
  int threads = 0;            ///< 0: all cores
  std::uint64_t seed = 1;     ///< every random draw derives from it
  bool json = false;          ///< exactly one JSON object on stdout
};

/// The shared flags a subcommand offers: only those that mean something to it (a command without
/// random draws takes no --seed; one without parallel work no --threads).
enum CommonFlag : unsigned { kThreads = 1u, kSeed = 2u, kJson = 4u, kAllCommon = 7u };

/// Add the offered shared flags to a subcommand. --threads and --seed where not offered are still
/// taken, hidden, with a note that they change nothing (older scripts pass them).
void add_common(CLI::App* sub, CommonOptions& options, unsigned offered = kAllCommon);

/// Run a command body inside a task arena of options.threads threads. A ts::Error or any other
/// exception becomes one line "touchstone: error: ..." on stderr and exit code 1.
/// The exit code is remembered for main (see exit_code()).
void run_command(const CommonOptions& options, const std::function<int()>& body);
int exit_code();

/// Resolved thread count (options.threads or all cores).
int thread_count(const CommonOptions& options);
bool stderr_is_terminal();

// One register function per command group; each lives in its own cmd_*.cpp.
void register_db(CLI::App& app);          // db build|add|info|export
void register_tactile(CLI::App& app);     // simulate, log info|export
void register_recognize(CLI::App& app);   // recognize
void register_experiment(CLI::App& app);  // experiment, report, merge, calibrate
void register_catalogue(CLI::App& app);   // catalogue
void register_stress(CLI::App& app);      // stress
void register_params(CLI::App& app);      // params

/// `touchstone --help-reference`: every subcommand, its positionals and flags as one JSON object
/// on stdout (cli_reference.cpp; scripts/command_reference.py writes docs/command-line.md from it).
void print_reference(const CLI::App& app);

/// The whole `touchstone` command line: registers every command, parses `argv`, runs the chosen
/// command and returns its exit code (0 done, 1 error, 2 usage). main() is this; the CLI tests
/// call it in process (tests/cli_run.hpp). `version` follows "touchstone " in --version.
int run_touchstone(int argc, char** argv, const char* version);

}  // namespace ts::cli
