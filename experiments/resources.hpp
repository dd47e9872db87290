// What a program runs with: the machine it reports beside its figures, and the memory budget of
// the object geometry it loads (`--memory-budget`, `memory_budget_mb`). Shared by the command,
// the experiment engine, the Python module and the benchmarks.
#pragma once

#include <optional>
#include <string>

namespace ts {
inline namespace database {
class Database;
}
}  // namespace ts

namespace ts::experiments {

/// Host description for reports: "<cpu model>, <n> cores, <allocator>" (allocator.hpp).
std::string machine_description();

/// This machine's physical memory, bytes (0 when unknown).
double physical_memory_bytes();

/// Default resident object geometry of `recognize`, `experiment` and the Python module (MB).
constexpr double kDefaultMemoryBudgetMb = 256;
/// Set a database's memory budget from --memory-budget / memory_budget_mb in MB (unset: the
/// default; 0: no limit). A budget given explicitly that cannot hold the largest object's
/// geometry (measured by loading it) is an error naming `file` and the option.
void set_memory_budget(Database& db, const std::optional<double>& mb, const std::string& file,
                       const std::string& option = "--memory-budget");

}  // namespace ts::experiments
