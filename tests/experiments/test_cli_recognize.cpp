// `touchstone recognize` run as a user runs it: the JSON keys of the interface contract, the
// result file, identical outputs for any --threads, the --cloud mode with a ground-truth file,
// and clear errors for bad input.
#include "engine/fusion.hpp"
#include "engine/recognizer.hpp"
#include "io/cloud_io.hpp"
#include "io/db_store.hpp"
#include "io/log_store.hpp"
#include "io/result_store.hpp"
#include "engine/recognition_fixture.hpp"
#include "cli_run.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>

using namespace ts;
namespace fs = std::filesystem;

namespace {

using Run = ts::test::CliRun;
using ts::test::touchstone;

/// The engine tests' six analytic shapes written as a database file.
fs::path make_db(const test::TempDir& dir, const std::string& name = "db.h5",
                 std::vector<std::string> skip = {}) {
  auto src = test::make_source();
  std::vector<BuiltObject> objects;
  for (std::size_t i = 0; i < src->size(); ++i) {
    if (std::find(skip.begin(), skip.end(), src->infos[i].name) != skip.end()) continue;
    BuiltObject o;
    o.info = src->infos[i];
    o.info.source = "test";
    o.info.mesh_sha256 = std::string(64, '0');
    o.mesh = src->meshes[i];
    o.features = src->feats[i];
    o.fine = src->fines[i];
    o.field = src->load_field(i);
    objects.push_back(std::move(o));
  }
  std::vector<io::StoredObject> stored;
  for (const auto& o : objects) stored.push_back({&o, 1});
  const auto path = dir / name;
  io::write_database(path, stored, src->db_settings, 1);
  return path;
}

// Small method parameters: the tests check plumbing, determinism and errors, not accuracy.
const std::string kFast = " -N 6 -R 40 -W 800 --n-p 20 --icp-points 64";

bool finite_numbers(const nlohmann::json& j) {
  if (j.is_number_float()) return std::isfinite(j.get<double>());
  if (j.is_structured())
    for (const auto& x : j)
      if (!finite_numbers(x)) return false;
  return true;
}

}  // namespace

TEST_CASE("cli recognize: JSON per the interface, result file, identical for any --threads") {
  test::TempDir dir("cli_rec");
  make_db(dir);
  const Run sim = touchstone(dir, "simulate --db db.h5 --object wedge --grasps 6 --noise ideal --seed 4 --out log.h5");
  REQUIRE_MESSAGE(sim.code == 0, sim.err);

  const Run a = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --threads 1 --out r1.h5" + kFast);
  REQUIRE_MESSAGE(a.code == 0, a.err);
  const Run b = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --threads 2 --out r2.h5" + kFast);
  REQUIRE_MESSAGE(b.code == 0, b.err);
  CHECK(test::read_bytes(dir / "r1.h5") == test::read_bytes(dir / "r2.h5"));

  const auto ja = nlohmann::json::parse(a.out), jb = nlohmann::json::parse(b.out);
  CHECK(ja["method"] == "bricpsf");
  REQUIRE(ja["steps"].size() == 6);
  CHECK(finite_numbers(ja));
  for (std::size_t k = 0; k < 6; ++k) {
    const auto& s = ja["steps"][k];
    for (const char* key : {"step", "object", "weight", "posterior", "pose", "position_error_m",
                            "orientation_error_deg", "symmetric_orientation_error_deg", "time_s"})
      CHECK_MESSAGE(s.contains(key), key);
    CHECK(s["step"] == k + 1);
    if (!s["object"].is_null()) {
      CHECK(s["pose"]["t"].size() == 3);
      CHECK(s["pose"]["q"].size() == 4);
      CHECK(s["position_error_m"].is_number());  // the simulated log carries the truth
      CHECK(s["symmetric_orientation_error_deg"].get<double>() <= s["orientation_error_deg"].get<double>() + 1e-9);
    }
    // everything but the timings is the same with 2 threads
    auto x = s, y = jb["steps"][k];
    for (auto* j : {&x, &y}) {
      j->erase("time_s");
      j->erase("stages_s");
    }
    CHECK(x == y);
  }

  const io::ResultData res = io::read_result(dir / "r1.h5");
  CHECK(res.header.method == "bricpsf");
  CHECK(res.header.truth_object == "wedge");
  CHECK(res.steps.size() == 6);
  CHECK(res.steps.back().hypotheses.size() <= 20);
  CHECK(res.header.objects.size() == 6);

  // The result file's parameters that the presets and flags decide.
  auto check_params = [](const io::ResultData& r, std::map<std::string, double> expect) {
    for (const auto& [k, v] : r.header.params) {
      const auto it = expect.find(k);
      if (it == expect.end()) continue;
      CHECK_MESSAGE(v == it->second, k);
      expect.erase(it);
    }
    CHECK_MESSAGE(expect.empty(), "missing parameters");
  };
  CHECK(ja["preset"] == "improved");  // the default
  check_params(res, {{"W_per_object", 200.0}, {"refine_new", 1.0}, {"grasp_offset_sigma", 0.003}});

  SUBCASE("--preset paper, and a flag on top of a preset") {
    const Run p = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --steps 2 --preset paper --out rp.h5" + kFast);
    REQUIRE_MESSAGE(p.code == 0, p.err);
    CHECK(nlohmann::json::parse(p.out)["preset"] == "paper");
    check_params(io::read_result(dir / "rp.h5"),
                 {{"W_per_object", 0.0}, {"refine_new", 0.0}, {"dedupe", 0.0}, {"grasp_offset_sigma", 0.0}});
    const Run q = touchstone(dir, "recognize --db db.h5 --log log.h5 --steps 1 --prune-per-object 50 --no-dedupe "
                                  "--grasp-offset-sigma 0.005 --out rq.h5" + kFast);
    REQUIRE_MESSAGE(q.code == 0, q.err);
    check_params(io::read_result(dir / "rq.h5"),
                 {{"W_per_object", 50.0}, {"dedupe", 0.0}, {"grasp_offset_sigma", 0.005}, {"refine_new", 1.0}});
  }
  SUBCASE("--steps and --method") {
    const Run c = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --steps 2 --method batch-ransac" + kFast);
    REQUIRE_MESSAGE(c.code == 0, c.err);
    const auto jc = nlohmann::json::parse(c.out);
    CHECK(jc["method"] == "batch-ransac");
    CHECK(jc["steps"].size() == 2);
  }
  SUBCASE("human output") {
    const Run h = touchstone(dir, "recognize --db db.h5 --log log.h5 --steps 2" + kFast);
    REQUIRE(h.code == 0);
    CHECK(h.out.find("step") != std::string::npos);
    CHECK(h.out.find("bricpsf") != std::string::npos);
  }
}

TEST_CASE("cli recognize --cloud: one step, ground truth from a 4x4 file, nulls without it") {
  test::TempDir dir("cli_rec");
  make_db(dir);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object nut --grasps 6 --noise ideal --seed 2 --out log.h5").code == 0);
  REQUIRE(touchstone(dir, "log export log.h5 --out cloud.ply").code == 0);
  const TactileLog log = io::read_log(dir / "log.h5");
  const Pose T = log.truth->object_pose;
  {
    std::ofstream gt(dir / "T.txt");
    gt.precision(17);
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) gt << T.matrix()(r, c) << (c < 3 ? " " : "\n");
    }
  }
  const Run a = touchstone(dir, "recognize --db db.h5 --cloud cloud.ply --ground-truth T.txt --object nut --json" + kFast);
  REQUIRE_MESSAGE(a.code == 0, a.err);
  const auto j = nlohmann::json::parse(a.out);
  REQUIRE(j["steps"].size() == 1);
  CHECK(j["steps"][0]["position_error_m"].is_number());
  CHECK(j["steps"][0]["correct"].is_boolean());
  const Run b = touchstone(dir, "recognize --db db.h5 --cloud cloud.ply --json" + kFast);
  REQUIRE_MESSAGE(b.code == 0, b.err);
  const auto jb = nlohmann::json::parse(b.out);
  CHECK(jb["steps"][0]["position_error_m"].is_null());
  CHECK(jb["steps"][0]["orientation_error_deg"].is_null());
  CHECK(jb["steps"][0]["symmetric_orientation_error_deg"].is_null());
  CHECK(jb["steps"][0]["free_points"] == 0);
}

TEST_CASE("cli recognize: bad input gives one clear error and no output file") {
  test::TempDir dir("cli_rec");
  make_db(dir);
  make_db(dir, "small.h5", {"wedge"});
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 3 --noise ideal --out log.h5").code == 0);

  auto expect_error = [&](const std::string& args, const std::string& what) {
    const Run r = touchstone(dir, args);
    INFO(args);
    CHECK(r.code == 1);
    CHECK(r.err.rfind("touchstone: error: ", 0) == 0);
    CHECK_MESSAGE(r.err.find(what) != std::string::npos, r.err);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
    CHECK_FALSE(fs::exists(dir / "out.h5"));
  };
  expect_error("recognize --db db.h5 --log log.h5 --steps 4 --out out.h5", "exceeds the log's 3 grasps");
  expect_error("recognize --db small.h5 --log log.h5 --out out.h5", "is not in the database");

  {  // a log without grasps
    TactileLog empty = io::read_log(dir / "log.h5");
    auto w = io::LogWriter::create(dir / "empty.h5", io::header_of(empty));
    w.close();
    expect_error("recognize --db db.h5 --log empty.h5 --out out.h5", "no grasps");
  }
  {  // contacts in millimetres against a database in metres
    PointCloud mm = io::read_cloud([&] {
      REQUIRE(touchstone(dir, "log export log.h5 --out c.ply").code == 0);
      return dir / "c.ply";
    }());
    for (Vec3& p : mm.points) p *= 1000.0;
    io::write_cloud(dir / "mm.ply", mm);
    expect_error("recognize --db db.h5 --cloud mm.ply --out out.h5" + kFast, "same units");
  }
  {  // malformed ground truth
    test::write_text(dir / "bad.txt", "1 0 0 0\n0 1 0 0\n0 0 1 zero\n0 0 0 1\n");
    REQUIRE(touchstone(dir, "log export log.h5 --out c2.ply").code == 0);
    expect_error("recognize --db db.h5 --cloud c2.ply --ground-truth bad.txt --out out.h5", "bad.txt, line 3");
    test::write_text(dir / "short.txt", "1 0 0\n");
    expect_error("recognize --db db.h5 --cloud c2.ply --ground-truth short.txt", "16 numbers");
  }
  // usage errors exit 2
  CHECK(touchstone(dir, "recognize --db db.h5").code == 2);
  CHECK(touchstone(dir, "recognize --db db.h5 --log log.h5 --method nonsense").code == 2);
}
