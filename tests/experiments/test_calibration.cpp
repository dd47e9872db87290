// Calibrated confidence (issue 14): the logistic fit against a known model, the calibration
// measures against hand-computed values, the calibration file's checks.
#include "experiments/calibration.hpp"
#include "experiments/metrics.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <fstream>

using namespace ts;
using namespace ts::experiments;

TEST_CASE("Logistic fit recovers the model that drew the labels") {
  // y ~ Bernoulli(sigmoid(1 + 2 x0 - 1 x1)), x ~ N(0, 1): standardized features are ~ x, so the
  // coefficients come back within sampling error (~0.05 at n = 20 000).
  Rng rng(5);
  std::vector<std::vector<double>> rows;
  std::vector<int> labels;
  for (int i = 0; i < 20000; ++i) {
    const double a = rng.normal(), b = rng.normal();
    const double p = 1.0 / (1.0 + std::exp(-(1.0 + 2.0 * a - 1.0 * b)));
    rows.push_back({a, b});
    labels.push_back(rng.uniform() < p ? 1 : 0);
  }
  const LogisticModel m = fit_logistic(rows, labels, 0.0);
  REQUIRE(m.coef.size() == 3);
  const double z0 = -m.mean[0] / m.scale[0], z1 = -m.mean[1] / m.scale[1];
  const double bias = m.coef[0] + m.coef[1] * z0 + m.coef[2] * z1;  // back to raw units
  CHECK(std::abs(bias - 1.0) < 0.1);
  CHECK(std::abs(m.coef[1] / m.scale[0] - 2.0) < 0.15);
  CHECK(std::abs(m.coef[2] / m.scale[1] + 1.0) < 0.1);
  const double at = m.predict(std::vector<double>{0.5, 0.0});
  CHECK(std::abs(at - 1.0 / (1.0 + std::exp(-2.0))) < 0.02);
  // Its own data are calibrated.
  std::vector<double> p;
  for (const auto& r : rows) p.push_back(m.predict(r));
  CHECK(confidence_calibration(p, labels).ece < 0.02);

  CHECK_THROWS_AS(fit_logistic({}, {}), Error);
  CHECK_THROWS_AS(fit_logistic({{1.0}, {1.0, 2.0}}, {0, 1}), Error);
  CHECK_THROWS_AS(fit_logistic({{1.0}, {2.0}}, {0, 2}), Error);
  CHECK_THROWS_AS(m.predict(std::vector<double>{1.0}), Error);
}

TEST_CASE("Expected calibration error, Brier score and reliability bins") {
  // 10 answers at 0.15 with 1 right (bin [0.1, 0.2): accuracy 0.1), 10 at 0.95 all right:
  // ECE = 0.5 * 0.05 + 0.5 * 0.05 = 0.05; Brier = (0.85^2 + 9 * 0.15^2 + 10 * 0.05^2) / 20.
  std::vector<double> c(10, 0.15);
  c.insert(c.end(), 10, 0.95);
  std::vector<int> y(20, 1);
  for (int i = 1; i < 10; ++i) y[static_cast<std::size_t>(i)] = 0;
  const ConfidenceCalibration r = confidence_calibration(c, y);
  CHECK(r.n == 20);
  CHECK(r.ece == doctest::Approx(0.05).epsilon(1e-12));
  CHECK(r.brier == doctest::Approx((0.85 * 0.85 + 9 * 0.15 * 0.15 + 10 * 0.05 * 0.05) / 20).epsilon(1e-12));
  REQUIRE(r.bins.size() == 10);
  CHECK(r.bins[1].n == 10);
  CHECK(r.bins[1].accuracy == doctest::Approx(0.1));
  CHECK(r.bins[9].n == 10);  // 0.95 and 1.0 land in the last bin
  CHECK(r.bins[9].mean_confidence == doctest::Approx(0.95));
  CHECK(r.accuracy == doctest::Approx(0.55));
  const std::vector<double> one{1.0};
  const std::vector<int> right{1};
  CHECK(confidence_calibration(one, right).ece == 0.0);
  const std::vector<double> bad{1.5};
  CHECK_THROWS_AS(confidence_calibration(bad, right), Error);
  CHECK(confidence_calibration(std::vector<double>{}, std::vector<int>{}).n == 0);
}

TEST_CASE("Calibration files: round trip, and another database, version or feature set is one clear error") {
  test::TempDir dir("calibration");
  Calibration c;
  c.database_fingerprint = "abc123";
  c.features = confidence_feature_names();
  const std::size_t f = c.features.size();
  c.object = {std::vector<double>(f, 0.5), std::vector<double>(f, 2.0), std::vector<double>(f + 1, 0.25)};
  c.pose = {std::vector<double>(f, 0.0), std::vector<double>(f, 1.0), std::vector<double>(f + 1, -0.5)};
  const auto path = dir / "cal.json";
  write_calibration(path, c);
  const Calibration back = read_calibration(path, "abc123");
  CHECK(back.object.coef == c.object.coef);
  CHECK(back.pose.mean == c.pose.mean);
  const std::vector<double> x(f, 0.5);
  CHECK(back.object_confidence(x) == doctest::Approx(1.0 / (1.0 + std::exp(-0.25))));
  CHECK_NOTHROW(read_calibration(path, ""));  // no database to check against

  auto error_of = [&](const std::string& text, const std::string& fingerprint) {
    const auto p = dir / "bad.json";
    std::ofstream(p) << text;
    try {
      read_calibration(p, fingerprint);
    } catch (const Error& e) {
      CHECK(e.file() == p.string());
      return e.field();
    }
    FAIL("no error for " << text);
    return std::string();
  };
  auto j = to_json(c);
  CHECK(error_of(j.dump(), "other") == "database_fingerprint");
  auto v = j;
  v["version"] = 2;
  CHECK(error_of(v.dump(), "abc123") == "version");
  auto fm = j;
  fm["format"] = "something";
  CHECK(error_of(fm.dump(), "abc123") == "format");
  auto fe = j;
  fe["features"] = {"posterior_best"};
  CHECK(error_of(fe.dump(), "abc123") == "features");
  auto co = j;
  co["object"]["coef"] = {1.0};
  CHECK(error_of(co.dump(), "abc123") == "object.coef");
  auto sc = j;
  sc["pose"]["scale"][0] = 0.0;
  CHECK(error_of(sc.dump(), "abc123") == "pose.scale");
  CHECK(error_of("[1, 2]", "abc123").empty());
  CHECK_THROWS_AS(read_calibration(dir / "missing.json", ""), Error);
}

TEST_CASE("Open-set threshold: the most confidence refused while at most the allowed share of runs loses its right answer") {
  // 100 runs at the step, 4 right answers: refusing below t costs the right answers under t.
  const std::vector<double> right{0.9, 0.2, 0.5, 0.7};
  CHECK(choose_open_set_threshold(right, 100, 0.0) == 0.2);    // nothing may be lost
  CHECK(choose_open_set_threshold(right, 100, 0.01) == 0.5);   // 1 run of 100
  CHECK(choose_open_set_threshold(right, 100, 0.03) == 0.9);   // 3 runs
  CHECK(choose_open_set_threshold(right, 100, 0.05) == 1.0);   // all 4 may go
  CHECK(choose_open_set_threshold({}, 10, 0.03) == 1.0);
  CHECK_THROWS_AS(choose_open_set_threshold(right, 100, 1.0), Error);
  CHECK_THROWS_AS(choose_open_set_threshold(right, 100, -0.1), Error);

  test::TempDir dir("calibration");
  Calibration c;
  c.database_fingerprint = "f";
  c.features = confidence_feature_names();
  const std::size_t f = c.features.size();
  c.object = {std::vector<double>(f, 0.0), std::vector<double>(f, 1.0), std::vector<double>(f + 1, 0.0)};
  c.pose = c.object;
  write_calibration(dir / "none.json", c);
  CHECK_FALSE(read_calibration(dir / "none.json", "f").open_set_threshold);
  c.open_set_threshold = 0.25;
  write_calibration(dir / "t.json", c);
  CHECK(read_calibration(dir / "t.json", "f").open_set_threshold == 0.25);
  auto j = to_json(c);
  j["open_set_threshold"] = 1.5;
  std::ofstream(dir / "bad.json") << j.dump();
  try {
    read_calibration(dir / "bad.json", "f");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "open_set_threshold");
    CHECK(e.file() == (dir / "bad.json").string());
  }
}
