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
             const std::string& name, const std::string& label, std::optional<double> answer_confidence,
             const SceneLimits& limits) {
  J s;
  s["name"] = name;
  s["label"] = label;
  s["step"] = r.step;
  s["contacts"] = J::array();
  for (const Vec3& p : contacts.points) s["contacts"].push_back(point(p));
  s["free"] = J::array();
  for (std::size_t i : spread(free.size(), limits.free_points)) s["free"].push_back(point(free[i]));
  s["free_total"] = free.size();
  // One entry per object: the answer's hypothesis for the answer's object, each other object's
  // best by ln w; ranked by the object's posterior (the number the legend shows), ties by ln w,
  // the answer always among those drawn.
  struct Entry {
    const Hypothesis* h;
    double posterior;
  };
  std::vector<Entry> objects;
  std::set<std::uint32_t> seen;
  if (r.valid) {
    seen.insert(r.best.object);
    objects.push_back({&r.best, 0.0});
  }
  for (const Hypothesis& h : r.hypotheses)   // best ln w first
    if (seen.insert(h.object).second) objects.push_back({&h, 0.0});
  for (Entry& e : objects) e.posterior = e.h->object < r.posteriors.size() ? r.posteriors[e.h->object] : 0.0;
  std::stable_sort(objects.begin(), objects.end(), [](const Entry& a, const Entry& b) {
    return a.posterior != b.posterior ? a.posterior > b.posterior : a.h->log_weight > b.h->log_weight;
  });
  if (objects.size() > limits.hypotheses) {
    const auto answer = std::find_if(objects.begin(), objects.end(),
                                     [&](const Entry& e) { return r.valid && e.h->object == r.best.object; });
    const auto cut = objects.begin() + static_cast<std::ptrdiff_t>(limits.hypotheses);
    if (answer >= cut && limits.hypotheses > 0) std::rotate(cut - 1, answer, answer + 1);   // in, last
    objects.resize(limits.hypotheses);
  }
  s["answer"] = r.valid ? J(db.info(r.best.object).name) : J(nullptr);
  s["ranked_by"] = "posterior";
  s["hypotheses"] = J::array();
  for (std::size_t k = 0; k < objects.size(); ++k) {
    const Hypothesis& h = *objects[k].h;
    const bool is_answer = r.valid && h.object == r.best.object;
    J hj;
    hj["rank"] = k + 1;
    hj["object"] = db.info(h.object).name;
    hj["answer"] = is_answer;
    hj["posterior"] = objects[k].posterior;
    hj["confidence"] = is_answer && answer_confidence ? J(*answer_confidence) : J(nullptr);
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
