// One experiment over the ranks of an MPI job (issue 16): `mpirun -n K touchstone experiment
// --mpi ...`. Runs are handed out dynamically (they differ in cost by an order of magnitude):
// rank 0 answers each request for work with the next run of the shared list, from a thread of
// its own that polls (so it takes no core from the runs), while its own workers take runs from
// the same counter. Each rank appends its runs to a store of its own, `OUT.ranks/rank-R.h5`;
// rank 0 folds them into OUT at the end. A run's record does not depend on which rank ran it
// (driver.hpp), so the folded store's results are those of one process.
//
// Built only when CMake finds MPI (TS_MPI); without it --mpi is an error saying so.
#pragma once

#include "experiments/runs/driver.hpp"

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace ts::experiments {

/// True when this build has the MPI mode.
bool mpi_built();

/// MPI_Init_thread (MPI_THREAD_SERIALIZED) on construction, MPI_Finalize on destruction.
class MpiSession {
 public:
  MpiSession();
  ~MpiSession();
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
  int rank() const { return rank_; }
  int size() const { return size_; }
  void barrier();
  /// Stop every rank of the job (after an error in one rank: the others would wait forever).
  [[noreturn]] void abort(int code);
  /// True when every rank passed the same value (a collective call: every rank must make it).
  bool same_on_every_rank(std::uint64_t value);

  /// Run the tasks `todo` (the same list on every rank) over the job: each rank computes the runs
  /// it is handed with `threads` workers and appends each to its store `rank_store` (which must
  /// exist). Returns what this rank completed.
  DriveOutcome drive(RunEngine& engine, const std::vector<RunTask>& todo,
                     const std::filesystem::path& rank_store, int threads, const DriveSettings& settings);

 private:
  int rank_ = 0, size_ = 1;
};

/// A fingerprint of what a rank is about to do: the experiment (configuration, database,
/// variants, objects, steps) and the list of runs left. Ranks that see different files (another
/// configuration or database under the same path on another node, or a store folder that is not
/// shared between nodes) get different fingerprints.
std::uint64_t plan_fingerprint(const io::RunStoreHeader& header, const std::vector<RunTask>& todo);

/// Where the ranks of an MPI experiment writing `out` keep their stores.
std::filesystem::path rank_folder(const std::filesystem::path& out);
std::filesystem::path rank_store(const std::filesystem::path& out, int rank);
/// The rank stores present (any job size), sorted by name.
std::vector<std::filesystem::path> rank_stores(const std::filesystem::path& out);

}  // namespace ts::experiments
