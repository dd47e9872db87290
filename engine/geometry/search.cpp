// Exact 3-D neighbours on nanoflann 1.4 and the feature index (exact: FLANN's single k-d tree;
// approximate: our own seeded randomized k-d forest, see FeatureIndex below).
//
// Tie-breaking. Both libraries prune with `dist < worstDist()` at the leaves, so with the stock
// result sets the point that survives among equidistant candidates depends on traversal order.
// Our result sets order candidates by (distance, index) and report a worstDist() slightly above
// the current k-th distance, so every candidate tied with the k-th reaches addPoint() and the
// smaller index wins. The slack only widens the search by a few ulps; the result is exact.
#include "engine/geometry/search.hpp"

#include <flann/algorithms/kdtree_single_index.h>
#include <nanoflann.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>

namespace ts {
inline namespace geometry {

namespace {

/// Strictly above `worst` by a few ulps (or the smallest positive double when worst is 0), so
/// that `dist < bound` admits every dist == worst despite rounding in the tree's bounds.
inline double tie_bound(double worst) {
  if (worst <= 0.0) return std::numeric_limits<double>::denorm_min();
  return std::max(worst * (1.0 + 1e-12), std::nextafter(worst, std::numeric_limits<double>::infinity()));
}

inline bool before(double da, std::uint32_t ia, double db, std::uint32_t ib) {
  return da < db || (da == db && ia < ib);
}

/// k best (distance, index) pairs as a max-heap on (distance, index). O(log k) per insertion.
class TopK {
 public:
  explicit TopK(std::size_t k) : k_(k) { heap_.reserve(std::min<std::size_t>(k, 1 << 16)); }

  bool full() const { return heap_.size() == k_; }
  std::size_t size() const { return heap_.size(); }
  /// Bound for the tree's pruning: +inf until full, then just above the k-th distance (kept
  /// up to date by add: the trees ask for it at every node).
  double bound() const { return bound_; }
  void add(double d, std::uint32_t i) {
    if (k_ == 0) return;
    if (!full()) {
      heap_.push_back({i, d});
      std::push_heap(heap_.begin(), heap_.end(), less);
    } else if (before(d, i, heap_.front().sq_distance, heap_.front().index)) {
      std::pop_heap(heap_.begin(), heap_.end(), less);
      heap_.back() = {i, d};
      std::push_heap(heap_.begin(), heap_.end(), less);
    } else {
      return;
    }
    if (full()) bound_ = tie_bound(heap_.front().sq_distance);
  }
  std::vector<Neighbour> sorted() && {
    std::sort_heap(heap_.begin(), heap_.end(), less);
    return std::move(heap_);
  }

 private:
  static bool less(const Neighbour& a, const Neighbour& b) {
    return before(a.sq_distance, a.index, b.sq_distance, b.index);
  }
  std::size_t k_;
  std::vector<Neighbour> heap_;
  double bound_ = std::numeric_limits<double>::max();
};

void sort_neighbours(std::vector<Neighbour>& v) {
  std::sort(v.begin(), v.end(), [](const Neighbour& a, const Neighbour& b) {
    return before(a.sq_distance, a.index, b.sq_distance, b.index);
  });
}

// ---------------------------------------------------------------------------------------------
// KdTree3 on nanoflann

struct CloudAdaptor {
  const Vec3* pts = nullptr;
  std::size_t n = 0;
  std::size_t kdtree_get_point_count() const { return n; }
  double kdtree_get_pt(std::uint32_t i, std::size_t d) const { return pts[i][static_cast<int>(d)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};

// sq_distance = (q0-p0)^2 + (q1-p1)^2 + (q2-p2)^2 accumulated in this order (nanoflann's
// L2_Simple_Adaptor), which a brute-force oracle can reproduce bit for bit.
using NanoTree = nanoflann::KDTreeSingleIndexAdaptor<
    nanoflann::L2_Simple_Adaptor<double, CloudAdaptor, double, std::uint32_t>, CloudAdaptor, 3,
    std::uint32_t>;

/// nanoflann result set: k best by (distance, index).
class NanoKnnSet {
 public:
  using DistanceType = double;
  using IndexType = std::uint32_t;
  explicit NanoKnnSet(std::size_t k) : top_(k) {}
  bool full() const { return top_.full(); }
  std::size_t size() const { return top_.size(); }
  double worstDist() const { return top_.bound(); }
  bool addPoint(double d, std::uint32_t i) {
    top_.add(d, i);
    return true;
  }
  std::vector<Neighbour> take() { return std::move(top_).sorted(); }

 private:
  TopK top_;
};

/// nanoflann result set: the nearest by (distance, index), as NanoKnnSet(1) without a heap.
class NanoNearestSet {
 public:
  using DistanceType = double;
  using IndexType = std::uint32_t;
  NanoNearestSet() = default;
  /// Only points with sq_distance < tie_bound(max_sq) are admitted (every one within reach).
  explicit NanoNearestSet(double max_sq) : bound_(tie_bound(max_sq)) {}
  bool full() const { return found_; }
  std::size_t size() const { return found_ ? 1 : 0; }
  double worstDist() const { return bound_; }
  bool addPoint(double d, std::uint32_t i) {
    if (!found_ || before(d, i, best_.sq_distance, best_.index)) {
      best_ = {i, d};
      found_ = true;
      bound_ = tie_bound(d);
    }
    return true;
  }
  const Neighbour& best() const { return best_; }

 private:
  bool found_ = false;
  Neighbour best_{0, std::numeric_limits<double>::infinity()};
  double bound_ = std::numeric_limits<double>::max();
};

/// nanoflann result set: everything with sq_distance <= r2 (inclusive, unlike nanoflann's own).
class NanoRadiusSet {
 public:
  using DistanceType = double;
  using IndexType = std::uint32_t;
  NanoRadiusSet(double r2, std::vector<Neighbour>& out) : r2_(r2), bound_(tie_bound(r2)), out_(out) {}
  bool full() const { return true; }
  std::size_t size() const { return out_.size(); }
  double worstDist() const { return bound_; }
  bool addPoint(double d, std::uint32_t i) {
    if (d <= r2_) out_.push_back({i, d});
    return true;
  }

 private:
  double r2_, bound_;
  std::vector<Neighbour>& out_;
};

}  // namespace

struct KdTree3::Impl {
  std::vector<Vec3> own;            // empty for a view (KdTree3::over)
  CloudAdaptor adaptor;
  std::unique_ptr<NanoTree> tree;   // null when empty

  Impl(std::vector<Vec3> p, const std::vector<Vec3>* view) : own(std::move(p)) {
    const std::vector<Vec3>& points = view ? *view : own;
    adaptor = {points.data(), points.size()};
    if (points.size() >= std::numeric_limits<std::uint32_t>::max())
      throw Error("KdTree3: too many points for 32-bit indices");
    if (!points.empty()) {
      tree = std::make_unique<NanoTree>(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
    }
  }
};

KdTree3::KdTree3() : impl_(std::make_unique<Impl>(std::vector<Vec3>{}, nullptr)) {}
KdTree3::KdTree3(std::vector<Vec3> points) : impl_(std::make_unique<Impl>(std::move(points), nullptr)) {}
KdTree3 KdTree3::over(const std::vector<Vec3>& points) {
  KdTree3 t;
  t.impl_ = std::make_unique<Impl>(std::vector<Vec3>{}, &points);
  return t;
}
KdTree3::~KdTree3() = default;
KdTree3::KdTree3(KdTree3&&) noexcept = default;
KdTree3& KdTree3::operator=(KdTree3&&) noexcept = default;

std::size_t KdTree3::memory_bytes() const {
  if (!impl_) return 0;
  const std::size_t n = impl_->adaptor.n;
  // its own points, the tree's index permutation, and about one node (~64 bytes) per 5 points
  // (leaves of at most 10)
  return impl_->own.capacity() * sizeof(Vec3) + n * sizeof(std::uint32_t) + (n / 5 + 1) * 64;
}

std::size_t KdTree3::size() const { return impl_ ? impl_->adaptor.n : 0; }

std::span<const Vec3> KdTree3::points() const {
  if (!impl_) return {};
  return {impl_->adaptor.pts, impl_->adaptor.n};
}

Neighbour KdTree3::nearest(const Vec3& q) const {
  if (!impl_ || !impl_->tree) return {0, std::numeric_limits<double>::infinity()};
  NanoNearestSet set;
  const double qv[3] = {q.x(), q.y(), q.z()};
  impl_->tree->findNeighbors(set, qv, nanoflann::SearchParams());
  return set.full() ? set.best() : Neighbour{0, std::numeric_limits<double>::infinity()};
}

Neighbour KdTree3::nearest_within(const Vec3& q, double max_distance) const {
  if (!impl_ || !impl_->tree || !(max_distance >= 0.0)) return {0, std::numeric_limits<double>::infinity()};
  // The nearest is the minimum by (distance, index) over the points admitted; every point
  // nearer than a point admitted is admitted too, so what is found is nearest()'s answer.
  NanoNearestSet set(max_distance * max_distance);
  const double qv[3] = {q.x(), q.y(), q.z()};
  impl_->tree->findNeighbors(set, qv, nanoflann::SearchParams());
  return set.full() ? set.best() : Neighbour{0, std::numeric_limits<double>::infinity()};
}

std::vector<Neighbour> KdTree3::knn(const Vec3& q, std::size_t k) const {
  if (!impl_ || !impl_->tree || k == 0) return {};
  NanoKnnSet set(std::min(k, impl_->adaptor.n));
  const double qv[3] = {q.x(), q.y(), q.z()};
  impl_->tree->findNeighbors(set, qv, nanoflann::SearchParams());
  return set.take();
}

std::vector<Neighbour> KdTree3::radius(const Vec3& q, double radius) const {
  std::vector<Neighbour> out;
  this->radius(q, radius, out, true);
  return out;
}

void KdTree3::radius(const Vec3& q, double radius, std::vector<Neighbour>& out, bool sorted) const {
  out.clear();
  if (!impl_ || !impl_->tree || !(radius >= 0.0)) return;
  NanoRadiusSet set(radius * radius, out);
  const double qv[3] = {q.x(), q.y(), q.z()};
  impl_->tree->findNeighbors(set, qv, nanoflann::SearchParams());
  if (sorted) sort_neighbours(out);
}

// ---------------------------------------------------------------------------------------------
// FeatureIndex

namespace {

/// Squared L2 between two features of `dim` values, accumulated in double in bin order
/// (documented in the header so that oracles can reproduce it exactly).
inline double feature_sq_distance(const float* a, const float* b, int dim) {
  double s = 0.0;
  for (int i = 0; i < dim; ++i) {
    const double d = static_cast<double>(a[i]) - static_cast<double>(b[i]);
    s += d * d;
  }
  return s;
}

/// As feature_sq_distance, but returns early (a partial sum > bound) once the sum exceeds a
/// positive bound, checked every 11 values (FPFH's blocks). Accepted candidates therefore always
/// carry the full sum.
inline double feature_sq_distance_bounded(const float* a, const float* b, int dim, double bound) {
  if (!(bound > 0.0)) return feature_sq_distance(a, b, dim);
  double s = 0.0;
  for (int block = 0; block < dim; block += 11) {
    for (int i = block; i < std::min(block + 11, dim); ++i) {
      const double d = static_cast<double>(a[i]) - static_cast<double>(b[i]);
      s += d * d;
    }
    if (s > bound) return s;
  }
  return s;
}

/// FLANN distance functor with the accumulation above (FLANN's own L2<float> sums in float,
/// four bins at a time).
struct FeatureL2 {
  using is_kdtree_distance = bool;
  using ElementType = float;
  using ResultType = double;
  /// Stops early, returning a partial sum above `worst`, once the candidate cannot qualify
  /// (the partial sums only grow, so the decision is the same as with the full sum).
  template <typename It1, typename It2>
  ResultType operator()(It1 a, It2 b, std::size_t size, ResultType worst = -1) const {
    return feature_sq_distance_bounded(&a[0], &b[0], static_cast<int>(size), worst);
  }
  template <typename U, typename V>
  ResultType accum_dist(const U& a, const V& b, int) const {
    const double d = static_cast<double>(a) - static_cast<double>(b);
    return d * d;
  }
};

/// FLANN result set with (distance, index) tie-breaking.
class FlannKnnSet final : public flann::ResultSet<double> {
 public:
  explicit FlannKnnSet(std::size_t k) : top_(k) {}
  bool full() const override { return top_.full(); }
  void addPoint(double d, std::size_t i) override { top_.add(d, static_cast<std::uint32_t>(i)); }
  double worstDist() const override { return top_.bound(); }
  std::vector<Neighbour> take() { return std::move(top_).sorted(); }

 private:
  TopK top_;
};

/// Randomized k-d forest (Silpa-Anan & Hartley 2008, as in FLANN's KDTreeIndex; Muja & Lowe
/// 2009), rewritten because FLANN 1.9 shuffles with std::random_device when it builds the trees,
/// so its approximate results differ from run to run. Here every random choice comes from
/// ts::Rng(seed, tree), which makes the index (and every query) reproducible.
class KdForest {
 public:
  KdForest(const FeatureRows& data, int trees, std::uint64_t seed) : data_(data) {
    trees_.resize(static_cast<std::size_t>(std::max(trees, 1)));
    tbb::parallel_for(std::size_t(0), trees_.size(), [&](std::size_t t) {
      Rng rng(seed, 0x6b64666f72657374ULL /* "kdforest" */, t);
      build_tree(trees_[t], rng);
    });
  }

  std::vector<Neighbour> knn(const float* q, std::size_t k, int max_checks) const {
    const std::size_t n = data_.size();
    TopK top(std::min(k, n));
    if (n == 0 || k == 0) return {};
    std::vector<std::uint64_t> checked((n + 63) / 64, 0);
    std::priority_queue<Branch, std::vector<Branch>, std::greater<Branch>> branches;
    int checks = 0;
    for (std::uint32_t t = 0; t < trees_.size(); ++t)
      descend(q, t, 0, 0.0, top, checked, checks, max_checks, branches);
    while (!branches.empty() && (checks < max_checks || !top.full())) {
      const Branch b = branches.top();
      branches.pop();
      descend(q, b.tree, b.node, b.mindist, top, checked, checks, max_checks, branches);
    }
    return std::move(top).sorted();
  }

 private:
  static constexpr int kSampleMean = 100;   // points used to estimate the split (FLANN: 100)
  static constexpr int kRandDim = 5;        // split among the top-variance dims (FLANN: 5)

  struct Node {
    std::int32_t child1 = -1;   // -1: leaf
    std::int32_t child2 = -1;
    std::int32_t feat = 0;      // split dimension, or the point index at a leaf
    float val = 0.0f;           // split value: child1 holds < val (and ties balanced)
  };
  using Tree = std::vector<Node>;

  struct Branch {
    double mindist;
    std::uint32_t tree;
    std::int32_t node;
    bool operator>(const Branch& o) const {
      if (mindist != o.mindist) return mindist > o.mindist;
      if (tree != o.tree) return tree > o.tree;
      return node > o.node;
    }
  };

  void build_tree(Tree& tree, Rng& rng) const {
    const std::size_t n = data_.size();
    std::vector<std::uint32_t> ind(n);
    for (std::size_t i = 0; i < n; ++i) ind[i] = static_cast<std::uint32_t>(i);
    for (std::size_t i = n; i > 1; --i) std::swap(ind[i - 1], ind[rng.index(i)]);
    tree.reserve(2 * n);
    tree.emplace_back();
    if (n == 0) return;
    // Explicit stack (node slot, first, count) instead of recursion.
    struct Job { std::int32_t node; std::size_t first, count; };
    std::vector<Job> stack{{0, 0, n}};
    while (!stack.empty()) {
      const Job j = stack.back();
      stack.pop_back();
      std::uint32_t* idx = ind.data() + j.first;
      if (j.count == 1) {
        tree[j.node].feat = static_cast<std::int32_t>(idx[0]);
        continue;
      }
      int feat;
      float val;
      choose_split(idx, j.count, rng, feat, val);
      const std::size_t left = split_point(idx, j.count, feat, val);
      const auto c1 = static_cast<std::int32_t>(tree.size());
      tree.emplace_back();
      tree.emplace_back();
      tree[j.node].child1 = c1;
      tree[j.node].child2 = c1 + 1;
      tree[j.node].feat = feat;
      tree[j.node].val = val;
      stack.push_back({c1 + 1, j.first + left, j.count - left});
      stack.push_back({c1, j.first, left});
    }
  }

  void choose_split(const std::uint32_t* idx, std::size_t count, Rng& rng, int& feat,
                    float& val) const {
    const std::size_t m = std::min<std::size_t>(count, kSampleMean);
    const int dim = data_.dim();
    std::vector<double> mean(static_cast<std::size_t>(dim), 0.0), var(static_cast<std::size_t>(dim), 0.0);
    for (std::size_t i = 0; i < m; ++i)
      for (int d = 0; d < dim; ++d) mean[d] += data_.row(idx[i])[d];
    for (auto& v : mean) v /= static_cast<double>(m);
    for (std::size_t i = 0; i < m; ++i)
      for (int d = 0; d < dim; ++d) {
        const double e = data_.row(idx[i])[d] - mean[d];
        var[d] += e * e;
      }
    // Top kRandDim dimensions by variance (ties by smaller dimension), one chosen at random.
    std::vector<int> order(static_cast<std::size_t>(dim));
    for (int d = 0; d < dim; ++d) order[d] = d;
    std::partial_sort(order.begin(), order.begin() + kRandDim, order.end(), [&](int a, int b) {
      return var[a] > var[b] || (var[a] == var[b] && a < b);
    });
    feat = order[rng.index(kRandDim)];
    val = static_cast<float>(mean[feat]);
  }

  /// Partition idx so that [0, lim1) < val, [lim1, lim2) == val, [lim2, count) > val, and
  /// return a split index that keeps both sides non-empty (ties spread to balance, as FLANN).
  std::size_t split_point(std::uint32_t* idx, std::size_t count, int feat, float val) const {
    auto part = [&](std::size_t from, auto goes_left) {
      std::size_t i = from;
      for (std::size_t j = from; j < count; ++j)
        if (goes_left(data_.row(idx[j])[feat])) std::swap(idx[i++], idx[j]);
      return i;
    };
    const std::size_t lim1 = part(0, [&](float x) { return x < val; });
    const std::size_t lim2 = part(lim1, [&](float x) { return x <= val; });
    std::size_t s;
    if (lim1 > count / 2) s = lim1;
    else if (lim2 < count / 2) s = lim2;
    else s = count / 2;
    if (s == 0 || s == count) s = count / 2;
    return s;
  }

  template <class Heap>
  void descend(const float* q, std::uint32_t t, std::int32_t node, double mindist, TopK& top,
               std::vector<std::uint64_t>& checked, int& checks, int max_checks,
               Heap& branches) const {
    const Tree& tree = trees_[t];
    for (;;) {
      const Node& nd = tree[node];
      if (nd.child1 < 0) {
        const auto i = static_cast<std::uint32_t>(nd.feat);
        std::uint64_t& word = checked[i >> 6];
        const std::uint64_t bit = std::uint64_t(1) << (i & 63);
        if ((word & bit) || (checks >= max_checks && top.full())) return;
        word |= bit;
        ++checks;
        top.add(feature_sq_distance_bounded(q, data_.row(i), data_.dim(), top.full() ? top.bound() : -1.0), i);
        return;
      }
      const double diff = static_cast<double>(q[nd.feat]) - static_cast<double>(nd.val);
      const std::int32_t best = diff < 0 ? nd.child1 : nd.child2;
      const std::int32_t other = diff < 0 ? nd.child2 : nd.child1;
      const double d = mindist + diff * diff;
      // FLANN's pruning. d (the path's summed squared cuts) may exceed the true distance to the
      // cell, so even an unlimited budget does not make this search exact; keeping every
      // branch instead made large budgets 2-5x slower for no practical gain.
      if (d < top.bound() || !top.full()) branches.push({d, t, other});
      node = best;
    }
  }

  const FeatureRows& data_;
  std::vector<Tree> trees_;
};

using FlannExact = flann::KDTreeSingleIndex<FeatureL2>;

}  // namespace

struct FeatureIndex::Impl {
  FeatureRows features;
  std::vector<FeatureRef> refs;
  FeatureIndexSettings settings;
  std::unique_ptr<FlannExact> exact;
  std::unique_ptr<KdForest> forest;
};

FeatureIndex::FeatureIndex() : impl_(std::make_unique<Impl>()) {}

FeatureIndex::FeatureIndex(FeatureRows features, std::vector<FeatureRef> refs,
                           const FeatureIndexSettings& settings)
    : impl_(std::make_unique<Impl>()) {
  if (features.size() != refs.size())
    throw Error("FeatureIndex: " + std::to_string(features.size()) + " features but " +
                std::to_string(refs.size()) + " references");
  if (features.size() >= static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
    throw Error("FeatureIndex: too many features");
  if (!settings.exact && (settings.trees < 1 || settings.checks < 1))
    throw Error("FeatureIndex: trees and checks must be >= 1", {}, "trees/checks");
  for (float v : features.values())
    if (!std::isfinite(v)) throw Error("FeatureIndex: non-finite feature value");
  impl_->features = std::move(features);
  impl_->refs = std::move(refs);
  impl_->settings = settings;
  if (impl_->features.empty()) return;
  if (settings.exact) {
    flann::Matrix<float> m(impl_->features.values().data(), impl_->features.size(),
                           static_cast<std::size_t>(impl_->features.dim()));
    impl_->exact = std::make_unique<FlannExact>(m, flann::KDTreeSingleIndexParams(32, true));
    impl_->exact->buildIndex();
  } else {
    impl_->forest = std::make_unique<KdForest>(impl_->features, settings.trees, settings.seed);
  }
}

FeatureIndex::~FeatureIndex() = default;
FeatureIndex::FeatureIndex(FeatureIndex&&) noexcept = default;
FeatureIndex& FeatureIndex::operator=(FeatureIndex&&) noexcept = default;

std::size_t FeatureIndex::size() const { return impl_ ? impl_->features.size() : 0; }
int FeatureIndex::dim() const { return impl_ ? impl_->features.dim() : kFeatureDim; }
const FeatureRef& FeatureIndex::ref(std::size_t i) const { return impl_->refs.at(i); }

std::vector<Neighbour> FeatureIndex::knn(const float* query, std::size_t w) const {
  if (!impl_ || impl_->features.empty() || w == 0) return {};
  const std::size_t k = std::min(w, impl_->features.size());
  if (impl_->exact) {
    FlannKnnSet set(k);
    flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED);
    impl_->exact->findNeighbors(set, query, params);
    return set.take();
  }
  return impl_->forest->knn(query, k, impl_->settings.checks);
}

}  // namespace geometry
}  // namespace ts
