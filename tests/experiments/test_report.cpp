// Report JSON: the interface's keys, values against hand-counted outcomes, plots.
#include "experiments/analysis/calibration.hpp"
#include "experiments/analysis/report.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <limits>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

using namespace ts;
using namespace ts::experiments;

namespace {

/// 2 objects x 4 runs x 3 steps. Run r of object o is correct at step k when k > r (so step 1:
/// 1 of 4 correct, step 2: 2 of 4, step 3: 3 of 4); position error 1 cm * (r + 1), orientation
/// 0.1 rad * (r + 1), symmetric half of it; time 0.1 * step.
io::RunStoreContents synthetic(int variants = 1) {
  io::RunStoreContents c;
  auto& h = c.header;
  h.config_json = R"({"name":"synthetic","runs":4,"steps":3,"method":"bricpsf","noise":"ideal","sensors":1})";
  h.database_json = "{}";
  h.versions_json = R"({"touchstone":"test","threads":2})";
  h.machine = "test machine";
  h.steps = 3;
  for (int v = 0; v < variants; ++v) {
    h.variant_labels.push_back(variants == 1 ? "" : "icp.iterations=" + std::to_string(v));
    h.variant_configs.push_back("{}");
  }
  h.objects = {"cube", "sphere"};
  h.database_objects = {"cube", "sphere", "bunny"};
  h.stages = {"ransac", "icp"};
  for (int v = 0; v < variants; ++v)
    for (int o = 0; o < 2; ++o)
      for (int r = 0; r < 4; ++r) {
        io::RunRecord rec;
        rec.variant = v;
        rec.object = o;
        rec.run = r;
        rec.grasps = {0, 1, 2};
        for (int k = 1; k <= 3; ++k) {
          io::RunStepRecord s;
          s.correct = k > r;
          s.best_object = s.correct ? o : 2;
          s.position_error_m = 0.01 * (r + 1);
          s.orientation_error_rad = 0.1 * (r + 1);
          s.symmetric_orientation_error_rad = 0.05 * (r + 1);
          s.time_s = 0.1 * k * (v + 1);
          s.stage_times_s = {0.06 * k, 0.04 * k};
          rec.steps.push_back(s);
        }
        c.runs.push_back(rec);
      }
  c.complete = true;
  return c;
}

}  // namespace

TEST_CASE("Report JSON has the interface's keys with the right values") {
  const auto j = report_json(synthetic(), {}, "run.h5");
  for (const char* k : {"config", "per_step", "per_object", "threads", "machine"})
    CHECK(j.contains(k));
  CHECK(j["threads"] == 2);
  CHECK(j["machine"] == "test machine");
  CHECK(j["config"]["name"] == "synthetic");
  CHECK(j["store"]["runs_done"] == 8);
  CHECK(j["store"]["runs_planned"] == 8);
  REQUIRE(j["per_step"].size() == 3);
  for (const auto& row : j["per_step"])
    for (const char* k : {"step", "recognition_rate", "recognition_rate_ci95", "position_error_m_median",
                          "orientation_error_deg_median", "symmetric_orientation_error_deg_median",
                          "time_s_median", "time_s_p95"})
      CHECK(row.contains(k));
  const auto& s1 = j["per_step"][0];
  CHECK(s1["step"] == 1);
  CHECK(s1["recognition_rate"].get<double>() == doctest::Approx(0.25));  // runs 0 of each object
  CHECK(s1["recognition_rate_ci95"][0].get<double>() == doctest::Approx(wilson_interval(2, 8).lo));
  CHECK(s1["position_error_m_median"].get<double>() == doctest::Approx(0.01));
  const auto& s3 = j["per_step"][2];
  CHECK(s3["recognition_rate"].get<double>() == doctest::Approx(0.75));
  // correct at step 3: runs 0, 1, 2 -> errors 1, 2, 3 cm; median 2 cm; bounded mean same (< 4 cm)
  CHECK(s3["position_error_m_median"].get<double>() == doctest::Approx(0.02));
  CHECK(s3["position_error_m_mean_bounded"].get<double>() == doctest::Approx(0.02));
  CHECK(s3["orientation_error_deg_median"].get<double>() == doctest::Approx(0.2 * 180 / std::numbers::pi));
  CHECK(s3["symmetric_orientation_error_deg_median"].get<double>() ==
        doctest::Approx(0.1 * 180 / std::numbers::pi));
  // orientation bounded mean: 0.1, 0.2, 0.3 rad, all under 1 rad.
  CHECK(s3["orientation_error_deg_mean_bounded"].get<double>() ==
        doctest::Approx(0.2 * 180 / std::numbers::pi));
  CHECK(s3["time_s_median"].get<double>() == doctest::Approx(0.3));
  CHECK(s3["stage_times_s_median"]["ransac"].get<double>() == doctest::Approx(0.18));
  REQUIRE(j["per_object"].size() == 2);
  CHECK(j["per_object"][1]["object"] == "sphere");
  CHECK(j["per_object"][1]["per_step"][2]["recognition_rate"].get<double>() == doctest::Approx(0.75));
  CHECK_FALSE(j.contains("variants"));
  std::ostringstream text;
  print_report(j, text);
  CHECK(text.str().find("sphere") != std::string::npos);
  CHECK(text.str().find("75") != std::string::npos);
}

TEST_CASE("A sweep reports every variant and the Pareto front") {
  const auto j = report_json(synthetic(3), {}, "run.h5");
  REQUIRE(j.contains("variants"));
  CHECK(j["variants"].size() == 3);
  // Same recognition, variant 0 is fastest: it alone is on both fronts.
  CHECK(j["pareto"]["recognition_rate_final"] == nlohmann::ordered_json::array({"icp.iterations=0"}));
  CHECK(j["pareto"]["position_error_m_median_final"] ==
        nlohmann::ordered_json::array({"icp.iterations=0"}));
  CHECK(j["variants"][2]["summary"]["time_s_per_step_mean"].get<double>() == doctest::Approx(0.6));
  std::ostringstream text;
  print_report(j, text);
  CHECK(text.str().find("icp.iterations=2") != std::string::npos);
}

TEST_CASE("Plots are written by the plot script") {
  test::TempDir dir("plots");
  const auto j = report_json(synthetic(), {}, "run.h5");
  const auto files = write_plots(j, dir.path());
  CHECK(files.size() == 5);
  for (const auto& f : files) {
    CHECK(std::filesystem::file_size(f) > 10000);
    CHECK(test::read_bytes(f).substr(1, 3) == "PNG");
  }
  CHECK(std::filesystem::exists(dir / "report.json"));
  const auto sweep = write_plots(report_json(synthetic(3), {}, "run.h5"), dir / "sweep");
  CHECK(sweep.size() == 5);
}

TEST_CASE("Report: class-aware rates count an answer congruent with the true object; the strict rates stay") {
  // Wrong answers are `bunny`; with `sphere` and `bunny` congruent, every sphere run is right
  // class-aware: step 1 cube 1 of 4 + sphere 4 of 4, step 3 cube 3 + sphere 4 (strict: 2 and 6
  // of 8).
  auto store = synthetic();
  const auto plain = report_json(store, {}, "run.h5");
  CHECK(plain["congruent_classes"].is_null());
  for (const auto& row : plain["per_step"]) CHECK(row["recognition_rate_class"] == row["recognition_rate"]);
  store.header.database_json = R"({"congruent_classes": [["sphere", "bunny"]]})";
  const auto j = report_json(store, {}, "run.h5");
  CHECK(j["congruent_classes"] == nlohmann::json::parse(R"([["sphere", "bunny"]])"));
  CHECK(j["per_step"][0]["recognition_rate"].get<double>() == doctest::Approx(2.0 / 8));
  CHECK(j["per_step"][0]["correct_class"] == 5);
  CHECK(j["per_step"][0]["recognition_rate_class"].get<double>() == doctest::Approx(5.0 / 8));
  CHECK(j["per_step"][0]["recognition_rate_class_ci95"][0].get<double>() == doctest::Approx(wilson_interval(5, 8).lo));
  CHECK(j["per_step"][2]["recognition_rate"].get<double>() == doctest::Approx(6.0 / 8));
  CHECK(j["per_step"][2]["recognition_rate_class"].get<double>() == doctest::Approx(7.0 / 8));
  CHECK(j["summary"]["recognition_rate_final"].get<double>() == doctest::Approx(6.0 / 8));
  CHECK(j["summary"]["recognition_rate_class_final"].get<double>() == doctest::Approx(7.0 / 8));
  // Errors stay over the strictly right runs.
  CHECK(j["per_step"][0]["position_error_m_median"] == plain["per_step"][0]["position_error_m_median"]);
  CHECK(j["per_object"][1]["per_step"][0]["recognition_rate_class"].get<double>() == doctest::Approx(1.0));
  CHECK(j["per_object"][0]["per_step"][0]["recognition_rate_class"].get<double>() == doctest::Approx(0.25));
  std::ostringstream text;
  print_report(j, text);
  CHECK(text.str().find("congruent classes of the database: sphere = bunny") != std::string::npos);
  // A large database's classes: beyond 10, only those of the explored objects are printed.
  nlohmann::ordered_json many = nlohmann::ordered_json::array();
  for (int k = 0; k < 11; ++k) many.push_back({"nut_" + std::to_string(2 * k), "nut_" + std::to_string(2 * k + 1)});
  many.push_back({"sphere", "bunny", "ball"});
  nlohmann::ordered_json big = j;
  big["congruent_classes"] = many;
  std::ostringstream large;
  print_report(big, large);
  INFO(large.str());
  CHECK(large.str().find("12 classes of 25 objects") != std::string::npos);
  CHECK(large.str().find("sphere = bunny = ball") != std::string::npos);   // an explored object's
  CHECK(large.str().find("nut_0 = nut_1") == std::string::npos);           // none explored
}

TEST_CASE("Report: the misses at the last step and what they named instead") {
  // Step 3: run 3 of each object misses, naming bunny; make the sphere's name nothing, and add a
  // cube run that names sphere (congruent with cube here) and one more that names bunny.
  auto store = synthetic();
  store.header.database_json = R"({"congruent_classes": [["cube", "sphere"]]})";
  for (auto& r : store.runs)
    if (r.object == 1 && r.run == 3) r.steps[2].best_object = -1;
  for (int extra : {1, 2}) {
    io::RunRecord r = store.runs[3];   // cube, run 3
    r.run = 3 + extra;
    r.steps[2].best_object = extra == 1 ? 1 : 2;
    store.runs.push_back(r);
  }
  const auto j = report_json(store, {}, "run.h5");
  const auto& c = j["confusions"];
  CHECK(c["step"] == 3);
  CHECK(c["misses"] == 4);
  REQUIRE(c["pairs"].size() == 3);
  CHECK(c["pairs"][0]["object"] == "cube");   // most frequent first
  CHECK(c["pairs"][0]["named"] == "bunny");
  CHECK(c["pairs"][0]["runs"] == 2);
  CHECK(c["pairs"][0]["share_of_object_misses"].get<double>() == doctest::Approx(2.0 / 3));
  CHECK(c["pairs"][0]["congruent"] == false);
  bool nothing = false, congruent = false;
  for (const auto& p : c["pairs"]) {
    nothing = nothing || (p["object"] == "sphere" && p["named"].is_null() && p["runs"] == 1);
    congruent = congruent || (p["object"] == "cube" && p["named"] == "sphere" && p["congruent"] == true);
  }
  CHECK(nothing);
  CHECK(congruent);
  CHECK(j["per_object"][1]["confusions"]["misses"] == 1);
  std::ostringstream text;
  print_report(j, text);
  INFO(text.str());
  CHECK(text.str().find("Misses at step 3 (4 runs)") != std::string::npos);
  CHECK(text.str().find("-> (nothing)  1 run") != std::string::npos);
  CHECK(text.str().find("-> sphere (=)  1 run") != std::string::npos);
}

TEST_CASE("Report: recognition rates get a cluster bootstrap over objects and say what each interval assumes") {
  // 10 objects x 4 runs x 1 step: objects 0-5 always right, 6-9 always wrong (all runs of an
  // object alike, the correlation the Wilson interval ignores).
  io::RunStoreContents c;
  auto& h = c.header;
  h.config_json = R"({"name":"clustered","runs":4,"steps":1,"protocol":"independent"})";
  h.database_json = "{}";
  h.versions_json = "{}";
  h.steps = 1;
  h.variant_labels = {""};
  h.variant_configs = {"{}"};
  for (int o = 0; o < 10; ++o) {
    // (not "o" + std::to_string(o): GCC 12 warns of a memcpy bound there, a false positive)
    const std::string name = std::string("o").append(std::to_string(o));
    h.objects.push_back(name);
    h.database_objects.push_back(name);
  }
  std::vector<ClusterCounts> expected;
  for (int o = 0; o < 10; ++o) {
    expected.push_back({o < 6 ? 4u : 0u, 4u});
    for (int r = 0; r < 4; ++r) {
      io::RunRecord rec;
      rec.object = o;
      rec.run = r;
      rec.grasps = {0};
      io::RunStepRecord s;
      s.correct = o < 6;
      s.best_object = s.correct ? o : (o + 1) % 10;
      rec.steps.push_back(s);
      c.runs.push_back(rec);
    }
  }
  c.complete = true;
  auto j = report_json(c, {});
  const auto& row = j["per_step"][0];
  CHECK(row["recognition_rate"].get<double>() == doctest::Approx(0.6));
  const Interval boot = cluster_bootstrap_interval(expected);
  CHECK(row["recognition_rate_cluster_ci95"][0].get<double>() == boot.lo);
  CHECK(row["recognition_rate_cluster_ci95"][1].get<double>() == boot.hi);
  CHECK(row["recognition_rate_class_cluster_ci95"] == row["recognition_rate_cluster_ci95"]);
  // Resampling 10 objects spreads far wider than 40 independent runs would.
  const double wilson = row["recognition_rate_ci95"][1].get<double>() - row["recognition_rate_ci95"][0].get<double>();
  CHECK(boot.hi - boot.lo > 1.3 * wilson);
  CHECK(j["summary"]["recognition_rate_step20_cluster_ci95"] == row["recognition_rate_cluster_ci95"]);
  CHECK(j["per_object"][0]["per_step"][0]["recognition_rate_cluster_ci95"].is_null());  // one object
  CHECK(j["intervals"]["protocol"] == "independent");
  CHECK(j["intervals"]["bootstrap_resamples"] == kBootstrapResamples);
  std::ostringstream text;
  print_report(j, text);
  CHECK(text.str().find("obj-boot") != std::string::npos);
  CHECK(text.str().find("protocol independent") != std::string::npos);
  CHECK(text.str().find("Wilson assumes every run independent;") != std::string::npos);

  // A store written before the protocol key was made with the shared pool.
  h.config_json = R"({"name":"old","runs":4,"steps":1})";
  j = report_json(c, {});
  CHECK(j["intervals"]["protocol"] == "shared_pool");
  std::ostringstream old;
  print_report(j, old);
  CHECK(old.str().find("Wilson assumes every run independent (they are not: too narrow)") != std::string::npos);
}

TEST_CASE("Report: confidences judged per step (ECE, Brier, reliability), recorded or recomputed with a calibration") {
  io::RunStoreContents c = synthetic();  // step k: runs r < k right (1, 2, 3 of 4 per object)
  auto& h = c.header;
  h.step_values = {"confidence_object", "confidence_pose"};
  for (const std::string& f : confidence_feature_names()) h.step_values.push_back("feature." + f);
  const std::size_t F = confidence_feature_names().size();
  for (auto& r : c.runs)
    for (std::size_t k = 0; k < r.steps.size(); ++k) {
      auto& s = r.steps[k];
      s.values.assign(2 + F, 0.0);
      s.values[0] = 0.25 * static_cast<double>(k + 1);  // 0.25, 0.5, 0.75: the true shares
      s.values[1] = 0.9;
      s.values[2] = static_cast<double>(r.run);         // feature.posterior_best
    }
  auto j = report_json(c, {});
  const auto& conf = j["confidence"];
  REQUIRE(conf.is_object());
  CHECK(conf["source"] == "recorded by the experiment");
  REQUIRE(conf["per_step"].size() == 3);
  for (int k = 0; k < 3; ++k) {
    const auto& row = conf["per_step"][static_cast<std::size_t>(k)];
    // Object: confidence (k + 1) / 4 for every run and exactly that share right: ECE 0.
    CHECK(row["object_ece"].get<double>() == doctest::Approx(0.0).epsilon(1e-12));
    const double p = 0.25 * (k + 1);
    CHECK(row["object_brier"].get<double>() == doctest::Approx(p * (1 - p) * (1 - p) + (1 - p) * p * p));
    // Pose: right and position error < 1 cm; run 0's error is 1 cm (not below), so none is.
    CHECK(row["pose_accuracy"].get<double>() == 0.0);
    CHECK(row["pose_ece"].get<double>() == doctest::Approx(0.9));
  }
  CHECK(conf["all_steps"]["n"] == 24);
  CHECK(conf["step20_reliability"]["object"][7]["n"] == 8);  // step 3 (the last): 0.75 in [0.7, 0.8)

  // A calibration recomputes from the features: coef on feature.posterior_best (the run) only.
  Calibration cal;
  cal.features = confidence_feature_names();
  StepModels m;
  m.object = {std::vector<double>(F, 0.0), std::vector<double>(F, 1.0), std::vector<double>(F + 1, 0.0)};
  m.object.coef[1] = 1.0;
  m.pose = m.object;
  cal.ranges = {m};
  ReportSettings rs;
  rs.calibration = &cal;
  rs.calibration_path = "cal.json";
  j = report_json(c, rs);
  std::vector<double> conf1;
  std::vector<int> right1;
  for (const auto& r : c.runs) {
    conf1.push_back(1.0 / (1.0 + std::exp(-static_cast<double>(r.run))));
    right1.push_back(r.steps[0].correct ? 1 : 0);
  }
  const ConfidenceCalibration expected = confidence_calibration(conf1, right1);
  CHECK(j["confidence"]["per_step"][0]["object_ece"].get<double>() == doctest::Approx(expected.ece));
  CHECK(j["confidence"]["source"].get<std::string>().find("cal.json") != std::string::npos);
  std::ostringstream text;
  print_report(j, text);
  CHECK(text.str().find("Confidence (recomputed") != std::string::npos);

  // Without recorded confidences (NaN) and without a calibration: no confidence section.
  for (auto& r : c.runs)
    for (auto& s : r.steps) s.values[0] = std::nan("");
  CHECK(report_json(c, {})["confidence"].is_null());
  // A calibration whose features the store lacks is one error naming the calibration file.
  h.step_values[2] = "feature.something_else";
  try {
    report_json(c, rs);
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.file() == "cal.json");
  }
}

TEST_CASE("Report: open set, false accepts of hidden objects and the known objects' drop under the threshold") {
  io::RunStoreContents c = synthetic();  // objects cube, sphere; step k: runs r < k right
  auto& h = c.header;
  h.config_json = R"({"name":"open","runs":4,"steps":3,"hidden":["sphere"]})";
  h.step_values = {"confidence_object", "confidence_pose"};
  for (const std::string& f : confidence_feature_names()) h.step_values.push_back("feature." + f);
  const std::size_t F = confidence_feature_names().size();
  for (auto& r : c.runs)
    for (auto& s : r.steps) {
      if (r.object == 1) s.correct = false;        // hidden: nothing is right
      s.values.assign(2 + F, 0.0);
      s.values[2] = 0.1 * static_cast<double>(r.run);   // feature.posterior_best: 0, .1, .2, .3
    }
  Calibration cal;
  cal.features = confidence_feature_names();
  StepModels m;
  m.object = {std::vector<double>(F, 0.0), std::vector<double>(F, 0.1), std::vector<double>(F + 1, 0.0)};
  m.pose = m.object;   // object confidence 0.5 throughout: the threshold does not look at it
  m.in_database = m.object;
  m.in_database->coef[1] = 1.0;   // in-database score sigmoid(run): 0.5, 0.73, 0.88, 0.95
  cal.ranges = {m};
  cal.open_set_threshold = 0.8;   // runs 2 and 3 accepted
  ReportSettings rs;
  rs.calibration = &cal;
  rs.calibration_path = "cal.json";
  const auto j = report_json(c, rs);
  // Recognition rates are over the known cube's runs only: step k, k of 4 right.
  CHECK(j["per_step"][1]["runs"] == 4);
  CHECK(j["per_step"][1]["recognition_rate"].get<double>() == doctest::Approx(0.5));
  const auto& o = j["open_set"];
  REQUIRE(o.is_object());
  CHECK(o["threshold"] == 0.8);
  for (int k = 0; k < 3; ++k) {
    const auto& row = o["per_step"][static_cast<std::size_t>(k)];
    CHECK(row["hidden_runs"] == 4);
    CHECK(row["false_accepts"] == 2);   // the sphere's runs 2 and 3 name an object confidently
    CHECK(row["false_accept_rate"].get<double>() == doctest::Approx(0.5));
    CHECK(row["false_accepts_class"] == 2);   // no congruent classes known: the strict count
    CHECK(row["known_runs"] == 4);
    // Cube: runs 0..k right; of those, runs >= 2 pass the threshold.
    const int right = k + 1, kept = std::max(0, k - 1);
    CHECK(row["known_rate_closed"].get<double>() == doctest::Approx(right / 4.0));
    CHECK(row["known_rate_open"].get<double>() == doctest::Approx(kept / 4.0));
    CHECK(row["known_drop"].get<double>() == doctest::Approx((right - kept) / 4.0));
  }
  std::ostringstream text;
  print_report(j, text);
  CHECK(text.str().find("Open set (threshold 0.800") != std::string::npos);
  // Class-aware: with `sphere` and `cube` congruent, a hidden sphere's run naming the sphere's
  // twin (or, in this synthetic store, the sphere itself) is no false accept; naming `bunny` is.
  // Accepted runs 2 and 3: run 2 names bunny at steps 1-2 and the sphere at step 3, run 3 bunny.
  h.database_json = R"({"congruent_classes": [["sphere", "cube"]]})";
  const auto classed = report_json(c, rs)["open_set"];
  for (int k = 0; k < 3; ++k) {
    const auto& row = classed["per_step"][static_cast<std::size_t>(k)];
    CHECK(row["false_accepts"] == 2);
    CHECK(row["false_accepts_class"] == (k < 2 ? 2 : 1));
    CHECK(row["false_accept_rate_class"].get<double>() == doctest::Approx((k < 2 ? 2 : 1) / 4.0));
  }
  h.database_json = "{}";
  // Without hidden objects: the known side alone.
  h.config_json = R"({"name":"closed","runs":4,"steps":3})";
  const auto closed = report_json(c, rs)["open_set"];
  REQUIRE(closed.is_object());
  CHECK(closed["per_step"][2]["false_accept_rate"].is_null());
  CHECK(closed["per_step"][2]["known_runs"] == 8);
  // Without a threshold there is no open-set section.
  cal.open_set_threshold.reset();
  CHECK(report_json(c, rs)["open_set"].is_null());
}

TEST_CASE("Report: the truth at its true pose per step, and the misses split into search and evidence") {
  io::RunStoreContents c = synthetic();  // step k: runs r < k right (1, 2, 3 of 4 per object)
  auto& h = c.header;
  h.step_values = {"truth_pose.wins", "truth_pose.log_weight", "truth_pose.answer_log_weight",
                   "truth_pose.twin_score", "truth_pose.rival_twin_score"};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (auto& r : c.runs)
    for (std::size_t k = 0; k < r.steps.size(); ++k) {
      auto& s = r.steps[k];
      // Right steps win; of the wrong ones, run 3 would win at its true pose (lost by the search),
      // the others not (lost by the evidence); step 1 of the cube's run 0 was not evaluated.
      const bool wins = s.correct || r.run == 3;
      s.values = {wins ? 1.0 : 0.0, -1e-6, -1e-6, 10.0, 20.0};
      if (k == 0 && r.object == 0 && r.run == 0) s.values[0] = nan;
    }
  const auto j = report_json(c, {});
  const auto& rows = j["truth_pose"];
  REQUIRE(rows.is_array());
  REQUIRE(rows.size() == 3);
  // Step 1: 7 evaluated (runs 0 right, except the unevaluated cube run 0), wrong: runs 1-3.
  CHECK(rows[0]["runs"] == 7);
  CHECK(rows[0]["correct"] == 1);
  CHECK(rows[0]["truth_pose_wins"] == 3);                 // the sphere's run 0, both runs 3
  CHECK(rows[0]["misses_lost_by_search"] == 2);           // runs 3
  CHECK(rows[0]["misses_lost_by_evidence"] == 4);         // runs 1, 2 of both objects
  // Step 3: runs 0-2 right, run 3 wrong but would win: no evidence loss.
  CHECK(rows[2]["runs"] == 8);
  CHECK(rows[2]["truth_pose_wins"] == 8);
  CHECK(rows[2]["misses_lost_by_search"] == 2);
  CHECK(rows[2]["misses_lost_by_evidence"] == 0);
  CHECK(rows[1]["truth_pose_rate"].get<double>() == doctest::Approx(6.0 / 8));
  REQUIRE(rows[1]["truth_pose_rate_ci95"].is_array());
  CHECK(rows[1]["truth_pose_rate_ci95"][0].get<double>() < 0.75);
  CHECK(rows[1]["truth_pose_rate_ci95"][1].get<double>() > 0.75);
  CHECK(rows[1]["truth_pose_rate_cluster_ci95"].is_array());   // two objects
  std::ostringstream text;
  print_report(j, text);
  CHECK(text.str().find("The true object at its true pose") != std::string::npos);
  // A store without the columns has no such section.
  const auto plain = report_json(synthetic(), {});
  CHECK(plain["truth_pose"].is_null());
}
