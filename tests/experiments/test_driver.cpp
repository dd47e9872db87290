// The driver with a synthetic engine: parallel = serial, interrupted + resumed = uninterrupted.
#include "experiments/runs/driver.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <tbb/task_arena.h>

#include <map>
#include <set>

using namespace ts;
using namespace ts::experiments;

namespace {

/// Deterministic fake runs: what a real engine would store, from (seed, variant, object, run).
class SyntheticEngine final : public RunEngine {
 public:
  SyntheticEngine() {
    h_.config_json = R"({"runs":4})";
    h_.database_json = "{}";
    h_.versions_json = "{}";
    h_.machine = "test";
    h_.steps = 5;
    h_.variant_labels = {"method=a", "method=b"};
    h_.variant_configs = {"{}", "{}"};
    h_.objects = {"cube", "sphere", "bunny"};
    h_.database_objects = {"cube", "sphere", "bunny", "cow"};
    h_.stages = {"a", "b"};
  }
  const io::RunStoreHeader& header() const override { return h_; }
  std::optional<io::RunRecord> run(const RunTask& t, const std::atomic<bool>* stop) override {
    io::RunRecord r;
    r.variant = t.variant;
    r.object = t.object;
    r.run = t.run;
    const std::string& name = h_.objects[static_cast<std::size_t>(t.object)];
    r.grasps = draw_grasps(7, name, t.run, 12, h_.steps);
    Rng rng(7, static_cast<std::uint64_t>(t.variant), name_hash(name), static_cast<std::uint64_t>(t.run));
    r.truth.translation() = Vec3(rng.uniform(), rng.uniform(), rng.uniform());
    for (int k = 0; k < h_.steps; ++k) {
      if (stop && stop->load()) return std::nullopt;
      io::RunStepRecord s;
      s.best_object = static_cast<std::int32_t>(rng.index(4));
      s.correct = s.best_object == t.object;
      s.weight = rng.uniform();
      s.position_error_m = rng.uniform();
      s.pose.linear() = rng.rotation().toRotationMatrix();
      s.time_s = 0.001;                 // timings fixed so that whole files can be compared
      s.stage_times_s = {0.0005, 0.0005};
      r.steps.push_back(s);
    }
    ++runs_computed;
    return r;
  }
  std::atomic<int> runs_computed{0};

 private:
  io::RunStoreHeader h_;
};

std::vector<io::RunRecord> runs_of(const std::filesystem::path& p) { return io::RunStore::read(p).runs; }

bool same(const std::vector<io::RunRecord>& a, const std::vector<io::RunRecord>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!a[i].same_key(b[i]) || a[i].grasps != b[i].grasps || !a[i].truth.isApprox(b[i].truth, 0))
      return false;
    for (std::size_t k = 0; k < a[i].steps.size(); ++k) {
      const auto &x = a[i].steps[k], &y = b[i].steps[k];
      if (x.best_object != y.best_object || x.correct != y.correct || x.weight != y.weight ||
          x.position_error_m != y.position_error_m || !x.pose.isApprox(y.pose, 0))
        return false;
    }
  }
  return true;
}

}  // namespace

TEST_CASE("Grasp sequences: distinct pool indices, per (seed, object, run)") {
  const auto a = draw_grasps(1, "cube", 0, 50, 40);
  REQUIRE(a.size() == 40);
  CHECK(std::set<std::int32_t>(a.begin(), a.end()).size() == 40);
  for (auto g : a) CHECK((g >= 0 && g < 50));
  CHECK(a == draw_grasps(1, "cube", 0, 50, 40));
  CHECK(a != draw_grasps(1, "cube", 1, 50, 40));
  CHECK(a != draw_grasps(1, "sphere", 0, 50, 40));
  CHECK(a != draw_grasps(2, "cube", 0, 50, 40));
  CHECK_THROWS_AS(draw_grasps(1, "cube", 0, 10, 11), Error);
  // The first grasp is uniform over the pool (chi-square over 4000 runs, 10 cells, df 9:
  // 99.9 % quantile 27.9).
  std::vector<int> counts(10, 0);
  for (int r = 0; r < 4000; ++r) counts[static_cast<std::size_t>(draw_grasps(3, "x", r, 10, 3)[0])]++;
  double chi2 = 0;
  for (int c : counts) chi2 += (c - 400.0) * (c - 400.0) / 400.0;
  CHECK(chi2 < 27.9);
}

TEST_CASE("Parallel, serial and interrupted-then-resumed experiments store the same runs") {
  test::TempDir dir("driver");
  SyntheticEngine engine;
  const auto tasks = all_tasks(engine.header(), 4);
  REQUIRE(tasks.size() == 24);

  const auto serial = dir / "serial.h5";
  io::RunStore::create(serial, engine.header());
  DriveSettings s1;
  s1.parallel_runs = false;
  const auto o1 = drive(engine, tasks, serial, s1);
  CHECK(o1.completed == 24);
  CHECK_FALSE(o1.interrupted);

  const auto parallel = dir / "parallel.h5";
  io::RunStore::create(parallel, engine.header());
  tbb::task_arena arena(2);
  arena.execute([&] { drive(engine, tasks, parallel, {}); });
  CHECK(same(runs_of(serial), runs_of(parallel)));

  // Interrupt after 7 runs, then resume twice (the second resume has nothing to do).
  const auto resumed = dir / "resumed.h5";
  io::RunStore::create(resumed, engine.header());
  std::atomic<bool> stop{false};
  DriveSettings s2;
  s2.stop = &stop;
  std::size_t last_done = 0;
  s2.on_progress = [&](const Progress& p) {
    last_done = p.done;
    if (p.session_done >= 7) stop = true;
  };
  DriveOutcome o2;
  arena.execute([&] { o2 = drive(engine, tasks, resumed, s2); });
  CHECK(o2.interrupted);
  CHECK(o2.completed >= 7);
  CHECK(o2.completed < 24);
  const std::size_t stored = runs_of(resumed).size();
  CHECK(stored == o2.completed);

  const int before = engine.runs_computed.load();
  DriveSettings s3;
  Progress seen;
  s3.on_progress = [&](const Progress& p) { seen = p; };
  const auto o3 = drive(engine, tasks, resumed, s3);
  CHECK(o3.completed == 24 - stored);
  CHECK(engine.runs_computed.load() - before == static_cast<int>(24 - stored));  // no run twice
  CHECK(seen.done == 24);
  CHECK(seen.total == 24);
  CHECK(drive(engine, tasks, resumed, {}).completed == 0);
  CHECK(same(runs_of(serial), runs_of(resumed)));

  // Compacted, the three stores are byte-identical.
  io::RunStore::compact(serial, true);
  io::RunStore::compact(parallel, true);
  io::RunStore::compact(resumed, true);
  CHECK(test::read_bytes(serial) == test::read_bytes(parallel));
  CHECK(test::read_bytes(serial) == test::read_bytes(resumed));
}

TEST_CASE("Progress estimates the time left from this session's rate") {
  Progress p;
  p.total = 100;
  p.done = 40;
  CHECK_FALSE(p.remaining_s().has_value());
  p.session_done = 10;
  p.elapsed_s = 20.0;
  CHECK(*p.remaining_s() == doctest::Approx(120.0));
  p.done = 100;
  CHECK(*p.remaining_s() == 0.0);
}

TEST_CASE("Resuming a store of another configuration names the first differing key") {
  SyntheticEngine engine;
  io::RunStoreHeader stored = engine.header();
  stored.config_json = R"({"name":"a","runs":20,"steps":40,"method":"bricpsf","sweep":{}})";
  stored.database_json = R"({"fingerprint":"abc"})";
  io::RunStoreHeader now = stored;
  CHECK_NOTHROW(check_resumable(stored, now, "run.h5"));
  now.config_json = R"({"name":"b","runs":20,"steps":40,"method":"bricpsf","sweep":{}})";
  CHECK_NOTHROW(check_resumable(stored, now, "run.h5"));  // the name is informative only
  now.config_json = R"({"name":"a","runs":10,"steps":40,"method":"ransac-icp","sweep":{}})";
  try {
    check_resumable(stored, now, "run.h5");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.file() == "run.h5");
    CHECK(e.field() == "runs");
    CHECK(e.message().find("20 there, 10 now") != std::string::npos);
  }
  now = stored;
  now.database_json = R"({"fingerprint":"def"})";
  CHECK_THROWS_AS(check_resumable(stored, now, "run.h5"), Error);
  now = stored;
  now.objects.pop_back();
  CHECK_THROWS_AS(check_resumable(stored, now, "run.h5"), Error);
}
