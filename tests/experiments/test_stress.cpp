// Study 10 (stiff and extreme cases, `touchstone stress`): the configuration's errors, and a
// reduced study whose outcomes are known: a dive 1 000 km from the origin answers as at the
// origin, a single flat patch is flagged, three contacts give no answer, nothing is NaN.
#include "experiments/runs/stress.hpp"
#include "cli_run.hpp"
#include "temp_dir.hpp"

#include "io/result_store.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

using namespace ts;
using namespace ts::experiments;

namespace {


/// The error a configuration gives (empty: none).
std::pair<std::string, std::string> config_error(const test::TempDir& dir, const std::string& text) {
  const auto file = dir / "study.toml";
  test::write_text(file, text);
  try {
    load_stress_study(file);
  } catch (const Error& e) {
    return {e.file(), e.field()};
  }
  return {};
}

}  // namespace

TEST_CASE("Stress study configuration: cases over a baseline, errors name the file and the key") {
  test::TempDir dir("stress");
  const auto file = dir / "study.toml";
  test::write_text(file, "runs = 3\n[baseline]\ngrasps = 4\ncontacts = 20\n"
                   "[cases]\nbase = \"\"\nfar = \"distance_m=1e6, arm_noise_m=0\"\n");
  const StressStudy s = load_stress_study(file);
  CHECK(s.runs == 3);
  REQUIRE(s.cases.size() == 2);
  CHECK(s.cases[0].name == "base");
  CHECK(s.cases[0].grasps == 4);
  CHECK(s.cases[1].distance_m == 1e6);
  CHECK(s.cases[1].arm_noise_m == 0.0);
  CHECK(s.cases[1].contacts == 20);  // from the baseline

  CHECK(config_error(dir, "[baseline]\nsize = 0.1\n[cases]\na = \"\"\n").second == "size");
  CHECK(config_error(dir, "[cases]\na = \"contacts=0\"\n").second == "contacts");
  CHECK(config_error(dir, "[cases]\na = \"contacts=2.5\"\n").second == "contacts");
  CHECK(config_error(dir, "[cases]\na = \"arm_noise_m=-1\"\n").second == "arm_noise_m");
  CHECK(config_error(dir, "[cases]\na = \"flat\"\n").second == "cases.a");
  CHECK(config_error(dir, "runs = 0\n[cases]\na = \"\"\n").second == "runs");
  CHECK(config_error(dir, "runs = 2\n").second == "cases");
  CHECK(config_error(dir, "[cases]\na = \"distance_m=nan\"\n").second == "distance_m");
  const auto [where, key] = config_error(dir, "[cases]\na = \"grasps=200, contacts=100000\"\n");
  CHECK(where.find("study.toml") != std::string::npos);
  CHECK(key == "contacts");
}

TEST_CASE("Every stress study of experiments/studies/stress loads, and the driver runs study 10") {
  // docs/testing.md's `touchstone stress --config ...` commands run these files: a key the loader
  // renames or a range it narrows must fail here, not at the start of an hour-long study. (What
  // the cases cover is the study's design, stated in the file and docs/testing.md, not code.)
  const auto dir = std::filesystem::path(TS_SOURCE_DIR) / "experiments" / "studies" / "stress";
  std::size_t n = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().extension() != ".toml") continue;
    ++n;
    CAPTURE(e.path().string());
    StressStudy s;
    REQUIRE_NOTHROW(s = load_stress_study(e.path()));
    CHECK_FALSE(s.cases.empty());
  }
  CHECK(n >= 1);
  // The driver takes study 10 as it stands (its preset and seed): one run of its cheapest case,
  // one grasp of three contacts, gives the known outcome, no answer and said so.
  StressStudy s = load_stress_study(dir / "study10_extreme.toml");
  const auto it = std::find_if(s.cases.begin(), s.cases.end(), [](const StressCase& c) { return c.name == "contacts_3"; });
  REQUIRE(it != s.cases.end());
  s.runs = 1;
  const StressCaseResult r = run_stress_case(s, static_cast<std::size_t>(it - s.cases.begin()), {});
  REQUIRE(r.runs.size() == 1);
  CHECK(r.runs[0].contacts == 3);
  CHECK_FALSE(r.runs[0].valid);
  CHECK(r.runs[0].ambiguous);
  CHECK(r.runs[0].finite);
}

TEST_CASE("Stress study, reduced: far dives answer as at the origin; degenerate contacts flagged") {
  test::TempDir dir("stress");
  StressStudy study;
  study.runs = 2;
  StressCase base;
  base.grasps = 5;
  base.contacts = 30;
  StressCase far = base, flat = base, three = base;
  base.name = "base";
  far.name = "far";
  far.distance_m = 1e6;
  flat.name = "flat";
  flat.flat = true;
  flat.grasps = 1;
  flat.contacts = 60;
  three.name = "three";
  three.grasps = 1;
  three.contacts = 3;
  study.cases = {base, far, flat, three};
  std::vector<StressCaseResult> results;
  for (std::size_t i = 0; i < study.cases.size(); ++i) results.push_back(run_stress_case(study, i, dir.path()));

  // 1 000 km away: the same contacts up to the rounding of their coordinates (1e-10 m). The
  // recognizer works in a frame centred on them (tests/engine/test_stability.cpp checks the
  // prepared query to 1e-9 m), so nothing degrades; but such a change can move a near-tie of
  // RANSAC, as it does at the origin (CHANGELOG.md, study 10: 5 to 7 of 20 runs, errors 0.03 to 7 mm
  // apart), so the answers are compared as answers: the same object and outcome for every run,
  // and errors of the same size for most. The feature-free source on every step (the improved
  // preset's default) has more near-ties to move: a nut answered upside down at 5 grasps in one of
  // these runs (7 mm and 4 degrees at the origin, 20 mm and 178 degrees far away). Coordinates
  // held in float anywhere would move every run's answer by centimetres.
  int agree = 0;
  for (int r = 0; r < study.runs; ++r) {
    const StressRun &a = results[0].runs[r], &b = results[1].runs[r];
    INFO("run " << r << " object " << a.object);
    CHECK(a.object == b.object);
    REQUIRE(a.valid);
    REQUIRE(b.valid);
    CHECK(a.correct == b.correct);
    INFO("errors at the origin " << a.symmetric_position_error_m << " m, " << a.symmetric_orientation_error_deg
         << " deg; far " << b.symmetric_position_error_m << " m, " << b.symmetric_orientation_error_deg << " deg");
    agree += std::abs(a.symmetric_position_error_m - b.symmetric_position_error_m) < 0.005 &&
             std::abs(a.symmetric_orientation_error_deg - b.symmetric_orientation_error_deg) < 1.0;
    CHECK(a.contacts == b.contacts);
  }
  CHECK(agree >= 1);   // of 2 runs
  CHECK(results[0].runs[0].correct);  // the wedge, at 5 noisy grasps
  // One flat patch: rotation about its normal and the translations in its plane unobservable.
  for (const StressRun& r : results[2].runs) {
    CHECK(r.ambiguous);
    CHECK(r.unobservable_dof >= 3);
  }
  // Three contacts: nothing to recognize, said so.
  for (const StressRun& r : results[3].runs) {
    CHECK_FALSE(r.valid);
    CHECK(r.ambiguous);
    CHECK(r.contacts == 3);
  }
  // Every step and every stored result finite; the stores are there and hold the runs.
  for (const StressCaseResult& c : results)
    for (int r = 0; r < study.runs; ++r) {
      CHECK(c.runs[r].finite);
      CHECK(c.runs[r].non_finite.empty());
      const io::ResultData d = io::read_result(dir / (c.config.name + "-" + std::to_string(r) + ".h5"));
      CHECK(static_cast<int>(d.steps.size()) == c.config.grasps);
      CHECK(d.header.truth_object == c.runs[r].object);
    }
  nlohmann::ordered_json j = stress_json(study, results);
  CHECK(first_non_finite(j).empty());
  CHECK(j["cases"][2]["flagged_ambiguous"] == 2);
  j["cases"][1]["per_run"][0]["position_error_m"] = std::numeric_limits<double>::infinity();
  CHECK(first_non_finite(j) == "/cases/1/per_run/0/position_error_m");
  CHECK(stress_table(results).find("| far | 15 cm | 1000 km |") != std::string::npos);

  // The same results on one thread.
  tbb::task_arena one(1);
  const StressCaseResult again = one.execute([&] { return run_stress_case(study, 1, {}); });
  for (int r = 0; r < study.runs; ++r) {
    CHECK(again.runs[r].position_error_m == results[1].runs[r].position_error_m);
    CHECK(again.runs[r].condition == results[1].runs[r].condition);
  }
}

TEST_CASE("touchstone stress: a bad configuration is one error naming the file and the key") {
  test::TempDir dir("stress_cli");
  test::write_text(dir / "s.toml", "[cases]\nsmall = \"size_m=0.00001\"\n");
  const test::CliRun r = test::touchstone(dir, "stress --config s.toml");
  CHECK(r.code == 1);
  CHECK(r.err.find("touchstone: error:") == 0);
  CHECK(r.err.find("s.toml") != std::string::npos);
  CHECK(r.err.find("size_m") != std::string::npos);
  CHECK(r.out.empty());
}
