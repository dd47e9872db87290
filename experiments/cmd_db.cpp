#include "experiments/cli_common.hpp"

namespace ts::cli {

void register_db(CLI::App& app) { (void)app; }

}  // namespace ts::cli
