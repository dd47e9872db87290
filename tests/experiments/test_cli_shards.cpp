// `touchstone experiment --shard I/N` and `touchstone merge` (issue 16): shards of one
// experiment merge into a store whose results equal one process's, and a wrong set of shards is
// one clear error naming the store at fault, with nothing written. The MPI mode (--mpi under
// mpirun) gives one process's results too, and a rank killed mid-run loses only its runs in
// flight.
#include "experiments/runs/mpi_runs.hpp"
#include "io/run_store.hpp"
#include "cli_run.hpp"
#include "db_fixture.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <bit>
#include <chrono>
#include <thread>
#include <cstdint>
#include <fstream>
#include <map>
#include <tuple>
#include <string>
#include <vector>

using namespace ts;
namespace fs = std::filesystem;

namespace {

using ts::test::touchstone;

// 3 objects x 3 runs, short runs and small method parameters: the tests check the partition and
// the merge, not accuracy.
const std::string kExperiment =
    "experiment --db db.h5 --objects box,nut,wedge --runs 3 --steps 3 --pool 5 --seed 3 "
    "--set bricpsf.hypotheses=20 --set ransac.samples=5x40 --threads 1";

bool same_bits(double a, double b) { return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b); }

/// Every stored result of two stores equal, bit for bit (NaN confidences included); timings
/// (wall and stage times) may differ.
void check_same_results(const io::RunStoreContents& a, const io::RunStoreContents& b) {
  CHECK(a.header.config_json == b.header.config_json);
  CHECK(a.header.objects == b.header.objects);
  REQUIRE(a.runs.size() == b.runs.size());
  for (std::size_t i = 0; i < a.runs.size(); ++i) {
    const io::RunRecord &x = a.runs[i], &y = b.runs[i];
    CHECK(x.same_key(y));
    CHECK(x.grasps == y.grasps);
    CHECK(x.truth.matrix() == y.truth.matrix());
    REQUIRE(x.steps.size() == y.steps.size());
    for (std::size_t k = 0; k < x.steps.size(); ++k) {
      const auto &p = x.steps[k], &q = y.steps[k];
      CHECK(p.best_object == q.best_object);
      CHECK(p.correct == q.correct);
      CHECK(same_bits(p.weight, q.weight));
      CHECK(same_bits(p.posterior_true, q.posterior_true));
      CHECK(same_bits(p.posterior_entropy, q.posterior_entropy));
      CHECK(p.true_rank == q.true_rank);
      CHECK(p.hypotheses == q.hypotheses);
      CHECK(p.contacts == q.contacts);
      CHECK(p.free_points == q.free_points);
      CHECK(p.pose.matrix() == q.pose.matrix());
      CHECK(same_bits(p.position_error_m, q.position_error_m));
      CHECK(same_bits(p.symmetric_orientation_error_rad, q.symmetric_orientation_error_rad));
      CHECK(same_bits(p.mssd_m, q.mssd_m));
      REQUIRE(p.values.size() == q.values.size());
      for (std::size_t v = 0; v < p.values.size(); ++v) CHECK(same_bits(p.values[v], q.values[v]));
    }
  }
}

std::string shard_name(int n, int i) { return 's' + std::to_string(n) + "_" + std::to_string(i) + ".h5"; }

/// Run shards 1..n of n; returns the merge arguments ("s3_1.h5 s3_2.h5 s3_3.h5").
std::string run_shards(const test::TempDir& dir, int n) {
  std::string names;
  for (int i = 1; i <= n; ++i) {
    const auto r = touchstone(dir, kExperiment + " --shard " + std::to_string(i) + "/" + std::to_string(n) +
                                       " --json --out " + shard_name(n, i));
    REQUIRE_MESSAGE(r.code == 0, r.err);
    names += ' ' + shard_name(n, i);
  }
  return names;
}

}  // namespace

TEST_CASE("experiment --shard I/N, then merge: the results of one process, for N = 1, 2, 3, 7") {
  test::TempDir dir("shards");
  test::make_db(dir);
  const auto whole = touchstone(dir, kExperiment + " --json --out whole.h5");
  REQUIRE_MESSAGE(whole.code == 0, whole.err);
  const io::RunStoreContents single = io::RunStore::read(dir / "whole.h5");
  REQUIRE(single.runs.size() == 9);
  CHECK(single.header.shard.empty());
  for (const int n : {1, 2, 3, 7}) {
    CAPTURE(n);
    const std::string names = run_shards(dir, n);
    // Each shard holds every n-th run in key order, and says which shard it is.
    std::size_t held = 0;
    for (int i = 1; i <= n; ++i) {
      const auto c = io::RunStore::read(dir / shard_name(n, i));
      CHECK(c.header.shard == std::to_string(i) + "/" + std::to_string(n));
      CHECK(c.complete);
      const std::size_t want = (9 + static_cast<std::size_t>(n - i)) / static_cast<std::size_t>(n);
      CHECK(c.runs.size() == want);
      held += c.runs.size();
    }
    CHECK(held == 9);
    const std::string merged = "merged" + std::to_string(n) + ".h5";
    const auto m = touchstone(dir, "merge --out " + merged + names + " --json --progress lines");
    REQUIRE_MESSAGE(m.code == 0, m.err);
    CHECK(nlohmann::json::parse(m.out)["runs"] == 9);
    // Progress: a line per store read and one for the merged store written, the last complete.
    const std::string last = "merge: stores " + std::to_string(n + 1) + "/" + std::to_string(n + 1) + " (100.0 %)";
    CHECK_MESSAGE(m.err.find(last) != std::string::npos, m.err);
    CHECK(m.err.find("old form") == std::string::npos);
    const io::RunStoreContents c = io::RunStore::read(dir / merged);
    CHECK(c.complete);
    CHECK(c.header.shard.empty());
    check_same_results(single, c);
    // The report reads the merged store as it reads the single process's.
    const auto ra = touchstone(dir, "report whole.h5 --json"), rb = touchstone(dir, "report " + merged + " --json");
    REQUIRE(ra.code == 0);
    REQUIRE(rb.code == 0);
    auto results = [](const std::string& out) {   // the per-step figures, timings left out
      nlohmann::json steps = nlohmann::json::parse(out)["per_step"];
      for (auto& s : steps)
        for (const char* k : {"time_s_mean", "time_s_median", "time_s_p95", "stage_times_s_median"}) {
          REQUIRE(s.contains(k));
          s.erase(k);
        }
      return steps.dump();
    };
    const bool same_report = results(ra.out) == results(rb.out);
    CHECK(same_report);
  }
}

TEST_CASE("merge: a missing, repeated, foreign, unsharded or incomplete shard is one error naming it") {
  test::TempDir dir("shards");
  test::make_db(dir);
  const std::string names = run_shards(dir, 3);   // s3_1.h5 s3_2.h5 s3_3.h5
  auto refused = [&](const std::string& args, const std::string& file, const std::string& words) {
    CAPTURE(args);
    const auto r = touchstone(dir, "merge --out out.h5 " + args + " --quiet");   // progress lines aside
    CHECK(r.code != 0);
    CHECK_MESSAGE(r.err.find(words) != std::string::npos, r.err);
    CHECK_MESSAGE(r.err.find(file) != std::string::npos, r.err);
    CHECK(r.err.find('\n') == r.err.size() - 1);   // one line
    CHECK_FALSE(fs::exists(dir / "out.h5"));
    CHECK_FALSE(fs::exists(dir / "out.h5.runs"));
  };
  refused("s3_1.h5 s3_3.h5", "out.h5", "shard 2/3 is missing");
  {  // With progress (not a terminal: a line per store read), the error is still the last line.
    const auto r = touchstone(dir, "merge --out out.h5 s3_1.h5 s3_3.h5");
    CHECK(r.code != 0);
    CHECK_MESSAGE(r.err.find("merge: stores 2/3") != std::string::npos, r.err);
    CHECK(r.err.rfind("error: ") > r.err.rfind("merge: stores"));
    CHECK_FALSE(fs::exists(dir / "out.h5"));
  }
  refused("s3_1.h5 s3_2.h5 s3_2.h5 s3_3.h5", "s3_2.h5", "given twice");
  // Another configuration (seed) for shard 2: named, with the key.
  REQUIRE(touchstone(dir, "experiment --db db.h5 --objects box,nut,wedge --runs 3 --steps 3 --pool 5 --seed 4 "
                          "--set bricpsf.hypotheses=20 --set ransac.samples=5x40 --threads 1 --shard 2/3 --json "
                          "--out other2.h5").code == 0);
  refused("s3_1.h5 other2.h5 s3_3.h5", "other2.h5", "seed");
  // Shards of another split.
  REQUIRE(touchstone(dir, kExperiment + " --shard 2/2 --json --out half2.h5").code == 0);
  refused("s3_1.h5 half2.h5 s3_3.h5", "half2.h5", "split into 2");
  // A whole experiment is not a shard.
  REQUIRE(touchstone(dir, kExperiment + " --json --out whole.h5").code == 0);
  refused("s3_1.h5 whole.h5 s3_3.h5", "whole.h5", "not a shard store");
  // An incomplete shard: shard 2's header with one of its runs.
  {
    const auto c = io::RunStore::read(dir / "s3_2.h5");
    REQUIRE(c.runs.size() == 3);
    io::RunStore::create(dir / "part2.h5", c.header);
    io::RunStore::append(dir / "part2.h5", {c.runs.front()});
  }
  refused("s3_1.h5 part2.h5 s3_3.h5", "part2.h5", "incomplete: 1 of its 3 runs");
  // The output exists: refused, and left as it was.
  {
    std::ofstream(dir / "taken.h5") << "mine";
    const auto r = touchstone(dir, "merge --out taken.h5" + names);
    CHECK(r.code != 0);
    CHECK(r.err.find("already exists") != std::string::npos);
    CHECK(test::read_bytes(dir / "taken.h5") == "mine");
  }
  // The old form, output first: still merges, with a note naming the new form.
  {
    const auto r = touchstone(dir, "merge old.h5" + names + " --quiet");
    CHECK_MESSAGE(r.code == 0, r.err);
    CHECK_MESSAGE(r.err.find("old form; write `merge --out old.h5 SHARD...`") != std::string::npos, r.err);
    CHECK(io::RunStore::read(dir / "old.h5").runs.size() == 9);
    // A range of runs is --run-range A:B (--runs counts runs in experiment); --runs A:B, the old
    // spelling, is taken with a note; both, or a range the wrong way round, are one error.
    const auto all = touchstone(dir, "report --store old.h5 --json");
    const auto first = touchstone(dir, "report --store old.h5 --run-range 0:1 --json");
    REQUIRE_MESSAGE(first.code == 0, first.err);
    CHECK(nlohmann::json::parse(all.out)["per_step"][0]["runs"] == 9);
    CHECK(nlohmann::json::parse(first.out)["per_step"][0]["runs"] == 3);
    const auto old_spelling = touchstone(dir, "report old.h5 --runs 0:1 --json");
    REQUIRE_MESSAGE(old_spelling.code == 0, old_spelling.err);
    CHECK(old_spelling.out == first.out);
    CHECK_MESSAGE(old_spelling.err.find("write `--run-range 0:1`") != std::string::npos, old_spelling.err);
    CHECK(first.err.find("note:") == std::string::npos);
    const auto both = touchstone(dir, "report old.h5 --runs 0:1 --run-range 0:1");
    CHECK(both.code == 1);
    CHECK(both.err.find("--runs") != std::string::npos);
    const auto backwards = touchstone(dir, "report old.h5 --run-range 2:1");
    CHECK(backwards.code == 1);
    CHECK(backwards.err.find("--run-range") != std::string::npos);
    const auto alone = touchstone(dir, "merge s3_1.h5");   // one name and no --out: which is the output?
    CHECK(alone.code != 0);
    CHECK_MESSAGE(alone.err.find("--out") != std::string::npos, alone.err);
  }
  // A shard store resumed as another shard is refused, untouched.
  {
    const auto before = test::read_bytes(dir / "s3_1.h5");
    const auto r = touchstone(dir, kExperiment + " --shard 2/3 --resume --out s3_1.h5");
    CHECK(r.code != 0);
    CHECK_MESSAGE(r.err.find("holds shard 1/3, not shard 2/3") != std::string::npos, r.err);
    CHECK(test::read_bytes(dir / "s3_1.h5") == before);
  }
  // Bad --shard values: one error naming the flag.
  for (const std::string bad : {"0/3", "4/3", "3", "1/0", "a/b", "1/3x"}) {
    const auto r = touchstone(dir, kExperiment + " --shard " + bad + " --out bad.h5");
    CHECK(r.code != 0);
    CHECK_MESSAGE(r.err.find("--shard") != std::string::npos, r.err);
    CHECK_FALSE(fs::exists(dir / "bad.h5"));
  }
}

namespace {

// Open MPI refuses root without these flags; --oversubscribe lets 4 ranks share 2 cores.
const std::string kMpirun = "mpirun --allow-run-as-root --oversubscribe -n ";

}  // namespace

TEST_CASE("experiment --mpi: one rank, mpirun -n 2 and an oversubscribed -n 4 give one process's results" *
          doctest::skip(!ts::experiments::mpi_built())) {
  test::TempDir dir("mpi");
  test::make_db(dir);
  const auto whole = touchstone(dir, kExperiment + " --json --out whole.h5");
  REQUIRE_MESSAGE(whole.code == 0, whole.err);
  const io::RunStoreContents single = io::RunStore::read(dir / "whole.h5");
  for (const int ranks : {0, 2, 4}) {   // 0: started without mpirun (a singleton job)
    CAPTURE(ranks);
    const std::string out = "mpi" + std::to_string(ranks) + ".h5";
    const auto r = touchstone(dir, kExperiment + " --mpi --json --out " + out,
                              ranks ? kMpirun + std::to_string(ranks) : "");
    REQUIRE_MESSAGE(r.code == 0, r.err);
    const io::RunStoreContents c = io::RunStore::read(dir / out);
    CHECK(c.complete);
    check_same_results(single, c);
    CHECK_FALSE(fs::exists(dir / (out + ".ranks")));   // the rank stores were folded in and removed
  }
  // The paper's protocol (one grasp pool per object, shared by its runs): each rank simulates the
  // pools its runs need, the same pools one process simulates.
  {
    const std::string shared = kExperiment + " --set protocol=shared_pool --json";
    const auto one = touchstone(dir, shared + " --out shared.h5");
    REQUIRE_MESSAGE(one.code == 0, one.err);
    const auto r = touchstone(dir, shared + " --mpi --out shared_mpi.h5", kMpirun + "2");
    REQUIRE_MESSAGE(r.code == 0, r.err);
    check_same_results(io::RunStore::read(dir / "shared.h5"), io::RunStore::read(dir / "shared_mpi.h5"));
    // Two workers a rank: requests from two threads of a rank, pools simulated while the other
    // worker runs.
    std::string two = shared;
    two.replace(two.find("--threads 1"), 11, "--threads 2");
    const auto t = touchstone(dir, two + " --mpi --out shared_mpi2.h5", kMpirun + "2 --bind-to none");
    REQUIRE_MESSAGE(t.code == 0, t.err);
    check_same_results(io::RunStore::read(dir / "shared.h5"), io::RunStore::read(dir / "shared_mpi2.h5"));
  }
  // Ranks that disagree on the experiment (here another seed on rank 1, as another configuration
  // file under the same path on another node would): one error naming --out, before any run.
  {
    const std::string other = kExperiment.substr(0, kExperiment.find("--seed 3")) + "--seed 4" +
                              kExperiment.substr(kExperiment.find("--seed 3") + 8);
    const std::string program = "'" TS_BINARY_DIR "/touchstone' ";
    const std::string cmd = "cd '" + dir.path().string() + "' && " + kMpirun + "1 " + program + kExperiment +
                            " --mpi --out split.h5 : -n 1 " + program + other +
                            " --mpi --out split.h5 >split.out 2>split.err";
    const int status = std::system(cmd.c_str());
    CHECK((!WIFEXITED(status) || WEXITSTATUS(status) != 0));
    const std::string err = test::read_bytes(dir / "split.err");
    CHECK(err.find("disagree") != std::string::npos);
    CHECK(err.find("--out") != std::string::npos);
    CHECK_FALSE(fs::exists(dir / "split.h5"));
    CHECK_FALSE(fs::exists(dir / "split.h5.ranks"));
  }
  // --shard and --mpi together: one error naming --mpi, nothing written.
  const auto both = touchstone(dir, kExperiment + " --mpi --shard 1/2 --out both.h5");
  CHECK(both.code != 0);
  CHECK(both.err.find("--mpi") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "both.h5"));
}

TEST_CASE("experiment --mpi: a rank killed mid-run loses only its runs in flight; --resume completes the store" *
          doctest::skip(!ts::experiments::mpi_built())) {
  test::TempDir dir("mpi");
  test::make_db(dir);
  const std::string args =
      "experiment --db db.h5 --objects box,nut,wedge --runs 12 --steps 6 --pool 8 --seed 5 "
      "--set bricpsf.hypotheses=20 --set ransac.samples=5x40 --threads 1";
  const auto whole = touchstone(dir, args + " --json --out whole.h5");
  REQUIRE_MESSAGE(whole.code == 0, whole.err);
  const io::RunStoreContents single = io::RunStore::read(dir / "whole.h5");
  REQUIRE(single.runs.size() == 36);
  // Start the job in the background; once some runs are stored, kill -9 one rank.
  const std::string start = "cd '" + dir.path().string() + "' && (" + kMpirun + "2 '" TS_BINARY_DIR
                            "/touchstone' " + args + " --mpi --json --out killed.h5 >job.out 2>job.err; echo $? > job.rc) "
                            ">/dev/null 2>&1 &";
  REQUIRE(std::system(start.c_str()) == 0);
  auto stored = [&] {
    std::size_t n = 0;
    for (const auto& r : ts::experiments::rank_stores(dir / "killed.h5")) {
      try {
        n += io::RunStore::read(r).runs.size();
      } catch (const std::exception&) {   // a rank store being created
      }
    }
    return n;
  };
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (stored() < 4 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  // A rank's command line starts with the program's path (mpirun's and the shells' do not).
  const std::string kill = "pkill -9 -n -f '^[^ ]*/touchstone experiment .*--out killed[.]h5'";
  REQUIRE(std::system(kill.c_str()) == 0);
  while (!fs::exists(dir / "job.rc") && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  REQUIRE(fs::exists(dir / "job.rc"));
  const std::size_t kept = stored();
  INFO("runs stored when the job died: " << kept);
  // The runs finished before the kill, with their wall times (a run computed again has another):
  // the resumed store must hold them as they were.
  std::map<std::tuple<int, int, int>, double> finished;
  for (const auto& r : ts::experiments::rank_stores(dir / "killed.h5"))
    for (const auto& run : io::RunStore::read(r).runs) finished[{run.variant, run.object, run.run}] = run.wall_time_s;
  CHECK(finished.size() == kept);
  CHECK(kept >= 4);
  CHECK(kept < 36);   // killed mid-run, not after the end
  CHECK_FALSE(fs::exists(dir / "killed.h5"));   // never folded
  // The same command without --resume is refused; with it the job computes the rest only.
  const auto again = touchstone(dir, args + " --mpi --out killed.h5", kMpirun + "2");
  CHECK(again.code != 0);
  CHECK(again.err.find("--resume") != std::string::npos);
  const auto resumed = touchstone(dir, args + " --mpi --resume --json --out killed.h5", kMpirun + "2");
  REQUIRE_MESSAGE(resumed.code == 0, resumed.err);
  const io::RunStoreContents c = io::RunStore::read(dir / "killed.h5");
  CHECK(c.complete);
  check_same_results(single, c);
  std::size_t same = 0;
  for (const auto& run : c.runs)
    if (const auto it = finished.find({run.variant, run.object, run.run}); it != finished.end())
      same += same_bits(it->second, run.wall_time_s) ? 1 : 0;
  CHECK(same == finished.size());   // every finished run kept as it was
}
