// touchstone: recognize and localize a known object in 6 DOF from touch alone.
#include "experiments/cli/cli_common.hpp"
#include "io/atomic_file.hpp"

#ifndef TS_VERSION
#define TS_VERSION "unknown"
#endif

int main(int argc, char** argv) {
  ts::io::remove_temporaries_on_interrupt();  // Ctrl-C leaves no <out>.tmp-<pid> behind
  return ts::cli::run_touchstone(argc, argv, TS_VERSION);
}
