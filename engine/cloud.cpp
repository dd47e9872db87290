// Point-cloud operations: voxel-grid filter (Section 4.1.2), PCA normals, bounds, transforms.
#include "engine/cloud.hpp"

#include "engine/search.hpp"

#include <Eigen/Eigenvalues>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>

namespace ts {

namespace {

using Key = std::array<std::int64_t, 3>;

/// Runs of equal voxel keys after sorting: [first[g], first[g + 1]) of `order` is voxel g.
struct VoxelGroups {
  std::vector<std::uint32_t> order;  ///< input indices sorted by (voxel key, index)
  std::vector<std::uint32_t> first;  ///< group starts, plus order.size() at the end
  std::vector<Key> key;              ///< one per group
};

VoxelGroups group_by_voxel(const std::vector<Vec3>& points, double voxel) {
  const std::size_t n = points.size();
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
  Key lo{INT64_MAX, INT64_MAX, INT64_MAX}, hi{INT64_MIN, INT64_MIN, INT64_MIN};
  std::size_t valid = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!ok[i]) continue;
    ++valid;
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], keys[i][k]);
      hi[k] = std::max(hi[k], keys[i][k]);
    }
  }
  VoxelGroups g;
  g.order.reserve(valid);
  if (valid == 0) {
    g.first.push_back(0);
    return g;
  }
  constexpr std::int64_t kSpan = std::int64_t{1} << 21;
  const bool packable = hi[0] - lo[0] < kSpan && hi[1] - lo[1] < kSpan && hi[2] - lo[2] < kSpan;
  if (packable) {
    // Lexicographic (i, j, k) order as one 63-bit integer, the index below it: every element
    // is distinct, so the (unstable) parallel sort has exactly one possible result.
    std::vector<std::pair<std::uint64_t, std::uint32_t>> items;
    items.reserve(valid);
    for (std::size_t i = 0; i < n; ++i) {
      if (!ok[i]) continue;
      const auto a = static_cast<std::uint64_t>(keys[i][0] - lo[0]);
      const auto b = static_cast<std::uint64_t>(keys[i][1] - lo[1]);
      const auto c = static_cast<std::uint64_t>(keys[i][2] - lo[2]);
      items.emplace_back((a << 42) | (b << 21) | c, static_cast<std::uint32_t>(i));
    }
    tbb::parallel_sort(items.begin(), items.end());
    for (std::size_t i = 0; i < items.size(); ++i) {
      if (i == 0 || items[i].first != items[i - 1].first) {
        g.first.push_back(static_cast<std::uint32_t>(i));
        g.key.push_back(keys[items[i].second]);
      }
      g.order.push_back(items[i].second);
    }
  } else {
    for (std::size_t i = 0; i < n; ++i)
      if (ok[i]) g.order.push_back(static_cast<std::uint32_t>(i));
    tbb::parallel_sort(g.order.begin(), g.order.end(), [&](std::uint32_t a, std::uint32_t b) {
      return keys[a] != keys[b] ? keys[a] < keys[b] : a < b;
    });
    for (std::size_t i = 0; i < g.order.size(); ++i) {
      if (i == 0 || keys[g.order[i]] != keys[g.order[i - 1]]) {
        g.first.push_back(static_cast<std::uint32_t>(i));
        g.key.push_back(keys[g.order[i]]);
      }
    }
  }
  g.first.push_back(static_cast<std::uint32_t>(g.order.size()));
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

std::vector<Vec3> estimate_normals(const std::vector<Vec3>& points, const NormalSettings& s) {
  if (!(s.radius > 0.0)) throw Error("normal radius must be positive", "", "radius");
  const std::size_t n = points.size();
  std::vector<Vec3> normals(n, Vec3::Zero());
  if (n == 0) return normals;
  const Vec3 c = centroid(points);
  const KdTree3 tree(points);
  const std::size_t min_n = static_cast<std::size_t>(std::max(3, s.min_neighbours));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Vec3& p = points[i];
      if (!finite(p)) continue;
      const auto nb = tree.radius(p, s.radius);
      if (nb.size() < min_n) continue;
      // Covariance about the neighbourhood mean, accumulated relative to the query point.
      Vec3 mean = Vec3::Zero();
      for (const auto& q : nb) mean += points[q.index] - p;
      mean /= static_cast<double>(nb.size());
      Mat3 cov = Mat3::Zero();
      for (const auto& q : nb) {
        const Vec3 d = points[q.index] - p - mean;
        cov.noalias() += d * d.transpose();
      }
      const Eigen::SelfAdjointEigenSolver<Mat3> eig(cov);
      if (eig.info() != Eigen::Success) continue;
      Vec3 normal = eig.eigenvectors().col(0);  // smallest eigenvalue
      if (!finite(normal) || !(normal.squaredNorm() > 0.0)) continue;
      normal.normalize();
      if (normal.dot(p - c) < 0.0) normal = -normal;  // away from the cloud centroid
      normals[i] = normal;
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

}  // namespace ts
