// Point-cloud operations: voxel-grid filter (Section 4.1.2), PCA normals, bounds, transforms.
#include "engine/geometry/cloud.hpp"

#include <Eigen/Eigenvalues>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace ts {
inline namespace geometry {

namespace {

using Key = std::array<std::int64_t, 3>;

/// Runs of equal voxel keys after sorting: [first[g], first[g + 1]) of `order` is voxel g.
struct VoxelGroups {
  std::vector<std::uint32_t> order;  ///< input indices sorted by (voxel key, index)
  std::vector<std::uint32_t> first;  ///< group starts, plus order.size() at the end
  std::vector<Key> key;              ///< one per group
};

inline std::uint64_t hash_key(const Key& k) {
  std::uint64_t h = static_cast<std::uint64_t>(k[0]) * 0x9e3779b97f4a7c15ULL;
  h ^= static_cast<std::uint64_t>(k[1]) * 0xc2b2ae3d27d4eb4fULL + (h >> 29);
  h ^= static_cast<std::uint64_t>(k[2]) * 0x165667b19e3779f9ULL + (h >> 32);
  return h ^ (h >> 31);
}

/// Group points by voxel in O(n): an open-addressing table gives each voxel an id in
/// first-seen order, the (few) voxel keys are sorted, and a stable counting sort orders the
/// points by voxel rank, keeping input order inside a voxel. Serial by design: the result is
/// one well-defined order, whatever the thread count.
VoxelGroups group_by_voxel(const std::vector<Vec3>& points, double voxel) {
  const std::size_t n = points.size();
  if (n >= std::numeric_limits<std::uint32_t>::max())
    throw Error("too many points for one cloud", "", "points");
  std::vector<Key> keys(n);
  std::vector<char> ok(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Vec3 s = points[i] / voxel;
      ok[i] = s.allFinite() && s.cwiseAbs().maxCoeff() < 4e18;
      if (ok[i])
        for (int k = 0; k < 3; ++k) keys[i][k] = static_cast<std::int64_t>(std::floor(s[k]));
    }
  });

  std::size_t capacity = 64;
  while (capacity < 2 * n) capacity *= 2;
  std::vector<std::uint32_t> table(capacity, UINT32_MAX);
  std::vector<Key> group_key;
  std::vector<std::uint32_t> group_of(n, UINT32_MAX), group_size;
  for (std::size_t i = 0; i < n; ++i) {
    if (!ok[i]) continue;
    std::size_t slot = hash_key(keys[i]) & (capacity - 1);
    while (table[slot] != UINT32_MAX && group_key[table[slot]] != keys[i]) slot = (slot + 1) & (capacity - 1);
    if (table[slot] == UINT32_MAX) {
      table[slot] = static_cast<std::uint32_t>(group_key.size());
      group_key.push_back(keys[i]);
      group_size.push_back(0);
    }
    group_of[i] = table[slot];
    ++group_size[table[slot]];
  }

  const std::size_t groups = group_key.size();
  std::vector<std::uint32_t> by_key(groups);
  for (std::size_t g = 0; g < groups; ++g) by_key[g] = static_cast<std::uint32_t>(g);
  std::sort(by_key.begin(), by_key.end(),
            [&](std::uint32_t a, std::uint32_t b) { return group_key[a] < group_key[b]; });
  std::vector<std::uint32_t> rank(groups);
  VoxelGroups g;
  g.key.resize(groups);
  g.first.resize(groups + 1);
  std::uint32_t offset = 0;
  for (std::size_t r = 0; r < groups; ++r) {
    rank[by_key[r]] = static_cast<std::uint32_t>(r);
    g.key[r] = group_key[by_key[r]];
    g.first[r] = offset;
    offset += group_size[by_key[r]];
  }
  g.first[groups] = offset;
  g.order.resize(offset);
  std::vector<std::uint32_t> fill(g.first.begin(), g.first.end() - 1);
  for (std::size_t i = 0; i < n; ++i)
    if (ok[i]) g.order[fill[rank[group_of[i]]]++] = static_cast<std::uint32_t>(i);
  return g;
}

}  // namespace

PointCloud voxel_filter(const PointCloud& cloud, double voxel) {
  if (!(voxel > 0.0) || !std::isfinite(voxel))
    throw Error("voxel size must be positive and finite", "", "voxel");
  const VoxelGroups g = group_by_voxel(cloud.points, voxel);
  const std::size_t groups = g.key.size();
  const bool with_normals = cloud.has_normals();
  PointCloud out;
  out.points.resize(groups);
  if (with_normals) out.normals.resize(groups);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, groups, 1024), [&](const auto& r) {
    for (std::size_t v = r.begin(); v != r.end(); ++v) {
      // Sum in a frame at the voxel's corner (precision far from the origin), in index order.
      const Vec3 corner(g.key[v][0] * voxel, g.key[v][1] * voxel, g.key[v][2] * voxel);
      Vec3 sum = Vec3::Zero(), nsum = Vec3::Zero();
      for (std::uint32_t i = g.first[v]; i < g.first[v + 1]; ++i) {
        const std::uint32_t p = g.order[i];
        sum += cloud.points[p] - corner;
        if (with_normals) nsum += cloud.normals[p];
      }
      out.points[v] = corner + sum / static_cast<double>(g.first[v + 1] - g.first[v]);
      if (with_normals) out.normals[v] = nsum.normalized();  // zero stays zero
    }
  });
  return out;
}

PointCloud voxel_representatives(const PointCloud& cloud, double voxel) {
  if (!(voxel > 0.0) || !std::isfinite(voxel))
    throw Error("voxel size must be positive and finite", "", "voxel");
  const VoxelGroups g = group_by_voxel(cloud.points, voxel);
  const std::size_t groups = g.key.size();
  const bool with_normals = cloud.has_normals();
  PointCloud out;
  out.points.resize(groups);
  if (with_normals) out.normals.resize(groups);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, groups, 1024), [&](const auto& r) {
    for (std::size_t v = r.begin(); v != r.end(); ++v) {
      const Vec3 corner(g.key[v][0] * voxel, g.key[v][1] * voxel, g.key[v][2] * voxel);
      Vec3 sum = Vec3::Zero();
      for (std::uint32_t i = g.first[v]; i < g.first[v + 1]; ++i) sum += cloud.points[g.order[i]] - corner;
      const Vec3 mean = sum / static_cast<double>(g.first[v + 1] - g.first[v]);
      // The member nearest to the centroid; ties go to the smaller input index (first in order).
      std::uint32_t best = g.order[g.first[v]];
      double best_d2 = std::numeric_limits<double>::infinity();
      for (std::uint32_t i = g.first[v]; i < g.first[v + 1]; ++i) {
        const double d2 = (cloud.points[g.order[i]] - corner - mean).squaredNorm();
        if (d2 < best_d2) {
          best_d2 = d2;
          best = g.order[i];
        }
      }
      out.points[v] = cloud.points[best];
      if (with_normals) out.normals[v] = cloud.normals[best];
    }
  });
  return out;
}

std::vector<Vec3> estimate_normals(const std::vector<Vec3>& points, const NormalSettings& s) {
  if (!(s.radius > 0.0) || !std::isfinite(s.radius)) throw Error("normal radius must be positive", "", "radius");
  const std::size_t n = points.size();
  std::vector<Vec3> normals(n, Vec3::Zero());
  if (n == 0) return normals;
  const Vec3 c = centroid(points);
  const std::size_t min_n = static_cast<std::size_t>(std::max(3, s.min_neighbours));
  const double r2 = s.radius * s.radius;
  // Fixed-radius search on a grid of radius-sized cells: a point's neighbours lie in the 27
  // cells around its own, i.e. in 9 runs of consecutive keys of the sorted cell list. Cells are
  // processed independently (one parallel task each) and neighbours are visited in cell-key
  // order, so the result does not depend on the thread count.
  const VoxelGroups g = group_by_voxel(points, s.radius);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, g.key.size(), 16), [&](const auto& range) {
    std::vector<std::uint32_t> candidates;
    for (std::size_t cell = range.begin(); cell != range.end(); ++cell) {
      candidates.clear();
      const Key& k = g.key[cell];
      for (std::int64_t di = -1; di <= 1; ++di)
        for (std::int64_t dj = -1; dj <= 1; ++dj) {
          const Key lo{k[0] + di, k[1] + dj, k[2] - 1}, hi{k[0] + di, k[1] + dj, k[2] + 1};
          for (auto it = std::lower_bound(g.key.begin(), g.key.end(), lo); it != g.key.end() && *it <= hi; ++it) {
            const auto gi = static_cast<std::size_t>(it - g.key.begin());
            candidates.insert(candidates.end(), g.order.begin() + g.first[gi], g.order.begin() + g.first[gi + 1]);
          }
        }
      for (std::uint32_t m = g.first[cell]; m < g.first[cell + 1]; ++m) {
        const std::uint32_t i = g.order[m];
        const Vec3& p = points[i];
        // Covariance of the neighbours (relative to p, for precision far from the origin).
        Vec3 sum = Vec3::Zero();
        Mat3 sum2 = Mat3::Zero();
        std::size_t count = 0;
        for (const std::uint32_t q : candidates) {
          const Vec3 d = points[q] - p;
          if (d.squaredNorm() > r2) continue;
          sum += d;
          sum2.noalias() += d * d.transpose();
          ++count;
        }
        if (count < min_n) continue;
        const Vec3 mean = sum / static_cast<double>(count);
        const Mat3 cov = sum2 / static_cast<double>(count) - mean * mean.transpose();
        const Eigen::SelfAdjointEigenSolver<Mat3> eig(cov);
        if (eig.info() != Eigen::Success) continue;
        Vec3 normal = eig.eigenvectors().col(0);  // smallest eigenvalue
        if (!finite(normal) || !(normal.squaredNorm() > 0.0)) continue;
        normal.normalize();
        if (normal.dot(p - c) < 0.0) normal = -normal;  // away from the cloud centroid
        normals[i] = normal;
      }
    }
  });
  return normals;
}

Eigen::AlignedBox3d bounds(const std::vector<Vec3>& points) {
  Eigen::AlignedBox3d box;
  for (const auto& p : points)
    if (finite(p)) box.extend(p);
  return box;
}

Vec3 centroid(const std::vector<Vec3>& points) {
  // Mean relative to the first finite point (precision far from the origin).
  Vec3 ref = Vec3::Zero(), sum = Vec3::Zero();
  std::size_t n = 0;
  for (const auto& p : points) {
    if (!finite(p)) continue;
    if (n == 0) ref = p;
    sum += p - ref;
    ++n;
  }
  return n == 0 ? Vec3::Zero() : Vec3(ref + sum / static_cast<double>(n));
}

PointCloud transformed(const PointCloud& cloud, const Pose& T) {
  PointCloud out;
  out.points.resize(cloud.points.size());
  for (std::size_t i = 0; i < cloud.points.size(); ++i) out.points[i] = T * cloud.points[i];
  if (cloud.has_normals()) {
    out.normals.resize(cloud.normals.size());
    const Mat3 R = T.linear();
    for (std::size_t i = 0; i < cloud.normals.size(); ++i) out.normals[i] = R * cloud.normals[i];
  }
  return out;
}

std::vector<Vec3> fibonacci_directions(int n) {
  std::vector<Vec3> dirs;
  dirs.reserve(static_cast<std::size_t>(std::max(n, 0)));
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    dirs.emplace_back(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  return dirs;
}

std::vector<Vec3> extreme_points(const std::vector<Vec3>& points, int directions) {
  if (points.empty()) return {};
  const std::vector<Vec3> dirs = fibonacci_directions(directions);
  std::vector<std::size_t> lowest(dirs.size(), 0);
  std::vector<double> low(dirs.size(), std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < points.size(); ++i)
    for (std::size_t k = 0; k < dirs.size(); ++k) {
      const double h = dirs[k].dot(points[i]);
      if (h < low[k]) {
        low[k] = h;
        lowest[k] = i;
      }
    }
  std::sort(lowest.begin(), lowest.end());
  lowest.erase(std::unique(lowest.begin(), lowest.end()), lowest.end());
  std::vector<Vec3> out;
  out.reserve(lowest.size());
  for (std::size_t i : lowest) out.push_back(points[i]);
  return out;
}

}  // namespace geometry
}  // namespace ts
