// Stage "state": the new state S_t in world coordinates (best first), the answer (the answer
// rule's choice), its posterior, and its fit in absolute terms (AnswerFit: the contacts'
// distances after the per-grasp offsets against evaluate.grasp_contact_sigma, in sigmas).
#include "engine/recognition/pipeline/stages.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace ts::inline recognition::pipeline {

AnswerFit absolute_fit(const Scene& scene, const Database& db, const Working& h, const EvaluateSettings& s) {
  AnswerFit out;
  const GeometryPins geometry = pin(db, std::vector<Working>{h});
  const ObjectGeometry& geo = geometry[h.cand.object];
  if (geo.field.empty()) return out;
  const GraspFit fit = contact_fit(scene, geo.field, h.cand.T_scene_object, s);
  if (fit.contacts == 0) return out;
  const double n = static_cast<double>(fit.contacts), sigma = s.grasp_contact_sigma;
  out.valid = true;
  out.contacts = fit.contacts;
  out.rms_sigma = std::sqrt(fit.clamped_sq_sum / n) / sigma;
  out.far_share = static_cast<double>(fit.far) / n;
  out.far10_share = static_cast<double>(fit.far10) / n;
  out.offset_rms_sigma = s.grasp_offset_sigma > 0.0 ? fit.offset_rms / s.grasp_offset_sigma : 0.0;
  out.free_conflict = h.eval.free_error / static_cast<double>(std::max<std::size_t>(scene.free_space.size(), 1));
  const GraspDiagnostics per = grasp_diagnostics(scene, geo.field, h.cand.T_scene_object, fit, s);
  const double cap = 30.0 * std::numbers::pi / 180.0;
  double angle_sq = 0.0;
  std::size_t angles = 0;
  for (std::size_t k = 0; k < per.rms.size(); ++k) {
    if (std::isfinite(per.rms[k])) out.worst_grasp_sigma = std::max(out.worst_grasp_sigma, per.rms[k] / sigma);
    if (!std::isfinite(per.normal_angle[k])) continue;
    const double a = std::min(per.normal_angle[k], cap);
    angle_sq += a * a;
    ++angles;
    out.normal_worst_deg = std::max(out.normal_worst_deg, a * 180.0 / std::numbers::pi);
  }
  if (angles > 0) out.normal_rms_deg = std::sqrt(angle_sq / static_cast<double>(angles)) * 180.0 / std::numbers::pi;
  return out;
}

namespace {

class StateStage final : public Stage {
 public:
  std::string_view name() const override { return "state"; }

  void run(StepContext& c) const override {
    StepResult& res = c.res;
    res.hypotheses.clear();
    for (const Working& h : c.next) {
      Hypothesis out;
      out.object = h.cand.object;
      out.pose = c.scene.to_world(h.cand.T_scene_object);
      out.log_weight = h.eval.log_weight;
      out.weight = std::exp(h.eval.log_weight);
      out.born = h.born;
      out.slot = h.cand.slot;
      out.icp_iterations = h.icp_iterations;
      out.icp_converged = h.icp_converged;
      res.hypotheses.push_back(out);
    }
    res.valid = !res.hypotheses.empty();
    if (!res.valid) return;
    const std::size_t chosen = c.rule.chosen;
    res.best = res.hypotheses[chosen];
    res.posterior = res.posteriors[res.best.object];
    res.fit = absolute_fit(c.scene, c.db, c.next[chosen], c.s.evaluate);
  }
};

}  // namespace

std::unique_ptr<const Stage> state_stage() { return std::make_unique<StateStage>(); }

}  // namespace ts::recognition::pipeline
