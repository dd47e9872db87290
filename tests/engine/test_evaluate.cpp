#include "engine/evaluate.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <numeric>

using namespace ts;

namespace {

/// A scene built by hand: only what the evaluation reads.
Scene make_scene(std::vector<Vec3> pts, std::vector<Vec3> free = {}, std::uint64_t seed = 1) {
  Scene s;
  const std::size_t n = pts.size();
  s.contacts.points = std::move(pts);
  s.contacts.normals.assign(n, Vec3::Zero());
  s.order.resize(n);
  std::iota(s.order.begin(), s.order.end(), 0u);
  Rng rng(seed);
  for (std::size_t i = n; i > 1; --i) std::swap(s.order[i - 1], s.order[rng.index(i)]);
  for (std::uint32_t i : s.order) s.ordered.push_back(s.contacts.points[i]);
  s.free_space = std::move(free);
  return s;
}

constexpr double kR = 0.05;  // sphere radius
double sphere_distance(const Vec3& p) { return p.norm() - kR; }
const Vec3 kHalf(kR, kR, kR);

/// Eq. 4, 5, 8, 9 and 6 written out literally as products (the oracle).
double oracle_weight(const std::vector<Vec3>& contacts, const std::vector<Vec3>& free,
                     const Pose& T_scene_object, const EvaluateSettings& s) {
  const Pose inv = T_scene_object.inverse();
  const double C = static_cast<double>(contacts.size());
  double wt_cont = 1.0;
  for (const Vec3& c : contacts) {
    const double d = std::abs(sphere_distance(inv * c));
    const double e = d < s.d_outlier ? (d / s.d_outlier) * (d / s.d_outlier) : 1.0;
    wt_cont *= std::exp(-e / C);
  }
  double wt_free = 1.0;
  const double dt = s.res_free / 2;
  for (const Vec3& q : free) {
    const double d = std::abs(sphere_distance(inv * q));
    const double e = d <= dt ? (dt * dt - d * d) / (dt * dt) : 0.0;
    wt_free *= std::exp(-s.lambda * e);
  }
  return wt_cont * (s.free_space ? wt_free : 1.0);
}

Pose some_pose() {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  T.translation() = Vec3(0.01, -0.02, 0.03);
  return T;
}

}  // namespace

TEST_CASE("Contacts on the surface at the true pose weigh 1") {
  Rng rng(1);
  const Pose T = some_pose();
  std::vector<Vec3> pts;
  for (int i = 0; i < 200; ++i) pts.push_back(T * (kR * rng.unit_vector()));
  const Scene sc = make_scene(pts);
  const Evaluation ev = evaluate_with(sc, sphere_distance, kHalf, T, EvaluateSettings{});
  CHECK(ev.complete);
  CHECK(ev.log_weight == doctest::Approx(0.0).epsilon(1e-12));
  CHECK(ev.contacts == 200);
}

TEST_CASE("Eq. 4-5: contact errors, outliers saturate at 1") {
  Rng rng(2);
  const Pose T = some_pose();
  std::vector<Vec3> pts;
  for (int i = 0; i < 100; ++i) pts.push_back(T * ((kR + 0.01) * rng.unit_vector()));   // e = 0.0025
  for (int i = 0; i < 100; ++i) pts.push_back(T * ((kR + 0.30) * rng.unit_vector()));   // e = 1
  const Scene sc = make_scene(pts);
  EvaluateSettings s;
  const Evaluation ev = evaluate_with(sc, sphere_distance, kHalf, T, s);
  const double expected = -(100 * 0.0025 + 100 * 1.0) / 200.0;
  CHECK(ev.log_weight == doctest::Approx(expected).epsilon(1e-9));
  CHECK(std::exp(ev.log_weight) == doctest::Approx(oracle_weight(pts, {}, T, s)).epsilon(1e-9));
  CHECK(ev.contact_error == doctest::Approx(-expected));
}

TEST_CASE("Eq. 6-9: free space near the surface costs, far free space does not") {
  Rng rng(3);
  const Pose T = some_pose();
  std::vector<Vec3> pts, free;
  for (int i = 0; i < 50; ++i) pts.push_back(T * ((kR + 0.002) * rng.unit_vector()));
  for (int i = 0; i < 30; ++i) free.push_back(T * ((kR + 0.005) * rng.unit_vector()));  // near
  for (int i = 0; i < 30; ++i) free.push_back(T * ((kR + 0.015) * rng.unit_vector()));  // near
  for (int i = 0; i < 300; ++i) free.push_back(T * ((kR + 0.1 + rng.uniform()) * rng.unit_vector()));
  const Scene sc = make_scene(pts, free);
  EvaluateSettings s;  // lambda 0.02, res_free 0.04 -> d_thresh 0.02
  const Evaluation ev = evaluate_with(sc, sphere_distance, kHalf, T, s);
  CHECK(ev.complete);
  CHECK(std::exp(ev.log_weight) == doctest::Approx(oracle_weight(pts, free, T, s)).epsilon(1e-9));
  const double e1 = (0.02 * 0.02 - 0.005 * 0.005) / (0.02 * 0.02);
  const double e2 = (0.02 * 0.02 - 0.015 * 0.015) / (0.02 * 0.02);
  CHECK(ev.free_error == doctest::Approx(30 * e1 + 30 * e2).epsilon(1e-9));
  CHECK(ev.free_points < 100);  // the far points were culled without a distance query

  SUBCASE("no free-space data: the term is skipped") {
    const Scene bare = make_scene(pts);
    const Evaluation e0 = evaluate_with(bare, sphere_distance, kHalf, T, s);
    CHECK(e0.free_points == 0);
    CHECK(e0.free_error == 0.0);
    CHECK(e0.log_weight == doctest::Approx(ev.log_weight + s.lambda * ev.free_error));
  }
  SUBCASE("free space switched off (Eq. 5)") {
    EvaluateSettings off = s;
    off.free_space = false;
    const Evaluation e0 = evaluate_with(sc, sphere_distance, kHalf, T, off);
    CHECK(e0.free_points == 0);
    CHECK(std::exp(e0.log_weight) == doctest::Approx(oracle_weight(pts, free, T, off)).epsilon(1e-9));
  }
}

TEST_CASE("Free space deep inside: paper form ignores it, the extension penalizes it") {
  const Pose T = some_pose();
  std::vector<Vec3> pts;
  Rng rng(4);
  for (int i = 0; i < 20; ++i) pts.push_back(T * (kR * rng.unit_vector()));
  const Scene sc = make_scene(pts, {T * Vec3(0, 0, 0), T * Vec3(0.001, 0, 0)});
  EvaluateSettings s;
  CHECK(evaluate_with(sc, sphere_distance, kHalf, T, s).free_error == 0.0);
  s.free_inside_penalty = true;
  CHECK(evaluate_with(sc, sphere_distance, kHalf, T, s).free_error == 2.0);
}

TEST_CASE("Early rejection: an upper bound when stopped, exact when not") {
  Rng rng(5);
  const Pose T = some_pose();
  std::vector<Vec3> pts, free;
  for (int i = 0; i < 500; ++i) pts.push_back(T * ((kR + 0.003 * rng.normal()) * rng.unit_vector()));
  for (int i = 0; i < 200; ++i) free.push_back(T * ((kR + 0.03 * rng.uniform()) * rng.unit_vector()));
  const Scene sc = make_scene(pts, free);
  const EvaluateSettings s;
  int stopped = 0;
  for (int trial = 0; trial < 50; ++trial) {
    Pose P = T;
    P.translation() += 0.02 * rng.unit_vector() * rng.uniform();
    P.linear() = P.linear() * Eigen::AngleAxisd(0.3 * rng.uniform(), rng.unit_vector()).toRotationMatrix();
    const Evaluation full = evaluate_with(sc, sphere_distance, kHalf, P, s);
    REQUIRE(full.complete);
    const double above = 0.5 * full.log_weight;  // ln wt < 0: a higher threshold
    const Evaluation hi = evaluate_with(sc, sphere_distance, kHalf, P, s, above);
    if (hi.complete) {
      CHECK(hi.log_weight == full.log_weight);  // only the last chunk crossed the threshold
    } else {
      ++stopped;
      CHECK(hi.log_weight >= full.log_weight);  // an upper bound
      CHECK(hi.log_weight < above);
      CHECK(hi.contacts + hi.free_points < full.contacts + full.free_points);
    }
    const Evaluation lo = evaluate_with(sc, sphere_distance, kHalf, P, s, full.log_weight - 1e-12);
    CHECK(lo.complete);
    CHECK(lo.log_weight == full.log_weight);
  }
  CHECK(stopped > 25);
}

TEST_CASE("Evaluation never returns NaN") {
  const Scene empty = make_scene({});
  CHECK(evaluate_with(empty, sphere_distance, kHalf, Pose::Identity(), {}).log_weight ==
        -std::numeric_limits<double>::infinity());
  Pose bad = Pose::Identity();
  bad.translation().x() = std::nan("");
  const Scene one = make_scene({Vec3(0, 0, 0)});
  const Evaluation e = evaluate_with(one, sphere_distance, kHalf, bad, {});
  CHECK_FALSE(std::isnan(e.log_weight));
  CHECK_FALSE(e.complete);
}
