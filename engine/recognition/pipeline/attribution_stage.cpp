// Stage "attribution": what explains each of the step's contacts (issue 58). A contact is the
// support's when the stage "support" set it aside (SupportSurface::explains), the
// object's when it lies within support.attribution_m of the answer's surface at the answer's
// pose, and unexplained otherwise (something else was touched: a neighbour, a fixture; or the
// answer is wrong). StepResult::attribution, one label per input contact in its order. Left out
// unless the support is looked for (support.mode plane or cylinder) or the background term is on
// (evaluate.outlier_m > 0): it is what those users ask of the answer.
#include "engine/recognition/pipeline/stages.hpp"

#include <cmath>
#include <limits>

namespace ts::inline recognition::pipeline {

namespace {

class AttributionStage final : public Stage {
 public:
  std::string_view name() const override { return "attribution"; }

  std::string skip_reason(const StepContext& c) const override {
    if (!c.s.support.enabled() && !(c.s.evaluate.outlier_m > 0.0)) return "support.mode off, evaluate.outlier_m 0";
    return {};
  }

  void run(StepContext& c) const override {
    const double near = c.s.support.attribution;
    if (!(std::isfinite(near) && near > 0.0))
      throw Error("support.attribution must be a positive length in m", {}, "support.attribution");
    const PointCloud& in = c.contacts_world;
    std::vector<ContactLabel>& out = c.res.attribution;
    out.assign(in.size(), ContactLabel::unexplained);
    // The support's (as the stage "support" set them aside), then the rest judged on the answer.
    const SupportSurface& sp = c.res.support;
    std::vector<Vec3> points;
    std::vector<std::size_t> index;
    for (std::size_t i = 0; i < in.size(); ++i) {
      if (sp.found && sp.explains(in.points[i], c.s.support.tolerance))
        out[i] = ContactLabel::support;
      else if (std::isfinite(in.points[i].squaredNorm()))
        points.push_back(in.points[i]), index.push_back(i);
    }
    if (!c.res.valid) return;
    const Hypothesis& h = c.res.best;
    const GeometryRef geo = c.db.geometry(h.object);
    std::vector<double> d(points.size());
    const Pose to_object = h.pose.inverse();
    if (!geo->field.empty()) {
      geo->field.distances(points.data(), points.size(), to_object, d.data());
    } else {   // no field (a database without one): the nearest surface point
      for (std::size_t k = 0; k < points.size(); ++k)
        d[k] = geo->fine.empty() ? std::numeric_limits<double>::infinity()
                                 : std::sqrt(geo->tree.nearest(to_object * points[k]).sq_distance);
    }
    for (std::size_t k = 0; k < points.size(); ++k)
      if (std::abs(d[k]) <= near) out[index[k]] = ContactLabel::object;
  }
};

}  // namespace

std::unique_ptr<const Stage> attribution_stage() { return std::make_unique<AttributionStage>(); }

}  // namespace ts::recognition::pipeline
