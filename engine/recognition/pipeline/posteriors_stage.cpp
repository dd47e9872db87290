// Stage "posteriors": the posterior of each object over the new state, its hypotheses' weights
// summed and normalized (log-sum-exp: finite even when every wt underflows).
#include "engine/recognition/pipeline/stages.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ts::inline recognition::pipeline {

namespace {

class PosteriorsStage final : public Stage {
 public:
  std::string_view name() const override { return "posteriors"; }

  void run(StepContext& c) const override {
    double max_lw = -std::numeric_limits<double>::infinity();
    for (const Working& h : c.next) max_lw = std::max(max_lw, h.eval.log_weight);
    double total = 0.0;
    std::vector<double>& p = c.res.posteriors;
    for (const Working& h : c.next) {
      const double rel = std::isfinite(max_lw) ? std::exp(h.eval.log_weight - max_lw) : 1.0;
      p[h.cand.object] += rel;
      total += rel;
    }
    if (total > 0.0)
      for (double& v : p) v /= total;
  }
};

}  // namespace

std::unique_ptr<const Stage> posteriors_stage() { return std::make_unique<PosteriorsStage>(); }

}  // namespace ts::recognition::pipeline
