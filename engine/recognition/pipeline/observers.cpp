#include "engine/recognition/pipeline/observers.hpp"

#include "engine/detail.hpp"
#include "engine/recognition/pipeline/stages.hpp"

#include <algorithm>
#include <cmath>

namespace ts::inline recognition::pipeline {

void FunnelObserver::before(std::string_view stage, bool runs, StepContext& c) {
  if (stage == "shortlist") {
    count_candidates(c);   // every source has proposed
    if (runs) unscreened_ = c.cands;
  }
}

void FunnelObserver::after(std::string_view stage, bool ran, StepContext& c) {
  if (!c.res.watched) return;
  Funnel& f = *c.res.watched;
  if (stage == "shortlist" && ran) {
    screening(c);
  } else if (stage == "pose_transfer" && ran) {
    const auto& order = c.transfer_ranked;
    const auto at = std::find(order.begin(), order.end(), object_);
    f.transfer_rank = at == order.end() ? 0 : static_cast<std::size_t>(at - order.begin()) + 1;
    f.transferred = at != order.end() && static_cast<std::size_t>(at - order.begin()) < c.transfer_kept;
  } else if (stage == "answer_rule" && ran && pose_) {
    at_true_pose(c);
  } else if (stage == "state") {
    f.hypotheses = static_cast<std::size_t>(std::count_if(
        c.res.hypotheses.begin(), c.res.hypotheses.end(), [&](const Hypothesis& h) { return h.object == object_; }));
  }
}

void FunnelObserver::count_candidates(StepContext& c) const {
  Funnel f;
  f.searched = object_ < c.rs.searched.size() && c.rs.searched[object_];
  f.candidates = static_cast<std::size_t>(
      std::count_if(c.cands.begin(), c.cands.end(), [&](const Candidate& k) { return k.object == object_; }));
  f.shortlisted = f.candidates > 0;   // unless the shortlist leaves it out
  if (c.prior) {
    const auto at = std::find(c.preferred.begin(), c.preferred.end(), object_);
    f.prior_rank = at == c.preferred.end() ? 0 : static_cast<std::size_t>(at - c.preferred.begin()) + 1;
  }
  c.res.watched = f;
}

/// How far its best candidate was from the shortlist's cut (every object's exact best score).
void FunnelObserver::screening(StepContext& c) const {
  if (!c.shortlist || !c.shortlist->active) return;
  const auto t0 = detail::Clock::now();
  const Shortlist& sl = *c.shortlist;
  Funnel& f = *c.res.watched;
  f.shortlisted = f.candidates > 0 && sl.mask[object_];
  if (f.candidates > 0) {
    const std::vector<double> all = screen_objects(c.scene, c.db, unscreened_, c.s.shortlist);
    f.screen_score = all[object_];
    f.screen_rank = 1 + static_cast<std::size_t>(
        std::count_if(all.begin(), all.end(), [&](double v) { return v < f.screen_score; }));
  }
  const std::size_t last = std::min(c.s.shortlist.objects, sl.ranked.size());
  if (last > 0) f.screen_cut = sl.best[sl.ranked[last - 1]];
  f.diagnostic_s += detail::seconds_since(t0);
}

/// The watched object at its true pose, through the step's ICP (none for batch-ransac),
/// evaluation and answer rule (Funnel::truth_pose_*).
void FunnelObserver::at_true_pose(StepContext& c) const {
  const auto t0 = detail::Clock::now();
  Funnel& f = *c.res.watched;
  std::vector<Working> truth(1);
  truth[0].cand.object = object_;
  truth[0].cand.T_scene_object = c.scene.to_scene(*pose_);
  truth[0].cand.slot = kTruthSlot;
  truth[0].born = c.step;
  const bool refined = c.s.method != Method::batch_ransac;   // the state's hypotheses' footing
  if (refined) refine_all(c.scene, c.db, c.s.icp, truth);
  evaluate_each(c.scene, c.db, refined ? c.ev : c.ev_raw, truth);
  std::vector<Working> all = c.next;
  all.push_back(truth[0]);
  std::stable_sort(all.begin(), all.end(), better);
  const AnswerRule rule = decide_answer(c.scene, c.db, all, c.s.twins);
  const std::size_t chosen = c.rule.chosen;
  f.truth_pose_evaluated = true;
  f.truth_pose_wins = all[rule.chosen].cand.object == object_ ||
                      (!c.next.empty() && c.next[chosen].cand.object == object_);
  f.truth_pose_log_weight = truth[0].eval.log_weight;
  if (!c.next.empty()) f.answer_log_weight = c.next[chosen].eval.log_weight;
  for (std::size_t k = 0; k < rule.leaders.size(); ++k) {
    const Working& h = all[rule.leaders[k]];
    if (h.cand.object == object_)   // its leading hypothesis: this one or a better of its own
      f.truth_pose_twin_score = rule.v[k];
    else
      f.rival_twin_score = std::min(f.rival_twin_score, rule.v[k]);
  }
  f.diagnostic_s += detail::seconds_since(t0);
}

void ExplainObserver::after(std::string_view stage, bool ran, StepContext& c) {
  if (stage != "state" || !ran || !c.res.valid || c.next.empty()) return;
  const auto t0 = detail::Clock::now();
  const std::size_t chosen = c.rule.chosen;
  std::optional<std::size_t> rival;   // the best hypothesis of another object
  for (std::size_t i = 0; i < c.next.size() && !rival; ++i)
    if (c.next[i].cand.object != c.next[chosen].cand.object) rival = i;
  const bool free_term = c.ev.free_space && c.scene.has_free_space() && c.ev.lambda > 0.0;
  auto evidence = [&](std::size_t i) {
    const Working& h = c.next[i];
    Evidence e;
    e.object = h.cand.object;
    e.pose = c.scene.to_world(h.cand.T_scene_object);
    e.rank = i + 1;
    e.log_weight = h.eval.log_weight;
    e.free_log_weight = free_term ? 0.0 - c.ev.lambda * h.eval.free_error : 0.0;   // (no -0)
    e.floor_log_weight = 0.0 - h.eval.sink_penalty;   // (no -0)
    e.contact_log_weight = e.log_weight - e.free_log_weight - e.floor_log_weight;
    e.free_points_checked = free_term ? h.eval.free_points : 0;
    e.offset_rms_m = h.eval.grasp_offset_rms;
    e.fit = i == chosen ? c.res.fit : absolute_fit(c.scene, c.db, h, c.s.evaluate);
    for (std::size_t k = 0; k < c.rule.leaders.size() && k < c.rule.v.size(); ++k)
      if (c.rule.leaders[k] == i) e.twin_score = c.rule.v[k];
    e.posterior = e.object < c.res.posteriors.size() ? c.res.posteriors[e.object] : 0.0;
    return e;
  };
  c.res.explanation = {evidence(chosen)};
  c.res.decided_by.clear();
  if (rival) {
    c.res.explanation.push_back(evidence(*rival));
    const Evidence& a = c.res.explanation[0];
    const Evidence& b = c.res.explanation[1];
    if (!std::isnan(a.twin_score) && !std::isnan(b.twin_score))
      c.res.decided_by = "near_twin";
    else {
      const double contacts = std::abs(a.contact_log_weight - b.contact_log_weight);
      const double free = std::abs(a.free_log_weight - b.free_log_weight);
      const double floor = std::abs(a.floor_log_weight - b.floor_log_weight);
      c.res.decided_by = floor > std::max(contacts, free) ? "floor" : free > contacts ? "free_space" : "contacts";
    }
  }
  seconds += detail::seconds_since(t0);
}

}  // namespace ts::recognition::pipeline
