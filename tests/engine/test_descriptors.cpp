// PFH, SHOT and Spin Images (engine/features/descriptors.hpp) against brute-force formulations written
// here from the descriptions of PCL's PFHEstimation, SHOTEstimation (with
// SHOTLocalReferenceFrameEstimation) and SpinImageEstimation: plain loops over every point, no
// tree, SHOT's volumes assigned directly from the azimuth angle and its interpolation written
// per axis. Also: analytic answers on a plane, rigid-motion invariance, thread-count
// independence, the name parser, and the errors.
#include "engine/features/descriptors.hpp"
#include "engine/features/fpfh.hpp"

#include <Eigen/Eigenvalues>
#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>

using namespace ts;

namespace {

using Row = std::vector<double>;

/// Every surface point within r of q (inclusive), ordered by (squared distance, index).
std::vector<std::size_t> brute_neighbours(const PointCloud& s, const Vec3& q, double r) {
  std::vector<std::size_t> out;
  for (std::size_t j = 0; j < s.size(); ++j)
    if ((s.points[j] - q).squaredNorm() <= r * r) out.push_back(j);
  std::stable_sort(out.begin(), out.end(), [&](std::size_t a, std::size_t b) {
    return (s.points[a] - q).squaredNorm() < (s.points[b] - q).squaredNorm();
  });
  return out;
}

// ---- PFH --------------------------------------------------------------------------------------

/// pcl::computePairFeatures as PCL writes it (the acos comparison included).
bool brute_pair(Vec3 p1, Vec3 n1, Vec3 p2, Vec3 n2, double f[3]) {
  Vec3 dp = p2 - p1;
  const double f4 = dp.norm();
  if (f4 == 0.0) return false;
  const double angle1 = n1.dot(dp) / f4, angle2 = n2.dot(dp) / f4;
  if (std::acos(std::fabs(angle1)) > std::acos(std::fabs(angle2))) {
    std::swap(n1, n2);
    dp = -dp;
    f[2] = -angle2;
  } else {
    f[2] = angle1;
  }
  const Vec3 v0 = dp.cross(n1);
  if (v0.norm() == 0.0) return false;
  const Vec3 v = v0.normalized();
  const Vec3 w = n1.cross(v);
  f[1] = v.dot(n2);
  f[0] = std::atan2(w.dot(n2), n1.dot(n2));
  return true;
}

std::pair<Row, bool> brute_pfh(const PointCloud& s, const Vec3& kp, double r) {
  const auto nb = brute_neighbours(s, kp, r);
  Row h(125, 0.0);
  if (nb.size() < 2) return {h, false};
  const double pairs = static_cast<double>(nb.size() * (nb.size() - 1) / 2);
  bool any = false;
  for (std::size_t i = 0; i < nb.size(); ++i)
    for (std::size_t j = 0; j < i; ++j) {
      double f[3] = {0, 0, 0};
      // PCL's PFHEstimation bins a degenerate pair (pcl::computePairFeatures false) at f = 0.
      if (!brute_pair(s.points[nb[i]], s.normals[nb[i]], s.points[nb[j]], s.normals[nb[j]], f)) f[0] = f[1] = f[2] = 0;
      const double unit[3] = {(f[0] + M_PI) / (2 * M_PI), (f[1] + 1) / 2, (f[2] + 1) / 2};
      int index = 0, place = 1;
      for (double u : unit) {
        index += place * std::min(4, std::max(0, static_cast<int>(std::floor(5 * u))));
        place *= 5;
      }
      h[index] += 100.0 / pairs;
      any = true;
    }
  return {any ? h : Row(125, 0.0), any};
}

// ---- SHOT -------------------------------------------------------------------------------------

/// Local reference frame (rows x, y, z) by the distance-weighted covariance of the neighbours
/// other than the keypoint; each axis toward the majority, ties settled by the 5 neighbours
/// around the median.
bool brute_frame(const PointCloud& s, const Vec3& kp, double r, Mat3& rf) {
  std::vector<Vec3> v;
  std::vector<double> w;
  for (std::size_t j : brute_neighbours(s, kp, r)) {
    if (s.points[j] == kp) continue;
    v.push_back(s.points[j] - kp);
    w.push_back(r - v.back().norm());
  }
  if (v.size() < 5) return false;
  Mat3 cov = Mat3::Zero();
  double wsum = 0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) cov(a, b) += w[i] * v[i][a] * v[i][b];
    wsum += w[i];
  }
  const Eigen::SelfAdjointEigenSolver<Mat3> es(cov / wsum);
  auto decide = [&](Vec3 axis) {
    int positive = 0, negative = 0;
    for (const Vec3& x : v) (x.dot(axis) >= 0 ? positive : negative) += 1;
    if (positive == negative) {
      int strictly = 0;
      const std::size_t m = v.size() / 2;
      for (std::size_t i = m - 2; i <= m + 2; ++i) strictly += v[i].dot(axis) > 0;
      return strictly >= 3 ? axis : Vec3(-axis);
    }
    return positive > negative ? axis : Vec3(-axis);
  };
  const Vec3 x = decide(es.eigenvectors().col(2)), z = decide(es.eigenvectors().col(0));
  rf.row(0) = x.transpose();
  rf.row(1) = z.cross(x).transpose();
  rf.row(2) = z.transpose();
  return true;
}

/// SHOT written per axis: volume = 4 azimuth sector + 2 shell + hemisphere; each of the four
/// axes (cosine bin, azimuth, shell, hemisphere) gives the point's own bin 1 - |t| and the
/// adjacent bin along that axis |t|, t the offset from the own bin's centre in bin widths; the
/// shells and hemispheres have no neighbour beyond their outer centres (the weight is lost
/// there), azimuth wraps over 8 sectors and the cosine over PCL's 10 shape bins.
std::pair<Row, bool> brute_shot(const PointCloud& s, const Vec3& kp, double r) {
  Row h(352, 0.0);
  Mat3 rf = Mat3::Zero();
  const auto nb = brute_neighbours(s, kp, r);
  if (!brute_frame(s, kp, r, rf) || nb.size() < 5) return {h, false};
  for (std::size_t j : nb) {
    const Vec3 q = rf * (s.points[j] - kp);
    const double d = q.norm();
    if (d < 1e-8) continue;
    const double azimuth = std::atan2(q.y(), q.x());
    const double a = (azimuth + M_PI) / (M_PI / 4);
    const int sector = std::min(7, static_cast<int>(std::floor(a)));
    const double ta = a - sector - 0.5;
    const int upper = q.z() > 0 ? 1 : 0;
    const double te = (std::acos(std::clamp(q.z() / d, -1.0, 1.0)) - (upper ? M_PI / 4 : 3 * M_PI / 4)) / (M_PI / 2);
    const int outer = d > r / 2 ? 1 : 0;
    const double tr = (d - (outer ? 0.75 * r : 0.25 * r)) / (r / 2);
    const double c = (1 + std::clamp(s.normals[j].dot(rf.row(2).transpose()), -1.0, 1.0)) * 5;
    const int k = static_cast<int>(std::floor(c + 0.5));
    const double tc = c - k;
    const auto at = [&](int sec, int shell, int hemi, int bin) -> double& {
      return h[(4 * sec + 2 * shell + hemi) * 11 + bin];
    };
    double own = 0;
    // cosine
    own += 1 - std::abs(tc);
    at(sector, outer, upper, tc > 0 ? (k + 1) % 10 : (k + 9) % 10) += std::abs(tc);
    // azimuth
    own += 1 - std::abs(ta);
    at(ta > 0 ? (sector + 1) % 8 : (sector + 7) % 8, outer, upper, k) += std::abs(ta);
    // shells
    own += 1 - std::abs(tr);
    if ((outer == 0 && tr > 0) || (outer == 1 && tr < 0)) at(sector, 1 - outer, upper, k) += std::abs(tr);
    // hemispheres (upper: inclination below 90 degrees)
    own += 1 - std::abs(te);
    if ((upper == 1 && te > 0) || (upper == 0 && te < 0)) at(sector, outer, 1 - upper, k) += std::abs(te);
    at(sector, outer, upper, k) += own;
  }
  const double norm = std::sqrt(std::inner_product(h.begin(), h.end(), h.begin(), 0.0));
  for (double& x : h) x /= norm;
  return {h, true};
}

// ---- Spin images ------------------------------------------------------------------------------

/// Spin image with PCL's defaults: alpha (distance from the axis) and beta (height along the
/// normal) in the cylinder of radius and half height r / sqrt(2), 8 bins of that per unit;
/// image 9 x 17 (beta bin shifted by 8); bilinear votes; divided by the total.
std::pair<Row, bool> brute_spin(const PointCloud& s, const Vec3& kp, const Vec3& n, double r) {
  Row h(153, 0.0);
  const double bin = r / 8 / std::sqrt(2.0);
  for (std::size_t j : brute_neighbours(s, kp, r)) {
    const Vec3 d = s.points[j] - kp;
    if (d.norm() < 1e-12) continue;
    const double beta = d.dot(n);
    const double alpha = std::sqrt(std::max(0.0, d.squaredNorm() - beta * beta));
    if (alpha >= 8 * bin || std::abs(beta) >= 8 * bin) continue;
    const double u = alpha / bin, w = beta / bin + 8;
    const int i0 = static_cast<int>(u), j0 = static_cast<int>(std::floor(w));
    const double fu = u - i0, fw = w - j0;
    for (int di = 0; di < 2; ++di)
      for (int dj = 0; dj < 2; ++dj)
        h[(i0 + di) * 17 + j0 + dj] += (di ? fu : 1 - fu) * (dj ? fw : 1 - fw);
  }
  const double total = std::accumulate(h.begin(), h.end(), 0.0);
  if (!(total > 0)) return {Row(153, 0.0), false};
  for (double& x : h) x /= total;
  return {h, true};
}

// ---- Test surfaces ----------------------------------------------------------------------------

/// Random points on a patch of the quadric z = a x^2 + b y^2 + c x y (curved both ways, a
/// saddle part), analytic unit normals with +z component.
PointCloud quadric_patch(Rng& rng, std::size_t n, double half) {
  const double a = 9.0, b = -4.0, c = 6.0;
  PointCloud cloud;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = rng.uniform(-half, half), y = rng.uniform(-half, half);
    cloud.points.emplace_back(x, y, a * x * x + b * y * y + c * x * y);
    cloud.normals.push_back(Vec3(-(2 * a * x + c * y), -(2 * b * y + c * x), 1.0).normalized());
  }
  return cloud;
}

/// Normals tilted at random (up to about 50 degrees) and a fifth of them flipped, so that pair
/// features and cosines spread over every bin.
PointCloud roughened(PointCloud c, Rng& rng) {
  for (Vec3& n : c.normals) {
    n = (n + 0.8 * rng.unit_vector()).normalized();
    if (rng.uniform() < 0.2) n = -n;
  }
  return c;
}

/// A quadric patch (roughened or not), its tree, and settings with the given feature radius;
/// rng continues the stream that drew the patch. Unpack with TS_UNPACK_PATCH(patch): references, not a
/// structured binding, which clang 14 cannot capture in a lambda.
struct Patch {
  Rng rng;
  PointCloud s;
  KdTree3 tree;
  DescriptorSettings set;
  Patch(std::uint64_t seed, std::size_t n, double half, double radius, bool rough) : rng(seed) {
    s = quadric_patch(rng, n, half);
    if (rough) s = roughened(std::move(s), rng);
    tree = KdTree3(s.points);
    set.feature_radius = radius;
  }
};

#define TS_UNPACK_PATCH(p) \
  Rng& rng = (p).rng;          \
  PointCloud& s = (p).s;       \
  KdTree3& tree = (p).tree;    \
  DescriptorSettings& set = (p).set

std::vector<Vec3> pick_keypoints(Rng& rng, const PointCloud& s, int on, int off, double half) {
  std::vector<Vec3> k;
  for (int i = 0; i < on; ++i) k.push_back(s.points[rng.index(s.size())]);
  for (int i = 0; i < off; ++i)
    k.emplace_back(rng.uniform(-half, half), rng.uniform(-half, half), rng.uniform(-0.003, 0.003));
  return k;
}

/// Normals for the spin axis: the surface normal at the nearest surface point.
std::vector<Vec3> nearest_normals(const PointCloud& s, const std::vector<Vec3>& kps) {
  const KdTree3 tree(s.points);
  std::vector<Vec3> n;
  for (const Vec3& k : kps) n.push_back(s.normals[tree.nearest(k).index]);
  return n;
}

double max_abs_diff(std::span<const float> got, const Row& want) {
  double worst = 0;
  for (std::size_t b = 0; b < want.size(); ++b) worst = std::max(worst, std::abs(double(got[b]) - want[b]));
  return worst;
}

/// Compare every keypoint's row with the brute force; returns the number of valid keypoints.
template <class Brute>
int check_against(const Descriptors& got, std::size_t n, double tolerance, Brute brute) {
  REQUIRE(got.size() == n);
  REQUIRE(got.values.size() == n * static_cast<std::size_t>(got.dim));
  int valid = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const auto [want, ok] = brute(k);
    REQUIRE(want.size() == static_cast<std::size_t>(got.dim));
    CHECK(got.valid[k] == ok);
    valid += ok;
    const double diff = max_abs_diff(got.row(k), want);
    CHECK_MESSAGE(diff < tolerance, "keypoint " << k << " differs by " << diff);
  }
  return valid;
}

}  // namespace

TEST_CASE("descriptor names, dimensions and the parser") {
  CHECK(descriptor_dim(Descriptor::fpfh) == 33);
  CHECK(descriptor_dim(Descriptor::pfh) == 125);
  CHECK(descriptor_dim(Descriptor::shot) == 352);
  CHECK(descriptor_dim(Descriptor::spin) == 153);
  for (Descriptor d : kAllDescriptors) CHECK(parse_descriptor(descriptor_name(d)) == d);
  CHECK(parse_descriptor("shot") == Descriptor::shot);
  try {
    parse_descriptor("SHOT352");
    FAIL("no exception");
  } catch (const Error& e) {
    CHECK(std::string(e.what()).find("'SHOT352'") != std::string::npos);
    CHECK(e.field() == "descriptor");
  }
  CHECK_THROWS_AS(parse_descriptor(""), Error);
}

TEST_CASE("PFH matches the brute-force formulation") {
  Patch patch(11, 500, 0.02, 0.006, true);
  TS_UNPACK_PATCH(patch);
  auto kps = pick_keypoints(rng, s, 25, 15, 0.024);
  kps.emplace_back(1, 1, 1);   // nothing around it
  const auto got = compute_descriptors(Descriptor::pfh, kps, {}, s, tree, set);
  CHECK(got.dim == 125);
  const int valid = check_against(got, kps.size(), 2e-4, [&](std::size_t k) { return brute_pfh(s, kps[k], set.feature_radius); });
  CHECK(valid >= 30);
  CHECK_FALSE(got.valid.back());
  // The increment counts every pair of the neighbourhood: on this surface no pair is
  // degenerate, so each valid histogram sums to 100.
  for (std::size_t k = 0; k < kps.size(); ++k)
    if (got.valid[k]) {
      const auto row = got.row(k);
      CHECK(std::accumulate(row.begin(), row.end(), 0.0) == doctest::Approx(100.0).epsilon(1e-5));
    }
}

TEST_CASE("PFH bins a degenerate pair as PCL does: f = (0, 0, 0), bin 62") {
  // Points of a plane z = 0 with normals +z, and the first point twice: its pair with its copy
  // has distance 0 (pcl::computePairFeatures returns false, PFHEstimation bins it anyway). Every
  // other pair of a plane has f1 = 0 (u = n, n2 = n), f2 = 0 and f3 = 0 as well: the whole
  // histogram is bin 62. A copy with a tilted normal instead has a well-defined pair elsewhere.
  PointCloud s;
  for (int i = 0; i < 6; ++i) {
    s.points.emplace_back(0.002 * i, 0.001 * (i % 3), 0.0);
    s.normals.emplace_back(0.0, 0.0, 1.0);
  }
  s.points.push_back(s.points[0]);
  s.normals.emplace_back(0.0, 0.0, 1.0);
  const KdTree3 tree(s.points);
  DescriptorSettings set;
  set.feature_radius = 0.05;
  const auto got = compute_descriptors(Descriptor::pfh, {s.points[0]}, {}, s, tree, set);
  REQUIRE(got.valid[0]);
  const auto row = got.row(0);
  CHECK(row[62] == doctest::Approx(100.0).epsilon(1e-6));
  CHECK(std::accumulate(row.begin(), row.end(), 0.0) == doctest::Approx(100.0).epsilon(1e-6));
  const auto [want, ok] = brute_pfh(s, s.points[0], set.feature_radius);
  REQUIRE(ok);
  for (int b = 0; b < 125; ++b) CHECK(row[b] == doctest::Approx(want[b]).epsilon(1e-6));
  // With the copy's normal tilted, its 5 pairs with the other points leave bin 62 (f3 = the
  // tilted normal's slope along the pair, about +-0.55), its pair with point 0 stays there
  // (degenerate), and so do the 15 planar pairs: 16 of the 21 pairs; the sum stays 100.
  s.normals.back() = Vec3(0.6, 0.0, 0.8);
  const KdTree3 tree2(s.points);
  const auto tilted = compute_descriptors(Descriptor::pfh, {s.points[0]}, {}, s, tree2, set);
  const auto r2 = tilted.row(0);
  CHECK(std::accumulate(r2.begin(), r2.end(), 0.0) == doctest::Approx(100.0).epsilon(1e-6));
  CHECK(r2[62] == doctest::Approx(100.0 * 15.0 / 21.0 + 100.0 / 21.0).epsilon(1e-6));   // + the degenerate pair
  // A non-finite normal leaves its pairs out, without undefined behaviour.
  s.normals.back() = Vec3(std::nan(""), 0.0, 1.0);
  const KdTree3 tree3(s.points);
  const auto with_nan = compute_descriptors(Descriptor::pfh, {s.points[0]}, {}, s, tree3, set);
  const auto nan_row = with_nan.row(0);
  CHECK(std::accumulate(nan_row.begin(), nan_row.end(), 0.0) == doctest::Approx(100.0 * 15.0 / 21.0).epsilon(1e-6));
}

TEST_CASE("SHOT matches the brute-force formulation (frame and per-axis interpolation)") {
  Patch patch(12, 600, 0.02, 0.007, true);
  TS_UNPACK_PATCH(patch);
  auto kps = pick_keypoints(rng, s, 30, 20, 0.024);
  kps.emplace_back(0.0, 0.0, 0.5);
  const auto got = compute_descriptors(Descriptor::shot, kps, {}, s, tree, set);
  CHECK(got.dim == 352);
  const int valid = check_against(got, kps.size(), 1e-6, [&](std::size_t k) { return brute_shot(s, kps[k], set.feature_radius); });
  CHECK(valid >= 35);
  for (std::size_t k = 0; k < kps.size(); ++k)
    if (got.valid[k]) {
      double sq = 0;
      for (float v : got.row(k)) sq += double(v) * v;
      CHECK(sq == doctest::Approx(1.0).epsilon(1e-5));
    }
}

TEST_CASE("SHOT's frame radius is its own setting") {
  Patch patch(15, 600, 0.02, 0.007, false);
  TS_UNPACK_PATCH(patch);
  const auto kps = pick_keypoints(rng, s, 20, 0, 0.015);
  const auto same = compute_descriptors(Descriptor::shot, kps, {}, s, tree, set);
  set.shot_lrf_radius = 0.007;
  const auto explicit_same = compute_descriptors(Descriptor::shot, kps, {}, s, tree, set);
  CHECK(same.values == explicit_same.values);
  set.shot_lrf_radius = 0.004;
  const auto other = compute_descriptors(Descriptor::shot, kps, {}, s, tree, set);
  CHECK(other.values != same.values);
}

TEST_CASE("SHOT needs 5 neighbours in its support, and 5 besides the keypoint for its frame") {
  // A ring of 4 points at 2 mm around the keypoint and 12 more at 6 mm, all in z = 0 but tilted
  // normals: over 3 mm the support has 4 points (5 with the keypoint's own point).
  PointCloud c;
  c.points.emplace_back(0, 0, 0.0001);
  c.normals.push_back(Vec3(0.1, 0, 1).normalized());
  for (int k = 0; k < 16; ++k) {
    const double a = 2 * M_PI * (k + 0.3) / (k < 4 ? 4 : 12), r = k < 4 ? 0.002 : 0.006;
    c.points.emplace_back(r * std::cos(a), r * std::sin(a), 0.0005 * std::sin(3 * a));
    c.normals.push_back(Vec3(0.2 * std::cos(a), 0.3, 1).normalized());
  }
  const KdTree3 tree(c.points);
  DescriptorSettings set;
  set.feature_radius = 0.003;
  set.shot_lrf_radius = 0.008;
  // on the centre point: 5 in the support (itself included), 16 others for the frame
  CHECK(compute_descriptors(Descriptor::shot, {c.points[0]}, {}, c, tree, set).valid[0]);
  // the same keypoint without its own point in the cloud: 4 in the support, 15 for the frame
  PointCloud ring = c;
  ring.points.erase(ring.points.begin());
  ring.normals.erase(ring.normals.begin());
  CHECK_FALSE(compute_descriptors(Descriptor::shot, {c.points[0]}, {}, ring, KdTree3(ring.points), set).valid[0]);
  // the frame over 3 mm has only the 4 ring points besides the keypoint
  set.shot_lrf_radius = 0.0;
  CHECK_FALSE(compute_descriptors(Descriptor::shot, {c.points[0]}, {}, c, tree, set).valid[0]);
}

TEST_CASE("Spin images match the brute-force formulation") {
  Patch patch(13, 500, 0.02, 0.006, false);
  TS_UNPACK_PATCH(patch);
  auto kps = pick_keypoints(rng, s, 25, 15, 0.024);
  kps.emplace_back(-1, 0, 0);
  auto normals = nearest_normals(s, kps);
  for (std::size_t k = 0; k < kps.size(); k += 4) normals[k] = -normals[k];   // the axis' sign mirrors beta
  const auto got = compute_descriptors(Descriptor::spin, kps, normals, s, tree, set);
  CHECK(got.dim == 153);
  const int valid = check_against(got, kps.size(), 1e-6,
                                  [&](std::size_t k) { return brute_spin(s, kps[k], normals[k], set.feature_radius); });
  CHECK(valid >= 30);
  CHECK_FALSE(got.valid.back());
}

TEST_CASE("on a plane: PFH puts every pair in one bin, the spin image on the beta = 0 column") {
  PointCloud plane;
  Rng rng(14);
  for (int i = 0; i < 400; ++i) {
    plane.points.emplace_back(rng.uniform(-0.01, 0.01), rng.uniform(-0.01, 0.01), 0.0);
    plane.normals.emplace_back(0, 0, 1);
  }
  const KdTree3 tree(plane.points);
  DescriptorSettings set;
  set.feature_radius = 0.005;
  const std::vector<Vec3> kps = {plane.points[0], Vec3(0.001, -0.002, 0.0), Vec3(0.0, 0.0, 0.0)};
  const std::vector<Vec3> normals(kps.size(), Vec3::UnitZ());
  // PFH: f1 = atan2(0, 1) = 0, f2 = 0, f3 = 0: bins (2, 2, 2) = 2 + 5 * 2 + 25 * 2 = 62.
  const auto pfh = compute_descriptors(Descriptor::pfh, kps, {}, plane, tree, set);
  for (std::size_t k = 0; k < kps.size(); ++k) {
    REQUIRE(pfh.valid[k]);
    for (int b = 0; b < 125; ++b) CHECK(std::abs(pfh.row(k)[b] - (b == 62 ? 100.0f : 0.0f)) <= (b == 62 ? 1e-3f : 0.0f));
  }
  // Spin: beta = 0 for every point (column 8); alpha spreads over the rows.
  const auto spin = compute_descriptors(Descriptor::spin, kps, normals, plane, tree, set);
  for (std::size_t k = 0; k < kps.size(); ++k) {
    REQUIRE(spin.valid[k]);
    double column = 0, total = 0;
    for (int i = 0; i < 9; ++i)
      for (int j = 0; j < 17; ++j) {
        total += spin.row(k)[i * 17 + j];
        if (j == 8) column += spin.row(k)[i * 17 + j];
      }
    CHECK(total == doctest::Approx(1.0).epsilon(1e-6));
    CHECK(column == doctest::Approx(1.0).epsilon(1e-6));
  }
  // A tilted spin axis moves mass off the beta = 0 column.
  const auto tilted = compute_descriptors(Descriptor::spin, kps, std::vector<Vec3>(3, Vec3(0.3, 0, 1).normalized()),
                                          plane, tree, set);
  double column = 0;
  for (int i = 0; i < 9; ++i) column += tilted.row(0)[i * 17 + 8];
  CHECK(column < 0.9);
}

TEST_CASE("FPFH through the common interface is compute_fpfh") {
  Patch patch(16, 500, 0.02, 0.006, false);
  TS_UNPACK_PATCH(patch);
  const auto kps = pick_keypoints(rng, s, 20, 10, 0.024);
  const auto got = compute_descriptors(Descriptor::fpfh, kps, {}, s, tree, set);
  FpfhSettings fs;
  fs.feature_radius = 0.006;
  const auto want = compute_fpfh(kps, {}, s, tree, fs);
  REQUIRE(got.dim == 33);
  for (std::size_t k = 0; k < kps.size(); ++k) {
    CHECK(got.valid[k] == want.valid[k]);
    CHECK(std::memcmp(got.row(k).data(), want.features[k].data(), sizeof(Feature)) == 0);
  }
}

TEST_CASE("every descriptor is invariant to rigid motions and independent of the thread count") {
  Patch patch(21, 1500, 0.025, 0.008, false);
  TS_UNPACK_PATCH(patch);
  const auto kps = pick_keypoints(rng, s, 60, 20, 0.02);
  const auto normals = nearest_normals(s, kps);
  for (Descriptor d : kAllDescriptors) {
    CAPTURE(descriptor_name(d));
    const auto base = compute_descriptors(d, kps, normals, s, tree, set);
    int valid = 0;
    for (bool v : base.valid) valid += v;
    CHECK(valid >= 60);
    for (int trial = 0; trial < 2; ++trial) {
      Pose T = Pose::Identity();
      T.linear() = rng.rotation().toRotationMatrix();
      T.translation() = Vec3(rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-3, 3));
      const PointCloud moved = [&] {
        PointCloud m;
        for (std::size_t i = 0; i < s.size(); ++i) {
          m.points.push_back(T * s.points[i]);
          m.normals.push_back(T.linear() * s.normals[i]);
        }
        return m;
      }();
      std::vector<Vec3> mk, mn;
      for (std::size_t k = 0; k < kps.size(); ++k) {
        mk.push_back(T * kps[k]);
        mn.push_back(T.linear() * normals[k]);
      }
      const auto res = compute_descriptors(d, mk, mn, moved, KdTree3(moved.points), set);
      // Histogram values up to 100 (PFH, FPFH) or 1 (SHOT, spin): a bin moved by one vote
      // changes a value by far more than these bounds.
      const double tol = (d == Descriptor::pfh || d == Descriptor::fpfh) ? 1e-3 : 1e-5;
      for (std::size_t k = 0; k < kps.size(); ++k) {
        CHECK(res.valid[k] == base.valid[k]);
        double worst = 0;
        for (int b = 0; b < res.dim; ++b) worst = std::max(worst, double(std::abs(res.row(k)[b] - base.row(k)[b])));
        CHECK_MESSAGE(worst < tol, "keypoint " << k << " differs by " << worst);
      }
    }
    Descriptors one, two;
    tbb::task_arena(1).execute([&] { one = compute_descriptors(d, kps, normals, s, tree, set); });
    tbb::task_arena(2).execute([&] { two = compute_descriptors(d, kps, normals, s, tree, set); });
    CHECK(one.valid == two.valid);
    REQUIRE(one.values.size() == two.values.size());
    CHECK(std::memcmp(one.values.data(), two.values.data(), one.values.size() * sizeof(float)) == 0);
  }
}

TEST_CASE("descriptors reject inconsistent inputs") {
  PointCloud c;
  c.points = {Vec3(0, 0, 0), Vec3(0.001, 0, 0)};
  const KdTree3 tree(c.points);
  const std::vector<Vec3> kp = {Vec3::Zero()};
  for (Descriptor d : kAllDescriptors) {
    CAPTURE(descriptor_name(d));
    PointCloud bare = c;
    CHECK_THROWS_AS(compute_descriptors(d, kp, {Vec3::UnitZ()}, bare, tree, {}), Error);   // no normals
    c.normals = {Vec3(0, 0, 1), Vec3(0, 0, 1)};
    CHECK_THROWS_AS(compute_descriptors(d, kp, {Vec3::UnitZ(), Vec3::UnitZ()}, c, tree, {}), Error);
    CHECK_THROWS_AS(compute_descriptors(d, kp, {Vec3::UnitZ()}, c, KdTree3({Vec3::Zero()}), {}), Error);
    DescriptorSettings bad;
    bad.feature_radius = 0;
    CHECK_THROWS_AS(compute_descriptors(d, kp, {Vec3::UnitZ()}, c, tree, bad), Error);
    bad.feature_radius = std::nan("");
    CHECK_THROWS_AS(compute_descriptors(d, kp, {Vec3::UnitZ()}, c, tree, bad), Error);
    bad = {};
    bad.shot_lrf_radius = -0.01;
    CHECK_THROWS_AS(compute_descriptors(d, kp, {Vec3::UnitZ()}, c, tree, bad), Error);
    const auto empty = compute_descriptors(d, {}, {}, c, tree, {});
    CHECK(empty.values.empty());
    CHECK(empty.dim == descriptor_dim(d));
    c.normals.clear();
  }
  c.normals = {Vec3(0, 0, 1), Vec3(0, 0, 1)};
  try {
    compute_descriptors(Descriptor::spin, kp, {}, c, tree, {});   // the spin axis is missing
    FAIL("no exception");
  } catch (const Error& e) {
    CHECK(e.field() == "keypoint_normals");
  }
}
