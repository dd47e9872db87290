#include "experiments/analysis/scene.hpp"

#include <algorithm>
#include <cmath>
#include <set>

namespace ts::experiments {

namespace {

using J = nlohmann::ordered_json;

double tenth_mm(double x) { return std::round(x * 1e4) / 1e4; }

J point(const Vec3& p) { return J::array({tenth_mm(p.x()), tenth_mm(p.y()), tenth_mm(p.z())}); }

/// At most `limit` of `n` indices, evenly spread.
std::vector<std::size_t> spread(std::size_t n, std::size_t limit) {
  std::vector<std::size_t> out;
  const std::size_t m = std::min(n, limit);
  for (std::size_t j = 0; j < m; ++j) out.push_back(j * n / m);
  return out;
}

J object_points(const Database& db, std::size_t object, const Pose& T_world_object, std::size_t limit) {
  J pts = J::array();
  const PointCloud cloud = db.load_fine(object);   // also when only distance fields are resident
  const std::vector<Vec3>& fine = cloud.points;
  for (std::size_t i : spread(fine.size(), limit)) pts.push_back(point(T_world_object * fine[i]));
  return pts;
}

J matrix_json(const Pose& T) {
  J m = J::array();
  for (int i = 0; i < 4; ++i) {
    J row = J::array();
    for (int j = 0; j < 4; ++j) row.push_back(T.matrix()(i, j));
    m.push_back(row);
  }
  return m;
}

}  // namespace

J scene_json(const Database& db, const StepResult& r, const PointCloud& contacts, const std::vector<Vec3>& free,
             const std::optional<std::size_t>& truth_object, const std::optional<Pose>& truth_pose,
             const std::string& name, const std::string& label, const SceneLimits& limits) {
  J s;
  s["name"] = name;
  s["label"] = label;
  s["step"] = r.step;
  s["contacts"] = J::array();
  for (const Vec3& p : contacts.points) s["contacts"].push_back(point(p));
  s["free"] = J::array();
  for (std::size_t i : spread(free.size(), limits.free_points)) s["free"].push_back(point(free[i]));
  s["free_total"] = free.size();
  s["hypotheses"] = J::array();
  std::set<std::uint32_t> drawn;
  for (const Hypothesis& h : r.hypotheses) {   // best first; one per object
    if (drawn.size() >= limits.hypotheses) break;
    if (!drawn.insert(h.object).second) continue;
    J hj;
    hj["rank"] = drawn.size();
    hj["object"] = db.info(h.object).name;
    hj["posterior"] = h.object < r.posteriors.size() ? r.posteriors[h.object] : 0.0;
    hj["log_weight"] = std::isfinite(h.log_weight) ? J(h.log_weight) : J(nullptr);
    hj["pose"] = matrix_json(h.pose);
    hj["points"] = object_points(db, h.object, h.pose, limits.object_points);
    s["hypotheses"].push_back(hj);
  }
  if (truth_object && truth_pose) {
    s["truth"] = {{"object", db.info(*truth_object).name}, {"pose", matrix_json(*truth_pose)},
                  {"points", object_points(db, *truth_object, *truth_pose, limits.object_points)}};
  } else {
    s["truth"] = nullptr;
  }
  return s;
}

std::vector<int> scene_steps(const std::vector<int>& asked, int steps, const std::string& input) {
  if (asked.empty()) return {steps};
  std::set<int> out;
  for (int k : asked) {
    if (k < 1 || k > steps)
      throw Error("scene step " + std::to_string(k) + " is outside the input's steps 1-" + std::to_string(steps),
                  input, "--scene-steps");
    out.insert(k);
  }
  return {out.begin(), out.end()};
}

}  // namespace ts::experiments
