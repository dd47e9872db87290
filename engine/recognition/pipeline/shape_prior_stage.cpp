// Stage "shape_prior" (extension for large databases): the objects ranked by how well their
// point-pair statistics fit the contacts' (engine/recognition/shape_prior.hpp), so that feature
// pruning searches the likely objects first. Reads ShapePriorSettings (through the recognizer's
// ShapePrior), ransac.prior_draws, ransac.object_draws, prior_min_database.
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

namespace ts::inline recognition::pipeline {

namespace {

class ShapePriorStage final : public Stage {
 public:
  std::string_view name() const override { return "shape_prior"; }

  std::string skip_reason(const StepContext& c) const override {
    if (c.prior) return {};
    if (c.s.ransac.prior_draws == 0 || c.s.ransac.object_draws == 0)
      return "ransac.prior_draws or ransac.object_draws is 0";
    return small_database(c.db, "the shape prior", c.s.prior_min_database);
  }

  void run(StepContext& c) const override {
    const auto t0 = detail::Clock::now();
    c.res.prior_scores = c.prior->score(c.scene, c.allowed, c.s.seed, c.step_u());   // also for set answers
    c.preferred = rank_by_prior(c.res.prior_scores);
    c.prior_s = detail::seconds_since(t0);
  }
};

}  // namespace

std::unique_ptr<const Stage> shape_prior_stage() { return std::make_unique<ShapePriorStage>(); }

}  // namespace ts::recognition::pipeline
