#include "engine/icp.hpp"

#include "engine/kabsch.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>

namespace ts {

IcpResult icp(const Scene& scene, const ObjectGeometry& geo, const Pose& T_init,
              const IcpSettings& s) {
  IcpResult res;
  res.T_scene_object = T_init;
  const std::size_t C = scene.ordered.size();
  const std::size_t m = s.max_points == 0 ? C : std::min(C, s.max_points);
  if (m < 3 || geo.tree.size() < 3 || !T_init.matrix().allFinite()) return res;
  res.valid = true;
  const double gate2 = s.max_correspondence > 0.0 ? s.max_correspondence * s.max_correspondence
                                                  : std::numeric_limits<double>::infinity();
  const double min_rot = s.min_rotation_deg * std::numbers::pi / 180.0;
  const double trim = std::clamp(s.trim_fraction, 0.0, 1.0);

  std::vector<Vec3> src, dst;        // object-frame model points, scene-frame contacts
  std::vector<std::pair<double, std::uint32_t>> d2(m);
  std::vector<std::uint32_t> nearest(m);
  src.reserve(m);
  dst.reserve(m);
  Pose T = T_init;
  for (int it = 0; it < s.max_iterations; ++it) {
    const Pose T_os = T.inverse();
    for (std::size_t i = 0; i < m; ++i) {
      const Neighbour nb = geo.tree.nearest(T_os * scene.ordered[i]);
      d2[i] = {nb.sq_distance, static_cast<std::uint32_t>(i)};
      nearest[i] = nb.index;
    }
    std::size_t keep = m;
    if (trim < 1.0) {
      keep = std::max<std::size_t>(3, static_cast<std::size_t>(std::ceil(trim * double(m))));
      keep = std::min(keep, m);
      std::nth_element(d2.begin(), d2.begin() + (keep - 1), d2.end());  // pairs: total order
      std::sort(d2.begin(), d2.begin() + keep, [](const auto& a, const auto& b) {
        return a.second < b.second;  // back to index order: fixed summation order
      });
    }
    src.clear();
    dst.clear();
    for (std::size_t j = 0; j < keep; ++j) {
      if (d2[j].first > gate2) continue;
      const std::uint32_t i = d2[j].second;
      src.push_back(geo.tree.points()[nearest[i]]);
      dst.push_back(scene.ordered[i]);
    }
    const RigidFit fit = kabsch(src, dst);
    res.iterations = it + 1;
    if (!fit.valid) break;
    const Pose delta = fit.T_target_source * T.inverse();
    T = fit.T_target_source;
    res.rms = fit.rms;
    res.pairs = src.size();
    if (delta.translation().norm() < s.min_translation && rotation_angle(delta.linear()) < min_rot) {
      res.converged = true;
      break;
    }
  }
  res.T_scene_object = T;
  return res;
}

}  // namespace ts
