// The HDF5 run store: round trip, appends in any order, crash leftovers, compaction.
#include "io/h5.hpp"
#include "io/run_store.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <fstream>
#include <thread>

using namespace ts;
using namespace ts::io;

namespace {

RunStoreHeader header(int steps = 3) {
  RunStoreHeader h;
  h.config_json = R"({"runs":2,"steps":3})";
  h.database_json = R"({"path":"db.h5"})";
  h.versions_json = R"({"touchstone":"test"})";
  h.machine = "test machine";
  h.steps = steps;
  h.variant_labels = {"method=a", "method=b"};
  h.variant_configs = {"{}", "{}"};
  h.objects = {"cube", "sphere"};
  h.database_objects = {"cube", "sphere", "bunny"};
  h.stages = {"ransac", "icp", "evaluate"};
  return h;
}

RunRecord record(int variant, int object, int run, int steps = 3) {
  RunRecord r;
  r.variant = variant;
  r.object = object;
  r.run = run;
  Rng rng(99, static_cast<std::uint64_t>(variant), static_cast<std::uint64_t>(object),
          static_cast<std::uint64_t>(run));
  r.truth.linear() = rng.rotation().toRotationMatrix();
  r.truth.translation() = Vec3(rng.uniform(), rng.uniform(), rng.uniform());
  r.wall_time_s = rng.uniform();
  for (int k = 0; k < steps; ++k) {
    r.grasps.push_back(static_cast<std::int32_t>(rng.index(50)));
    RunStepRecord s;
    s.best_object = static_cast<std::int32_t>(rng.index(3));
    s.correct = s.best_object == object;
    s.weight = rng.uniform();
    s.posterior_true = rng.uniform();
    s.posterior_best = rng.uniform();
    s.posterior_entropy = rng.uniform();
    s.true_rank = static_cast<std::int32_t>(rng.index(4));
    s.hypotheses = 100;
    s.contacts = 10 * (k + 1);
    s.free_points = 7 * k;
    s.pose.linear() = rng.rotation().toRotationMatrix();
    s.pose.translation() = Vec3(rng.normal(), rng.normal(), rng.normal());
    s.position_error_m = rng.uniform();
    s.orientation_error_rad = rng.uniform();
    s.symmetric_orientation_error_rad = rng.uniform();
    s.mssd_m = rng.uniform();
    s.time_s = rng.uniform();
    s.stage_times_s = {rng.uniform(), rng.uniform(), rng.uniform()};
    r.steps.push_back(s);
  }
  return r;
}

void check_equal(const RunRecord& a, const RunRecord& b) {
  CHECK(a.same_key(b));
  CHECK(a.grasps == b.grasps);
  CHECK(a.truth.isApprox(b.truth, 1e-12));
  CHECK(a.wall_time_s == b.wall_time_s);
  REQUIRE(a.steps.size() == b.steps.size());
  for (std::size_t k = 0; k < a.steps.size(); ++k) {
    const auto &x = a.steps[k], &y = b.steps[k];
    CHECK(x.best_object == y.best_object);
    CHECK(x.correct == y.correct);
    CHECK(x.weight == y.weight);
    CHECK(x.posterior_true == y.posterior_true);
    CHECK(x.posterior_best == y.posterior_best);
    CHECK(x.posterior_entropy == y.posterior_entropy);
    CHECK(x.true_rank == y.true_rank);
    CHECK(x.hypotheses == y.hypotheses);
    CHECK(x.contacts == y.contacts);
    CHECK(x.free_points == y.free_points);
    CHECK(x.pose.isApprox(y.pose, 1e-12));
    CHECK(x.position_error_m == y.position_error_m);
    CHECK(x.orientation_error_rad == y.orientation_error_rad);
    CHECK(x.symmetric_orientation_error_rad == y.symmetric_orientation_error_rad);
    CHECK(x.mssd_m == y.mssd_m);
    CHECK(x.time_s == y.time_s);
    CHECK(x.stage_times_s == y.stage_times_s);
  }
}

}  // namespace

TEST_CASE("Run store round trip: appends in any order read back sorted") {
  test::TempDir dir("runstore");
  const auto path = dir / "run.h5";
  RunStore::create(path, header());
  CHECK_THROWS_AS(RunStore::create(path, header()), Error);  // never overwrites

  const RunStoreHeader h = RunStore::read_header(path);
  CHECK(h.config_json == header().config_json);
  CHECK(h.variant_labels == header().variant_labels);
  CHECK(h.stages == header().stages);
  CHECK(h.database_objects == header().database_objects);
  CHECK(h.steps == 3);

  RunStore::append(path, {record(1, 0, 1), record(0, 1, 0)});
  RunStore::append(path, {record(0, 0, 0)});
  const RunStoreContents c = RunStore::read(path);
  CHECK_FALSE(c.complete);
  REQUIRE(c.runs.size() == 3);
  check_equal(c.runs[0], record(0, 0, 0));
  check_equal(c.runs[1], record(0, 1, 0));
  check_equal(c.runs[2], record(1, 0, 1));

  // Bad appends are refused before anything is written.
  CHECK_THROWS_AS(RunStore::append(path, {record(2, 0, 0)}), Error);
  CHECK_THROWS_AS(RunStore::append(path, {record(0, 0, 5, 2)}), Error);
  CHECK(RunStore::read(path).runs.size() == 3);
}

TEST_CASE("Leftovers of an interrupted append are ignored, later appends stay aligned") {
  test::TempDir dir("runstore");
  const auto path = dir / "run.h5";
  RunStore::create(path, header());
  RunStore::append(path, {record(0, 0, 0)});
  {
    // A crash after some step columns of the next run were written, before its run row.
    h5::File f = h5::File::open(path, h5::File::Access::read_write);
    h5::Group st = f.root().open_group("steps");
    const std::int32_t steps[] = {1, 2};
    st.append<std::int32_t>("step", steps, 2);
    const double w[] = {0.5, 0.5};
    st.append<double>("weight", w, 2);
    h5::Group rg = f.root().open_group("runs");
    const std::int64_t first[] = {3};
    rg.append<std::int64_t>("first_step_row", first, 1);  // half a run row
    f.close();
  }
  REQUIRE(RunStore::read(path).runs.size() == 1);
  RunStore::append(path, {record(1, 1, 1), record(0, 1, 0)});
  const RunStoreContents c = RunStore::read(path);
  REQUIRE(c.runs.size() == 3);
  check_equal(c.runs[0], record(0, 0, 0));
  check_equal(c.runs[1], record(0, 1, 0));
  check_equal(c.runs[2], record(1, 1, 1));
}

TEST_CASE("Compaction gives the same bytes whatever the completion order") {
  test::TempDir dir("runstore");
  const auto a = dir / "a.h5", b = dir / "b.h5";
  RunStore::create(a, header());
  RunStore::create(b, header());
  RunStore::append(a, {record(0, 0, 0), record(0, 0, 1)});
  RunStore::append(a, {record(1, 1, 0)});
  RunStore::append(b, {record(1, 1, 0)});
  RunStore::append(b, {record(0, 0, 1)});
  RunStore::append(b, {record(0, 0, 0)});
  // appends leave both stores as created; their pending runs came in different batches
  CHECK(test::read_bytes(a) == test::read_bytes(b));
  CHECK(std::filesystem::exists(dir / "a.h5.runs" / "00000002.h5"));
  CHECK_FALSE(std::filesystem::exists(dir / "a.h5.runs" / "00000003.h5"));
  CHECK(std::filesystem::exists(dir / "b.h5.runs" / "00000003.h5"));
  RunStore::compact(a, true);
  RunStore::compact(b, true);
  CHECK(test::read_bytes(a) == test::read_bytes(b));
  const RunStoreContents c = RunStore::read(a);
  CHECK(c.complete);
  REQUIRE(c.runs.size() == 3);
  check_equal(c.runs[2], record(1, 1, 0));
  CHECK(std::filesystem::directory_iterator(dir.path()) != std::filesystem::directory_iterator());
  int files = 0;
  for (auto& e : std::filesystem::directory_iterator(dir.path())) (void)e, ++files;
  CHECK(files == 2);  // no temporary nor pending folder left behind
}

TEST_CASE("Foreign and missing files give clear errors") {
  test::TempDir dir("runstore");
  CHECK_THROWS_AS(RunStore::read(dir / "missing.h5"), Error);
  test::write_text(dir / "text.h5", "not hdf5");
  CHECK_THROWS_AS(RunStore::read(dir / "text.h5"), Error);
  {
    h5::File f = h5::File::create(dir / "other.h5");
    f.root().set_attribute("format", "touchstone-db");
    f.close();
  }
  try {
    RunStore::read(dir / "other.h5");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.message().find("not a Touchstone run store") != std::string::npos);
    CHECK(e.field() == "/@format");
  }
}

TEST_CASE("Compaction is idempotent: stored values never round-trip") {
  test::TempDir dir("runstore");
  const auto a = dir / "a.h5", b = dir / "b.h5";
  RunStore::create(a, header());
  RunStore::create(b, header());
  for (const auto& p : {a, b}) RunStore::append(p, {record(1, 1, 0), record(0, 0, 3)});
  RunStore::compact(a, true);
  RunStore::compact(b, true);
  RunStore::compact(b, true);
  RunStore::compact(b, true);
  CHECK(test::read_bytes(a) == test::read_bytes(b));
}

TEST_CASE("An append waits while another process holds the store's HDF5 lock") {
  // `touchstone report` (here: h5py) reading the store at the moment the experiment appends.
  test::TempDir dir("runstore");
  const auto path = dir / "run.h5";
  RunStore::create(path, header());
  const auto ready = dir / "locked";
  const std::string script = "import h5py, time, pathlib\nf = h5py.File('" + path.string() +
                             "', 'r+')\npathlib.Path('" + ready.string() +
                             "').touch()\ntime.sleep(1.5)\nf.close()\n";
  std::vector<std::string> args{"/usr/bin/python3", "-c", script};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  REQUIRE(posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), environ) == 0);
  for (int i = 0; i < 200 && !std::filesystem::exists(ready); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  REQUIRE(std::filesystem::exists(ready));
  CHECK_NOTHROW(RunStore::append(path, {record(0, 0, 0)}));
  int status = 0;
  waitpid(pid, &status, 0);
  CHECK(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 0);
  CHECK(RunStore::read(path).runs.size() == 1);
}

TEST_CASE("Appends never write the store in place: pending files, merged on read, folded by compact") {
  test::TempDir dir("runstore");
  const auto path = dir / "run.h5";
  const auto pending = dir / "run.h5.runs";
  RunStore::create(path, header());
  const std::string created = test::read_bytes(path);
  RunStore::append(path, {record(1, 0, 0)});
  RunStore::append(path, {record(0, 1, 1), record(0, 0, 0)});
  CHECK(test::read_bytes(path) == created);   // the store itself is untouched
  CHECK(std::filesystem::exists(pending / "00000001.h5"));
  CHECK(std::filesystem::exists(pending / "00000002.h5"));
  // a writer's temporary file (killed mid-write) is ignored
  { std::ofstream(pending / "00000003.h5.tmp-1-0") << "half a file"; }
  RunStoreContents c = RunStore::read(path);
  REQUIRE(c.runs.size() == 3);
  check_equal(c.runs[0], record(0, 0, 0));
  check_equal(c.runs[1], record(0, 1, 1));
  check_equal(c.runs[2], record(1, 0, 0));
  CHECK_FALSE(c.complete);
  RunStore::compact(path, true);
  CHECK_FALSE(std::filesystem::exists(pending / "00000001.h5"));
  CHECK_FALSE(std::filesystem::exists(pending / "00000002.h5"));
  c = RunStore::read(path);
  REQUIRE(c.runs.size() == 3);
  check_equal(c.runs[1], record(0, 1, 1));
  CHECK(c.complete);
  // the same runs appended to one store in place of three gives the same bytes
  const auto other = dir / "other.h5";
  RunStore::create(other, header());
  RunStore::append(other, {record(0, 0, 0), record(0, 1, 1), record(1, 0, 0)});
  RunStore::compact(other, true);
  CHECK(test::read_bytes(other) == test::read_bytes(path));
  CHECK_FALSE(std::filesystem::exists(dir / "other.h5.runs"));
}

TEST_CASE("Pending runs fold into the store every 64 files; a fold interrupted before the removal counts runs once") {
  test::TempDir dir("runstore");
  const auto path = dir / "run.h5";
  RunStore::create(path, header());
  for (int r = 0; r < 70; ++r) RunStore::append(path, {record(r % 2, 0, r)});
  std::size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir / "run.h5.runs")) files += e.is_regular_file();
  CHECK(files == 6);   // 64 folded, 6 since
  CHECK(RunStore::read(path).runs.size() == 70);
  // A kill after the fold's rename, before it removed the files: copy a folded run back.
  const auto copy = dir / "copy.h5";
  RunStore::create(copy, header());
  RunStore::append(copy, {record(0, 0, 0)});
  std::filesystem::copy_file(dir / "copy.h5.runs" / "00000001.h5", dir / "run.h5.runs" / "00000099.h5");
  const RunStoreContents c = RunStore::read(path);
  CHECK(c.runs.size() == 70);
  RunStore::compact(path, true);
  CHECK(RunStore::read(path).runs.size() == 70);
}

TEST_CASE("A pending file of another experiment, or left by an earlier store, is an error naming it") {
  test::TempDir dir("runstore");
  const auto path = dir / "run.h5";
  RunStore::create(path, header());
  RunStoreHeader h = header();
  h.config_json = R"({"runs":2,"steps":3,"seed":2})";
  const auto foreign = dir / "foreign.h5";
  RunStore::create(foreign, h);
  RunStore::append(foreign, {record(0, 0, 0)});
  std::filesystem::create_directories(dir / "run.h5.runs");
  std::filesystem::copy_file(dir / "foreign.h5.runs" / "00000001.h5", dir / "run.h5.runs" / "00000001.h5");
  try {
    RunStore::read(path);
    FAIL("a foreign pending file was read");
  } catch (const Error& e) {
    CHECK(std::string(e.what()).find("00000001.h5") != std::string::npos);
    CHECK(std::string(e.what()).find("another experiment") != std::string::npos);
  }
  std::filesystem::remove(path);   // the store removed, its pending runs left
  try {
    RunStore::create(path, header());
    FAIL("a store was created over pending runs");
  } catch (const Error& e) {
    CHECK(std::string(e.what()).find("run.h5.runs") != std::string::npos);
  }
  CHECK_FALSE(std::filesystem::exists(path));
}

TEST_CASE("Killed at random instants while appending and folding, the store loses only the run in flight") {
  // A child process appends runs 0, 1, 2, ... in order (folding every 64 files) and is killed
  // (SIGKILL) after a random delay; the store must read, hold a prefix of the runs with
  // their exact values, and the next child continues from there. 50 kills.
  test::TempDir dir("runstore");
  const auto path = dir / "run.h5";
  RunStore::create(path, header(2));
  const int total = 400;
  Rng rng(2024);
  std::size_t stored = 0;
  int kills = 0;
  for (int round = 0; round < 200 && kills < 50 && stored < static_cast<std::size_t>(total); ++round) {
    const pid_t pid = fork();
    REQUIRE(pid >= 0);
    if (pid == 0) {
      try {
        for (int r = static_cast<int>(stored); r < total; ++r) RunStore::append(path, {record(0, 0, r, 2)});
      } catch (...) {
        _exit(3);
      }
      _exit(0);
    }
    std::this_thread::sleep_for(std::chrono::microseconds(rng.index(40000)));
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    if (WIFSIGNALED(status)) ++kills;
    else REQUIRE(WEXITSTATUS(status) == 0);
    const RunStoreContents c = RunStore::read(path);
    REQUIRE(c.runs.size() >= stored);
    for (std::size_t i = 0; i < c.runs.size(); ++i) REQUIRE(c.runs[i].run == static_cast<int>(i));
    stored = c.runs.size();
  }
  CHECK(kills == 50);
  const RunStoreContents c = RunStore::read(path);
  for (std::size_t i = 0; i < c.runs.size(); i += 37) check_equal(c.runs[i], record(0, 0, static_cast<int>(i), 2));
  RunStore::compact(path, true);
  CHECK(RunStore::read(path).runs.size() == stored);
}

TEST_CASE("Per-step values: named in the header, stored per step, folded by compact; optional") {
  test::TempDir dir("runstore");
  const auto path = dir / "values.h5";
  RunStoreHeader h = header();
  h.step_values = {"confidence_object", "feature.a"};
  RunStore::create(path, h);
  CHECK(RunStore::read_header(path).step_values == h.step_values);
  auto with_values = [](RunRecord r) {
    for (std::size_t k = 0; k < r.steps.size(); ++k)
      r.steps[k].values = {0.1 * static_cast<double>(k + r.run), std::nan("")};
    return r;
  };
  RunStore::append(path, {with_values(record(0, 1, 1))});
  RunStore::append(path, {with_values(record(0, 0, 0))});
  for (bool folded : {false, true}) {
    if (folded) RunStore::compact(path, true);
    const RunStoreContents c = RunStore::read(path);
    REQUIRE(c.runs.size() == 2);
    check_equal(c.runs[0], record(0, 0, 0));
    REQUIRE(c.runs[1].steps[2].values.size() == 2);
    CHECK(c.runs[1].steps[2].values[0] == doctest::Approx(0.3));
    CHECK(std::isnan(c.runs[1].steps[2].values[1]));
  }
  // A step with the wrong number of values is refused before anything is written.
  CHECK_THROWS_AS(RunStore::append(path, {record(1, 0, 0)}), Error);
  CHECK(RunStore::read(path).runs.size() == 2);
  // A store without values (as written before them) has none.
  const auto plain = dir / "plain.h5";
  RunStore::create(plain, header());
  RunStore::append(plain, {record(0, 0, 0)});
  CHECK(RunStore::read_header(plain).step_values.empty());
  CHECK(RunStore::read(plain).runs[0].steps[0].values.empty());
}
