#include "experiments/runs/driver.hpp"

#include "experiments/allocator.hpp"
#include "experiments/params/config.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <chrono>
#include <mutex>
#include <numeric>

namespace ts::experiments {

std::optional<double> Progress::remaining_s() const {
  if (session_done == 0 || done >= total) return done >= total ? std::optional<double>(0.0) : std::nullopt;
  const double per_run = elapsed_s / static_cast<double>(session_done);
  return per_run * static_cast<double>(total - done);
}

std::vector<RunTask> all_tasks(const io::RunStoreHeader& header, int runs) {
  std::vector<RunTask> tasks;
  const int variants = static_cast<int>(header.variant_labels.size());
  const int objects = static_cast<int>(header.objects.size());
  tasks.reserve(static_cast<std::size_t>(variants) * static_cast<std::size_t>(objects) *
                static_cast<std::size_t>(std::max(runs, 0)));
  for (int v = 0; v < variants; ++v)
    for (int o = 0; o < objects; ++o)
      for (int r = 0; r < runs; ++r) tasks.push_back({v, o, r});
  return tasks;
}

DriveOutcome drive(RunEngine& engine, const std::vector<RunTask>& tasks,
                   const std::filesystem::path& store, const DriveSettings& settings) {
  const io::RunStoreContents existing = io::RunStore::read(store);
  std::set<RunTask> done;
  for (const auto& r : existing.runs) done.insert({r.variant, r.object, r.run});
  std::vector<RunTask> todo;
  for (const RunTask& t : tasks)
    if (!done.count(t)) todo.push_back(t);

  DriveOutcome outcome;
  Progress progress;
  progress.total = tasks.size();
  progress.done = tasks.size() - todo.size();
  if (todo.empty()) return outcome;
  engine.prepare(todo);
  release_free_memory();   // what the set-up freed (experiments/allocator.hpp)

  const auto start = std::chrono::steady_clock::now();
  std::mutex store_mutex;
  auto stopped = [&] { return settings.stop && settings.stop->load(); };
  auto execute = [&](const RunTask& task) {
    if (stopped()) return;
    std::optional<io::RunRecord> record = engine.run(task, settings.stop);
    release_free_memory();   // what the run freed, before the next one
    if (!record) return;
    std::lock_guard<std::mutex> lock(store_mutex);
    io::RunStore::append(store, {*record});
    ++outcome.completed;
    ++progress.done;
    ++progress.session_done;
    progress.elapsed_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (settings.on_progress) settings.on_progress(progress);
  };

  if (settings.parallel_runs) {
    // One run per task (runs take seconds; no batching needed). Exceptions cancel the rest and
    // are rethrown here by TBB.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, todo.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        for (std::size_t i = range.begin(); i != range.end(); ++i) execute(todo[i]);
                      },
                      tbb::simple_partitioner());
  } else {
    for (const RunTask& t : todo) execute(t);
  }
  outcome.interrupted = outcome.completed < todo.size();
  return outcome;
}

/// A store made by another configuration or database is refused, naming the first difference;
/// the store is not touched.
void check_resumable(const io::RunStoreHeader& stored, const io::RunStoreHeader& now,
                     const std::string& path) {
  const auto a = nlohmann::ordered_json::parse(stored.config_json, nullptr, false);
  const auto b = nlohmann::ordered_json::parse(now.config_json, nullptr, false);
  if (a.is_discarded()) throw Error("the run store's configuration is not valid JSON", path, "/header/config");
  const std::string key = first_difference(a, b);
  if (!key.empty()) {
    const std::string was = a.contains(key) ? a[key].dump() : "absent";
    const std::string is = b.contains(key) ? b[key].dump() : "absent";
    throw Error("the run store was made with another configuration: " + key + " is " + was +
                " there, " + is + " now (the store is left untouched)", path, key);
  }
  const auto da = nlohmann::ordered_json::parse(stored.database_json, nullptr, false);
  const auto db = nlohmann::ordered_json::parse(now.database_json, nullptr, false);
  if (da.is_discarded() || !da.contains("fingerprint") || da["fingerprint"] != db["fingerprint"])
    throw Error("the run store was made with another database (fingerprints differ; the store is "
                "left untouched)", path, "database");
  if (stored.objects != now.objects || stored.database_objects != now.database_objects ||
      stored.variant_labels != now.variant_labels || stored.steps != now.steps)
    throw Error("the run store's objects or variants differ from this configuration's (the store "
                "is left untouched)", path, "objects");
  if (stored.shard != now.shard)
    throw Error("the run store holds " + (stored.shard.empty() ? std::string("a whole experiment") : "shard " + stored.shard) +
                ", not " + (now.shard.empty() ? std::string("the whole experiment") : "shard " + now.shard) +
                " (the store is left untouched)", path, "/@shard");
  if (stored.stages != now.stages)
    throw Error("the run store was written by a build with other timing stages", path, "/header/stages");
  if (stored.step_values != now.step_values)
    throw Error("the run store was written by a build that records other per-step values", path,
                "/header/step_values");
}

std::uint64_t name_hash(const std::string& name) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (unsigned char c : name) {
    h ^= c;
    h *= 0x100000001b3ULL;
  }
  return h;
}

std::vector<std::int32_t> draw_grasps(std::uint64_t seed, const std::string& object, int run,
                                      int pool, int steps) {
  if (pool < 1 || steps < 1 || steps > pool)
    throw Error("a run needs 1 <= steps <= pool (steps " + std::to_string(steps) + ", pool " +
                std::to_string(pool) + ")", {}, "pool");
  constexpr std::uint64_t kGraspStream = 0x67726173ULL;  // "gras"
  Rng rng(seed, kGraspStream, name_hash(object), static_cast<std::uint64_t>(run));
  std::vector<std::int32_t> idx(static_cast<std::size_t>(pool));
  std::iota(idx.begin(), idx.end(), 0);
  for (int k = 0; k < steps; ++k) {
    const std::size_t j = static_cast<std::size_t>(k) + rng.index(static_cast<std::size_t>(pool - k));
    std::swap(idx[static_cast<std::size_t>(k)], idx[j]);
  }
  idx.resize(static_cast<std::size_t>(steps));
  return idx;
}

}  // namespace ts::experiments
