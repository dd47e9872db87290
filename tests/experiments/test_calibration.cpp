// Calibrated confidence (issue 14): the logistic fit against a known model, the calibration
// measures against hand-computed values, the calibration file's checks.
#include "experiments/analysis/calibration.hpp"
#include "experiments/analysis/metrics.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <fstream>
#include <limits>

using namespace ts;
using namespace ts::experiments;

namespace {
/// A calibration for database `fingerprint` with one range of steps whose models give 0.5.
Calibration flat_calibration(const std::string& fingerprint) {
  Calibration c;
  c.database_fingerprint = fingerprint;
  c.features = confidence_feature_names();
  const std::size_t f = c.features.size();
  StepModels m;
  m.object = {std::vector<double>(f, 0.0), std::vector<double>(f, 1.0), std::vector<double>(f + 1, 0.0)};
  m.pose = m.object;
  c.ranges = {m};
  return c;
}
}  // namespace

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
  StepModels early, late;
  early.first_step = 1;
  early.object = {std::vector<double>(f, 0.5), std::vector<double>(f, 2.0), std::vector<double>(f + 1, 0.25)};
  early.pose = {std::vector<double>(f, 0.0), std::vector<double>(f, 1.0), std::vector<double>(f + 1, -0.5)};
  late = early;
  late.first_step = 5;
  late.object.coef[0] = 2.0;
  late.in_database = early.pose;
  early.in_database = early.object;
  c.ranges = {early, late};
  c.open_set_threshold = 0.4;
  const auto path = dir / "cal.json";
  write_calibration(path, c);
  const Calibration back = read_calibration(path, "abc123");
  REQUIRE(back.ranges.size() == 2);
  CHECK(back.ranges[0].object.coef == early.object.coef);
  CHECK(back.ranges[1].pose.mean == late.pose.mean);
  CHECK(back.ranges[1].first_step == 5);
  CHECK(back.open_set_threshold == 0.4);
  const std::vector<double> x(f, 0.5);
  // Steps 1-4 use the first range's models, 5 on the second's.
  for (int step : {1, 4})
    CHECK(back.object_confidence(step, x) == doctest::Approx(1.0 / (1.0 + std::exp(-0.25))));
  for (int step : {5, 40}) CHECK(back.object_confidence(step, x) == doctest::Approx(1.0 / (1.0 + std::exp(-2.0))));
  // pose's model: mean 0, scale 1, every coefficient -0.5: z = -0.5 - 0.5 * 0.5 * f.
  CHECK(back.in_database(7, x).value() == doctest::Approx(1.0 / (1.0 + std::exp(0.5 + 0.25 * double(f)))));
  CHECK_NOTHROW(read_calibration(path, ""));  // no database to check against
  // Without a step given, the features' own ln(step) picks the range.
  StepResult r;
  for (int step : {1, 4, 5, 13}) {
    r.step = step;
    const std::vector<double> feats = confidence_features(r);
    CHECK(feature_step(feats) == step);
    CHECK(back.object_confidence(feats) == back.object_confidence(step, feats));
  }

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
  v["version"] = 1;   // the single-model files before the ranges of steps
  CHECK(error_of(v.dump(), "abc123") == "version");
  auto fm = j;
  fm["format"] = "something";
  CHECK(error_of(fm.dump(), "abc123") == "format");
  auto fe = j;
  fe["features"] = {"posterior_best"};
  CHECK(error_of(fe.dump(), "abc123") == "features");
  auto co = j;
  co["steps"][0]["object"]["coef"] = {1.0};
  CHECK(error_of(co.dump(), "abc123") == "steps[0].object.coef");
  auto sc = j;
  sc["steps"][1]["pose"]["scale"][0] = 0.0;
  CHECK(error_of(sc.dump(), "abc123") == "steps[1].pose.scale");
  auto first = j;
  first["steps"][0]["first_step"] = 2;
  CHECK(error_of(first.dump(), "abc123") == "steps[0].first_step");
  auto order = j;
  order["steps"][1]["first_step"] = 1;
  CHECK(error_of(order.dump(), "abc123") == "steps[1].first_step");
  auto none = j;
  none["steps"] = nlohmann::ordered_json::array();
  CHECK(error_of(none.dump(), "abc123") == "steps");
  auto open = j;   // a threshold without the open-set model of every range
  open["steps"][1]["in_database"] = nullptr;
  CHECK(error_of(open.dump(), "abc123") == "steps[1].in_database");
  auto indb = j;
  indb["steps"][0]["in_database"]["mean"] = "x";
  CHECK(error_of(indb.dump(), "abc123") == "steps[0].in_database.mean");
  CHECK(error_of("[1, 2]", "abc123").empty());
  CHECK_THROWS_AS(read_calibration(dir / "missing.json", ""), Error);

  // Quadratic models (version 3): twice the terms, the squares after the features. The late
  // object model weighs the square of the first feature alone: z = 1 + 2 x0^2.
  Calibration qc = c;
  LogisticModel& q = qc.ranges[1].object;
  q.quadratic = true;
  q.mean.assign(2 * f, 0.0);
  q.scale.assign(2 * f, 1.0);
  q.coef.assign(2 * f + 1, 0.0);
  q.coef[0] = 1.0;
  q.coef[1 + f] = 2.0;
  write_calibration(path, qc);
  const Calibration qback = read_calibration(path, "abc123");
  CHECK(qback.ranges[1].object.quadratic);
  CHECK_FALSE(qback.ranges[0].object.quadratic);
  CHECK(qback.object_confidence(9, x) == doctest::Approx(1.0 / (1.0 + std::exp(-(1.0 + 2.0 * 0.25)))));
  CHECK(qback.object_confidence(1, x) == back.object_confidence(1, x));
  CHECK_THROWS_AS(q.predict(std::vector<double>(2 * f, 0.0)), Error);   // terms given as features
  auto qj = to_json(qc);
  CHECK(qj["version"] == 7);
  CHECK(qj["steps"][1]["object"]["terms"] == "quadratic");
  auto short_q = qj;   // quadratic, but the coefficients of a linear model
  short_q["steps"][1]["object"]["coef"] = j["steps"][1]["object"]["coef"];
  CHECK(error_of(short_q.dump(), "abc123") == "steps[1].object.coef");
  short_q["steps"][1]["object"]["mean"] = j["steps"][1]["object"]["mean"];
  short_q["steps"][1]["object"]["scale"] = j["steps"][1]["object"]["scale"];
  CHECK(error_of(short_q.dump(), "abc123") == "steps[1].object.mean");
  auto terms = qj;
  terms["steps"][0]["pose"]["terms"] = "cubic";
  CHECK(error_of(terms.dump(), "abc123") == "steps[0].pose.terms");
  auto old = j;   // version 2: no terms, every model linear
  old["version"] = 2;
  for (auto& r : old["steps"])
    for (const char* k : {"object", "pose", "in_database"}) r[k].erase("terms");
  std::ofstream(dir / "v2.json") << old.dump();
  const Calibration v2 = read_calibration(dir / "v2.json", "abc123");
  CHECK_FALSE(v2.ranges[1].object.quadratic);
  CHECK(v2.object_confidence(9, x) == back.object_confidence(9, x));
  auto v3 = qj;   // version 3: no answer sets
  v3["version"] = 3;
  v3.erase("answer_sets");
  std::ofstream(dir / "v3.json") << v3.dump();
  CHECK(read_calibration(dir / "v3.json", "abc123").answer_sets.empty());
  auto newer = qj;
  newer["version"] = Calibration::kVersion + 1;
  CHECK(error_of(newer.dump(), "abc123") == "version");
  // The clamp of standardized terms: written, read back, applied (the pose model, mean 0 and
  // scale 1: z = -0.5 - 0.5 * sum(clamp(t)), t = 10 clamped to 4 in every term).
  Calibration cc = c;
  cc.ranges[0].pose.clamp = 4.0;
  write_calibration(path, cc);
  const Calibration cback = read_calibration(path, "abc123");
  CHECK(cback.ranges[0].pose.clamp == 4.0);
  CHECK(cback.ranges[0].object.clamp == 0.0);
  CHECK(cback.pose_confidence(1, std::vector<double>(f, 10.0)) ==
        doctest::Approx(1.0 / (1.0 + std::exp(0.5 + 0.5 * 4.0 * double(f)))));
  auto neg = to_json(cc);
  neg["steps"][0]["pose"]["clamp"] = -1.0;
  CHECK(error_of(neg.dump(), "abc123") == "steps[0].pose.clamp");
}

TEST_CASE("Clamped terms: a rare extreme value of a nearly constant feature cannot swing the confidence") {
  // y ~ Bernoulli(sigmoid(2 x0)); x1 is 0 except in 3 of 6 000 rows, where it is 0.015 and the
  // answer right. Unclamped, x1's scale is tiny and a new value of 0.05 sits hundreds of scales
  // out; clamped at 4 scales, it moves the logit no more than the fitted rows did.
  Rng rng(4);
  std::vector<std::vector<double>> rows;
  std::vector<int> y;
  for (int i = 0; i < 6000; ++i) {
    const double a = rng.normal();
    const bool rare = i % 2000 == 7;
    rows.push_back({a, rare ? 0.015 : 0.0});
    y.push_back(rare ? 1 : (rng.uniform() < 1.0 / (1.0 + std::exp(-2.0 * a)) ? 1 : 0));
  }
  const LogisticModel free = fit_logistic(rows, y, 1e-3), held = fit_logistic(rows, y, 1e-3, kTermClamp);
  const std::vector<double> at0{0.0, 0.0}, seen{0.0, 0.015}, far{0.0, 0.05};
  auto logit = [](double p) { return std::log(p / (1.0 - p)); };
  // Unclamped, the logit keeps growing past the values it was fitted on (3.3 times as far out,
  // at least 3 times the shift, and the answer at ~1); clamped, a value beyond the fitted ones
  // is read as the largest fitted one, and its shift stays what those 3 rows support.
  CHECK(free.predict(far) > 0.999);
  CHECK(logit(free.predict(far)) - logit(free.predict(at0)) > 3.0 * (logit(free.predict(seen)) - logit(free.predict(at0))));
  CHECK(held.predict(far) == held.predict(seen));
  CHECK(logit(held.predict(far)) - logit(held.predict(at0)) < 3.0);
  CHECK(std::abs(held.predict(at0) - 0.5) < 0.05);   // the rest of the model is unchanged
  CHECK(held.clamp == kTermClamp);
}

TEST_CASE("Quadratic terms: a confidence that depends on a feature's size both ways is calibrated only with them") {
  // y ~ Bernoulli(sigmoid(2 - 1.5 x0^2)), x ~ N(0, 1) with two features of noise: right when x0
  // is near 0 either way. A linear model cannot follow it: it gives x0 no weight and every row
  // the base rate (calibrated on average, but telling nothing: a Brier score far above the
  // quadratic model's); the quadratic one recovers the weights and is calibrated on fresh rows.
  auto draw = [](Rng& rng, std::size_t n, std::vector<std::vector<double>>& rows, std::vector<int>& y) {
    for (std::size_t i = 0; i < n; ++i) {
      std::vector<double> r{rng.normal(), rng.normal(), rng.normal()};
      y.push_back(rng.uniform() < 1.0 / (1.0 + std::exp(-(2.0 - 1.5 * r[0] * r[0]))) ? 1 : 0);
      rows.push_back(std::move(r));
    }
  };
  Rng rng(8);
  std::vector<std::vector<double>> rows, fresh, terms;
  std::vector<int> y, fy;
  draw(rng, 20000, rows, y);
  draw(rng, 20000, fresh, fy);
  for (const auto& r : rows) terms.push_back(quadratic_terms(r));
  REQUIRE(terms[0].size() == 6);
  CHECK(terms[0][3] == rows[0][0] * rows[0][0]);
  const LogisticModel lin = fit_logistic(rows, y, 0.0);
  LogisticModel quad = fit_logistic(terms, y, 0.0);
  quad.quadratic = true;
  // Raw weight of x0^2 and the bias at x = 0 (the standardization undone).
  const double w_sq = quad.coef[4] / quad.scale[3];
  double bias = quad.coef[0];
  for (std::size_t k = 0; k < 6; ++k) bias -= quad.coef[k + 1] * quad.mean[k] / quad.scale[k];
  CHECK(std::abs(w_sq + 1.5) < 0.15);
  CHECK(std::abs(bias - 2.0) < 0.15);
  std::vector<double> pl, pq;
  for (const auto& r : fresh) {
    pl.push_back(lin.predict(r));
    pq.push_back(quad.predict(r));
  }
  const auto cl = confidence_calibration(pl, fy), cq = confidence_calibration(pq, fy);
  CHECK(cq.ece < 0.02);
  CHECK(cq.brier < cl.brier - 0.03);
  CHECK(std::abs(lin.coef[1] / lin.scale[0]) < 0.1);
  // fit_step_models makes object and pose quadratic and keeps the in-database score linear.
  std::vector<CalibrationRow> cr;
  for (std::size_t i = 0; i < 4000; ++i) {
    CalibrationRow r;
    r.features = confidence_features(StepResult{});
    r.features[0] = rows[i][0];
    r.step = 1 + static_cast<int>(i % 20);
    r.features[5] = std::log(static_cast<double>(r.step));
    r.group = static_cast<int>(i % 40);
    r.right = r.pose_right = y[i] != 0;
    r.hidden = i % 7 == 0;
    cr.push_back(r);
  }
  const auto models = fit_step_models(cr, {1, 11});
  REQUIRE(models.size() == 2);
  for (const auto& m : models) {
    CHECK(m.object.quadratic);
    CHECK(m.pose.quadratic);
    REQUIRE(m.in_database.has_value());
    CHECK_FALSE(m.in_database->quadratic);
    CHECK(m.object.coef.size() == 2 * confidence_feature_names().size() + 1);
  }
}

TEST_CASE("Step-aware fit: each range of steps recovers its own model; one model over all steps does not") {
  // One feature x ~ N(0, 1). Known objects: steps 1-2 right with p = sigmoid(-1 + 2 x), steps 3-4
  // with p = sigmoid(2 + 0.5 x). Hidden objects (open set) have x ~ N(-1, 1): the in-database
  // odds are then exp(x + 0.5) times the known:hidden ratio (1:1 here), the exact
  // P(known | x) = sigmoid(0.5 + x).
  Rng rng(11);
  auto sigmoid = [](double z) { return 1.0 / (1.0 + std::exp(-z)); };
  std::vector<CalibrationRow> rows;
  for (int i = 0; i < 40000; ++i) {
    CalibrationRow r;
    r.step = 1 + i % 4;
    r.group = i % 97;
    r.hidden = (i / 4) % 2 == 1;
    const double x = rng.normal() - (r.hidden ? 1.0 : 0.0);
    r.features = {x};
    const double p = r.step <= 2 ? sigmoid(-1.0 + 2.0 * x) : sigmoid(2.0 + 0.5 * x);
    r.right = !r.hidden && rng.uniform() < p;
    r.pose_right = r.right && rng.uniform() < 0.5;
    rows.push_back(r);
  }
  const auto models = fit_step_models(rows, {1, 3}, {0.0});
  REQUIRE(models.size() == 2);
  CHECK(models[1].first_step == 3);
  for (double x : {-1.5, 0.0, 1.0}) {
    const std::vector<double> f{x};
    CHECK(std::abs(models[0].object.predict(f) - sigmoid(-1.0 + 2.0 * x)) < 0.03);
    CHECK(std::abs(models[1].object.predict(f) - sigmoid(2.0 + 0.5 * x)) < 0.03);
    for (const auto& m : models) {
      REQUIRE(m.in_database);
      CHECK(std::abs(m.in_database->predict(f) - sigmoid(0.5 + x)) < 0.03);
    }
  }
  // Judged per step on fresh draws: the ranges are calibrated, one model over all steps is not.
  const auto pooled = fit_step_models(rows, {1}, {0.0});
  Rng fresh(12);
  for (int step : {1, 4}) {
    std::vector<double> by_range, by_pool;
    std::vector<int> y;
    for (int i = 0; i < 20000; ++i) {
      const double x = fresh.normal();
      const double p = step <= 2 ? sigmoid(-1.0 + 2.0 * x) : sigmoid(2.0 + 0.5 * x);
      y.push_back(fresh.uniform() < p ? 1 : 0);
      by_range.push_back(models[step <= 2 ? 0 : 1].object.predict(std::vector<double>{x}));
      by_pool.push_back(pooled[0].object.predict(std::vector<double>{x}));
    }
    CHECK(confidence_calibration(by_range, y).ece < 0.02);
    CHECK(confidence_calibration(by_pool, y).ece > 0.1);
  }
  // Bad ranges, a range without known answers, hidden answers missing from one range.
  CHECK_THROWS_AS(fit_step_models(rows, {2, 3}), Error);
  CHECK_THROWS_AS(fit_step_models(rows, {1, 3, 3}), Error);
  try {
    fit_step_models(rows, {1, 5});
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "--step-ranges");
    CHECK(std::string(e.what()).find("steps 5 on") != std::string::npos);
  }
  std::erase_if(rows, [](const CalibrationRow& r) { return r.hidden && r.step >= 3; });
  CHECK_THROWS_AS(fit_step_models(rows, {1, 3}), Error);
  CHECK(fit_step_models(rows, {1})[0].in_database);

  // A hidden object whose answer names a congruent copy of it counts as known to the open-set
  // score. Unpenalized, a logistic fit with a bias matches the share of 1s exactly (the score
  // equations): half the rows known, and half of the hidden ones copies, gives a mean score of
  // 3/4 where it was 1/2.
  auto mean_in_database = [&](const std::vector<CalibrationRow>& rs) {
    const auto m = fit_step_models(rs, {1}, {0.0});
    double sum = 0.0;
    for (const CalibrationRow& r : rs) sum += m[0].in_database->predict(r.features);
    return sum / static_cast<double>(rs.size());
  };
  std::size_t known = 0;
  for (const CalibrationRow& r : rows) known += r.hidden ? 0 : 1;
  const double share = static_cast<double>(known) / static_cast<double>(rows.size());
  CHECK(mean_in_database(rows) == doctest::Approx(share).epsilon(1e-6).scale(0));
  std::size_t copies = 0;
  for (std::size_t i = 0; i < rows.size(); ++i)
    if (rows[i].hidden && i % 2 == 0) {
      rows[i].copy_in_database = true;
      ++copies;
    }
  CHECK(copies > rows.size() / 8);
  CHECK(mean_in_database(rows) ==
        doctest::Approx(static_cast<double>(known + copies) / static_cast<double>(rows.size())).epsilon(1e-6).scale(0));
}

TEST_CASE("L2 penalty by cross-validation over objects: strong for noise, weak for a clear signal") {
  Rng rng(3);
  // 60 answers, 10 features of pure noise, labels fair coins: any fit is overfitting.
  std::vector<std::vector<double>> noise;
  std::vector<int> coin, groups;
  for (int i = 0; i < 60; ++i) {
    std::vector<double> f;
    for (int j = 0; j < 10; ++j) f.push_back(rng.normal());
    noise.push_back(f);
    coin.push_back(rng.uniform() < 0.5 ? 1 : 0);
    groups.push_back(i % 15);
  }
  CHECK(choose_l2(noise, coin, groups, default_l2_grid()) >= 0.1);
  // 5 000 answers of y ~ Bernoulli(sigmoid(3 x)): shrinking the weight only costs.
  std::vector<std::vector<double>> clear;
  std::vector<int> y, g;
  for (int i = 0; i < 5000; ++i) {
    const double x = rng.normal();
    clear.push_back({x});
    y.push_back(rng.uniform() < 1.0 / (1.0 + std::exp(-3.0 * x)) ? 1 : 0);
    g.push_back(i % 45);
  }
  CHECK(choose_l2(clear, y, g, default_l2_grid()) <= 1e-2);
  // One group only (no held-out fold): the grid's first.
  CHECK(choose_l2(clear, y, std::vector<int>(5000, 0), {0.5, 0.1}) == 0.5);
  CHECK_THROWS_AS(choose_l2(clear, y, g, {}), Error);
}

TEST_CASE("ECE of an exactly calibrated model: what sampling alone gives") {
  // 100 answers at 0.5 (one bin): ECE = |share right - 0.5|, share ~ Binomial(100, 0.5) / 100:
  // E|.| = 0.0398 (sum_k C(100, k) |k / 100 - 0.5| / 2^100); 400 draws: standard error 0.0015.
  const std::vector<double> half(100, 0.5);
  const EceNoise n = ece_sampling_noise(half);
  CHECK(n.mean > 0.0398 - 0.005);
  CHECK(n.mean < 0.0398 + 0.005);
  CHECK(n.p95 >= 0.08);   // |k - 50| >= 8 to 10 has probability ~ 0.05
  CHECK(n.p95 <= 0.11);
  // Certain answers: no noise.
  const EceNoise zero = ece_sampling_noise(std::vector<double>(50, 1.0));
  CHECK(zero.mean == 0.0);
  CHECK(ece_sampling_noise(half).mean == n.mean);   // fixed seed
}

TEST_CASE("Open-set threshold over resamples of the explored objects: an object whose runs fail together lowers it") {
  // 20 objects x 5 right answers. 19 score high (0.80 to 0.99); object 7's five runs all score
  // low (0.10 to 0.14), as the runs of one hard object do. 3 % of 100 runs may be lost.
  std::vector<KnownAnswer> a;
  for (int g = 0; g < 20; ++g)
    for (int r = 0; r < 5; ++r)
      a.push_back({g, true, g == 7 ? 0.10 + 0.01 * r : 0.80 + 0.01 * ((g * 5 + r) % 20)});
  std::vector<double> right;
  for (const auto& x : a) right.push_back(x.score);
  // On the runs as they are: the 4th smallest score, one of object 7's.
  const double plain = choose_open_set_threshold(right, a.size(), 0.03);
  CHECK(plain == doctest::Approx(0.13).scale(0));
  CHECK(choose_open_set_threshold_clustered(a, 0.03, 0.0) == plain);
  // Object 7 drawn once in 38 % of resamples (threshold 0.13), never in 36 % (a high one), twice
  // or more in 26 % (0.11 or lower): the median is the plain rule's, the 10 % quantile is lower.
  CHECK(choose_open_set_threshold_clustered(a, 0.03, 0.5) == doctest::Approx(0.13).scale(0));
  const double robust = choose_open_set_threshold_clustered(a, 0.03, 0.9);
  CHECK(robust <= 0.11 + 1e-12);
  CHECK(robust >= 0.10 - 1e-12);
  // Objects, not runs, are resampled: object 7's five runs all score 0.10 and 9 % of the runs may
  // be lost (the 10th smallest score). Ten low runs need object 7 drawn twice or more, in 26 % of
  // the resamples of objects: their 10 % quantile is low. Drawn run by run, 10 of the 5 low runs
  // in 100 draws come in about 3 % of resamples: that quantile would be a high score.
  std::vector<KnownAnswer> same;
  for (int g = 0; g < 20; ++g)
    for (int r = 0; r < 5; ++r) same.push_back({g, true, g == 7 ? 0.10 : 0.80 + 0.01 * ((g * 5 + r) % 20)});
  CHECK(choose_open_set_threshold_clustered(same, 0.09, 0.0) >= 0.80);   // as they are: a high one
  CHECK(choose_open_set_threshold_clustered(same, 0.09, 0.9) == doctest::Approx(0.10).scale(0));
  // No right answer at all: nothing to refuse, whatever the confidence.
  std::vector<KnownAnswer> none;
  for (int g = 0; g < 20; ++g) none.push_back({g, false, 0.0});
  CHECK(choose_open_set_threshold_clustered(none, 0.03, 0.9) == 1.0);
  // Monotone in the confidence; the order of the answers does not matter; deterministic.
  double last = 2.0;
  for (double c : {0.0, 0.5, 0.8, 0.9, 0.95}) {
    const double t = choose_open_set_threshold_clustered(a, 0.03, c);
    CHECK(t <= last);
    last = t;
  }
  std::vector<KnownAnswer> reversed(a.rbegin(), a.rend());
  CHECK(choose_open_set_threshold_clustered(reversed, 0.03, 0.9) == robust);
  CHECK(choose_open_set_threshold_clustered(a, 0.03, 0.9) == robust);
  // Wrong answers count as runs but carry no score to refuse.
  std::vector<KnownAnswer> wrong = a;
  for (int g = 0; g < 20; ++g) wrong.push_back({g, false, 0.0});
  CHECK(choose_open_set_threshold_clustered(wrong, 0.03, 0.0) ==
        choose_open_set_threshold(right, wrong.size(), 0.03));
  CHECK_THROWS_AS(choose_open_set_threshold_clustered(a, 1.0, 0.9), Error);
  CHECK_THROWS_AS(choose_open_set_threshold_clustered(a, 0.03, 1.0), Error);
  CHECK_THROWS_AS(choose_open_set_threshold_clustered(a, 0.03, -0.5), Error);
  CHECK_THROWS_AS(choose_open_set_threshold_clustered(a, 0.03, 0.9, 0), Error);
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
  Calibration c = flat_calibration("f");
  const std::size_t f = c.features.size();
  write_calibration(dir / "none.json", c);
  CHECK_FALSE(read_calibration(dir / "none.json", "f").open_set_threshold);
  CHECK_FALSE(read_calibration(dir / "none.json", "f").in_database(3, std::vector<double>(f, 0.0)));
  c.ranges[0].in_database = c.ranges[0].object;
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

TEST_CASE("Calibration files: answer sets round trip, and every bad count or number is one error naming its key") {
  test::TempDir dir("calibration_sets");
  Calibration c = flat_calibration("f");
  AnswerSetCalibration a;
  a.alpha = 0.1;
  a.simulation = {{"noise", "underwater"}, {"sensors", 1}};
  const double inf = std::numeric_limits<double>::infinity();
  a.steps.emplace_back(std::vector<double>{inf, 0.5, 0.0, inf});
  a.steps.emplace_back(std::vector<double>{0.25, 0.0, 0.0, 0.125});
  c.answer_sets = {a};
  write_calibration(dir / "sets.json", c);
  const Calibration back = read_calibration(dir / "sets.json", "f");
  REQUIRE(back.answer_sets.size() == 1);
  CHECK(back.answer_sets_for(a.simulation) == &back.answer_sets[0]);
  CHECK(&back.single_answer_sets("sets.json") == &back.answer_sets[0]);
  CHECK(back.answer_sets[0].alpha == 0.1);
  CHECK(back.answer_sets[0].simulation == a.simulation);
  REQUIRE(back.answer_sets[0].steps.size() == 2);
  CHECK(back.answer_sets[0].steps[0].infinite() == 2);
  CHECK(back.answer_sets[0].steps[0].finite() == std::vector<double>{0.0, 0.5});
  CHECK(back.answer_sets[0].steps[1].finite() == std::vector<double>{0.0, 0.0, 0.125, 0.25});
  // Steps past the last calibrated one use the last.
  CHECK(back.answer_sets[0].calibrated_step(1) == 1);
  CHECK(back.answer_sets[0].calibrated_step(9) == 2);
  CHECK(back.answer_sets[0].at(9).finite() == back.answer_sets[0].steps[1].finite());
  CHECK(back.answer_sets[0].at(1).p_value(0.5) == doctest::Approx(4.0 / 5.0));   // 0.5 and two infinite
  // A class outside the state ranked by the shape prior (1e6 + its prior gap): finite, kept as
  // written, above every gap of the state.
  AnswerSetCalibration ranked = a;
  ranked.steps[1] = ConformalScores(std::vector<double>{0.25, 0.0, kOutsideState + 0.75, 0.125});
  c.answer_sets = {ranked};
  write_calibration(dir / "ranked.json", c);
  const Calibration ranked_back = read_calibration(dir / "ranked.json", "f");
  const ConformalScores& r1 = ranked_back.answer_sets.at(0).steps.at(1);
  CHECK(r1.infinite() == 0);
  CHECK(r1.finite() == std::vector<double>{0.0, 0.125, 0.25, kOutsideState + 0.75});
  CHECK(r1.p_value(kOutsideState + 0.5) == doctest::Approx(2.0 / 5.0));
  // Version 6 (a class without hypotheses scored +inf) is read as it was written.
  auto v6 = to_json(back);
  v6["version"] = 6;
  std::ofstream(dir / "v6.json") << v6.dump();
  const Calibration back6 = read_calibration(dir / "v6.json", "f");
  REQUIRE(back6.answer_sets.size() == 1);
  CHECK(back6.answer_sets[0].steps[0].infinite() == 2);
  CHECK(back6.answer_sets[0].steps[1].finite() == back.answer_sets[0].steps[1].finite());
  c.answer_sets = {a};

  auto error_of = [&](const nlohmann::ordered_json& j) {
    const auto p = dir / "bad.json";
    std::ofstream(p) << j.dump();
    try {
      read_calibration(p, "f");
    } catch (const Error& e) {
      CHECK(e.file() == p.string());
      return e.field();
    }
    FAIL("no error for " << j.dump());
    return std::string();
  };
  const auto j = to_json(c);
  for (double alpha : {0.0, 1.0, -0.2, 3.0}) {
    auto bad = j;
    bad["answer_sets"][0]["alpha"] = alpha;
    CHECK(error_of(bad) == "answer_sets[0].alpha");
  }
  auto runs = j;   // a count that disagrees with the gaps
  runs["answer_sets"][0]["steps"][1]["runs"] = 40000000000ULL;
  CHECK(error_of(runs) == "answer_sets[0].steps[1].runs");
  auto infinite = j;
  infinite["answer_sets"][0]["steps"][0]["infinite"] = -1;
  CHECK(error_of(infinite) == "answer_sets[0].steps[0].infinite");
  // Version 4's answer sets were scored against the ln w leader: refused (refit), its models not.
  auto v4 = j;
  v4["version"] = 4;
  CHECK(error_of(v4) == "answer_sets");
  v4["answer_sets"] = nullptr;
  {
    std::ofstream(dir / "v4.json") << v4.dump();
    CHECK(read_calibration(dir / "v4.json", "f").answer_sets.empty());
  }
  // A huge count that agrees with itself is read without allocating by it.
  auto huge = j;
  huge["answer_sets"][0]["steps"][0]["gaps"] = nlohmann::ordered_json::array();
  huge["answer_sets"][0]["steps"][0]["infinite"] = 1ULL << 62;
  huge["answer_sets"][0]["steps"][0]["runs"] = 1ULL << 62;
  {
    std::ofstream(dir / "huge.json") << huge.dump();
    const Calibration h = read_calibration(dir / "huge.json", "f");
    CHECK(h.answer_sets[0].steps[0].size() == (1ULL << 62));
    CHECK(h.answer_sets[0].steps[0].threshold(0.05) == inf);
  }
  auto negative = j;
  negative["answer_sets"][0]["steps"][1]["gaps"][0] = -0.5;
  CHECK(error_of(negative) == "answer_sets[0].steps[1].gaps");
  auto text = j;
  text["answer_sets"][0]["steps"][1]["gaps"][0] = "x";
  CHECK(error_of(text) == "answer_sets[0].steps[1].gaps");
  auto order = j;
  order["answer_sets"][0]["steps"][1]["step"] = 3;
  CHECK(error_of(order) == "answer_sets[0].steps[1].step");
  auto empty = j;
  empty["answer_sets"][0]["steps"] = nlohmann::ordered_json::array();
  CHECK(error_of(empty) == "answer_sets[0].steps");
  auto none = j;
  none["answer_sets"][0]["steps"][0]["gaps"] = nlohmann::ordered_json::array();
  none["answer_sets"][0]["steps"][0]["infinite"] = 0;
  none["answer_sets"][0]["steps"][0]["runs"] = 0;
  CHECK(error_of(none) == "answer_sets[0].steps[0].runs");
  auto kind = j;
  kind["answer_sets"] = 5;
  CHECK(error_of(kind) == "answer_sets");
  kind["answer_sets"] = nlohmann::ordered_json::array({5});
  CHECK(error_of(kind) == "answer_sets[0]");
  auto simulation = j;
  simulation["answer_sets"][0]["simulation"] = "underwater";
  CHECK(error_of(simulation) == "answer_sets[0].simulation");
  // Version 5 held one simulation's sets, an object: read as the one entry.
  auto v5 = j;
  v5["version"] = 5;
  v5["answer_sets"] = j["answer_sets"][0];
  v5["answer_sets"]["simulation"]["noise.joint_sigma_deg"] = nullptr;   // version 5 wrote unset keys as null
  {
    std::ofstream(dir / "v5.json") << v5.dump();
    const Calibration r = read_calibration(dir / "v5.json", "f");
    REQUIRE(r.answer_sets.size() == 1);
    CHECK(r.answer_sets[0].simulation == a.simulation);
    CHECK(r.answer_sets_for(a.simulation) == &r.answer_sets[0]);   // runs of today's builds match it
    CHECK(r.answer_sets[0].steps[1].finite() == back.answer_sets[0].steps[1].finite());
  }
  v5["answer_sets"]["alpha"] = 2.0;
  CHECK(error_of(v5) == "answer_sets.alpha");
  // The tie: written, read back into every step's scores; a bad one named.
  {
    Calibration t = c;
    t.answer_sets[0].tie_nats = 0.01;
    write_calibration(dir / "tie.json", t);
    const Calibration r = read_calibration(dir / "tie.json", "f");
    CHECK(r.answer_sets[0].tie_nats == 0.01);
    for (const auto& st : r.answer_sets[0].steps) CHECK(st.tie() == 0.01);
    CHECK(back.answer_sets[0].tie_nats == 0.0);   // none by default
    CHECK(back.answer_sets[0].steps[0].tie() == 0.0);
  }
  for (const nlohmann::ordered_json& bad : {nlohmann::ordered_json(-0.5), nlohmann::ordered_json("x"),
                                            nlohmann::ordered_json(1000.0)}) {
    auto t = j;
    t["answer_sets"][0]["tie_nats"] = bad;
    CHECK(error_of(t) == "answer_sets[0].tie_nats");
  }
}

TEST_CASE("Calibration files: a noise sweep's answer sets, one entry per simulation, each found by its own") {
  test::TempDir dir("calibration_sweep");
  Calibration c = flat_calibration("f");
  std::vector<AnswerSetCalibration> levels(3);
  for (std::size_t k = 0; k < levels.size(); ++k) {
    levels[k].simulation = {{"noise", "underwater"}, {"noise.arm_scale", 0.5 * static_cast<double>(k)}};
    levels[k].steps.emplace_back(std::vector<double>{0.0, 1.0 + static_cast<double>(k)});
  }
  c.answer_sets = levels;
  write_calibration(dir / "sweep.json", c);
  const Calibration back = read_calibration(dir / "sweep.json", "f");
  REQUIRE(back.answer_sets.size() == 3);
  for (std::size_t k = 0; k < levels.size(); ++k) {
    const AnswerSetCalibration* found = back.answer_sets_for(levels[k].simulation);
    REQUIRE(found != nullptr);
    CHECK(found->steps[0].finite() == std::vector<double>{0.0, 1.0 + static_cast<double>(k)});
  }
  CHECK(back.answer_sets_for({{"noise", "underwater"}, {"noise.arm_scale", 0.25}}) == nullptr);
  CHECK(back.answer_sets_for({{"noise", "deepsea"}}) == nullptr);
  // Data without a simulation to match (recognize, Python) cannot choose a level: one error.
  try {
    (void)back.single_answer_sets("sweep.json");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.file() == "sweep.json");
    CHECK(e.field() == "answer_sets");
    CHECK(std::string(e.what()).find("3 simulations") != std::string::npos);
  }
  // Two entries for one simulation: which one holds?
  auto j = to_json(c);
  j["answer_sets"][2]["simulation"] = j["answer_sets"][0]["simulation"];
  std::ofstream(dir / "twice.json") << j.dump();
  try {
    (void)read_calibration(dir / "twice.json", "f");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "answer_sets[2].simulation");
  }
  const Calibration none = flat_calibration("f");
  CHECK_THROWS_AS((void)none.single_answer_sets("x.json"), Error);
}

TEST_CASE("The simulation an answer-set calibration holds for: noise, its overrides, sensing and sensors alone") {
  const auto config = nlohmann::ordered_json::parse(
      R"({"seed": 3, "runs": 4, "noise": "deep_sea", "noise.arm_position_sigma_m": 0.002, "sensing": "pads",
          "sensors": 2, "method": "bricpsf", "calibration": "x.json", "noise.arm_scale": null})");
  const auto sim = simulation_of(config);
  CHECK(sim == nlohmann::ordered_json::parse(
                   R"({"noise": "deep_sea", "noise.arm_position_sigma_m": 0.002, "sensing": "pads", "sensors": 2})"));
  CHECK(simulation_of(nlohmann::ordered_json("text")).empty());
  // The scene and the probe's and fingertips' keys are the simulation's too; "none" is no scene.
  // Sorted: the order keys come in does not matter.
  const auto scene = nlohmann::ordered_json::parse(
      R"({"sensors": 1, "scene.pipe_radius_m": 0.1, "noise": "underwater", "scene": "pipe", "probe.tilt_deg": null,
          "fingertips.quantization_m": 0.001, "runs": 2})");
  CHECK(simulation_of(scene).dump() ==
        R"({"fingertips.quantization_m":0.001,"noise":"underwater","scene":"pipe","scene.pipe_radius_m":0.1,"sensors":1})");
  CHECK(simulation_of(nlohmann::ordered_json::parse(R"({"scene": "none", "noise": "ideal"})")).dump() == R"({"noise":"ideal"})");
  // An arm scale of 1 is the profile's arm: a sweep's level 1 is the runs without the key.
  CHECK(simulation_of(nlohmann::ordered_json::parse(R"({"noise.arm_scale": 1.0, "noise": "ideal"})")).dump() ==
        R"({"noise":"ideal"})");
  CHECK(simulation_of(nlohmann::ordered_json::parse(R"({"noise.arm_scale": 0.5, "noise": "ideal"})")).dump() ==
        R"({"noise":"ideal","noise.arm_scale":0.5})");
  // An unset override (null) is the profile's value, as if absent: a calibration written before a
  // key existed still matches runs of a build that has it. Read from a file alike.
  test::TempDir dir("calibration_nulls");
  Calibration c = flat_calibration("f");
  AnswerSetCalibration a;
  a.simulation = nlohmann::ordered_json::parse(R"({"noise": "underwater", "noise.joint_sigma_deg": null, "sensors": 1})");
  a.steps.emplace_back(std::vector<double>{0.0});
  c.answer_sets = {a};
  write_calibration(dir / "nulls.json", c);
  const Calibration back = read_calibration(dir / "nulls.json", "f");
  CHECK(back.answer_sets_for(nlohmann::ordered_json::parse(R"({"noise": "underwater", "sensors": 1})")) != nullptr);
  CHECK(back.answer_sets[0].simulation == nlohmann::ordered_json::parse(R"({"noise": "underwater", "sensors": 1})"));
  CHECK(back.answer_sets_for(a.simulation) == &back.answer_sets[0]);   // a lookup with nulls alike
}
