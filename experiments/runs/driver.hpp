// The experiment driver: runs every (variant, object, run) of an experiment that the run store
// does not hold yet, in parallel over TBB, and appends each completed run to the store.
//
// Section 5.2: one exploration run is a sequence of `steps` grasps drawn at random from the
// object's pool of simulated grasps (Section 5.1); results are averaged over runs. What one run
// computes is behind RunEngine (a coarse boundary: one virtual call per run), so the scheduling,
// resuming and storing are tested with a synthetic engine and used with the real one
// (simulator + recognizer, experiments/runs/recognition_engine.hpp).
//
// Determinism: a run's record depends only on (seed, variant's configuration, object name, run);
// never on the thread count, the schedule, the order runs complete in, or interruptions.
#pragma once

#include "engine/core.hpp"
#include "io/run_store.hpp"

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace ts::experiments {

struct RunTask {
  int variant = 0;
  int object = 0;      ///< index into RunStoreHeader::objects
  int run = 0;
  auto key() const { return std::tuple(variant, object, run); }
  bool operator<(const RunTask& o) const { return key() < o.key(); }
};

/// Computes one exploration run. Implementations must be callable from several threads at once.
class RunEngine {
 public:
  virtual ~RunEngine() = default;
  /// Everything the store's header needs (configuration, objects, stages, versions...).
  virtual const io::RunStoreHeader& header() const = 0;
  /// Run one task. Return nullopt when `stop` became true in the middle (the run is dropped).
  virtual std::optional<io::RunRecord> run(const RunTask& task, const std::atomic<bool>* stop) = 0;
  /// Work to do once before the runs (e.g. simulate the grasp pools), in the caller's arena.
  virtual void prepare(const std::vector<RunTask>& tasks) { (void)tasks; }
  /// As prepare(), but what only some runs need (the grasp pools of protocol shared_pool) is
  /// made by the first run that needs it: for a process that gets an unknown share of the runs
  /// (a rank of an MPI job). Results are the same.
  virtual void prepare_lazily(const std::vector<RunTask>& tasks) { prepare(tasks); }
};

struct Progress {
  std::size_t done = 0;          ///< runs in the store (including earlier sessions)
  std::size_t total = 0;         ///< runs planned
  std::size_t session_done = 0;  ///< runs completed in this session
  double elapsed_s = 0.0;        ///< this session's wall time
  /// Estimated seconds left from this session's rate; nullopt before the first run completes.
  std::optional<double> remaining_s() const;
};

struct DriveSettings {
  bool parallel_runs = true;     ///< schedule "runs": runs in parallel; "steps": one at a time
  const std::atomic<bool>* stop = nullptr;               ///< set to stop early (Ctrl-C)
  std::function<void(const Progress&)> on_progress;      ///< after each stored run (any thread,
                                                         ///< serialized)
};

struct DriveOutcome {
  std::size_t completed = 0;     ///< runs completed and stored in this session
  bool interrupted = false;      ///< stopped before every task was done
};

/// Every task of an experiment: variants x objects x runs, in key order.
std::vector<RunTask> all_tasks(const io::RunStoreHeader& header, int runs);

/// Run `tasks` minus those already in the store at `store` (which must exist with `engine`'s
/// header) and append each as it completes. Call inside the caller's task arena.
DriveOutcome drive(RunEngine& engine, const std::vector<RunTask>& tasks,
                   const std::filesystem::path& store, const DriveSettings& settings = {});

/// Refuse to resume a store written with another configuration, database, object list or
/// timing stages: throws ts::Error naming `path` and the first differing key. Reads nothing
/// and writes nothing (the store is left untouched).
void check_resumable(const io::RunStoreHeader& stored, const io::RunStoreHeader& now,
                     const std::string& path);

/// Stable 64-bit hash of a name (FNV-1a), so an object's runs do not depend on its position in
/// a list: the same (seed, object, run) draws the same grasps in every experiment.
std::uint64_t name_hash(const std::string& name);

/// The grasp sequence of one run: `steps` distinct pool indices drawn uniformly without
/// replacement (a partial Fisher-Yates shuffle) from the stream (seed, "grasps", object, run).
std::vector<std::int32_t> draw_grasps(std::uint64_t seed, const std::string& object, int run,
                                      int pool, int steps);

}  // namespace ts::experiments
