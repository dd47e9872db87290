// The real engine (simulator + recognizer) on a small in-memory database: complete, consistent
// records; the same results for 1 and 2 threads and after an interruption.
#include "datasets/simulator.hpp"
#include "engine/recognition_fixture.hpp"
#include "experiments/analysis/calibration.hpp"
#include "experiments/runs/engine_database.hpp"
#include "experiments/runs/recognition_engine.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <tbb/task_arena.h>

#include <cmath>
#include <set>

using namespace ts;
using namespace ts::experiments;

namespace {

EngineDatabase small_database() {
  auto src = test::make_source(1.0);
  EngineDatabase db;
  db.source = src;
  db.load_mesh = [src](std::size_t i) { return src->meshes.at(i); };
  db.description["path"] = "(test)";
  db.description["fingerprint"] = source_fingerprint(*src);
  return db;
}

ExperimentConfig small_config() {
  ExperimentConfig c;
  set_key(c, "objects", {"box,nut"});
  set_key(c, "runs", {"2"});
  set_key(c, "steps", {"3"});
  set_key(c, "pool", {"5"});
  set_key(c, "bricpsf.hypotheses", {"20"});
  set_key(c, "ransac.samples", {"5x40"});
  set_key(c, "seed", {"3"});
  validate(c);
  return c;
}

std::vector<io::RunRecord> run_all(RunEngine& engine, const ExperimentConfig& c,
                                   const std::filesystem::path& store, int threads,
                                   bool parallel_runs, const std::atomic<bool>* stop = nullptr,
                                   std::function<void(const Progress&)> progress = {}) {
  if (!std::filesystem::exists(store)) io::RunStore::create(store, engine.header());
  DriveSettings s;
  s.parallel_runs = parallel_runs;
  s.stop = stop;
  s.on_progress = std::move(progress);
  tbb::task_arena(threads).execute([&] { drive(engine, all_tasks(engine.header(), c.runs), store, s); });
  return io::RunStore::read(store).runs;
}

void check_same_results(const std::vector<io::RunRecord>& a, const std::vector<io::RunRecord>& b) {
  REQUIRE(a.size() == b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].same_key(b[i]));
    CHECK(a[i].grasps == b[i].grasps);
    CHECK(a[i].truth.isApprox(b[i].truth, 0.0));
    REQUIRE(a[i].steps.size() == b[i].steps.size());
    for (std::size_t k = 0; k < a[i].steps.size(); ++k) {
      const auto &x = a[i].steps[k], &y = b[i].steps[k];
      CHECK(x.best_object == y.best_object);
      CHECK(x.correct == y.correct);
      CHECK(x.weight == y.weight);
      CHECK(x.posterior_true == y.posterior_true);
      CHECK(x.hypotheses == y.hypotheses);
      CHECK(x.contacts == y.contacts);
      CHECK(x.free_points == y.free_points);
      CHECK(x.position_error_m == y.position_error_m);
      CHECK(x.symmetric_orientation_error_rad == y.symmetric_orientation_error_rad);
      CHECK(x.mssd_m == y.mssd_m);
      CHECK(x.pose.isApprox(y.pose, 0.0));
    }
  }
}

/// The object pose a simulator places `object` at with this seed (the oracle of a run's truth).
Pose simulated_pose(const EngineDatabase& db, const std::string& object, std::uint64_t seed) {
  for (std::size_t i = 0; i < db.source->size(); ++i)
    if (db.source->info(i).name == object) {
      datasets::SimulatorSettings s;
      s.seed = seed;
      s.grasps = 0;
      return datasets::Simulator(db.load_mesh(i), object, Gripper(), s).object_pose();
    }
  FAIL("no object " << object);
  return Pose::Identity();
}

}  // namespace

TEST_CASE("Recognition engine: consistent records, thread-count and resume independent") {
  test::TempDir dir("engine");
  const ExperimentConfig c = small_config();
  auto engine = make_recognition_engine(c, small_database(), 2);
  const io::RunStoreHeader& h = engine->header();
  CHECK(h.objects == std::vector<std::string>{"box", "nut"});
  CHECK(h.database_objects.size() == 6);
  CHECK(h.stages == recognition_stages());
  CHECK(h.steps == 3);

  const auto serial = run_all(*engine, c, dir / "serial.h5", 1, false);
  REQUIRE(serial.size() == 4);
  long contacts = 0;
  const EngineDatabase db = small_database();
  for (const auto& r : serial) {
    CHECK(r.grasps.size() == 3);
    // Independent runs (the default protocol): each run's object pose is its own pool's, from
    // (seed, object, run); the two runs of an object differ.
    const std::string& name = h.objects[static_cast<std::size_t>(r.object)];
    CHECK(r.truth.isApprox(simulated_pose(db, name, pool_seed(3, name, r.run)), 1e-9));
    CHECK_FALSE(r.truth.isApprox(serial[r.object == 0 ? 1 - r.run : 3 - r.run].truth, 1e-6));
    for (const auto& s : r.steps) {
      CHECK(s.best_object >= -1);
      CHECK(s.best_object < 6);
      const bool right = s.best_object >= 0 &&
                         h.database_objects[static_cast<std::size_t>(s.best_object)] ==
                             h.objects[static_cast<std::size_t>(r.object)];
      CHECK(s.correct == right);
      CHECK(s.posterior_true >= 0.0);
      CHECK(s.posterior_true <= 1.0 + 1e-12);
      CHECK(std::isfinite(s.position_error_m));
      CHECK(std::isfinite(s.mssd_m));
      CHECK(s.symmetric_orientation_error_rad <= s.orientation_error_rad + 1e-12);
      CHECK(s.stage_times_s.size() == recognition_stages().size());
      CHECK(s.time_s > 0.0);
      contacts += s.contacts;
    }
    // Cumulative clouds grow (or stay) step by step.
    CHECK(r.steps[2].contacts >= r.steps[0].contacts);
  }

  CHECK(contacts > 0);

  const auto parallel = run_all(*engine, c, dir / "parallel.h5", 2, true);
  check_same_results(serial, parallel);

  // Interrupted after the first stored run, then resumed by a fresh engine.
  std::atomic<bool> stop{false};
  const auto first = run_all(*engine, c, dir / "resumed.h5", 2, true, &stop,
                             [&](const Progress&) { stop = true; });
  CHECK(first.size() >= 1);
  CHECK(first.size() < 4);
  auto engine2 = make_recognition_engine(c, small_database(), 1);
  check_resumable(io::RunStore::read_header(dir / "resumed.h5"), engine2->header(), "resumed.h5");
  const auto resumed = run_all(*engine2, c, dir / "resumed.h5", 1, true);
  check_same_results(serial, resumed);
}

TEST_CASE("Recognition engine: database subsets and unknown objects") {
  ExperimentConfig c = small_config();
  set_key(c, "objects", {"wedge"});
  set_key(c, "runs", {"1"});
  set_key(c, "sweep.database_size", {"2", "6"});
  auto engine = make_recognition_engine(c, small_database(), 1);
  CHECK(engine->header().variant_labels.size() == 2);
  test::TempDir dir("engine");
  const auto runs = run_all(*engine, c, dir / "subset.h5", 1, true);
  REQUIRE(runs.size() == 2);
  // With 2 objects the recognizer knows only the wedge and the first database object (box).
  for (const auto& s : runs[0].steps)
    CHECK((s.best_object == -1 || s.best_object == 0 || s.best_object == 4));

  ExperimentConfig bad = small_config();
  set_key(bad, "objects", {"box,teapot"});
  try {
    make_recognition_engine(bad, small_database(), 1);
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "objects");
    CHECK(e.message().find("teapot") != std::string::npos);
  }
}

TEST_CASE("Recognition engine: the paper's shared pool as an option; protocols never mix") {
  test::TempDir dir("engine");
  ExperimentConfig c = small_config();
  set_key(c, "objects", {"nut"});
  set_key(c, "runs", {"3"});
  set_key(c, "protocol", {"shared_pool"});
  const EngineDatabase db = small_database();
  auto engine = make_recognition_engine(c, small_database(), 2);
  const auto serial = run_all(*engine, c, dir / "shared1.h5", 1, false);
  REQUIRE(serial.size() == 3);
  // One pool per object: every run has the pose of the object's shared pool, and the runs
  // differ only in the grasps they draw.
  const Pose shared = simulated_pose(db, "nut", pool_seed(3, "nut", std::nullopt));
  for (const auto& r : serial) CHECK(r.truth.isApprox(shared, 1e-9));
  CHECK(serial[0].grasps != serial[1].grasps);
  CHECK_FALSE(shared.isApprox(simulated_pose(db, "nut", pool_seed(3, "nut", 0)), 1e-6));
  const auto parallel = run_all(*engine, c, dir / "shared2.h5", 2, true);
  check_same_results(serial, parallel);

  // A store of one protocol is not resumed under the other (nothing is written to it).
  ExperimentConfig independent = c;
  set_key(independent, "protocol", {"independent"});
  auto other = make_recognition_engine(independent, small_database(), 1);
  try {
    check_resumable(io::RunStore::read_header(dir / "shared1.h5"), other->header(), "shared1.h5");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "protocol");
    CHECK(e.file() == "shared1.h5");
  }
  CHECK(io::RunStore::read(dir / "shared1.h5").runs.size() == 3);
}

TEST_CASE("Recognition engine: per-step confidence features; confidences from this database's calibration only") {
  test::TempDir dir("engine");
  ExperimentConfig c = small_config();
  set_key(c, "objects", {"box"});
  set_key(c, "runs", {"1"});
  auto plain = make_recognition_engine(c, small_database(), 1);
  CHECK(plain->header().step_values == recognition_step_values());
  const auto runs = run_all(*plain, c, dir / "plain.h5", 1, true);
  REQUIRE(runs.size() == 1);
  const std::size_t F = confidence_feature_names().size();
  const std::size_t G = 2 + F + pipeline_stage_names().size();   // set.truth_score, then answer_set.*
  for (const auto& s : runs[0].steps) {
    REQUIRE(s.values.size() == G + 15);
    CHECK(std::isnan(s.values[0]));  // no calibration: no confidence
    CHECK(std::isnan(s.values[1]));
    for (std::size_t i = 2; i < 2 + F; ++i) CHECK(std::isfinite(s.values[i]));
    for (std::size_t i = 2 + F; i < G; ++i)   // ran.<stage>: 1, 0, or NaN (not bricpsf's)
      CHECK((s.values[i] == 1.0 || s.values[i] == 0.0 || std::isnan(s.values[i])));
    CHECK(s.values[2 + F] == 0.0);       // ran.support: support.mode off
    CHECK(s.values[2 + F + 1] == 1.0);   // ran.scene
    CHECK(s.values[2] == doctest::Approx(s.posterior_best));  // feature.posterior_best
    // The true class's gap: >= 0 (+inf without a hypothesis of it).
    CHECK(s.values[G] >= 0.0);
    for (std::size_t i = G + 1; i < G + 4; ++i) CHECK(std::isnan(s.values[i]));   // no answer sets
    CHECK(std::isnan(s.values[G + 4]));   // random grasps: nothing planned
    CHECK(std::isnan(s.values[G + 5]));
    // fit.contact_distance_m: the contacts' mean distance to the answer at its pose; none
    // without an answer. A right answer sits on its contacts within the noise.
    if (s.best_object < 0) CHECK(std::isnan(s.values[G + 7]));
    if (s.best_object >= 0) CHECK(s.values[G + 7] >= 0.0);
    if (s.correct) CHECK(s.values[G + 7] < 0.004);
    // attribution.right_share, contacts.off_target_share: no scene, nothing to score.
    CHECK(std::isnan(s.values[G + 8]));
    CHECK(std::isnan(s.values[G + 9]));
    CHECK(std::isnan(s.values[G + 10]));   // scene.answer_is_neighbour: no neighbours
    for (std::size_t i = G + 11; i < G + 15; ++i) CHECK(std::isnan(s.values[i]));   // support.*: not looked for
  }
  // The entropy drop: the previous step's posterior entropy minus this one's (none at step 1).
  const auto& st = runs[0].steps;
  CHECK(std::isnan(st[0].values[G + 6]));
  for (std::size_t k = 1; k < st.size(); ++k)
    CHECK(st[k].values[G + 6] == st[k - 1].posterior_entropy - st[k].posterior_entropy);

  // A calibration of this database: the recorded confidences are its predictions on the
  // recorded features.
  Calibration cal;
  cal.database_fingerprint = small_database().description["fingerprint"].get<std::string>();
  cal.features = confidence_feature_names();
  StepModels early, late;
  early.object = {std::vector<double>(F, 0.0), std::vector<double>(F, 1.0), std::vector<double>(F + 1, 0.3)};
  early.pose = {std::vector<double>(F, 0.1), std::vector<double>(F, 2.0), std::vector<double>(F + 1, -0.2)};
  late = early;
  late.first_step = 2;
  late.object.coef[0] = -0.4;
  cal.ranges = {early, late};
  write_calibration(dir / "cal.json", cal);
  ExperimentConfig with = c;
  set_key(with, "calibration", {(dir / "cal.json").string()});
  auto calibrated = make_recognition_engine(with, small_database(), 1);
  const auto cruns = run_all(*calibrated, with, dir / "calibrated.h5", 1, true);
  REQUIRE(cruns.size() == 1);
  for (std::size_t k = 0; k < cruns[0].steps.size(); ++k) {
    const auto& v = cruns[0].steps[k].values;
    const auto F_end = static_cast<std::ptrdiff_t>(2 + F);   // the features; ran.<stage> after them
    const std::vector<double> f(v.begin() + 2, v.begin() + F_end);
    CHECK(f == std::vector<double>(runs[0].steps[k].values.begin() + 2, runs[0].steps[k].values.begin() + F_end));
    const int step = static_cast<int>(k) + 1;   // each step by its own range's models
    CHECK(v[0] == (step == 1 ? early : late).object.predict(f));
    CHECK(v[0] == cal.object_confidence(step, f));
    CHECK(v[1] == cal.pose_confidence(step, f));
    CHECK(v[0] > 0.0);
    CHECK(v[0] < 1.0);
  }

  // Another database's calibration: one error naming the file and the key, before any run.
  cal.database_fingerprint = "0123456789abcdef";
  write_calibration(dir / "other.json", cal);
  set_key(with, "calibration", {(dir / "other.json").string()});
  try {
    make_recognition_engine(with, small_database(), 1);
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.file() == (dir / "other.json").string());
    CHECK(e.field() == "database_fingerprint");
  }
}

TEST_CASE("Recognition engine: hidden objects (open set) are explored but never answerable") {
  test::TempDir dir("engine");
  for (const char* hidden : {"nut", "each"}) {
    CAPTURE(hidden);
    ExperimentConfig c = small_config();
    set_key(c, "objects", {"box,nut"});
    set_key(c, "runs", {"1"});
    set_key(c, "hidden", {hidden});
    auto engine = make_recognition_engine(c, small_database(), 1);
    const auto& h = engine->header();
    CHECK(h.database_objects.size() == 6);   // indices stay those of the file
    const auto runs = run_all(*engine, c, dir / (std::string(hidden) + ".h5"), 1, true);
    REQUIRE(runs.size() == 2);
    for (const auto& r : runs) {
      const std::string& explored = h.objects[static_cast<std::size_t>(r.object)];
      const bool is_hidden = std::string(hidden) == "each" || explored == "nut";
      for (const auto& s : r.steps) {
        if (is_hidden) {
          CHECK_FALSE(s.correct);
          CHECK(s.posterior_true == 0.0);
          if (s.best_object >= 0) CHECK(h.database_objects[static_cast<std::size_t>(s.best_object)] != explored);
        }
        // The hidden nut is never an answer, for any explored object.
        if (std::string(hidden) == "nut" && s.best_object >= 0)
          CHECK(h.database_objects[static_cast<std::size_t>(s.best_object)] != "nut");
      }
    }
  }
  ExperimentConfig bad = small_config();
  set_key(bad, "hidden", {"teapot"});
  try {
    make_recognition_engine(bad, small_database(), 1);
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "hidden");
    CHECK(e.message().find("teapot") != std::string::npos);
  }
}

TEST_CASE("Recognition engine: a sweep of the FLANN index settings searches each variant with its own index") {
  // The paper's preset searches a FLANN index (not the feature table); variants of one database
  // differing in index.exact must each give what that configuration gives alone.
  ExperimentConfig c = small_config();
  set_key(c, "objects", {"nut"});
  set_key(c, "runs", {"1"});
  set_key(c, "preset", {"paper"});
  set_key(c, "ransac.prune", {"5"});
  set_key(c, "index.checks", {"1"});
  set_key(c, "sweep.index.exact", {"true", "false"});
  test::TempDir dir("engine_index");
  auto swept = make_recognition_engine(c, small_database(), 1);
  REQUIRE(swept->header().variant_labels.size() == 2);
  const auto runs = run_all(*swept, c, dir / "swept.h5", 1, true);
  REQUIRE(runs.size() == 2);
  const auto variants = expand_variants(c);
  for (int v = 0; v < 2; ++v) {
    CAPTURE(v);
    const ExperimentConfig alone = variants[static_cast<std::size_t>(v)].config;
    auto engine = make_recognition_engine(alone, small_database(), 1);
    const auto own = run_all(*engine, alone, dir / ("alone" + std::to_string(v) + ".h5"), 1, true);
    REQUIRE(own.size() == 1);
    std::vector<io::RunRecord> from_sweep{runs[static_cast<std::size_t>(v)]};
    from_sweep[0].variant = own[0].variant;
    check_same_results(from_sweep, own);
  }
  // On this small database both settings find the same features; the group's lookup keeps
  // one index per setting all the same.
  DatabaseGroup group;
  FeatureIndexSettings exact, approximate, other;
  approximate.exact = other.exact = false;
  approximate.checks = 7;
  other.checks = 8;
  const auto a = std::make_shared<const FeatureIndex>(), b = std::make_shared<const FeatureIndex>();
  group.indices = {{exact, a}, {approximate, b}};
  CHECK(group.index_for(exact) == a);
  CHECK(group.index_for(approximate) == b);
  CHECK(group.index_for(other) == nullptr);
}

TEST_CASE("Recognition engine: active exploration plans each grasp after the first, deterministically") {
  test::TempDir dir("engine_active");
  ExperimentConfig c = small_config();
  set_key(c, "sweep.exploration.strategy", {"random", "active"});   // one variant each, paired runs
  set_key(c, "active.candidates", {"12"});
  validate(c);
  auto engine = make_recognition_engine(c, small_database(), 2);
  const auto serial = run_all(*engine, c, dir / "serial.h5", 1, false);
  REQUIRE(serial.size() == 8);
  const auto plan = static_cast<std::size_t>(
      std::find(recognition_stages().begin(), recognition_stages().end(), "plan") - recognition_stages().begin());
  REQUIRE(plan < recognition_stages().size());
  int differing = 0;
  for (const auto& r : serial) {
    const bool active = r.variant == 1;
    // The paired random run: same object and run, the other variant.
    const io::RunRecord* twin = nullptr;
    for (const auto& o : serial)
      if (o.variant != r.variant && o.object == r.object && o.run == r.run) twin = &o;
    REQUIRE(twin);
    CHECK(r.truth.isApprox(twin->truth, 0.0));        // same object pose
    CHECK(r.grasps.front() == twin->grasps.front());    // the same first grasp
    std::set<std::int32_t> distinct(r.grasps.begin(), r.grasps.end());
    CHECK(distinct.size() == r.grasps.size());          // pool grasps, each at most once
    CHECK(*distinct.begin() >= 0);
    CHECK(*distinct.rbegin() < 5);
    CHECK(r.steps[0].contacts == twin->steps[0].contacts);   // the first grasp is the drawn one
    const auto& names = recognition_step_values();
    const auto col = [&](const char* n) { return static_cast<std::size_t>(std::find(names.begin(), names.end(), n) - names.begin()); };
    const std::size_t info = col("plan.expected_information"), object_info = col("plan.expected_object_information");
    REQUIRE(object_info < names.size());
    for (std::size_t k = 0; k < r.steps.size(); ++k) {
      const double t = r.steps[k].stage_times_s.at(plan);
      const auto& v = r.steps[k].values;
      // Planned after a step that left hypotheses; otherwise (and in random runs) the drawn grasp.
      if (!active || k == 0 || r.steps[k - 1].hypotheses == 0) {
        CHECK(t == 0.0);
        CHECK(std::isnan(v.at(info)));   // nothing expected of a grasp nobody chose
      } else {
        CHECK(t > 0.0);
        // The chosen grasp's expectation: 0 <= I(O; Y) <= I(H; Y) <= ln K (K <= 16 hypotheses).
        CHECK(v.at(object_info) >= 0.0);
        CHECK(v.at(object_info) <= v.at(info) + 1e-12);
        CHECK(v.at(info) <= std::log(16.0) + 1e-9);
      }
    }
    if (active) differing += r.grasps != twin->grasps;
  }
  CHECK(differing > 0);   // the planner's choices are not the drawn order
  const auto parallel = run_all(*engine, c, dir / "parallel.h5", 2, true);
  check_same_results(serial, parallel);
}

TEST_CASE("Recognition engine: diagnostics.oracle_belief plans with the truth in the belief, deterministically") {
  test::TempDir dir("engine_oracle");
  ExperimentConfig c = small_config();
  set_key(c, "diagnostics.oracle_belief", {"0.9"});
  CHECK_THROWS_WITH_AS(make_recognition_engine(c, small_database(), 1), doctest::Contains("diagnostics.oracle_belief"),
                       Error);   // random grasps have no planner to give the truth to
  set_key(c, "exploration.strategy", {"active"});
  set_key(c, "active.candidates", {"12"});
  set_key(c, "sweep.diagnostics.oracle_belief", {"0", "0.9"});
  validate(c);
  auto engine = make_recognition_engine(c, small_database(), 2);
  const auto serial = run_all(*engine, c, dir / "serial.h5", 1, false);
  REQUIRE(serial.size() == 8);
  int differing = 0;
  for (const auto& r : serial)
    if (r.variant == 1)
      for (const auto& o : serial)
        if (o.variant == 0 && o.object == r.object && o.run == r.run) {
          CHECK(r.grasps.front() == o.grasps.front());   // the same first grasp, then planned
          differing += r.grasps != o.grasps;
        }
  CHECK(differing > 0);   // a belief that holds the truth changes the planner's choices
  const auto parallel = run_all(*engine, c, dir / "parallel.h5", 2, true);
  check_same_results(serial, parallel);
}

TEST_CASE("Recognition engine: diagnostics.truth_pose records the truth at its pose and changes no result") {
  test::TempDir dir("engine");
  ExperimentConfig c = small_config();
  set_key(c, "steps", {"4"});
  auto plain = make_recognition_engine(c, small_database(), 1);
  const auto a = run_all(*plain, c, dir / "plain.h5", 1, true);
  ExperimentConfig d = c;
  set_key(d, "diagnostics.truth_pose", {"true"});
  auto diag = make_recognition_engine(d, small_database(), 1);
  const auto& names = diag->header().step_values;
  REQUIRE(names.size() == recognition_step_values().size() + truth_pose_step_values().size());
  CHECK(std::equal(truth_pose_step_values().begin(), truth_pose_step_values().end(),
                   names.end() - static_cast<std::ptrdiff_t>(truth_pose_step_values().size())));
  const auto b = run_all(*diag, d, dir / "diag.h5", 2, false);
  check_same_results(a, b);
  // The diagnostic's own values: the same for 1 and 2 threads, bit for bit (NaN as NaN).
  const auto b1 = run_all(*diag, d, dir / "diag1.h5", 1, false);
  REQUIRE(b1.size() == b.size());
  for (std::size_t i = 0; i < b.size(); ++i)
    for (std::size_t k = 0; k < b[i].steps.size(); ++k) {
      const auto &x = b[i].steps[k].values, &y = b1[i].steps[k].values;
      REQUIRE(x.size() == y.size());
      for (std::size_t j = 0; j < x.size(); ++j)
        CHECK(((std::isnan(x[j]) && std::isnan(y[j])) || x[j] == y[j]));
    }
  const std::size_t at = recognition_step_values().size();   // truth_pose.wins
  std::size_t steps = 0, named = 0, compared = 0;
  for (const auto& r : b)
    for (const auto& s : r.steps) {
      if (s.contacts == 0) continue;
      ++steps;
      REQUIRE(s.values.size() == names.size());
      const double wins = s.values[at], truth_lw = s.values[at + 1], answer_lw = s.values[at + 2];
      CHECK((wins == 0.0 || wins == 1.0));
      CHECK(std::isfinite(truth_lw));
      if (s.best_object < 0) continue;
      CHECK(answer_lw == doctest::Approx(std::log(s.weight)).epsilon(1e-9));
      // A right answer counts as a win (Funnel::truth_pose_wins). Where the near-twin
      // verification compared the truth with other leaders, the lower V wins; elsewhere the
      // better ln wt.
      const double truth_v = s.values[at + 3], rival_v = s.values[at + 4];
      if (s.correct) CHECK(wins == 1.0);
      if (std::isfinite(truth_v) && std::isfinite(rival_v)) {
        ++compared;
        if (!s.correct && truth_v != rival_v) CHECK((wins == 1.0) == (truth_v < rival_v));
      } else if (!s.correct) {
        CHECK((wins == 1.0) == (truth_lw > answer_lw));
      }
      named += s.correct ? 1 : 0;
    }
  CHECK(steps > 0);
  CHECK(named > 0);
  CHECK(compared > 0);   // the improved preset's verification ran
}
