#include "experiments/cli_common.hpp"

namespace ts::cli {

void register_tactile(CLI::App& app) { (void)app; }

}  // namespace ts::cli
