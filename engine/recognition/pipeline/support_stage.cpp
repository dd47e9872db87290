// Stage "support": the plane under the object (a seabed) or the cylinder it sits on (a pipe) from
// the step's contacts and free space, and the inputs without the contacts it explains
// (support.hpp). Reads RecognizerSettings::support; left out unless support.mode is plane or
// cylinder.
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

namespace ts::inline recognition::pipeline {

namespace {

class SupportStage final : public Stage {
 public:
  std::string_view name() const override { return "support"; }

  std::string skip_reason(const StepContext& c) const override {
    return c.s.support.enabled() ? std::string() : std::string("support.mode off");
  }

  void run(StepContext& c) const override {
    SupportSettings s = c.s.support;
    if (s.free_margin < 0.0)
      s.free_margin = s.tolerance + (c.s.evaluate.d_thresh > 0.0 ? c.s.evaluate.d_thresh : 0.5 * c.s.evaluate.res_free);
    c.res.support = estimate_support(c.contacts_world, c.grasps, c.free_world, s, c.s.seed, c.step_u());
    if (!c.res.support.found) return;
    c.object_contacts = without_support(c.contacts_world, c.res.support, s.tolerance);
    c.object_grasps = without_support(c.grasps, c.res.support, s.tolerance);
  }
};

}  // namespace

std::unique_ptr<const Stage> support_stage() { return std::make_unique<SupportStage>(); }

}  // namespace ts::recognition::pipeline
