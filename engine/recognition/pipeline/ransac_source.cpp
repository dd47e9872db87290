// Stage "ransac", a candidate source: Batch RANSAC hypothesis generation (Section 4.3.2), every
// method, every step: N x R registrations over the allowed objects (the shape prior's first
// when it ranked them). Reads RansacSettings (lengths in m, angles in degrees).
#include "engine/recognition/pipeline/stages.hpp"

namespace ts::inline recognition::pipeline {

namespace {

class RansacSource final : public Stage {
 public:
  std::string_view name() const override { return "ransac"; }

  std::string skip_reason(const StepContext& c) const override { return c.stop_early; }

  void run(StepContext& c) const override {
    c.cands = ransac_candidates(c.scene, c.db, c.search, c.allowed, c.s.ransac, c.s.seed, c.step_u(), &c.rs,
                                c.preferred);
    c.rs.time_prune_s += c.prior_s;
    StepResult& res = c.res;
    res.times.prune_s = c.rs.time_prune_s;
    res.times.register_s = c.rs.time_register_s;
    res.candidates = c.rs.registrations;
    res.objects_allowed = c.rs.objects_allowed;
    res.objects_reached = c.rs.objects_reached;
    res.boundary_fallback = c.rs.boundary_fallback;
  }
};

}  // namespace

std::unique_ptr<const Stage> ransac_source() { return std::make_unique<RansacSource>(); }

}  // namespace ts::recognition::pipeline
