// Stage "early_stop" (bricpsf, an extension, off unless RecognizerSettings::early_stop): when the
// previous state's leading hypothesis, evolved on this step's contacts (stage "survivors"),
// explains every contact within noise and no other object's best survivor does, the step
// proposes no new hypotheses: the candidate sources and the shortlist are left out with the
// reason, and the sequential filter keeps the survivors. A contact the leader cannot explain
// (a new face touched, a look-alike's difference felt) brings the sources back on the next
// step it happens.
// "Within noise" (AnswerFit's measures): no contact beyond 3 evaluate.grasp_contact_sigma after
// the per-grasp offsets, their RMS (each clamped there) within early_stop_rms_sigma sigmas, and
// Eq. 8's error per free point at most early_stop_free_conflict.
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

#include <atomic>
#include <cmath>
#include <set>
#include <string>

namespace ts::inline recognition::pipeline {

namespace {

/// Whether `h` explains every contact of the step within noise.
bool explains(const StepContext& c, const ObjectGeometry& geo, const Working& h) {
  if (geo.field.empty()) return false;
  const GraspFit fit = contact_fit(c.scene, geo.field, h.cand.T_scene_object, c.ev);
  if (fit.contacts == 0 || fit.far > 0) return false;
  const double rms_sigma = std::sqrt(fit.clamped_sq_sum / static_cast<double>(fit.contacts)) / c.ev.grasp_contact_sigma;
  if (!(rms_sigma <= c.s.early_stop_rms_sigma)) return false;
  const double free_points = static_cast<double>(std::max<std::size_t>(c.scene.free_space.size(), 1));
  return h.eval.free_error / free_points <= c.s.early_stop_free_conflict;
}

class EarlyStop final : public Stage {
 public:
  std::string_view name() const override { return "early_stop"; }

  std::string skip_reason(const StepContext& c) const override {
    if (!c.s.early_stop) return "early_stop off";
    const std::size_t most = c.s.early_stop_max_database;
    if (most > 0 && c.db.size() > most)
      return "database of " + std::to_string(c.db.size()) + " objects (early stop acts up to " + std::to_string(most) + ")";
    if (c.old.empty()) return "no hypotheses from an earlier step";
    return {};
  }

  void run(StepContext& c) const override {
    // The best survivor of each object, best first (c.old is sorted by `better`).
    std::vector<Working> leaders;
    std::set<std::uint32_t> seen;
    for (const Working& h : c.old)
      if (seen.insert(h.cand.object).second) leaders.push_back(h);
    const GeometryPins geometry = pin(c.db, leaders);
    if (!explains(c, geometry[leaders.front().cand.object], leaders.front())) return;
    // Not one object alone when any other leader explains the step too: the rivals checked in
    // parallel, each skipped once one is found (the answer, any, is the same in every order).
    std::atomic<bool> rival{false};
    detail::parallel_each(leaders.size() - 1, 1, [&](std::size_t k) {
      if (rival.load(std::memory_order_relaxed)) return;
      if (explains(c, geometry[leaders[k + 1].cand.object], leaders[k + 1])) rival.store(true, std::memory_order_relaxed);
    });
    if (rival.load()) return;
    c.stop_early = "early stop: the leading survivor explains every contact within noise, no other object's does";
  }
};

}  // namespace

std::unique_ptr<const Stage> early_stop_stage() { return std::make_unique<EarlyStop>(); }

}  // namespace ts::recognition::pipeline
