// Stage "survivors", a candidate source (bricpsf): the previous step's hypotheses, evolved by
// ICP against their own objects and evaluated with Eq. 6 (Algorithm 1, lines 3-7). A hypothesis
// keeps its object, its birth step and its slot. Reads IcpSettings and the step's evaluation.
#include "engine/recognition/pipeline/stages.hpp"

#include <algorithm>

namespace ts::inline recognition::pipeline {

namespace {

class SurvivorsSource final : public Stage {
 public:
  std::string_view name() const override { return "survivors"; }

  std::string skip_reason(const StepContext& c) const override {
    return c.previous.empty() ? "no hypotheses from an earlier step" : std::string();
  }

  void run(StepContext& c) const override {
    c.old.assign(c.previous.size(), Working{});
    for (std::size_t i = 0; i < c.previous.size(); ++i) {
      const Hypothesis& h = c.previous[i];
      c.old[i].cand.object = h.object;
      c.old[i].cand.T_scene_object = c.scene.to_scene(h.pose);
      c.old[i].cand.slot = h.slot;
      c.old[i].born = h.born;
    }
    refine_and_evaluate(c, c.old);
    std::sort(c.old.begin(), c.old.end(), better);
  }
};

}  // namespace

std::unique_ptr<const Stage> survivors_source() { return std::make_unique<SurvivorsSource>(); }

}  // namespace ts::recognition::pipeline
