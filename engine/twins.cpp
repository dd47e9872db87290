#include "engine/twins.hpp"

#include <limits>

namespace ts {

double twin_score(const Scene& scene, const ObjectGeometry& geo, const Pose& T_scene_object,
                  const TwinSettings& s) {
  if (scene.grasps.grasps() == 0 || geo.field.empty()) return std::numeric_limits<double>::infinity();
  EvaluateSettings fit_settings;
  fit_settings.grasp_offset_sigma = s.offset_sigma;
  fit_settings.grasp_contact_sigma = s.contact_sigma;
  fit_settings.grasp_fit_points = s.fit_points;
  fit_settings.grasp_offset_iterations = s.iterations;
  const GraspFit fit = fit_grasp_offsets(scene, geo.field, T_scene_object, fit_settings);
  double prior = 0.0;
  for (const Vec3& t : fit.offsets) prior += t.squaredNorm();
  return prior / (s.offset_sigma * s.offset_sigma) + fit.clamped_sq_sum / (s.contact_sigma * s.contact_sigma);
}

}  // namespace ts
