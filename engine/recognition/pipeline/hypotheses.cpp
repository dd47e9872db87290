#include "engine/recognition/pipeline/hypotheses.hpp"

#include "engine/detail.hpp"
#include "engine/geometry/kabsch.hpp"

#include <numbers>

namespace ts::inline recognition::pipeline {

bool better(const Working& a, const Working& b) {
  if (a.eval.log_weight != b.eval.log_weight) return a.eval.log_weight > b.eval.log_weight;
  if (a.born != b.born) return a.born < b.born;
  return a.cand.slot < b.cand.slot;
}

GeometryPins pin(const Database& db, const std::vector<Working>& w) {
  return GeometryPins(db, w, [](const Working& h) { return h.cand.object; });
}

void refine_all(const Scene& scene, const Database& db, const IcpSettings& s, std::vector<Working>& w) {
  const GeometryPins geometry = pin(db, w);
  detail::parallel_each(w.size(), 1, [&](std::size_t i) {
    Working& h = w[i];
    const IcpResult r = icp(scene, geometry[h.cand.object], h.cand.T_scene_object, s);
    if (r.valid) h.cand.T_scene_object = r.T_scene_object;
    h.icp_iterations = r.iterations;
    h.icp_converged = r.converged;
  });
}

void evaluate_each(const Scene& scene, const Database& db, const EvaluateSettings& s,
                   std::vector<Working>& w) {
  const GeometryPins geometry = pin(db, w);
  detail::parallel_each(w.size(), 1, [&](std::size_t i) {
    Working& h = w[i];
    h.eval = evaluate(scene, geometry[h.cand.object], db.info(h.cand.object), h.cand.T_scene_object, s);
  });
}

bool duplicates(const Working& a, const Working& b, double distance) {
  if (a.cand.object != b.cand.object) return false;
  const Pose d = a.cand.T_scene_object.inverse() * b.cand.T_scene_object;
  return d.translation().norm() < distance &&
         rotation_angle(d.linear()) < 2.0 * std::numbers::pi / 180.0;
}

void take(std::vector<Working>& into, const std::vector<Working>& from, std::size_t limit,
          bool dedupe, double distance) {
  for (const Working& h : from) {
    if (into.size() >= limit) break;
    if (dedupe) {
      bool dup = false;
      for (const Working& k : into)
        if (duplicates(k, h, distance)) { dup = true; break; }
      if (dup) continue;
    }
    into.push_back(h);
  }
}

std::vector<Working> from_scored(const std::vector<Candidate>& cands,
                                 const std::vector<ScoredCandidate>& top, int born) {
  std::vector<Working> w;
  w.reserve(top.size());
  for (const ScoredCandidate& sc : top) {
    Working h;
    h.cand = cands[sc.index];
    h.eval = sc.eval;
    h.born = born;
    w.push_back(h);
  }
  return w;
}

}  // namespace ts::recognition::pipeline
