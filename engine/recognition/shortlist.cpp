#include "engine/recognition/shortlist.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <set>

namespace ts {
inline namespace recognition {

namespace {

/// e of contact k of the scene under candidate pose T_object_scene (see shortlist.hpp).
struct Screen {
  const Scene& scene;
  const PointCloud& coarse;
  const KdTree3& tree;
  double voxel, inv2;
  /// Beyond this distance the nearest point gives e = 1 exactly: d >= |p - x| - voxel is then
  /// more than the outlier distance by a margin (1e-6 of it) that the rounding of the reach, its
  /// square and the square root cannot cross while the voxel is below about 1e9 outlier
  /// distances (the defaults: 5 mm and 1 cm).
  double reach;
  Screen(const Scene& sc, const PointCloud& c, const KdTree3& t, double voxel_m, double outlier_m)
      : scene(sc), coarse(c), tree(t), voxel(voxel_m), inv2(1.0 / (outlier_m * outlier_m)),
        reach(voxel_m + outlier_m * (1.0 + 1e-6)) {}
  double error(const Pose& T_object_scene, std::size_t k) const {
    const Vec3 p = T_object_scene * scene.ordered[k];
    const Neighbour nb = tree.nearest_within(p, reach);
    if (!(nb.sq_distance < std::numeric_limits<double>::infinity())) return 1.0;
    const Vec3 v = p - coarse.points[nb.index];
    double d = std::sqrt(nb.sq_distance) - voxel;
    if (coarse.has_normals()) d = std::max(d, std::abs(coarse.normals[nb.index].dot(v)));
    return std::min(1.0, d * d * inv2);
  }
};

}  // namespace

std::vector<double> screen_candidates(const Scene& scene, const Database& db,
                                      const std::vector<Candidate>& cands, const ShortlistSettings& s) {
  std::vector<double> score(cands.size(), 1.0);
  const std::size_t m = std::min(s.contacts, scene.ordered.size());
  if (m == 0 || !(s.outlier_distance > 0.0)) return score;
  for (const Candidate& c : cands) (void)db.keypoints(c.object);  // load on this thread first
  const double voxel = db.settings().scan.coarse_voxel;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cands.size(), 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const Candidate& c = cands[i];
                        const ObjectKeypoints& kp = db.keypoints(c.object);
                        if (kp.tree().size() == 0) continue;
                        const Screen sc(scene, kp.coarse, kp.tree(), voxel, s.outlier_distance);
                        const Pose T = c.T_scene_object.inverse();
                        double sum = 0.0;
                        for (std::size_t k = 0; k < m; ++k) sum += sc.error(T, k);
                        score[i] = sum / double(m);
                      }
                    });
  return score;
}

std::vector<double> screen_objects(const Scene& scene, const Database& db, const std::vector<Candidate>& cands,
                                   const ShortlistSettings& s, std::size_t keep) {
  std::vector<double> best(db.size(), 1.0);
  const std::size_t m = std::min(s.contacts, scene.ordered.size());
  if (m == 0 || !(s.outlier_distance > 0.0)) return best;
  std::vector<std::vector<std::uint32_t>> of(db.size());   // candidates of each object, in order
  for (std::size_t i = 0; i < cands.size(); ++i) of[cands[i].object].push_back(static_cast<std::uint32_t>(i));
  std::vector<std::uint32_t> objects;
  for (std::uint32_t o = 0; o < db.size(); ++o)
    if (!of[o].empty()) {
      objects.push_back(o);
      (void)db.keypoints(o);   // load on this thread first
    }
  // Objects with the most candidates first: likely the good ones, which lower the bar early.
  std::stable_sort(objects.begin(), objects.end(),
                   [&](std::uint32_t x, std::uint32_t y) { return of[x].size() > of[y].size(); });
  const double voxel = db.settings().scan.coarse_voxel;
  // The bar of `keep`: the keep-th smallest of the objects' best scores so far (each an upper
  // bound of that object's final best), so never below the final keep-th best.
  std::mutex bar_mutex;
  std::multiset<double> bests;
  std::atomic<double> bar{std::numeric_limits<double>::infinity()};
  auto publish = [&](double before, double now) {
    std::lock_guard<std::mutex> lock(bar_mutex);
    if (before < 1.5) bests.erase(bests.find(before));
    bests.insert(now);
    if (bests.size() >= keep) bar.store(*std::next(bests.begin(), static_cast<std::ptrdiff_t>(keep - 1)));
  };
  tbb::parallel_for(std::size_t{0}, objects.size(), [&](std::size_t j) {
    const std::uint32_t o = objects[j];
    const ObjectKeypoints& kp = db.keypoints(o);
    if (kp.tree().size() == 0) return;
    const Screen sc(scene, kp.coarse, kp.tree(), voxel, s.outlier_distance);
    double low = 1.0, published = 2.0;   // 2: not published yet
    for (std::uint32_t i : of[o]) {
      // Stop once the partial sum (each e >= 0) shows the candidate cannot beat the object's
      // best so far (nor, with keep, the bar), with a margin that rounding cannot cross.
      const double limit = keep > 0 ? std::min(low, bar.load(std::memory_order_relaxed)) : low;
      const double stop = limit * double(m) * (1.0 + 1e-12) + 1e-12;
      const Pose T = cands[i].T_scene_object.inverse();
      double sum = 0.0;
      std::size_t k = 0;
      for (; k < m && sum <= stop; ++k) sum += sc.error(T, k);
      if (k == m && sum <= stop && sum / double(m) < low) {
        low = sum / double(m);
        if (keep > 0) {
          publish(published, low);
          published = low;
        }
      }
    }
    best[o] = low;
  });
  if (keep > 0) {
    // Only the keep best are exact (the others may have been cut short, depending on timing):
    // report 1 for the others, so that the result does not depend on the threads.
    std::vector<std::uint32_t> order = objects;
    std::sort(order.begin(), order.end(),
              [&](std::uint32_t x, std::uint32_t y) { return best[x] != best[y] ? best[x] < best[y] : x < y; });
    for (std::size_t r = keep; r < order.size(); ++r) best[order[r]] = 1.0;
  }
  return best;
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
  out.best = screen_objects(scene, db, cands, s, s.objects);
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

}  // namespace recognition
}  // namespace ts
