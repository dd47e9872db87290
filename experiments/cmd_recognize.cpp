#include "experiments/cli_common.hpp"

namespace ts::cli {

void register_recognize(CLI::App& app) { (void)app; }

}  // namespace ts::cli
