// Metrics against hand-computed and published values.
#include "experiments/analysis/metrics.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

using namespace ts;
using namespace ts::experiments;

namespace {
Mat3 rot(double angle, const Vec3& axis) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}
Pose pose(const Mat3& r, const Vec3& t) {
  Pose p = Pose::Identity();
  p.linear() = r;
  p.translation() = t;
  return p;
}
}  // namespace

TEST_CASE("Wilson interval matches Newcombe (1998) Table I") {
  // Newcombe, Statistics in Medicine 17:857-872, method 3 (score, no continuity correction).
  // The table gives 4 decimals: each bound within half a unit of the last (plus slack).
  Interval a = wilson_interval(81, 263);
  CHECK(std::abs(a.lo - 0.2553) < 6e-5);
  CHECK(std::abs(a.hi - 0.3662) < 6e-5);
  Interval b = wilson_interval(15, 148);
  CHECK(std::abs(b.lo - 0.0624) < 6e-5);
  CHECK(std::abs(b.hi - 0.1605) < 6e-5);
  Interval c = wilson_interval(0, 20);
  CHECK(c.lo == 0.0);
  CHECK(std::abs(c.hi - 0.1611) < 6e-5);
  Interval d = wilson_interval(1, 29);
  CHECK(std::abs(d.lo - 0.0061) < 6e-5);
  CHECK(std::abs(d.hi - 0.1718) < 6e-5);
}

TEST_CASE("Wilson interval at hand-computed points and edges") {
  // 8/10: centre (0.8 + 1.92/10) / 1.384 etc., computed by hand from the score formula.
  Interval a = wilson_interval(8, 10);
  CHECK(std::abs(a.lo - 0.490162) < 6e-7);
  CHECK(std::abs(a.hi - 0.943318) < 6e-7);
  Interval h = wilson_interval(5, 10);  // symmetric about 1/2
  CHECK(h.lo + h.hi == doctest::Approx(1.0));
  CHECK(std::abs(h.lo - 0.236593) < 6e-7);
  Interval all = wilson_interval(10, 10);
  CHECK(all.hi == 1.0);
  CHECK(all.lo == doctest::Approx(0.722467).epsilon(1e-5));
  Interval none = wilson_interval(0, 0);
  CHECK(none.lo == 0.0);
  CHECK(none.hi == 1.0);
  CHECK_THROWS_AS(wilson_interval(3, 2), Error);
  // Wider at 90 % than... narrower at lower confidence.
  Interval z90 = wilson_interval(8, 10, 1.6448536269514722);
  CHECK(z90.lo > a.lo);
  CHECK(z90.hi < a.hi);
}

TEST_CASE("Quantiles are type 7 (linear interpolation)") {
  const std::vector<double> v{4, 1, 3, 2};
  CHECK(*median(v) == doctest::Approx(2.5));
  CHECK(*quantile(v, 0.95) == doctest::Approx(3.85));
  CHECK(*quantile(v, 0.0) == 1.0);
  CHECK(*quantile(v, 1.0) == 4.0);
  const std::vector<double> odd{3, 1, 2};
  CHECK(*median(odd) == 2.0);
  const std::vector<double> one{7};
  CHECK(*quantile(one, 0.95) == 7.0);
  CHECK_FALSE(median(std::vector<double>{}).has_value());
  CHECK_THROWS_AS(quantile(v, 1.5), Error);
  const std::vector<double> bad{1, std::nan("")};
  CHECK_THROWS_AS(median(bad), Error);
}

TEST_CASE("Student t quantiles match tables") {
  CHECK(student_t_quantile(0.975, 1) == doctest::Approx(12.706204736).epsilon(1e-8));
  CHECK(student_t_quantile(0.975, 2) == doctest::Approx(4.302652730).epsilon(1e-8));
  CHECK(student_t_quantile(0.975, 4) == doctest::Approx(2.776445105).epsilon(1e-8));
  CHECK(student_t_quantile(0.975, 19) == doctest::Approx(2.093024054).epsilon(1e-8));
  CHECK(student_t_quantile(0.975, 30) == doctest::Approx(2.042272456).epsilon(1e-8));
  CHECK(student_t_quantile(0.975, 1e6) == doctest::Approx(kZ95).epsilon(1e-5));
  CHECK(student_t_quantile(0.025, 4) == doctest::Approx(-2.776445105).epsilon(1e-8));
  CHECK(student_t_cdf(-1.5, 3) == doctest::Approx(0.115291932622).epsilon(1e-9));
  CHECK(incomplete_beta(0.3, 2.5, 1.5) == doctest::Approx(0.088943723171).epsilon(1e-9));
}

TEST_CASE("Mean with a Student-t interval") {
  const std::vector<double> v{1, 2, 3, 4, 5};
  const MeanInterval m = mean_t_interval(v);
  CHECK(m.n == 5);
  CHECK(m.mean == doctest::Approx(3.0));
  REQUIRE(m.ci.has_value());
  // s = sqrt(2.5); half width = t(0.975, 4) * s / sqrt(5) = 2.776445 * 0.707107
  CHECK(m.ci->hi - m.mean == doctest::Approx(2.776445105 * std::sqrt(0.5)).epsilon(1e-8));
  CHECK(m.mean - m.ci->lo == doctest::Approx(2.776445105 * std::sqrt(0.5)).epsilon(1e-8));
  const MeanInterval one = mean_t_interval(std::vector<double>{2.0});
  CHECK(one.mean == 2.0);
  CHECK_FALSE(one.ci.has_value());
}

TEST_CASE("MSSD, symmetry-aware") {
  const Pose truth = pose(rot(0.4, {1, 1, 0}), {1.0, -2.0, 0.5});
  // MSSD: two points on the x axis, symmetric under a half turn about z.
  const std::vector<Vec3> pts{{0.05, 0, 0}, {-0.05, 0, 0}};
  const std::vector<Pose> half{pose(rot(std::numbers::pi, {0, 0, 1}), Vec3::Zero())};
  const Pose flipped = truth * half[0];
  CHECK(mssd(flipped, truth, {}, pts) == doctest::Approx(0.10));
  CHECK(mssd(flipped, truth, half, pts) == doctest::Approx(0.0));
  // A pure 1 cm shift moves every point by 1 cm.
  Pose shifted = truth;
  shifted.translation() += Vec3(0.0, 0.01, 0.0);
  CHECK(mssd(shifted, truth, half, pts) == doctest::Approx(0.01));
  // Symmetries with a translation part (origin off the symmetry axis) are honoured.
  const std::vector<Vec3> off{{0.06, 0, 0}, {0.04, 0, 0}};
  const Pose about_x005 = pose(rot(std::numbers::pi, {0, 0, 1}), {0.10, 0, 0});
  const std::vector<Pose> sym_off{about_x005};
  CHECK(mssd(truth * about_x005, truth, sym_off, off) == doctest::Approx(0.0));
  CHECK(mssd(truth, truth, {}, {}) == 0.0);
}

TEST_CASE("Step summary follows the paper's bounded averaging") {
  std::vector<StepSample> s(4);
  s[0] = {true, 0.01, 0.1, 0.05, 0.012, 1.0};
  s[1] = {true, 0.02, 2.0, 0.10, 0.030, 2.0};
  s[2] = {true, 0.10, 0.3, 0.20, 0.200, 3.0};
  s[3] = {false, 0.50, 3.0, 3.00, 0.900, 4.0};
  const StepSummary m = summarize_step(7, s);
  CHECK(m.step == 7);
  CHECK(m.runs == 4);
  CHECK(m.correct == 3);
  CHECK(m.recognition_rate == doctest::Approx(0.75));
  CHECK(m.recognition_rate_ci95.lo == doctest::Approx(0.300642).epsilon(1e-5));
  CHECK(m.recognition_rate_ci95.hi == doctest::Approx(0.954413).epsilon(1e-5));
  // Errors only over the 3 correct runs; the mean caps each at 4 cm / 1 rad.
  CHECK(m.position_m.n == 3);
  CHECK(*m.position_m.median == doctest::Approx(0.02));
  CHECK(*m.position_m.p95 == doctest::Approx(0.02 + 0.9 * 0.08));
  CHECK(m.position_m.bounded_mean == doctest::Approx((0.01 + 0.02 + 0.04) / 3));
  CHECK(m.orientation_rad.bounded_mean == doctest::Approx((0.1 + 1.0 + 0.3) / 3));
  REQUIRE(m.position_m.bounded_mean_ci95.has_value());
  // s of {0.01, 0.02, 0.04} = 0.0152753; t(0.975, 2) = 4.302653
  const double half = 4.302652730 * 0.015275252316519 / std::sqrt(3.0);
  CHECK(m.position_m.bounded_mean_ci95->hi == doctest::Approx(0.0233333 + half).epsilon(1e-5));
  CHECK(*m.time_s_median == doctest::Approx(2.5));
  CHECK(*m.time_s_p95 == doctest::Approx(3.85));

  // No correct run: the bound itself, no median.
  std::vector<StepSample> wrong{s[3], s[3]};
  const StepSummary w = summarize_step(1, wrong);
  CHECK(w.recognition_rate == 0.0);
  CHECK(w.position_m.bounded_mean == 0.04);
  CHECK(w.orientation_rad.bounded_mean == 1.0);
  CHECK_FALSE(w.position_m.median.has_value());
  CHECK_FALSE(w.position_m.bounded_mean_ci95.has_value());
}

TEST_CASE("Pareto front: cheaper or better, never dominated") {
  //                      0    1    2    3    4    5
  const std::vector<double> cost{1.0, 2.0, 3.0, 2.0, 5.0, 3.0};
  const std::vector<double> gain{0.5, 0.7, 0.6, 0.4, 0.9, 0.7};
  const auto f = pareto_front(cost, gain);
  REQUIRE(f.size() == 3);
  CHECK(f[0] == 0);
  CHECK(f[1] == 1);
  CHECK(f[2] == 4);
  // Brute force: each front member is not dominated; each other point is.
  for (std::size_t i = 0; i < cost.size(); ++i) {
    bool dominated = false;
    for (std::size_t j = 0; j < cost.size(); ++j)
      if (cost[j] <= cost[i] && gain[j] >= gain[i] && (cost[j] < cost[i] || gain[j] > gain[i]))
        dominated = true;
    CHECK(dominated == (std::find(f.begin(), f.end(), i) == f.end()));
  }
}

TEST_CASE("Class-aware recognition rate: a twin in the true object's class counts, the strict rate does not") {
  // Three runs: right, the congruent twin, another object.
  std::vector<StepSample> s(3);
  s[0].correct = true;
  s[1].correct_class = true;
  const StepSummary m = summarize_step(20, s);
  CHECK(m.correct == 1);
  CHECK(m.recognition_rate == doctest::Approx(1.0 / 3));
  CHECK(m.correct_class == 2);
  CHECK(m.recognition_rate_class == doctest::Approx(2.0 / 3));
  CHECK(m.recognition_rate_class_ci95.lo == doctest::Approx(wilson_interval(2, 3).lo));
  CHECK(m.position_m.n == 1);   // errors over the strictly right runs only
}

TEST_CASE("Cluster bootstrap resamples objects, not runs") {
  // 20 objects x 10 runs; every run of an object has the same outcome (15 objects always right,
  // 5 always wrong). Resampling objects gives the rate K / 20, K ~ Binomial(20, 0.75), whose
  // 2.5 % and 97.5 % quantiles are 11 and 18-19 (P(K <= 10) = 0.014, P(K <= 11) = 0.041,
  // P(K <= 18) = 0.976): [0.55, 0.90-0.95]. Resampling the 200 runs would give about
  // 0.75 +- 0.06, as the Wilson interval does.
  std::vector<ClusterCounts> objects;
  for (int i = 0; i < 20; ++i) objects.push_back({i < 15 ? 10u : 0u, 10u});
  const Interval b = cluster_bootstrap_interval(objects);
  CHECK(std::abs(b.lo - 0.55) < 1e-9);
  CHECK(b.hi >= 0.90 - 1e-12);
  CHECK(b.hi <= 0.95 + 1e-12);
  const Interval w = wilson_interval(150, 200);
  CHECK(w.lo > 0.68);
  CHECK(w.hi < 0.81);
  CHECK(b.hi - b.lo > 2.5 * (w.hi - w.lo));

  // Deterministic for a seed; another seed draws other resamples.
  const Interval again = cluster_bootstrap_interval(objects);
  CHECK(again.lo == b.lo);
  CHECK(again.hi == b.hi);

  // One run per object: the ordinary bootstrap of a proportion, close to the normal interval
  // 0.5 +- 1.96 sqrt(0.25 / 400) = 0.5 +- 0.049.
  std::vector<ClusterCounts> single;
  for (int i = 0; i < 400; ++i) single.push_back({i % 2 == 0 ? 1u : 0u, 1u});
  const Interval s = cluster_bootstrap_interval(single, 4000, 11);
  CHECK(std::abs(s.lo - 0.451) < 0.012);
  CHECK(std::abs(s.hi - 0.549) < 0.012);

  // Pooled rate over clusters of different sizes; empty clusters ignored; edges.
  std::vector<ClusterCounts> uneven{{30, 30}, {30, 30}, {0, 0}};
  const Interval u = cluster_bootstrap_interval(uneven);
  CHECK(u.lo == 1.0);
  CHECK(u.hi == 1.0);
  std::vector<ClusterCounts> none{{0, 0}};
  CHECK(cluster_bootstrap_interval(none).lo == 0.0);
  CHECK(cluster_bootstrap_interval(none).hi == 1.0);
  std::vector<ClusterCounts> bad{{3, 2}};
  CHECK_THROWS_AS(cluster_bootstrap_interval(bad), Error);
  CHECK_THROWS_AS(cluster_bootstrap_interval(objects, 0), Error);
}
