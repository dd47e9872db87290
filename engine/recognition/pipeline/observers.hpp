// Observers of a step's pipeline: diagnostics that see every stage and change nothing the step
// answers (its hypotheses, weights and answer). Their time is kept apart (Funnel::diagnostic_s).
#pragma once

#include "engine/recognition/pipeline/stage.hpp"

#include <optional>

namespace ts::inline recognition::pipeline {

/// Where one watched object stands in the step's search (Funnel): searched by the pruning,
/// candidates, the shortlist's screening, the shape prior's and pose transfer's ranks, its
/// hypotheses in the new state; with its true pose (T_world_object), that pose refined and
/// evaluated like the state's hypotheses and put through the answer rule.
class FunnelObserver final : public StepObserver {
 public:
  FunnelObserver(std::uint32_t object, std::optional<Pose> T_world_object)
      : object_(object), pose_(T_world_object) {}
  void before(std::string_view stage, bool runs, StepContext& c) override;
  void after(std::string_view stage, bool ran, StepContext& c) override;

 private:
  void count_candidates(StepContext& c) const;
  void screening(StepContext& c) const;
  void at_true_pose(StepContext& c) const;

  std::uint32_t object_;
  std::optional<Pose> pose_;
  std::vector<Candidate> unscreened_;   ///< the candidates before the shortlist (one step)
};

/// Why the answer won (StepResult::explanation): once the state is set, the answer's and its
/// best rival's evidence from the step's own evaluations (ln wt split into Eq. 6's terms), their
/// absolute fit, the near-twin verification's V where it compared them, and their posteriors.
class ExplainObserver final : public StepObserver {
 public:
  void before(std::string_view, bool, StepContext&) override {}
  void after(std::string_view stage, bool ran, StepContext& c) override;
  double seconds = 0.0;   ///< its own time (kept out of the step's)
};

}  // namespace ts::recognition::pipeline
