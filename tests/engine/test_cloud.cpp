#include "engine/geometry/cloud.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <map>

using namespace ts;

namespace {

PointCloud random_cloud(std::size_t n, const Vec3& offset, double size, std::uint64_t seed) {
  Rng rng(seed);
  PointCloud c;
  for (std::size_t i = 0; i < n; ++i) {
    c.points.push_back(offset + Vec3(rng.uniform(0, size), rng.uniform(0, size), rng.uniform(0, size)));
    c.normals.push_back(rng.unit_vector());
  }
  return c;
}

/// Oracle: a std::map keyed by floor(p / voxel), which iterates in lexicographic key order.
PointCloud brute_voxel_filter(const PointCloud& c, double voxel) {
  std::map<std::array<long long, 3>, std::pair<std::vector<Vec3>, std::vector<Vec3>>> cells;
  for (std::size_t i = 0; i < c.size(); ++i) {
    if (!c.points[i].allFinite()) continue;
    std::array<long long, 3> key{};
    for (int k = 0; k < 3; ++k) key[k] = static_cast<long long>(std::floor(c.points[i][k] / voxel));
    cells[key].first.push_back(c.points[i]);
    if (c.has_normals()) cells[key].second.push_back(c.normals[i]);
  }
  PointCloud out;
  for (const auto& [key, v] : cells) {
    Vec3 s = Vec3::Zero(), n = Vec3::Zero();
    for (const auto& p : v.first) s += p;
    for (const auto& q : v.second) n += q;
    out.points.push_back(s / static_cast<double>(v.first.size()));
    if (c.has_normals()) out.normals.push_back(n.normalized());
  }
  return out;
}

}  // namespace

TEST_CASE("voxel_filter matches a brute-force grid, in key order") {
  for (const double voxel : {0.0015, 0.005, 0.02}) {
    CAPTURE(voxel);
    PointCloud c = random_cloud(20000, Vec3(-0.1, -0.05, 0.02), 0.2, 3);
    c.points[17] = Vec3(std::nan(""), 0, 0);  // dropped
    const PointCloud got = voxel_filter(c, voxel);
    const PointCloud want = brute_voxel_filter(c, voxel);
    REQUIRE(got.size() == want.size());
    REQUIRE(got.has_normals());
    for (std::size_t i = 0; i < got.size(); ++i) {
      CHECK((got.points[i] - want.points[i]).norm() < 1e-12);
      CHECK((got.normals[i] - want.normals[i]).norm() < 1e-9);
      CHECK(std::abs(got.normals[i].norm() - 1.0) < 1e-12);
    }
  }
}

TEST_CASE("voxel_filter: one point per voxel, inside it; far from the origin; without normals") {
  const double voxel = 0.002;
  // 100 km from the origin: the centroids must stay inside their voxels to sub-micrometre.
  PointCloud c = random_cloud(5000, Vec3(1e5, -2e5, 3e4), 0.05, 4);
  c.normals.clear();
  const PointCloud got = voxel_filter(c, voxel);
  CHECK_FALSE(got.has_normals());
  const PointCloud want = brute_voxel_filter(c, voxel);
  REQUIRE(got.size() == want.size());
  std::map<std::array<long long, 3>, int> seen;
  for (std::size_t i = 0; i < got.size(); ++i) {
    CHECK((got.points[i] - want.points[i]).norm() < 1e-8);
    std::array<long long, 3> key{};
    for (int k = 0; k < 3; ++k) key[k] = static_cast<long long>(std::floor(got.points[i][k] / voxel));
    CHECK(++seen[key] == 1);
  }
  // Filtering twice changes nothing more (every point already alone in its voxel).
  CHECK(voxel_filter(got, voxel).size() == got.size());
  CHECK(voxel_filter(PointCloud{}, voxel).empty());
  CHECK_THROWS_AS(voxel_filter(c, 0.0), Error);
  CHECK_THROWS_AS(voxel_filter(c, std::nan("")), Error);
}

TEST_CASE("voxel_filter output is identical for 1 and 2 threads and any input order") {
  const PointCloud c = random_cloud(60000, Vec3(0, 0, 0), 0.1, 5);
  PointCloud a, b;
  tbb::task_arena(1).execute([&] { a = voxel_filter(c, 0.003); });
  tbb::task_arena(2).execute([&] { b = voxel_filter(c, 0.003); });
  CHECK(a.points == b.points);
  CHECK(a.normals == b.normals);
  // Reversed input: same voxels in the same order, same centroids up to summation order.
  PointCloud r;
  r.points.assign(c.points.rbegin(), c.points.rend());
  r.normals.assign(c.normals.rbegin(), c.normals.rend());
  const PointCloud rr = voxel_filter(r, 0.003);
  REQUIRE(rr.size() == a.size());
  for (std::size_t i = 0; i < a.size(); ++i) CHECK((rr.points[i] - a.points[i]).norm() < 1e-15);
}

TEST_CASE("estimate_normals: planes, spheres, sparse points, brute-force PCA") {
  Rng rng(8);
  SUBCASE("tilted plane: normals are the plane normal (up to sign)") {
    const Vec3 n = Vec3(0.3, -0.2, 0.9).normalized();
    const Vec3 u = n.unitOrthogonal(), v = n.cross(u);
    std::vector<Vec3> pts;
    for (int i = 0; i < 3000; ++i)
      pts.push_back(Vec3(5, 6, 7) + rng.uniform(-0.05, 0.05) * u + rng.uniform(-0.05, 0.05) * v);
    const auto normals = estimate_normals(pts, NormalSettings{0.007, 3});
    for (const auto& m : normals) CHECK(std::abs(std::abs(m.dot(n)) - 1.0) < 1e-9);
  }
  SUBCASE("sphere: normals are radial and point outward") {
    const double r = 0.05;
    const Vec3 c(0.3, -0.1, 0.2);
    std::vector<Vec3> pts;
    for (int i = 0; i < 8000; ++i) pts.push_back(c + r * rng.unit_vector());
    const NormalSettings s{0.007, 3};
    const auto normals = estimate_normals(pts, s);
    double worst = 1.0;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      REQUIRE(normals[i].norm() == doctest::Approx(1.0));
      worst = std::min(worst, normals[i].dot((pts[i] - c).normalized()));
    }
    CHECK(worst > 0.995);  // a 7 mm cap of a 50 mm sphere: PCA normal within a few degrees
    // Same as a brute-force PCA over all points within the radius.
    for (int i = 0; i < 200; ++i) {
      const Vec3& p = pts[i];
      std::vector<Vec3> nb;
      for (const auto& q : pts)
        if ((q - p).norm() <= s.radius) nb.push_back(q);
      Vec3 mean = Vec3::Zero();
      for (const auto& q : nb) mean += q;
      mean /= static_cast<double>(nb.size());
      Mat3 cov = Mat3::Zero();
      for (const auto& q : nb) cov += (q - mean) * (q - mean).transpose();
      const Vec3 want = Eigen::SelfAdjointEigenSolver<Mat3>(cov).eigenvectors().col(0);
      CHECK(std::abs(std::abs(want.dot(normals[i])) - 1.0) < 1e-9);
    }
  }
  SUBCASE("isolated points get a zero normal, never NaN") {
    const std::vector<Vec3> pts = {Vec3(0, 0, 0), Vec3(0.001, 0, 0), Vec3(1, 1, 1)};
    const auto normals = estimate_normals(pts, NormalSettings{0.007, 3});
    for (const auto& m : normals) CHECK(m == Vec3::Zero());
    CHECK(estimate_normals({}, NormalSettings{}).empty());
  }
}

TEST_CASE("bounds, centroid and transformed") {
  const std::vector<Vec3> pts = {Vec3(1, 2, 3), Vec3(-1, 5, 0), Vec3(std::nan(""), 0, 0), Vec3(3, 2, 1)};
  const auto box = bounds(pts);
  CHECK(box.min() == Vec3(-1, 2, 0));
  CHECK(box.max() == Vec3(3, 5, 3));
  CHECK((centroid(pts) - Vec3(1, 3, 4.0 / 3.0)).norm() < 1e-12);
  CHECK(bounds({}).isEmpty());
  CHECK(centroid({}) == Vec3::Zero());

  PointCloud c;
  c.points = {Vec3(1, 0, 0), Vec3(0, 1, 0)};
  c.normals = {Vec3(1, 0, 0), Vec3(0, 0, 1)};
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()).toRotationMatrix();
  T.translation() = Vec3(10, 0, 0);
  const PointCloud t = transformed(c, T);
  CHECK((t.points[0] - Vec3(10, 1, 0)).norm() < 1e-12);
  CHECK((t.points[1] - Vec3(9, 0, 0)).norm() < 1e-12);
  CHECK((t.normals[0] - Vec3(0, 1, 0)).norm() < 1e-12);
  CHECK((t.normals[1] - Vec3(0, 0, 1)).norm() < 1e-12);
}

TEST_CASE("voxel_representatives keeps the input point nearest to each voxel's centroid") {
  const double voxel = 0.004;
  const PointCloud c = random_cloud(20000, Vec3(-0.03, 0.01, -0.02), 0.06, 12);
  const PointCloud got = voxel_representatives(c, voxel);
  const PointCloud centroids = voxel_filter(c, voxel);
  REQUIRE(got.size() == centroids.size());
  REQUIRE(got.has_normals());
  // Oracle: per voxel, scan all of its members.
  std::map<std::array<long long, 3>, std::vector<std::size_t>> members;
  for (std::size_t i = 0; i < c.size(); ++i) {
    std::array<long long, 3> key{};
    for (int k = 0; k < 3; ++k) key[k] = static_cast<long long>(std::floor(c.points[i][k] / voxel));
    members[key].push_back(i);
  }
  std::size_t v = 0;
  for (const auto& [key, idx] : members) {
    // got is a member, at the smallest distance to the centroid (two members of a voxel of
    // two are equally far: rounding decides, so compare distances with a tolerance).
    double best = 1e30;
    for (std::size_t i : idx) best = std::min(best, (c.points[i] - centroids.points[v]).norm());
    bool member = false;
    for (std::size_t i : idx)
      if (got.points[v] == c.points[i] && got.normals[v] == c.normals[i]) member = true;
    CHECK(member);
    CHECK((got.points[v] - centroids.points[v]).norm() <= best + 1e-12);
    ++v;
  }
}

TEST_CASE("estimate_normals: identical for 1 and 2 threads, and far from the origin") {
  Rng rng(21);
  std::vector<Vec3> pts, far;
  const Vec3 offset(1e5, -3e4, 2e3);
  for (int i = 0; i < 20000; ++i) {
    const Vec3 p = 0.05 * rng.unit_vector();
    pts.push_back(p);
    far.push_back(p + offset);
  }
  std::vector<Vec3> a, b;
  tbb::task_arena(1).execute([&] { a = estimate_normals(pts, NormalSettings{}); });
  tbb::task_arena(2).execute([&] { b = estimate_normals(pts, NormalSettings{}); });
  CHECK(a == b);
  const auto f = estimate_normals(far, NormalSettings{});
  double worst = 1.0;
  for (std::size_t i = 0; i < pts.size(); ++i) worst = std::min(worst, f[i].dot(a[i]));
  CHECK(worst > 1.0 - 1e-6);  // same normals 100 km away (a local frame per neighbourhood)
}

TEST_CASE("extreme_points: the lowest along any direction, from above and within the sampling's curvature") {
  // Points on and inside a sphere of radius r: along a direction u the lowest of all is -r (up
  // to the sampling); the extremes' lowest may only lie above it, by at most about
  // r (1 - cos a) for the angle a to the nearest of 256 directions (under 9 degrees: 0.012 r).
  constexpr double r = 0.1;
  Rng rng(3);
  std::vector<Vec3> pts;
  for (int i = 0; i < 6000; ++i) pts.push_back(r * rng.unit_vector());
  for (int i = 0; i < 2000; ++i) pts.push_back(0.9 * r * rng.uniform() * rng.unit_vector());
  const std::vector<Vec3> ext = extreme_points(pts, 256);
  CHECK(ext.size() <= 256);
  CHECK(ext.size() >= 100);
  for (const Vec3& e : ext) CHECK(std::find(pts.begin(), pts.end(), e) != pts.end());
  double worst = 0.0;
  for (int k = 0; k < 500; ++k) {
    const Vec3 u = rng.unit_vector();
    double all = 1e9, some = 1e9;
    for (const Vec3& p : pts) all = std::min(all, u.dot(p));
    for (const Vec3& e : ext) some = std::min(some, u.dot(e));
    CHECK(some >= all);
    worst = std::max(worst, some - all);
  }
  CHECK(worst <= 0.015 * r);
  CHECK(extreme_points({}, 256).empty());
  // A box: every direction's lowest point is a corner, and the corners are among the extremes.
  std::vector<Vec3> box;
  for (int i = 0; i <= 10; ++i)
    for (int j = 0; j <= 10; ++j)
      for (int k = 0; k <= 10; ++k) box.emplace_back(0.04 * (i / 5.0 - 1), 0.03 * (j / 5.0 - 1), 0.02 * (k / 5.0 - 1));
  const std::vector<Vec3> corners = extreme_points(box, 256);
  CHECK(corners.size() == 8);
  for (const Vec3& c : corners) CHECK(c.cwiseAbs().isApprox(Vec3(0.04, 0.03, 0.02)));
}
