// touchstone: recognize and localize a known object in 6 DOF from touch alone.
#include "experiments/cli/cli_common.hpp"
#include "io/atomic_file.hpp"

#ifndef TS_VERSION
#define TS_VERSION "unknown"
#endif

int main(int argc, char** argv) {
  ts::io::remove_temporaries_on_interrupt();  // Ctrl-C leaves no <out>.tmp-<pid> behind
  CLI::App app{"touchstone: tactile object recognition and 6-DOF localization"};
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "Help for every subcommand");
  app.set_version_flag("--version", "touchstone " TS_VERSION);
  ts::cli::register_db(app);
  ts::cli::register_tactile(app);
  ts::cli::register_recognize(app);
  ts::cli::register_experiment(app);
  ts::cli::register_catalogue(app);
  ts::cli::register_stress(app);
  ts::cli::register_params(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);  // prints help or "error message + usage hint"
    return rc == 0 ? 0 : 2;      // usage errors exit 2
  }
  return ts::cli::exit_code();
}
