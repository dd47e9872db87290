// FPFH against an independent brute-force implementation written here from PCL's description
// (no code shared with engine/features/fpfh.cpp), and on shapes whose answer is known: a plane, spheres
// of different radii, rigid-motion invariance, thread-count independence, the valid flag.
#include "engine/features/fpfh.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <cstring>

using namespace ts;

namespace {

// ---- Brute-force reference (PCL's FPFHEstimation, transcribed independently) ----------------
using Hist = std::array<double, 33>;

int ref_bin(double normalized) {   // normalized in [0, 1]
  int b = static_cast<int>(std::floor(11.0 * normalized));
  return std::min(10, std::max(0, b));
}

// pcl::computePairFeatures, literally (acos comparison included).
bool ref_pair(Vec3 p1, Vec3 n1, Vec3 p2, Vec3 n2, double f[3]) {
  Vec3 dp = p2 - p1;
  const double f4 = std::sqrt(dp.x() * dp.x() + dp.y() * dp.y() + dp.z() * dp.z());
  if (f4 == 0.0) return false;
  Vec3 n1c = n1, n2c = n2;
  const double angle1 = n1c.dot(dp) / f4;
  const double angle2 = n2c.dot(dp) / f4;
  if (std::acos(std::fabs(angle1)) > std::acos(std::fabs(angle2))) {
    n1c = n2;
    n2c = n1;
    dp = -dp;
    f[2] = -angle2;
  } else {
    f[2] = angle1;
  }
  Vec3 v = dp.cross(n1c);
  const double vn = v.norm();
  if (vn == 0.0) return false;
  v = v / vn;
  const Vec3 w = n1c.cross(v);
  f[1] = v.dot(n2c);
  f[0] = std::atan2(w.dot(n2c), n1c.dot(n2c));
  return true;
}

std::vector<std::size_t> ref_neighbours(const PointCloud& s, const Vec3& q, double r, std::vector<double>* d2) {
  std::vector<std::size_t> out;
  for (std::size_t j = 0; j < s.size(); ++j) {
    const double d = (s.points[j] - q).squaredNorm();
    if (d <= r * r) {
      out.push_back(j);
      if (d2) d2->push_back(d);
    }
  }
  return out;
}

Hist ref_spfh(const PointCloud& s, std::size_t p, double r) {
  Hist h{};
  const auto nb = ref_neighbours(s, s.points[p], r, nullptr);
  const double incr = 100.0 / static_cast<double>(nb.size() - 1);
  for (std::size_t q : nb) {
    if (q == p) continue;
    double f[3];
    if (!ref_pair(s.points[p], s.normals[p], s.points[q], s.normals[q], f)) continue;
    h[ref_bin((f[0] + M_PI) / (2.0 * M_PI))] += incr;
    h[11 + ref_bin((f[1] + 1.0) * 0.5)] += incr;
    h[22 + ref_bin((f[2] + 1.0) * 0.5)] += incr;
  }
  return h;
}

std::pair<Hist, bool> ref_fpfh(const PointCloud& s, const Vec3& kp, double r) {
  std::vector<double> d2;
  const auto nb = ref_neighbours(s, kp, r, &d2);
  Hist acc{};
  int others = 0;
  for (std::size_t i = 0; i < nb.size(); ++i) {
    if (d2[i] == 0.0) continue;
    ++others;
    const Hist h = ref_spfh(s, nb[i], r);
    for (int b = 0; b < 33; ++b) acc[b] += h[b] / d2[i];
  }
  if (others < 2) return {Hist{}, false};
  for (int blk = 0; blk < 3; ++blk) {
    double sum = 0;
    for (int b = 0; b < 11; ++b) sum += acc[blk * 11 + b];
    for (int b = 0; b < 11; ++b) acc[blk * 11 + b] *= 100.0 / sum;
  }
  return {acc, true};
}

// ---- Test surfaces ----------------------------------------------------------------------------

/// Random points on a bumpy height field, analytic normals, some flipped.
PointCloud bumpy_surface(Rng& rng, std::size_t n, double half) {
  PointCloud c;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = rng.uniform(-half, half), y = rng.uniform(-half, half);
    const double z = 0.006 * std::sin(90.0 * x) * std::cos(70.0 * y);
    const double zx = 0.006 * 90.0 * std::cos(90.0 * x) * std::cos(70.0 * y);
    const double zy = -0.006 * 70.0 * std::sin(90.0 * x) * std::sin(70.0 * y);
    Vec3 nrm = Vec3(-zx, -zy, 1.0).normalized();
    if (rng.uniform() < 0.2) nrm = -nrm;
    c.points.emplace_back(x, y, z);
    c.normals.push_back(nrm);
  }
  return c;
}

PointCloud fibonacci_sphere(double radius, double spacing) {
  const auto n = static_cast<std::size_t>(4.0 * M_PI * radius * radius / (spacing * spacing));
  PointCloud c;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (std::size_t i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (static_cast<double>(i) + 0.5) / static_cast<double>(n);
    const double rho = std::sqrt(1.0 - z * z);
    const Vec3 u(rho * std::cos(golden * i), rho * std::sin(golden * i), z);
    c.points.push_back(radius * u);
    c.normals.push_back(u);
  }
  return c;
}

double feature_distance(const Feature& a, const Feature& b) {
  double s = 0;
  for (int i = 0; i < kFeatureDim; ++i) s += double(a[i] - b[i]) * double(a[i] - b[i]);
  return std::sqrt(s);
}

}  // namespace

TEST_CASE("FPFH matches an independent brute-force implementation") {
  Rng rng(101);
  const PointCloud surface = bumpy_surface(rng, 700, 0.025);
  const KdTree3 tree(surface.points);
  FpfhSettings settings;
  settings.feature_radius = 0.008;
  std::vector<Vec3> keypoints;
  for (int i = 0; i < 40; ++i) keypoints.push_back(surface.points[rng.index(surface.size())]);
  for (int i = 0; i < 25; ++i)   // off the surface, some near the border with few neighbours
    keypoints.emplace_back(rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03), rng.uniform(-0.006, 0.006));
  keypoints.emplace_back(1.0, 1.0, 1.0);   // nothing around it
  const auto res = compute_fpfh(keypoints, {}, surface, tree, settings);
  REQUIRE(res.features.size() == keypoints.size());
  REQUIRE(res.valid.size() == keypoints.size());
  int valid = 0;
  for (std::size_t k = 0; k < keypoints.size(); ++k) {
    const auto [want, ok] = ref_fpfh(surface, keypoints[k], settings.feature_radius);
    CHECK(res.valid[k] == ok);
    valid += ok;
    for (int b = 0; b < kFeatureDim; ++b) CHECK(std::abs(res.features[k][b] - want[b]) < 1e-4);
  }
  CHECK(valid >= 50);
  CHECK_FALSE(res.valid.back());
}

TEST_CASE("FPFH matches the brute-force implementation where pairs tie (n_s . d = n_t . d)") {
  // Points on two planes, z = 0 and z = 2 mm, with normals ~(sin a, 0.3, +-cos a) for a few
  // tilts a and either sign of z: two points of one plane with the same tilt have
  // n_s . d = n_t . d exactly (d has no z component), so the source stays the frame origin and
  // the pair's bins depend on its direction (f3 changes sign). The engine counts each pair once
  // and must compute such pairs twice.
  PointCloud surface;
  Rng rng(7);
  for (int i = 0; i < 500; ++i) {
    const double a = 0.4 + 0.5 * static_cast<double>(rng.index(3));
    const double z = rng.uniform() < 0.5 ? std::cos(a) : -std::cos(a);
    surface.points.emplace_back(rng.uniform(-0.012, 0.012), rng.uniform(-0.012, 0.012),
                                rng.uniform() < 0.5 ? 0.0 : 0.002);
    surface.normals.push_back(Vec3(std::sin(a), 0.3, z).normalized());
  }
  const KdTree3 tree(surface.points);
  FpfhSettings settings;
  settings.feature_radius = 0.006;
  std::vector<Vec3> keypoints;
  for (int i = 0; i < 30; ++i) keypoints.emplace_back(rng.uniform(-0.006, 0.006), rng.uniform(-0.006, 0.006), 0.001);
  const auto res = compute_fpfh(keypoints, {}, surface, tree, settings);
  for (std::size_t k = 0; k < keypoints.size(); ++k) {
    const auto [want, ok] = ref_fpfh(surface, keypoints[k], settings.feature_radius);
    REQUIRE(ok);
    CHECK(res.valid[k]);
    for (int b = 0; b < kFeatureDim; ++b) CHECK(std::abs(res.features[k][b] - want[b]) < 1e-4);
  }
}

TEST_CASE("FPFH of a plane is the same everywhere: all pairs fall in the middle bins") {
  PointCloud plane;
  for (int i = 0; i < 30; ++i)
    for (int j = 0; j < 30; ++j) {
      plane.points.emplace_back(0.001 * i, 0.001 * j, 0.0);
      plane.normals.emplace_back(0, 0, 1);
    }
  const KdTree3 tree(plane.points);
  std::vector<Vec3> kps = plane.points;
  kps.emplace_back(0.0105, 0.0123, 0.002);   // above the plane: same neighbours' SPFHs
  FpfhSettings s;
  s.feature_radius = 0.004;
  const auto res = compute_fpfh(kps, {}, plane, tree, s);
  for (std::size_t k = 0; k < kps.size(); ++k) {
    REQUIRE(res.valid[k]);
    for (int b = 0; b < kFeatureDim; ++b) CHECK(res.features[k][b] == ((b % 11 == 5) ? 100.0f : 0.0f));
  }
}

TEST_CASE("FPFH separates spheres of 2 cm and 5 cm radius") {
  const PointCloud small = fibonacci_sphere(0.02, 0.002), large = fibonacci_sphere(0.05, 0.002);
  const KdTree3 ts(small.points), tl(large.points);
  FpfhSettings s;   // paper radii: features over 10 mm
  auto sample = [](const PointCloud& c, std::size_t n) {
    std::vector<Vec3> k;
    for (std::size_t i = 0; i < n; ++i) k.push_back(c.points[i * c.size() / n]);
    return k;
  };
  const auto fs = compute_fpfh(sample(small, 60), {}, small, ts, s);
  const auto fl = compute_fpfh(sample(large, 60), {}, large, tl, s);
  auto mean = [](const FpfhResult& r) {
    Feature m{};
    for (const auto& f : r.features)
      for (int b = 0; b < kFeatureDim; ++b) m[b] += f[b] / static_cast<float>(r.features.size());
    return m;
  };
  const Feature ms = mean(fs), ml = mean(fl);
  double spread = 0.0;
  for (const auto& f : fs.features) spread = std::max(spread, feature_distance(f, ms));
  for (const auto& f : fl.features) spread = std::max(spread, feature_distance(f, ml));
  const double separation = feature_distance(ms, ml);
  MESSAGE("sphere separation " << separation << ", largest within-sphere spread " << spread);
  for (bool v : fs.valid) CHECK(v);
  for (bool v : fl.valid) CHECK(v);
  CHECK(separation > 5.0 * spread);
}

TEST_CASE("FPFH is invariant to rigid motions and independent of the thread count") {
  Rng rng(202);
  const PointCloud surface = bumpy_surface(rng, 1500, 0.03);
  const KdTree3 tree(surface.points);
  std::vector<Vec3> kps;
  for (int i = 0; i < 200; ++i) kps.push_back(surface.points[i * 7] + Vec3(0, 0, rng.uniform(-0.002, 0.002)));
  FpfhSettings s;
  const auto base = compute_fpfh(kps, {}, surface, tree, s);

  for (int trial = 0; trial < 3; ++trial) {
    Pose T = Pose::Identity();
    T.linear() = rng.rotation().toRotationMatrix();
    T.translation() = Vec3(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-5, 5));
    PointCloud moved;
    for (std::size_t i = 0; i < surface.size(); ++i) {
      moved.points.push_back(T * surface.points[i]);
      moved.normals.push_back(T.linear() * surface.normals[i]);
    }
    std::vector<Vec3> mk;
    for (const auto& k : kps) mk.push_back(T * k);
    const auto res = compute_fpfh(mk, {}, moved, KdTree3(moved.points), s);
    for (std::size_t k = 0; k < kps.size(); ++k) {
      CHECK(res.valid[k] == base.valid[k]);
      double worst = 0;
      for (int b = 0; b < kFeatureDim; ++b) worst = std::max(worst, double(std::abs(res.features[k][b] - base.features[k][b])));
      CHECK(worst < 1e-4);
    }
  }

  FpfhResult one, two;
  tbb::task_arena(1).execute([&] { one = compute_fpfh(kps, {}, surface, tree, s); });
  tbb::task_arena(2).execute([&] { two = compute_fpfh(kps, {}, surface, tree, s); });
  CHECK(one.valid == two.valid);
  REQUIRE(one.features.size() == two.features.size());
  CHECK(std::memcmp(one.features.data(), two.features.data(), one.features.size() * sizeof(Feature)) == 0);
}

TEST_CASE("FPFH valid flag needs two neighbours other than the keypoint") {
  PointCloud c;
  c.points = {Vec3(0, 0, 0), Vec3(0.001, 0, 0), Vec3(0, 0.001, 0)};
  c.normals = {Vec3(0, 0, 1), Vec3(0.3, 0, 1).normalized(), Vec3(0, 0.4, 1).normalized()};
  const KdTree3 tree(c.points);
  FpfhSettings s;
  s.feature_radius = 0.010;
  const std::vector<Vec3> kps = {
      Vec3(0.0005, 0.0005, 0),   // three neighbours
      Vec3(0, 0, 0),             // on A: A is itself, B and C are the two others
      Vec3(-0.009, -0.004, 0),   // only A within 10 mm (9.85 mm; B 10.8, C 10.3)
      Vec3(0.5, 0.5, 0.5),       // nothing
  };
  const auto r = compute_fpfh(kps, std::vector<Vec3>(kps.size(), Vec3(0, 0, 1)), c, tree, s);
  CHECK(r.valid[0]);
  CHECK(r.valid[1]);
  CHECK_FALSE(r.valid[2]);
  CHECK_FALSE(r.valid[3]);
  for (int k : {2, 3})
    for (float v : r.features[k]) CHECK(v == 0.0f);
  for (int k : {0, 1}) {
    for (int blk = 0; blk < 3; ++blk) {
      double sum = 0;
      for (int b = 0; b < 11; ++b) sum += r.features[k][blk * 11 + b];
      CHECK(sum == doctest::Approx(100.0).epsilon(1e-5));
    }
  }
}

TEST_CASE("FPFH rejects inconsistent inputs") {
  PointCloud c;
  c.points = {Vec3(0, 0, 0), Vec3(0.001, 0, 0)};
  const KdTree3 tree(c.points);
  CHECK_THROWS_AS(compute_fpfh({Vec3::Zero()}, {}, c, tree, {}), Error);   // no normals
  c.normals = {Vec3(0, 0, 1), Vec3(0, 0, 1)};
  CHECK_THROWS_AS(compute_fpfh({Vec3::Zero()}, {Vec3::UnitZ(), Vec3::UnitZ()}, c, tree, {}), Error);
  CHECK_THROWS_AS(compute_fpfh({Vec3::Zero()}, {}, c, KdTree3({Vec3::Zero()}), {}), Error);
  FpfhSettings bad;
  bad.feature_radius = 0;
  CHECK_THROWS_AS(compute_fpfh({Vec3::Zero()}, {}, c, tree, bad), Error);
  const auto empty = compute_fpfh({}, {}, c, tree, {});
  CHECK(empty.features.empty());
}
