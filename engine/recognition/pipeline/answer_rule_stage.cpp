// Stage "answer_rule": the answer of a step is the best hypothesis, unless the near-twin
// verification (engine/recognition/twins.hpp) of the leading objects' best hypotheses
// re-decides a near tie. (Answering the object of largest posterior instead was measured and
// rejected: the weights are so flat that the posterior counts an object's hypotheses; 45
// objects, 135 logs: 27 % right against 91 %.) Reads TwinSettings (rivals, max_gap in ln wt).
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

namespace ts::inline recognition::pipeline {

AnswerRule decide_answer(const Scene& scene, const Database& db, const std::vector<Working>& next,
                         const TwinSettings& twins) {
  AnswerRule out;
  std::vector<std::size_t> lead;  // first (best) hypothesis of each leading object, best first
  for (std::size_t i = 0; i < next.size() && lead.size() < twins.rivals; ++i) {
    if (!(next[i].eval.log_weight >= next.front().eval.log_weight - twins.max_gap)) break;
    bool seen = false;
    for (std::size_t j : lead) seen = seen || next[j].cand.object == next[i].cand.object;
    if (!seen) lead.push_back(i);
  }
  if (twins.rivals > 1 && !scene.grasps.empty() && lead.size() > 1) {
    std::vector<Working> leaders;
    for (std::size_t i : lead) leaders.push_back(next[i]);
    const GeometryPins geometry = pin(db, leaders);
    std::vector<double> v(lead.size());
    detail::parallel_each(lead.size(), 1, [&](std::size_t k) {
      v[k] = twin_score(scene, geometry[leaders[k].cand.object], leaders[k].cand.T_scene_object, twins);
    });
    std::size_t best_k = 0;
    for (std::size_t k = 1; k < v.size(); ++k)
      if (v[k] < v[best_k]) best_k = k;
    out.chosen = lead[best_k];
    out.leaders = std::move(lead);
    out.v = std::move(v);
  }
  return out;
}

namespace {

class AnswerRuleStage final : public Stage {
 public:
  std::string_view name() const override { return "answer_rule"; }

  void run(StepContext& c) const override { c.rule = decide_answer(c.scene, c.db, c.next, c.s.twins); }
};

}  // namespace

std::unique_ptr<const Stage> answer_rule_stage() { return std::make_unique<AnswerRuleStage>(); }

}  // namespace ts::recognition::pipeline
