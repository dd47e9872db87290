// Shape prior: which objects could have produced the contacts, before any pose is known
// (Touchstone extension for large databases: "leave out what a scene does not need").
//
// On a database of thousands of objects a step can search the features of only a slice of
// them; drawing that slice blindly reaches the true object every few steps at best. The shape
// prior ranks every object by how well the contacts' point pairs fit the object's own pair
// statistics, a pose-free test: for a pair of points with unit normals (p_a, n_a), (p_b, n_b),
//     d = |p_b - p_a|,  u = (p_b - p_a) / d,
//     (x, y, z) = (min(|n_a.u|, |n_b.u|), max(|n_a.u|, |n_b.u|), |n_a.n_b|)
// (absolute values: the contacts' normals are oriented by a heuristic that is wrong on part of
// the surface). Each object holds the histogram h_o of these features over the pairs of a
// sample of its coarse keypoints (distance in bins of distance_bin, split linearly between the
// two nearest bins; each angle term in angle_bins bins), and the contacts' score for the object
// is the mean over the contact pairs of ln(h_o(bin) + floor), the log-likelihood of the pairs
// under the object's pair distribution (the pairs treated as independent: for ranking only).
// A pair longer than the object's diagonal falls outside its histogram and scores ln(floor):
// the prior also knows each object's size.
// Contacts that mostly lack normals (fewer than half have one: fingertips, a probe, a
// points-only cloud) are scored on the pair distances alone, against each object's marginal
// of the same histogram (the D2 shape distribution, Osada et al. 2002): a weaker test, but one
// that still ranks the objects by size and shape where the angles are unknown. Pose-free and geometry-free: the histograms come
// from the keypoints, which stay in memory; a step scores every object in a few milliseconds.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/scene.hpp"

#include <cstdint>
#include <memory>
#include <vector>

namespace ts {
inline namespace recognition {

struct ShapePriorSettings {
  double distance_bin = 0.01;         ///< m, pair-distance bin
  int angle_bins = 6;                 ///< bins of each angle term (|cos| in [0, 1])
  std::size_t object_points = 500;    ///< keypoints per object whose pairs make its histogram
  std::size_t scene_pairs = 1000;     ///< contact pairs scored per step (all when fewer)
  double min_pair_distance = 0.02;    ///< m; closer pairs (one patch) are not scored
  double floor = 1e-5;                ///< probability floor of a bin (ln(floor): an empty bin)
};

/// The objects' pair histograms (immutable after construction; safe to query from many
/// threads). Deterministic: the same database and settings give the same histograms.
class ShapePrior {
 public:
  ShapePrior(const Database& db, const ShapePriorSettings& settings,
             const std::vector<std::uint8_t>& objects = {});
  ~ShapePrior();
  ShapePrior(ShapePrior&&) noexcept;
  ShapePrior& operator=(ShapePrior&&) noexcept;

  std::size_t size() const;                ///< database objects

  /// Per database object, the mean log-likelihood of the scene's contact pairs (higher is
  /// better; -inf for objects not allowed, outside the construction mask, or when the scene
  /// has no scorable pair). The pairs are drawn from Rng(seed, step): the same for any thread
  /// count.
  std::vector<double> score(const Scene& scene, const std::vector<std::uint8_t>& allowed,
                            std::uint64_t seed, std::uint64_t step) const;

  /// One prior per (database, settings, object mask), shared while someone holds it.
  static std::shared_ptr<const ShapePrior> shared(const Database& db, const ShapePriorSettings& settings,
                                                  const std::vector<std::uint8_t>& objects = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Objects with a finite score, best first (ties: smaller index).
std::vector<std::uint32_t> rank_by_prior(const std::vector<double>& score);

}  // namespace recognition
}  // namespace ts
