#include "engine/recognition/pipeline/stage.hpp"

#include "engine/detail.hpp"

#include <exception>

namespace ts::inline recognition::pipeline {

namespace {

constexpr std::string_view kRun = "the stage";

/// Calls `f`, turning what it throws into one Error that names the stage (and who threw). A
/// stage's own Error (a database file's, which names its file and field) passes unchanged.
template <class F>
void naming_stage(std::string_view stage, std::string_view who, F&& f) {
  try {
    f();
  } catch (const Error& e) {
    if (who == kRun) throw;
    throw Error("stage '" + std::string(stage) + "': " + std::string(who) + " failed: " + e.message(), e.file(),
                e.field().empty() ? "stage." + std::string(stage) : e.field());
  } catch (const std::exception& e) {
    throw Error("stage '" + std::string(stage) + "': " + std::string(who) + " failed: " + e.what(), {},
                "stage." + std::string(stage));
  }
}

}  // namespace

void run_pipeline(const Pipeline& stages, StepContext& c, std::span<StepObserver* const> observers) {
  for (const auto& stage : stages) {
    StageRun record;
    record.name = std::string(stage->name());
    if (c.finished) {   // nothing left to work on: observers are not told
      record.reason = *c.finished;
      c.res.stages.push_back(std::move(record));
      continue;
    }
    record.reason = stage->skip_reason(c);
    record.ran = record.reason.empty();
    for (StepObserver* o : observers)
      naming_stage(record.name, "an observer before it", [&] { o->before(record.name, record.ran, c); });
    if (record.ran) {
      const auto t0 = detail::Clock::now();
      naming_stage(record.name, kRun, [&] { stage->run(c); });
      record.seconds = detail::seconds_since(t0);
    }
    for (StepObserver* o : observers)
      naming_stage(record.name, "an observer after it", [&] { o->after(record.name, record.ran, c); });
    c.res.stages.push_back(std::move(record));
  }
}

std::vector<Working> select_scored(StepContext& c, const std::vector<Candidate>& cands, std::size_t k,
                                   const EvaluateSettings& e) {
  SelectStats ss;
  const auto t0 = detail::Clock::now();
  const std::vector<ScoredCandidate> top = select_top(c.scene, c.db, cands, k, e, &ss);
  c.res.times.evaluate_s += detail::seconds_since(t0);
  c.res.evaluated_full += ss.full;
  c.res.rejected_early += ss.rejected_prefix + ss.rejected_later;
  return from_scored(cands, top, c.step);
}

void refine_and_evaluate(StepContext& c, std::vector<Working>& w) {
  auto t = detail::Clock::now();
  refine_all(c.scene, c.db, c.s.icp, w);
  c.res.times.icp_s += detail::seconds_since(t);
  t = detail::Clock::now();
  evaluate_each(c.scene, c.db, c.ev, w);
  c.res.times.evaluate_s += detail::seconds_since(t);
}

std::string small_database(const Database& db, std::string_view what, std::size_t above) {
  return "database of " + std::to_string(db.size()) + " objects (" + std::string(what) + " acts above " +
         std::to_string(above) + ")";
}

}  // namespace ts::recognition::pipeline
