// Search structures: exact 3-D nearest neighbours (nanoflann) and the database-wide feature
// index (FLANN). Both are immutable after construction and safe to query from many threads.
// Ties are broken by the smaller index, so results never depend on thread count.
#pragma once

#include "engine/core.hpp"

#include <memory>
#include <span>

namespace ts {
inline namespace geometry {

struct Neighbour {
  std::uint32_t index = 0;
  double sq_distance = 0.0;
};

/// Exact k-d tree over 3-D points. Keeps its own copy of the points, or (KdTree3::over) searches
/// points its owner keeps beside it. sq_distance is
/// (q0-p0)^2 + (q1-p1)^2 + (q2-p2)^2 summed in that order; radius() is inclusive (<= r).
class KdTree3 {
 public:
  KdTree3();
  explicit KdTree3(std::vector<Vec3> points);
  /// A tree over points it does not copy: `points`' buffer must outlive the tree unchanged
  /// (moving the vector keeps its buffer; resizing or assigning it does not). For a cloud and its
  /// tree held together (a database object's coarse and fine clouds): half the memory of a copy.
  static KdTree3 over(const std::vector<Vec3>& points);
  ~KdTree3();
  KdTree3(KdTree3&&) noexcept;
  KdTree3& operator=(KdTree3&&) noexcept;

  std::size_t size() const;
  std::span<const Vec3> points() const;
  std::size_t memory_bytes() const;   ///< own points and tree nodes (estimate from their counts)
  /// Nearest point; sq_distance = +inf when the tree is empty.
  Neighbour nearest(const Vec3& q) const;
  /// nearest(q), bit for bit, when some point lies within `max_distance` of q; otherwise none
  /// (sq_distance = +inf) or some point a few ulps beyond `max_distance`. Searches only
  /// the part of the tree within reach, so a query far from every point costs a few nodes.
  Neighbour nearest_within(const Vec3& q, double max_distance) const;
  /// k nearest, sorted by distance then index.
  std::vector<Neighbour> knn(const Vec3& q, std::size_t k) const;
  /// All points within `radius`, sorted by distance then index.
  std::vector<Neighbour> radius(const Vec3& q, double radius) const;
  /// All points within `radius` into `out` (cleared first; its capacity is reused). Unsorted,
  /// the order is the tree's traversal order, which depends only on the points and q (so it is
  /// still deterministic); `sorted` = true sorts as radius() does.
  void radius(const Vec3& q, double radius, std::vector<Neighbour>& out, bool sorted) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// One database feature: which object, which coarse point.
struct FeatureRef {
  std::uint32_t object = 0;
  std::uint32_t point = 0;
};

struct FeatureIndexSettings {
  /// exact: single k-d tree, unlimited checks; approximate: randomized trees. Exact by default:
  /// on the dev45 database (210k FPFH) it answers W = 3000 in ~2.5 ms and W = 100 in ~0.35 ms
  /// per query, while the approximate forest needs ~16k checks (slower than exact) to pass 0.9
  /// recall at W = 3000 (experiments/bench/bench_features.cpp).
  bool exact = true;
  int trees = 4;        ///< approximate mode: randomized k-d trees
  int checks = 256;     ///< approximate mode: leaves visited per query (at least W are visited)
  std::uint64_t seed = 1;  ///< approximate mode: seed of the randomized trees' split choices
};

/// Index over all objects' features (the cumulative feature k-d tree KT_db,cum^feat).
/// Exact mode: FLANN's single k-d tree with unlimited checks. Approximate mode: a randomized
/// k-d forest searched best-bin-first (FLANN's KDTreeIndex algorithm) whose split choices come
/// from ts::Rng(seed): the same features and settings give the same results on every run.
/// sq_distance = sum over bins i = 0..dim-1, in that order, of (double(a_i) - double(b_i))^2.
class FeatureIndex {
 public:
  FeatureIndex();
  FeatureIndex(FeatureRows features, std::vector<FeatureRef> refs,
               const FeatureIndexSettings& settings);
  ~FeatureIndex();
  FeatureIndex(FeatureIndex&&) noexcept;
  FeatureIndex& operator=(FeatureIndex&&) noexcept;

  std::size_t size() const;
  const FeatureRef& ref(std::size_t i) const;
  /// The W nearest features to `query` (dim values, L2), sorted by distance then index.
  std::vector<Neighbour> knn(const float* query, std::size_t w) const;
  int dim() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace geometry
}  // namespace ts
