#include "engine/shortlist.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace ts {

std::vector<double> screen_candidates(const Scene& scene, const Database& db,
                                      const std::vector<Candidate>& cands, const ShortlistSettings& s) {
  std::vector<double> score(cands.size(), 1.0);
  const std::size_t m = std::min(s.contacts, scene.ordered.size());
  if (m == 0 || !(s.outlier_distance > 0.0)) return score;
  for (const Candidate& c : cands) (void)db.keypoints(c.object);  // load on this thread first
  const double voxel = db.settings().scan.coarse_voxel;
  const double inv2 = 1.0 / (s.outlier_distance * s.outlier_distance);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cands.size(), 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const Candidate& c = cands[i];
                        const PointCloud& coarse = db.keypoints(c.object).coarse;
                        const KdTree3& tree = db.keypoints(c.object).tree;
                        if (tree.size() == 0) continue;
                        const Pose T = c.T_scene_object.inverse();
                        double sum = 0.0;
                        for (std::size_t k = 0; k < m; ++k) {
                          const Vec3 p = T * scene.ordered[k];
                          const Neighbour nb = tree.nearest(p);
                          const Vec3 v = p - coarse.points[nb.index];
                          double d = std::sqrt(nb.sq_distance) - voxel;
                          if (coarse.has_normals()) d = std::max(d, std::abs(coarse.normals[nb.index].dot(v)));
                          sum += std::min(1.0, d * d * inv2);
                        }
                        score[i] = sum / double(m);
                      }
                    });
  return score;
}

Shortlist shortlist_objects(const Scene& scene, const Database& db, const std::vector<Candidate>& cands,
                            const std::vector<std::uint32_t>& always, const ShortlistSettings& s) {
  Shortlist out;
  out.best.assign(db.size(), 1.0);
  out.mask.assign(db.size(), 0);
  std::vector<std::uint8_t> reached(db.size(), 0);
  for (const Candidate& c : cands) reached[c.object] = 1;
  const auto n_reached = static_cast<std::size_t>(std::count(reached.begin(), reached.end(), 1));
  if (s.objects == 0 || n_reached <= s.objects) {
    out.mask = reached;
    out.kept = n_reached;
    for (std::uint32_t o = 0; o < db.size(); ++o)
      if (reached[o]) out.ranked.push_back(o);
    return out;
  }
  const std::vector<double> score = screen_candidates(scene, db, cands, s);
  for (std::size_t i = 0; i < cands.size(); ++i)
    out.best[cands[i].object] = std::min(out.best[cands[i].object], score[i]);
  for (std::uint32_t o = 0; o < db.size(); ++o)
    if (reached[o]) out.ranked.push_back(o);
  std::stable_sort(out.ranked.begin(), out.ranked.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return out.best[a] < out.best[b]; });
  out.active = true;
  for (std::size_t i = 0; i < s.objects; ++i) out.mask[out.ranked[i]] = 1;
  for (std::uint32_t o : always)
    if (o < db.size()) out.mask[o] = 1;
  out.kept = static_cast<std::size_t>(std::count(out.mask.begin(), out.mask.end(), 1));
  return out;
}

}  // namespace ts
