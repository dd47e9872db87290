// `touchstone recognize` run as a user runs it: the JSON keys of the interface contract, the
// result file, identical outputs for any --threads, the --cloud mode with a ground-truth file,
// and clear errors for bad input.
#include "engine/recognition/recognizer.hpp"
#include "engine/recognition_fixture.hpp"
#include "engine/touch/fusion.hpp"
#include "experiments/analysis/calibration.hpp"
#include "experiments/analysis/scene.hpp"
#include "experiments/runs/recognition_engine.hpp"
#include "io/cloud_io.hpp"
#include "io/db_store.hpp"
#include "io/log_store.hpp"
#include "io/result_store.hpp"
#include "io/run_store.hpp"
#include "cli_run.hpp"
#include "db_fixture.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <tuple>

using namespace ts;
namespace fs = std::filesystem;

namespace {

using Run = ts::test::CliRun;
using ts::test::touchstone;

using ts::test::make_db;

// Small method parameters: the tests check plumbing, determinism and errors, not accuracy.
const std::string kFastFlags = " -N 6 -R 40 -W 800 --n-p 20 --icp-points 64";

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

  const Run a = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --threads 1 --out r1.h5" + kFastFlags);
  REQUIRE_MESSAGE(a.code == 0, a.err);
  const Run b = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --threads 2 --out r2.h5" + kFastFlags);
  REQUIRE_MESSAGE(b.code == 0, b.err);
  CHECK(test::read_bytes(dir / "r1.h5") == test::read_bytes(dir / "r2.h5"));

  const auto ja = nlohmann::json::parse(a.out), jb = nlohmann::json::parse(b.out);
  CHECK(ja["method"] == "bricpsf");
  REQUIRE(ja["steps"].size() == 6);
  CHECK(finite_numbers(ja));
  // The per-answer checks below run at least on the last step: six ideal grasps give an answer.
  REQUIRE_FALSE(ja["steps"][5]["object"].is_null());
  for (std::size_t k = 0; k < 6; ++k) {
    const auto& s = ja["steps"][k];
    for (const char* key : {"step", "object", "weight", "posterior", "pose", "position_error_m",
                            "orientation_error_deg", "symmetric_orientation_error_deg", "time_s"})
      CHECK_MESSAGE(s.contains(key), key);
    CHECK(s["step"] == k + 1);
    CHECK(s["observability"] == "contact_normals");   // tactile patches carry their normals
    // The step's pipeline: every stage of bricpsf either ran (with a time) or was left out (with
    // a reason); a 6-object database needs none of the large-database stages.
    REQUIRE(s["stages_ran"].is_array());
    REQUIRE(s["stages_skipped"].is_array());
    CHECK(s["stages_ran"].size() + s["stages_skipped"].size() == 15);
    CHECK(s["support"].is_null());   // support.mode off: none looked for
    CHECK(s["support_verdict"].is_null());
    for (const auto& name : s["stages_ran"]) CHECK(s["pipeline_s"][name.get<std::string>()].get<double>() >= 0.0);
    CHECK(s["pipeline_s"].size() == s["stages_ran"].size());
    std::set<std::string> skipped;
    for (const auto& g : s["stages_skipped"]) {
      CHECK_FALSE(g["reason"].get<std::string>().empty());
      skipped.insert(g["stage"].get<std::string>());
    }
    CHECK(skipped.count("shortlist") == 1);
    CHECK(skipped.count("pose_transfer") == 1);
    CHECK(skipped.count("survivors") == (k == 0 ? 1u : 0u));
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
      j->erase("pipeline_s");
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
  check_params(res, {{"ransac.prune_per_object", 200.0}, {"bricpsf.refine_new", 1.0}, {"evaluate.grasp_offset_sigma_m", 0.003},
                     {"ransac.object_draws", 100.0}, {"shortlist.objects", 16.0}, {"twins.rivals", 5.0}, {"ransac.prune_blocks", 8.0}});

  SUBCASE("--preset paper, and a flag on top of a preset") {
    const Run p = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --steps 2 --preset paper --out rp.h5" + kFastFlags);
    REQUIRE_MESSAGE(p.code == 0, p.err);
    CHECK(nlohmann::json::parse(p.out)["preset"] == "paper");
    check_params(io::read_result(dir / "rp.h5"),
                 {{"ransac.prune_per_object", 0.0}, {"bricpsf.refine_new", 0.0}, {"bricpsf.dedupe", 0.0}, {"evaluate.grasp_offset_sigma_m", 0.0},
                  {"ransac.object_draws", 0.0}, {"shortlist.objects", 0.0}, {"twins.rivals", 0.0}});
    const Run q = touchstone(dir, "recognize --db db.h5 --log log.h5 --steps 1 --prune-per-object 50 --no-dedupe "
                                  "--grasp-offset-sigma 0.005 --shortlist 3 --twins 0 --prune-blocks 2 --out rq.h5" + kFastFlags);
    REQUIRE_MESSAGE(q.code == 0, q.err);
    check_params(io::read_result(dir / "rq.h5"),
                 {{"ransac.prune_per_object", 50.0}, {"bricpsf.dedupe", 0.0}, {"evaluate.grasp_offset_sigma_m", 0.005}, {"bricpsf.refine_new", 1.0},
                  {"shortlist.objects", 3.0}, {"twins.rivals", 0.0}, {"ransac.prune_blocks", 2.0}, {"ransac.object_draws", 100.0}});
  }
  SUBCASE("--steps and --method") {
    const Run c = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --steps 2 --method batch-ransac" + kFastFlags);
    REQUIRE_MESSAGE(c.code == 0, c.err);
    const auto jc = nlohmann::json::parse(c.out);
    CHECK(jc["method"] == "batch-ransac");
    CHECK(jc["steps"].size() == 2);
  }
  SUBCASE("human output") {
    const Run h = touchstone(dir, "recognize --db db.h5 --log log.h5 --steps 2" + kFastFlags);
    REQUIRE(h.code == 0);
    CHECK(h.out.find("step") != std::string::npos);
    CHECK(h.out.find("bricpsf") != std::string::npos);
    CHECK(h.out.find("why ") == std::string::npos);   // no explanation unless asked
  }
  SUBCASE("--explain: the answer beside its best rival, the same answers") {
    const Run e = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --threads 1 --explain" + kFastFlags);
    REQUIRE_MESSAGE(e.code == 0, e.err);
    const auto je = nlohmann::json::parse(e.out);
    REQUIRE(je["steps"].size() == 6);
    for (std::size_t k = 0; k < 6; ++k) {
      const auto& s = je["steps"][k];
      CHECK_FALSE(ja["steps"][k].contains("explanation"));
      if (s["object"].is_null()) continue;
      auto x = s, y = ja["steps"][k];   // everything else as without --explain
      for (auto* j : {&x, &y})
        for (const char* key : {"time_s", "stages_s", "pipeline_s", "explanation"}) j->erase(key);
      CHECK(x == y);
      const auto& ex = s["explanation"];
      REQUIRE(ex["hypotheses"].is_array());
      REQUIRE(ex["hypotheses"].size() >= 1);
      const auto& ans = ex["hypotheses"][0];
      CHECK(ans["role"] == "answer");
      CHECK(ans["object"] == s["object"]);
      CHECK(ans["log_weight"].get<double>() == s["log_weight"].get<double>());
      const double terms = ans["contact_log_weight"].get<double>() + ans["free_log_weight"].get<double>() +
                           ans["floor_log_weight"].get<double>();
      CHECK(terms == doctest::Approx(ans["log_weight"].get<double>()).epsilon(1e-12));
      if (ex["hypotheses"].size() == 2) {
        CHECK(ex["hypotheses"][1]["role"] == "rival");
        CHECK(ex["hypotheses"][1]["object"] != s["object"]);
        CHECK(ex["hypotheses"][1]["log_weight"].get<double>() <= ans["log_weight"].get<double>() + 0.1);
        const std::string by = ex["decided_by"].get<std::string>();
        CHECK((by == "contacts" || by == "free_space" || by == "near_twin"));
      }
    }
    const Run t = touchstone(dir, "recognize --db db.h5 --log log.h5 --threads 1 --explain" + kFastFlags);
    REQUIRE_MESSAGE(t.code == 0, t.err);
    const std::string answer = je["steps"][5]["object"].get<std::string>();
    CHECK_MESSAGE(t.out.find("why " + answer) != std::string::npos, t.out);
    CHECK(t.out.find("ln wt (Eq. 6)") != std::string::npos);
    const bool said = t.out.find("decided by") != std::string::npos || t.out.find("(no rival)") != std::string::npos;
    CHECK(said);
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
  const Run a = touchstone(dir, "recognize --db db.h5 --cloud cloud.ply --ground-truth T.txt --object nut --json" + kFastFlags);
  REQUIRE_MESSAGE(a.code == 0, a.err);
  const auto j = nlohmann::json::parse(a.out);
  REQUIRE(j["steps"].size() == 1);
  CHECK(j["steps"][0]["position_error_m"].is_number());
  CHECK(j["steps"][0]["correct"].is_boolean());
  const Run b = touchstone(dir, "recognize --db db.h5 --cloud cloud.ply --json" + kFastFlags);
  REQUIRE_MESSAGE(b.code == 0, b.err);
  const auto jb = nlohmann::json::parse(b.out);
  CHECK(jb["steps"][0]["position_error_m"].is_null());
  CHECK(jb["steps"][0]["orientation_error_deg"].is_null());
  CHECK(jb["steps"][0]["symmetric_orientation_error_deg"].is_null());
  CHECK(jb["steps"][0]["free_points"] == 0);
  CHECK(jb["steps"][0]["reason"].is_null());   // an object was named

  // Fewer than 3 distinct points (four readings of two spots): no answer, and why, exit 0.
  PointCloud two;
  two.points = {Vec3(0.1, 0.2, 0.3), Vec3(0.12, 0.2, 0.3), Vec3(0.1, 0.2, 0.3), Vec3(0.12, 0.2, 0.3)};
  io::write_cloud(dir / "two.ply", two);
  const Run t = touchstone(dir, "recognize --db db.h5 --cloud two.ply --json" + kFastFlags);
  REQUIRE_MESSAGE(t.code == 0, t.err);
  const auto jt = nlohmann::json::parse(t.out);
  CHECK(jt["steps"][0]["object"].is_null());
  CHECK(jt["steps"][0]["reason"] == "not_enough_contacts");
  CHECK(jt["steps"][0]["reason_detail"] == "fewer than 3 distinct contacts (2)");
  const Run tt = touchstone(dir, "recognize --db db.h5 --cloud two.ply" + kFastFlags);
  REQUIRE_MESSAGE(tt.code == 0, tt.err);
  CHECK_MESSAGE(tt.out.find("no answer: fewer than 3 distinct contacts (2); a pose needs at least 3") != std::string::npos,
                tt.out);
  CHECK(tt.out.find("unobservable") == std::string::npos);   // not the pose's ambiguity: there is no pose
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
  {  // a log of an object outside the database (the open set) is recognized, and scored wrong
    const Run r = touchstone(dir, "recognize --db small.h5 --log log.h5 --json" + kFastFlags);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    const auto j = nlohmann::json::parse(r.out);
    CHECK(j["truth_object"] == "wedge");
    CHECK(j["truth_in_database"] == false);
    for (const auto& st : j["steps"]) CHECK(st["correct"] == st["object"].is_null());
    CHECK(j["steps"][0]["confidence"].is_null());   // no --calibration
  }
  expect_error("recognize --db db.h5 --log log.h5 --calibration missing.json --out out.h5", "missing.json");

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
    expect_error("recognize --db db.h5 --cloud mm.ply --out out.h5" + kFastFlags, "same units");
  }
  {  // malformed ground truth
    test::write_text(dir / "bad.txt", "1 0 0 0\n0 1 0 0\n0 0 1 zero\n0 0 0 1\n");
    REQUIRE(touchstone(dir, "log export log.h5 --out c2.ply").code == 0);
    expect_error("recognize --db db.h5 --cloud c2.ply --ground-truth bad.txt --out out.h5", "bad.txt, line 3");
    test::write_text(dir / "short.txt", "1 0 0\n");
    expect_error("recognize --db db.h5 --cloud c2.ply --ground-truth short.txt", "16 numbers");
  }
  // a memory budget that cannot hold the largest object's geometry
  expect_error("recognize --db db.h5 --log log.h5 --memory-budget 0.01 --out out.h5" + kFastFlags,
               "cannot hold one object");
  expect_error("recognize --db db.h5 --log log.h5 --memory-budget 0.01 --out out.h5" + kFastFlags,
               "(db.h5, --memory-budget)");
  {  // a database truncated mid-object
    const auto size = fs::file_size(dir / "db.h5");
    fs::copy_file(dir / "db.h5", dir / "cut.h5");
    fs::resize_file(dir / "cut.h5", size * 2 / 3);
    expect_error("recognize --db cut.h5 --log log.h5 --out out.h5" + kFastFlags, "cut.h5");
  }
  // a budget that holds the largest object and little more: the same answer as no limit
  // (eviction changes nothing)
  {
    const Run refused = touchstone(dir, "recognize --db db.h5 --log log.h5 --memory-budget 0.01" + kFastFlags);
    // "... needs N MB ...": N (std::regex would double this file's compile time)
    const auto at = refused.err.find("needs ");
    REQUIRE_MESSAGE(at != std::string::npos, refused.err);
    std::size_t digits = 0;
    const double needs_mb = std::stod(refused.err.substr(at + 6), &digits);
    REQUIRE(refused.err.compare(at + 6 + digits, 3, " MB") == 0);
    const std::string budget = std::to_string(1.3 * needs_mb);
    const Run small = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --memory-budget " + budget + kFastFlags);
    const Run none = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --memory-budget 0" + kFastFlags);
    REQUIRE_MESSAGE(small.code == 0, small.err);
    REQUIRE_MESSAGE(none.code == 0, none.err);
    auto strip = [](nlohmann::json j) {
      for (auto& st : j["steps"])
        for (const char* k : {"time_s", "stages_s", "pipeline_s", "geometry_loads", "geometry_resident"}) st.erase(k);
      return j;
    };
    const auto js = nlohmann::json::parse(small.out), jn = nlohmann::json::parse(none.out);
    CHECK(strip(js)["steps"] == strip(jn)["steps"]);
    // and the small budget did evict: objects were loaded again
    CHECK(js["steps"].back()["geometry_loads"].get<int>() > jn["steps"].back()["geometry_loads"].get<int>());
    CHECK(js["steps"].back()["geometry_resident"].get<int>() < jn["steps"].back()["geometry_resident"].get<int>());
  }
  // usage errors exit 2
  CHECK(touchstone(dir, "recognize --db db.h5").code == 2);
  CHECK(touchstone(dir, "recognize --db db.h5 --log log.h5 --method nonsense").code == 2);
  // An unknown flag: one line naming it, its command and the nearest valid flag; before any
  // other usage error (a misspelt --db is named, not "--db is required").
  for (const auto& [args, flag, nearest] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"recognize --db db.h5 --lgo log.h5", "--lgo", "--log"},
           {"recognize --dbb db.h5 --log log.h5", "--dbb", "--db"},
           {"recognize --db=db.h5 --log log.h5 --sparse.mdoe=always", "--sparse.mdoe", "--sparse.mode"},
           {"db info --db db.h5 --jsno", "--jsno", "--json"},
           {"--versoin", "--versoin", "--version"}}) {
    CAPTURE(args);
    const auto r = touchstone(dir, args);
    CHECK(r.code == 2);
    CHECK(r.err.find("unknown flag " + flag + " for `touchstone") != std::string::npos);
    CHECK(r.err.find("(did you mean " + nearest + "?)") != std::string::npos);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
  }
  const auto far = touchstone(dir, "recognize --db db.h5 --log log.h5 --zzzzzzzz");
  CHECK(far.code == 2);
  CHECK(far.err.find("unknown flag --zzzzzzzz for `touchstone recognize`; `touchstone recognize --help` lists") !=
        std::string::npos);
  CHECK(far.err.find("did you mean") == std::string::npos);
  // Known flags in every form pass the check: --flag=value, a hidden alias (`report --runs`),
  // an option group's (`db build --manifest`), and what follows `--`.
  CHECK(touchstone(dir, "recognize --db=db.h5 --log=log.h5 --steps 1 --json").code == 0);
  CHECK(touchstone(dir, "db info db.h5 --json").code == 0);
  for (const char* args : {"report --store missing.h5 --runs 0:1", "db build --manifest missing.tsv --out x.h5",
                           "recognize --db db.h5 --log missing.h5 -- --not-a-flag"}) {
    CAPTURE(args);
    const auto r = touchstone(dir, args);
    CHECK(r.err.find("unknown flag") == std::string::npos);
    CHECK(r.code != 0);   // (the files are missing)
  }
  // A hidden alias is taken but never suggested: `--run` suggests --run-range, not --runs.
  const auto near_hidden = touchstone(dir, "report --store missing.h5 --run 0:1");
  CHECK(near_hidden.err.find("(did you mean --run-range?)") != std::string::npos);
  // A misspelt subcommand is CLI11's to name, not the flags after it.
  const auto misspelt = touchstone(dir, "recognise --db db.h5");
  CHECK(misspelt.code == 2);
  CHECK(misspelt.err.find("unknown flag") == std::string::npos);
}

// ---- several inputs in one process ------------------------------------------------------------

namespace {

/// A recognize JSON object without the timings (which differ from run to run).
nlohmann::json without_times(nlohmann::json j) {
  for (auto& s : j["steps"]) {
    s.erase("time_s");
    s.erase("stages_s");
    s.erase("pipeline_s");
  }
  return j;
}

/// What a batch entry must equal: the per-input fields of a single-input run's JSON.
nlohmann::json input_fields(const nlohmann::json& single) {
  nlohmann::json j;
  for (const char* key : {"method", "preset", "steps", "input", "truth_object", "truth_in_database"})
    j[key] = single.at(key);
  return without_times(j);
}

/// `recognize` on one input alone (the oracle of the batch tests); its JSON.
nlohmann::json alone(const test::TempDir& dir, const std::string& args) {
  const Run r = touchstone(dir, "recognize --json " + args + kFastFlags);
  REQUIRE_MESSAGE(r.code == 0, r.err);
  return nlohmann::json::parse(r.out);
}

/// Each batch entry equals its input's run alone, in input order.
void check_entries(const nlohmann::json& batch, const std::vector<nlohmann::json>& singles) {
  REQUIRE(batch["inputs"].size() == singles.size());
  for (std::size_t i = 0; i < singles.size(); ++i) {
    INFO("input " << i << ": " << singles[i]["input"]);
    CHECK(without_times(batch["inputs"][i]) == input_fields(singles[i]));
  }
  for (const char* key : {"database", "seed", "params"}) CHECK_MESSAGE(batch[key] == singles[0][key], key);
}

}  // namespace

TEST_CASE("cli recognize, several logs: each input's steps and result file as alone, for any --threads") {
  test::TempDir dir("cli_batch");
  make_db(dir);
  const std::vector<std::pair<std::string, std::string>> objects = {{"wedge", "4"}, {"nut", "2"}, {"box", "7"}};
  std::string list;
  std::vector<nlohmann::json> singles;
  for (const auto& [object, seed] : objects) {
    const Run sim = touchstone(dir, "simulate --db db.h5 --object " + object + " --grasps 3 --noise ideal --seed " +
                                        seed + " --out " + object + ".h5");
    REQUIRE_MESSAGE(sim.code == 0, sim.err);
    list += " " + object + ".h5";
    singles.push_back(alone(dir, "--db db.h5 --log " + object + ".h5 --threads 2 --out " + object + "_alone.h5"));
    CHECK(singles.back()["steps"].size() == 3);
  }
  // the inputs differ, so a mix-up of inputs cannot pass unnoticed
  CHECK(singles[0]["truth_object"] != singles[1]["truth_object"]);

  const Run one = touchstone(dir, "recognize --db db.h5 --json --threads 1 --out r1 --log" + list + kFastFlags);
  REQUIRE_MESSAGE(one.code == 0, one.err);
  const Run two = touchstone(dir, "recognize --db db.h5 --json --threads 2 --out r2 --log" + list + kFastFlags);
  REQUIRE_MESSAGE(two.code == 0, two.err);
  const auto j1 = nlohmann::json::parse(one.out), j2 = nlohmann::json::parse(two.out);
  CHECK(j1["threads"] == 1);
  CHECK(j2["threads"] == 2);
  check_entries(j1, singles);
  check_entries(j2, singles);
  for (const auto& [object, seed] : objects) {
    INFO(object);
    // the result files are byte for byte those of the runs alone (header, every hypothesis)
    const std::string bytes = test::read_bytes(dir / (object + "_alone.h5"));
    REQUIRE_FALSE(bytes.empty());
    CHECK(test::read_bytes(dir / "r1" / (object + ".h5")) == bytes);
    CHECK(test::read_bytes(dir / "r2" / (object + ".h5")) == bytes);
  }
  CHECK(std::distance(fs::directory_iterator(dir / "r1"), fs::directory_iterator{}) == 3);

  SUBCASE("human output: each input's table in input order under its name") {
    const Run h = touchstone(dir, "recognize --db db.h5 --log" + list + kFastFlags);
    REQUIRE_MESSAGE(h.code == 0, h.err);
    const auto a = h.out.find("input wedge.h5 (object wedge)"), b = h.out.find("input nut.h5 (object nut)"),
               c = h.out.find("input box.h5 (object box)");
    CHECK(h.out.rfind("method bricpsf, 6 objects, 3 inputs\n", 0) == 0);
    REQUIRE(a != std::string::npos);
    REQUIRE(b != std::string::npos);
    REQUIRE(c != std::string::npos);
    CHECK(a < b);
    CHECK(b < c);
    CHECK(std::count(h.out.begin(), h.out.end(), '\n') >= 3 * 5);  // header + table of 3 steps each
  }
}

TEST_CASE("cli recognize --cloud DIR/: every .ply/.pcd file of the folder, in name order") {
  test::TempDir dir("cli_batch");
  make_db(dir);
  fs::create_directories(dir / "clouds");
  // written out of name order; one more file that is no cloud
  const std::vector<std::pair<std::string, std::string>> made = {
      {"nut", "c.ply"}, {"wedge", "a.pcd"}, {"ball", "b.ply"}};
  for (const auto& [object, file] : made) {
    REQUIRE(touchstone(dir, "simulate --db db.h5 --object " + object + " --grasps 3 --noise ideal --out " + object + ".h5").code == 0);
    REQUIRE(touchstone(dir, "log export " + object + ".h5 --out clouds/" + file).code == 0);
  }
  test::write_text(dir / "clouds" / "notes.txt", "not a cloud\n");

  std::vector<nlohmann::json> singles;
  for (const char* file : {"a.pcd", "b.ply", "c.ply"})
    singles.push_back(alone(dir, "--db db.h5 --cloud clouds/" + std::string(file)));
  const Run r = touchstone(dir, "recognize --db db.h5 --cloud clouds/ --json --threads 2" + kFastFlags);
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const auto j = nlohmann::json::parse(r.out);
  REQUIRE(j["inputs"].size() == 3);
  CHECK(j["inputs"][0]["input"] == "clouds/a.pcd");
  CHECK(j["inputs"][1]["input"] == "clouds/b.ply");
  CHECK(j["inputs"][2]["input"] == "clouds/c.ply");
  check_entries(j, singles);

  // a folder alone is several inputs even with one file in it (the output keeps one shape)
  fs::create_directories(dir / "one");
  fs::copy_file(dir / "clouds" / "b.ply", dir / "one" / "b.ply");
  const Run o = touchstone(dir, "recognize --db db.h5 --cloud one --json" + kFastFlags);
  REQUIRE_MESSAGE(o.code == 0, o.err);
  check_entries(nlohmann::json::parse(o.out), {alone(dir, "--db db.h5 --cloud one/b.ply")});
  // an empty folder is an error
  fs::create_directories(dir / "empty");
  const Run e = touchstone(dir, "recognize --db db.h5 --cloud empty" + kFastFlags);
  CHECK(e.code == 1);
  CHECK_MESSAGE(e.err.find("no .ply or .pcd file (empty, --cloud)") != std::string::npos, e.err);
}

TEST_CASE("cli recognize, several logs: broken inputs are reported, the others still recognized") {
  test::TempDir dir("cli_batch");
  make_db(dir);
  make_db(dir, "small.h5", {"wedge"});
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object nut --grasps 3 --noise ideal --seed 2 --out nut.h5").code == 0);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object box --grasps 3 --noise ideal --seed 3 --out box.h5").code == 0);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 3 --noise ideal --out wedge.h5").code == 0);
  test::write_text(dir / "junk.h5", "this is not an HDF5 file\n");
  const std::string log = test::read_bytes(dir / "nut.h5");
  test::write_text(dir / "cut.h5", log.substr(0, log.size() / 2));  // truncated

  const std::vector<nlohmann::json> singles = {
      alone(dir, "--db small.h5 --log nut.h5 --out nut_alone.h5"),
      alone(dir, "--db small.h5 --log box.h5 --out box_alone.h5")};
  // inputs: good, not HDF5, good, truncated, object not in the database (recognized: open set)
  const Run r = touchstone(dir, "recognize --db small.h5 --log nut.h5 junk.h5 box.h5 cut.h5 wedge.h5 --json --out res" + kFastFlags);
  CHECK(r.code == 1);
  const auto j = nlohmann::json::parse(r.out);  // the JSON is complete all the same
  REQUIRE(j["inputs"].size() == 5);
  CHECK(without_times(j["inputs"][0]) == input_fields(singles[0]));
  CHECK(without_times(j["inputs"][2]) == input_fields(singles[1]));
  const std::vector<std::pair<std::size_t, std::string>> broken = {{1, "junk.h5"}, {3, "cut.h5"}};
  for (const auto& [i, names] : broken) {
    const auto& entry = j["inputs"][i];
    INFO(entry.dump());
    CHECK_FALSE(entry.contains("steps"));
    REQUIRE(entry["error"].is_string());
    CHECK(entry["error"].get<std::string>().find(names) != std::string::npos);
  }
  CHECK(j["inputs"][4]["truth_in_database"] == false);
  CHECK(j["inputs"][4].contains("steps"));
  // stderr: one line per broken input, naming it, in input order
  std::vector<std::string> lines;
  for (std::size_t at = 0, nl; (nl = r.err.find('\n', at)) != std::string::npos; at = nl + 1)
    lines.push_back(r.err.substr(at, nl - at));
  REQUIRE(lines.size() == 2);
  for (std::size_t k = 0; k < 2; ++k) {
    INFO(lines[k]);
    CHECK(lines[k].rfind("touchstone: error: ", 0) == 0);
    CHECK(lines[k].find(broken[k].second) != std::string::npos);
  }
  // the results of the good inputs, as alone; nothing else (no partial or temporary files)
  CHECK(test::read_bytes(dir / "res" / "nut.h5") == test::read_bytes(dir / "nut_alone.h5"));
  CHECK(test::read_bytes(dir / "res" / "box.h5") == test::read_bytes(dir / "box_alone.h5"));
  CHECK(fs::exists(dir / "res" / "wedge.h5"));
  CHECK(std::distance(fs::directory_iterator(dir / "res"), fs::directory_iterator{}) == 3);
}

TEST_CASE("cli recognize, several inputs: refusals before any work") {
  test::TempDir dir("cli_batch");
  make_db(dir);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object nut --grasps 2 --noise ideal --out a.h5").code == 0);
  fs::create_directories(dir / "sub");
  fs::copy_file(dir / "a.h5", dir / "sub" / "a.h5");
  REQUIRE(touchstone(dir, "log export a.h5 --out a.ply").code == 0);
  test::write_text(dir / "junk_db.h5", "not a database\n");  // any work would fail on it first

  {  // two inputs with one stem and --out DIR
    for (const std::string inputs : {"--log a.h5 sub/a.h5", "--cloud a.ply sub/../a.ply"}) {
      const Run r = touchstone(dir, "recognize --db junk_db.h5 " + inputs + " --out res");
      INFO(inputs);
      CHECK(r.code == 1);
      CHECK_MESSAGE(r.err.find("share the name 'a'") != std::string::npos, r.err);
      CHECK(r.err.find("res, --out") != std::string::npos);
      CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
      CHECK(r.out.empty());
      CHECK_FALSE(fs::exists(dir / "res"));
    }
    // without --out the same stems are fine (the database error shows the work started)
    const Run r = touchstone(dir, "recognize --db junk_db.h5 --log a.h5 sub/a.h5");
    CHECK(r.code == 1);
    CHECK(r.err.find("share the name") == std::string::npos);
    CHECK(r.err.find("junk_db.h5") != std::string::npos);
  }
  {  // --out DIR that is a file, or that would replace an input
    test::write_text(dir / "taken", "x");
    const Run f = touchstone(dir, "recognize --db junk_db.h5 --log a.h5 sub/a.h5 --out taken");
    CHECK(f.code == 1);
    CHECK(f.err.find("takes a folder") != std::string::npos);
    REQUIRE(touchstone(dir, "simulate --db db.h5 --object box --grasps 2 --noise ideal --out sub/b.h5").code == 0);
    const std::string before = test::read_bytes(dir / "sub" / "b.h5");
    const Run g = touchstone(dir, "recognize --db junk_db.h5 --log a.h5 sub/b.h5 --out sub");
    CHECK(g.code == 1);
    CHECK_MESSAGE(g.err.find("would replace the input") != std::string::npos, g.err);
    CHECK(test::read_bytes(dir / "sub" / "b.h5") == before);
  }
  {  // --object and --ground-truth take a single input
    test::write_text(dir / "T.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
    for (const std::string args : {"--log a.h5 sub/a.h5 --object nut", "--cloud a.ply sub --ground-truth T.txt",
                                   "--cloud sub --object nut"}) {
      const Run r = touchstone(dir, "recognize --db junk_db.h5 " + args);
      INFO(args);
      CHECK(r.code == 2);  // a usage error
      CHECK_MESSAGE(r.err.find("takes a single input") != std::string::npos, r.err);
      CHECK(r.out.empty());
    }
  }
}

TEST_CASE("cli recognize: each answer's class of congruent objects, and whether it lies in the true object's class") {
  test::TempDir dir("cli_rec");
  const auto db = make_db(dir);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 4 --noise ideal --seed 4 --out log.h5").code == 0);
  // No classes recorded: each answer is its own class.
  const Run plain = touchstone(dir, "recognize --db db.h5 --log log.h5 --json" + kFastFlags);
  REQUIRE_MESSAGE(plain.code == 0, plain.err);
  const auto jp = nlohmann::json::parse(plain.out);
  CHECK(jp["congruent_classes_known"] == false);
  for (const auto& s : jp["steps"]) {
    if (s["object"].is_null()) continue;
    CHECK(s["object_class"] == nlohmann::json::array({s["object"]}));
    CHECK(s["correct_class"] == s["correct"]);
  }
  // A record that declares wedge congruent with every other object: every answer is right by
  // class, and names the whole database as its class.
  io::CongruenceRecord rec;
  std::size_t n = 0, wedge = 0;
  {
    io::DbReader reader(db);
    n = reader.size();
    wedge = reader.find("wedge");
  }
  rec.signatures.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    if (i != wedge) rec.pairs.push_back({static_cast<std::uint32_t>(std::min(i, wedge)), static_cast<std::uint32_t>(std::max(i, wedge))});
  std::sort(rec.pairs.begin(), rec.pairs.end(), [](const auto& x, const auto& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; });
  io::write_congruence(db, rec);
  const Run twin = touchstone(dir, "recognize --db db.h5 --log log.h5 --json" + kFastFlags);
  REQUIRE_MESSAGE(twin.code == 0, twin.err);
  const auto jt = nlohmann::json::parse(twin.out);
  CHECK(jt["congruent_classes_known"] == true);
  REQUIRE_FALSE(jt["steps"].back()["object"].is_null());
  for (const auto& s : jt["steps"]) {
    if (s["object"].is_null()) continue;
    CHECK(s["object_class"].size() == n);
    CHECK(s["correct_class"] == true);
  }
}

TEST_CASE("cli probe: simulate --sensing probe, recognize the log, --only, --cloud with --free") {
  test::TempDir dir("cli_probe");
  make_db(dir);
  const Run sim = touchstone(dir, "simulate --db db.h5 --object wedge --grasps 24 --sensing probe --noise ideal "
                                  "--contact-sigma 0.0005 --quantization 0.001 --seed 4 --out probe.h5 --json");
  REQUIRE_MESSAGE(sim.code == 0, sim.err);
  CHECK(nlohmann::json::parse(sim.out)["sensing"] == "probe");
  const Run info = touchstone(dir, "log info probe.h5 --json");
  REQUIRE(info.code == 0);
  const auto ji = nlohmann::json::parse(info.out);
  CHECK(ji["sensing"] == "probe");
  CHECK(ji["grasps"] == 24);
  for (const auto& n : ji["contacts_per_grasp"]) CHECK(n.get<int>() <= 1);

  // The log among the six objects, and the wedge alone (localization of a known object).
  for (const std::string only : {"", " --only wedge", " --only wedge,nut"}) {
    INFO(only);
    const Run r = touchstone(dir, "recognize --db db.h5 --log probe.h5 --json" + only + kFastFlags);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    const auto j = nlohmann::json::parse(r.out);
    REQUIRE(j["steps"].size() == 24);
    const auto& last = j["steps"][23];
    // The feature-free source proposes the probe's poses; once the leader alone explains every
    // contact, the early stop (the improved preset) leaves it out with that reason.
    int sparse_steps = 0;
    for (const auto& s : j["steps"]) {
      if (s["sparse_candidates"].get<int>() > 0) {
        ++sparse_steps;
        continue;
      }
      bool early = false;
      for (const auto& k : s["stages_skipped"])
        early = early || (k["stage"] == "sparse" && k["reason"].get<std::string>().starts_with("early stop"));
      CHECK((early || s["sparse_active"] == true || s["contacts"].get<int>() < 3));
    }
    CHECK(sparse_steps > 0);
    CHECK(last["object"] == "wedge");
    REQUIRE(last["contact_model_distance_m"].is_number());
    // 0.5 mm contact noise and 1 mm quantization: the contacts lie about a millimetre from the
    // surface at the right pose, centimetres at a wrong one.
    CHECK(last["contact_model_distance_m"].get<double>() < 0.0015);
    CHECK(last["position_error_m"].get<double>() < 0.005);
    CHECK(j["steps"][0]["contact_model_distance_m"].is_null());   // one contact: no answer yet
    if (!only.empty())
      for (const auto& s : j["steps"])
        if (!s["object"].is_null()) CHECK((s["object"] == "wedge" || (only.size() > 13 && s["object"] == "nut")));
  }

  // The same touches as a plain contact cloud (with normals) and a free-space cloud.
  REQUIRE(touchstone(dir, "log export probe.h5 --out contacts.ply --free free.ply").code == 0);
  const Run c = touchstone(dir, "recognize --db db.h5 --cloud contacts.ply --free free.ply --d-thresh 0.0001 "
                                "--free-inside-margin 0.01 --only wedge --json" + kFastFlags);
  REQUIRE_MESSAGE(c.code == 0, c.err);
  const auto jc = nlohmann::json::parse(c.out);
  CHECK(jc["steps"][0]["free_points"].get<int>() > 50);
  CHECK(jc["steps"][0]["object"] == "wedge");
  CHECK(jc["steps"][0]["contact_model_distance_m"].get<double>() < 0.0015);

  // Bad input: one clear error.
  const Run bad = touchstone(dir, "recognize --db db.h5 --log probe.h5 --only wedge,teapot --json" + kFastFlags);
  CHECK(bad.code == 1);
  CHECK(bad.err.find("no object 'teapot'") != std::string::npos);
  CHECK(bad.err.find("--only") != std::string::npos);
  CHECK(touchstone(dir, "recognize --db db.h5 --log probe.h5 --free free.ply").code == 2);   // --free needs --cloud
  CHECK(touchstone(dir, "recognize --db db.h5 --cloud contacts.ply --free missing.ply").code == 2);
  CHECK(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 3 --sensing taxels --out x.h5").code == 2);
  CHECK_FALSE(fs::exists(dir / "x.h5"));
}

TEST_CASE("cli fingertips: simulate --sensing fingertips, recognize the log and its points-only cloud, --only") {
  test::TempDir dir("cli_tips");
  make_db(dir);
  const Run sim = touchstone(dir, "simulate --db db.h5 --object wedge --grasps 20 --sensing fingertips --noise ideal "
                                  "--fingertips.quantization-m 0.001 --seed 3 --out tips.h5 --json");
  REQUIRE_MESSAGE(sim.code == 0, sim.err);
  CHECK(nlohmann::json::parse(sim.out)["sensing"] == "fingertips");
  const Run info = touchstone(dir, "log info tips.h5 --json");
  REQUIRE(info.code == 0);
  const auto ji = nlohmann::json::parse(info.out);
  CHECK(ji["sensing"] == "fingertips");
  CHECK(ji["fingertip_normals"] == false);
  int contacts = 0;
  for (const auto& n : ji["contacts_per_grasp"]) {
    CHECK(n.get<int>() <= 3);   // one per fingertip of the three-finger hand
    contacts += n.get<int>();
  }
  CHECK(contacts >= 20);
  for (const std::string only : {"", " --only wedge"}) {
    INFO(only);
    // (The default sampling: kFastFlags' finds a flipped wedge that fits these contacts within
    // 0.7 mm, 5 mm off.)
    const Run r = touchstone(dir, "recognize --db db.h5 --log tips.h5 --json" + only);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    const auto j = nlohmann::json::parse(r.out);
    const auto& last = j["steps"].back();
    CHECK(last["object"] == "wedge");
    // 1 mm rounding, no other noise: the contacts lie within a millimetre of the surface.
    REQUIRE(last["contact_model_distance_m"].is_number());
    CHECK(last["contact_model_distance_m"].get<double>() < 0.001);
    CHECK(last["position_error_m"].get<double>() < 0.002);
  }
  // The same contacts as a cloud of points without normals (a recording's points): an answer
  // and a pose.
  REQUIRE(touchstone(dir, "log export tips.h5 --out points.ply").code == 0);
  const Run c = touchstone(dir, "recognize --db db.h5 --cloud points.ply --json");
  REQUIRE_MESSAGE(c.code == 0, c.err);
  const auto jc = nlohmann::json::parse(c.out);
  CHECK(jc["steps"][0]["object"] == "wedge");
  CHECK(jc["steps"][0]["contact_model_distance_m"].get<double>() < 0.001);
  // An experiment on fingertips, each run localizing its own object (database = each), under
  // the shared pool (the pool stays a fingertip log).
  const Run e = touchstone(dir, "experiment --db db.h5 --objects wedge,nut --runs 1 --steps 6 --pool 6 --set sensing=fingertips "
                                "--set database=each --set protocol=shared_pool --json --out each.h5");
  REQUIRE_MESSAGE(e.code == 0, e.err);
  const Run rep = touchstone(dir, "report each.h5 --json");
  REQUIRE_MESSAGE(rep.code == 0, rep.err);
  const auto per_step = nlohmann::json::parse(rep.out)["per_step"];
  REQUIRE(per_step.size() == 6);
  CHECK(per_step.back()["contact_distance_m_median"].get<double>() < 0.003);
  for (const auto& run : io::RunStore::read(dir / "each.h5").runs)
    for (const auto& st : run.steps)
      if (st.best_object >= 0) CHECK(st.correct);   // it may name nothing else
  // Each object alone has no rival to rank: no answer sets from such runs, and why.
  const Run cal = touchstone(dir, "calibrate each.h5 --step-ranges 1 --out each_cal.json");
  CHECK_MESSAGE(cal.out.find("no answer sets (") != std::string::npos, cal.out << cal.err);
  CHECK_MESSAGE(cal.out.find("database = \"each\"") != std::string::npos, cal.out << cal.err);
  CHECK(touchstone(dir, "experiment --db db.h5 --objects wedge --runs 1 --steps 2 --pool 2 --set database=each "
                        "--set hidden=nut --out bad.h5").code == 1);
  CHECK_FALSE(fs::exists(dir / "bad.h5"));
}

TEST_CASE("cli seabed: simulate a scene, log info names it, recognize --support plane sets the seabed aside") {
  test::TempDir dir("cli_seabed");
  make_db(dir);
  const Run sim = touchstone(dir, "simulate --db db.h5 --object box --grasps 24 --noise ideal --scene seabed "
                                  "--scene-off-target 0.4 --seed 5 --out seabed.h5 --json");
  REQUIRE_MESSAGE(sim.code == 0, sim.err);
  const Run info = touchstone(dir, "log info seabed.h5 --json");
  REQUIRE(info.code == 0);
  const auto ji = nlohmann::json::parse(info.out);
  CHECK(ji["scene"]["kind"] == "seabed");
  CHECK(ji["scene"]["support_faces"] == 2);
  const double floor_z = io::read_log(dir / "seabed.h5").truth->support.vertices[0].z();
  const Run r = touchstone(dir, "recognize --db db.h5 --log seabed.h5 --support plane --json");
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const auto last = nlohmann::json::parse(r.out)["steps"].back();
  CHECK(last["object"] == "box");
  REQUIRE(last["support"].is_object());
  CHECK(last["support_verdict"] == "found");
  CHECK(last["support"]["normal"][2].get<double>() > std::cos(2.0 * 3.14159265 / 180));   // up, within 2 degrees
  CHECK(std::abs(last["support"]["offset_m"].get<double>() - floor_z) < 0.002);          // at the seabed's height
  CHECK(last["support"]["contacts"].get<int>() >= 12);
  CHECK(last["position_error_m"].get<double>() < 0.005);
  // What explains each contact, in the order of the cloud `log export` writes: the seabed's set
  // aside on the seabed; every contact clear of it the box's (ideal noise, the right answer).
  REQUIRE(last["attribution"].is_object());
  const std::string labels = last["attribution"]["labels"];
  CHECK(last["attribution"]["support"] == last["support"]["contacts"]);
  CHECK(last["attribution"]["object"].get<std::size_t>() + last["attribution"]["support"].get<std::size_t>() +
            last["attribution"]["unexplained"].get<std::size_t>() == labels.size());
  REQUIRE(touchstone(dir, "log export seabed.h5 --out cloud.ply").code == 0);
  const PointCloud cloud = io::read_cloud(dir / "cloud.ply");
  REQUIRE(cloud.size() == labels.size());
  std::size_t clear = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const double h = cloud.points[i].z() - floor_z;
    if (labels[i] == 's') CHECK(std::abs(h) < 0.006);
    if (h > 0.01) {
      ++clear;
      CHECK(labels[i] == 'o');
    }
  }
  CHECK(clear > 20);
  // An experiment on the scene scores the attribution against the truth; without the stage
  // nothing is labelled, and the share off the target is the same.
  const std::string exp = "experiment --db db.h5 --objects box --runs 1 --steps 24 --pool 24 --set noise=ideal "
                          "--set scene=seabed --set scene.off_target=0.6 --json ";
  const Run on = touchstone(dir, exp + "--set support.mode=plane --out on.h5");
  const Run off = touchstone(dir, exp + "--out off.h5");
  REQUIRE_MESSAGE(on.code == 0, on.err);
  REQUIRE_MESSAGE(off.code == 0, off.err);
  const auto s_on = nlohmann::json::parse(on.out)["per_step"][23], s_off = nlohmann::json::parse(off.out)["per_step"][23];
  CHECK(s_on["recognition_rate"] == 1.0);
  CHECK(s_on["off_target_share_mean"].get<double>() > 0.02);   // a single pad often misses a flat seabed
  CHECK(s_on["off_target_share_mean"] == s_off["off_target_share_mean"]);
  CHECK(s_on["attribution_accuracy_mean"].get<double>() >= 0.95);
  CHECK(s_off["attribution_accuracy_mean"].is_null());
  // The support found against the true one under the box: level and at its height (ideal noise).
  CHECK(s_on["support_found_share"] == 1.0);
  CHECK(s_on["support_verdict_shares"]["found"] == 1.0);
  CHECK(s_on["support_tilt_deg_median"].get<double>() < 1.0);
  CHECK(s_on["support_height_error_m_median"].get<double>() < 0.001);
  CHECK(s_off["support_found_share"].is_null());
  CHECK(s_off["support_verdict_shares"].is_null());
  CHECK(s_off["support_tilt_deg_median"].is_null());
  // Bad scenes: one error naming the key, nothing written.
  const Run gap = touchstone(dir, "simulate --db db.h5 --object box --grasps 2 --scene seabed --scene-gap -0.01 "
                                  "--out gap.h5");
  CHECK(gap.code != 0);
  CHECK(gap.err.find("scene.gap") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "gap.h5"));
  const Run probe = touchstone(dir, "experiment --db db.h5 --objects box --runs 1 --steps 2 --pool 2 --set sensing=probe "
                                    "--set scene=seabed --out probe.h5");
  CHECK(probe.code != 0);
  CHECK(probe.err.find("(scene)") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "probe.h5"));
}

TEST_CASE("cli cluttered: neighbours from the database beside the box, in the log and scored by the experiment") {
  test::TempDir dir("cli_cluttered");
  make_db(dir);
  const Run sim = touchstone(dir, "simulate --db db.h5 --object box --grasps 20 --noise ideal --scene cluttered "
                                  "--scene-neighbours 2 --scene-off-target 0.5 --seed 5 --out cluttered.h5");
  REQUIRE_MESSAGE(sim.code == 0, sim.err);
  const Run info = touchstone(dir, "log info cluttered.h5 --json");
  REQUIRE(info.code == 0);
  const auto scene = nlohmann::json::parse(info.out)["scene"];
  CHECK(scene["kind"] == "cluttered");
  REQUIRE(scene["neighbours"].size() == 2);
  const TactileLog log = io::read_log(dir / "cluttered.h5");
  const io::DbReader db(dir / "db.h5");
  for (std::size_t k = 0; k < 2; ++k) {   // database objects, not the box, placed as the log says
    const auto& n = log.truth->neighbours[k];
    CHECK(scene["neighbours"][k]["object"] == n.name);
    CHECK(n.name != "box");
    const std::size_t i = db.find(n.name);
    REQUIRE(i < db.size());
    const Mesh m = db.load_mesh(i);
    REQUIRE(m.vertices.size() == n.mesh.vertices.size());
    CHECK((n.pose * m.vertices.front() - n.mesh.vertices.front()).norm() < 1e-9);
  }
  // The experiment: every off-target grasp at a neighbour; the contacts off the target are
  // counted against the neighbours too, and the answer named a neighbour or not in every run.
  const std::string exp = "experiment --db db.h5 --objects box --runs 2 --steps 16 --pool 20 --set noise=ideal "
                          "--set scene=cluttered --set scene.off_target=0.5 --set scene.neighbour_share=1 --json ";
  const Run on = touchstone(dir, exp + "--set support.mode=plane --out on.h5");
  REQUIRE_MESSAGE(on.code == 0, on.err);
  const auto last = nlohmann::json::parse(on.out)["per_step"][15];
  CHECK(last["off_target_share_mean"].get<double>() > 0.1);
  const double named = last["neighbour_answer_share"].get<double>();
  CHECK((named == 0.0 || named == 0.5 || named == 1.0));
  CHECK(named + last["recognition_rate"].get<double>() <= 1.0);
  // Bad input: a cluttered scene's key for another scene, named; nothing written.
  const Run bad = touchstone(dir, "simulate --db db.h5 --object box --grasps 2 --scene seabed --scene-neighbours 2 "
                                  "--out bad.h5");
  CHECK(bad.code != 0);
  CHECK(bad.err.find("scene.neighbours") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "bad.h5"));
}

TEST_CASE("cli pipe: recognize --support cylinder finds the pipe under the box and sets it aside") {
  test::TempDir dir("cli_pipe");
  make_db(dir);
  const double radius = 0.08;
  const Run sim = touchstone(dir, "simulate --db db.h5 --object box --grasps 24 --noise ideal --scene pipe "
                                  "--scene.pipe-radius-m 0.08 --scene-off-target 0.4 --seed 5 --out pipe.h5");
  REQUIRE_MESSAGE(sim.code == 0, sim.err);
  const Run r = touchstone(dir, "recognize --db db.h5 --log pipe.h5 --support cylinder --json");
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const auto last = nlohmann::json::parse(r.out)["steps"].back();
  CHECK(last["object"] == "box");
  REQUIRE(last["support"].is_object());
  CHECK(last["support"]["shape"] == "cylinder");
  CHECK(std::abs(last["support"]["radius_m"].get<double>() - radius) < 0.002);
  CHECK(std::abs(last["support"]["axis"][2].get<double>()) < std::sin(2.0 * 3.14159265 / 180));   // horizontal
  CHECK(last["attribution"]["support"] == last["support"]["contacts"]);
  // The true pipe's axis: its mesh's centroid and longest direction (it is longer than wide).
  const Mesh pipe = io::read_log(dir / "pipe.h5").truth->support;
  Vec3 c = Vec3::Zero();
  for (const Vec3& v : pipe.vertices) c += v;
  c /= static_cast<double>(pipe.vertices.size());
  Mat3 cov = Mat3::Zero();
  for (const Vec3& v : pipe.vertices) cov += (v - c) * (v - c).transpose();
  const Vec3 axis = Eigen::SelfAdjointEigenSolver<Mat3>(cov).eigenvectors().col(2);
  auto from_axis = [&](const Vec3& x) { return ((x - c) - axis.dot(x - c) * axis).norm(); };
  const Vec3 found_axis(last["support"]["axis"][0].get<double>(), last["support"]["axis"][1].get<double>(),
                        last["support"]["axis"][2].get<double>());
  CHECK(std::abs(found_axis.dot(axis)) > std::cos(2.0 * 3.14159265 / 180));
  const Vec3 found_point(last["support"]["point"][0].get<double>(), last["support"]["point"][1].get<double>(),
                         last["support"]["point"][2].get<double>());
  CHECK(from_axis(found_point) < 0.002);
  // Every contact it set aside lies on the true pipe (within the tolerance, 6 mm).
  const std::string labels = last["attribution"]["labels"];
  REQUIRE(touchstone(dir, "log export pipe.h5 --out cloud.ply").code == 0);
  const PointCloud cloud = io::read_cloud(dir / "cloud.ply");
  REQUIRE(cloud.size() == labels.size());
  std::size_t set_aside = 0, on_pipe = 0, missed = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const bool on = std::abs(from_axis(cloud.points[i]) - radius) < 0.001;   // truly on it (ideal noise)
    on_pipe += on;
    missed += on && labels[i] != 's';
    if (labels[i] != 's') continue;
    ++set_aside;
    CHECK(std::abs(from_axis(cloud.points[i]) - radius) < 0.006);
  }
  CHECK(on_pipe >= 24);      // (the off-target grasps touched it)
  CHECK(missed == 0);        // every contact on the pipe set aside
  // An experiment: the pipe found in the step's runs, level with the true one and at its height.
  const Run e = touchstone(dir, "experiment --db db.h5 --objects box --runs 1 --steps 24 --pool 24 --set noise=ideal "
                                "--set scene=pipe --set scene.pipe_radius_m=0.08 --set scene.off_target=0.5 "
                                "--set support.mode=cylinder --json --out on.h5");
  REQUIRE_MESSAGE(e.code == 0, e.err);
  const auto s = nlohmann::json::parse(e.out)["per_step"][23];
  CHECK(s["recognition_rate"] == 1.0);
  CHECK(s["support_found_share"] == 1.0);
  // The true normal under the box is a facet's of the pipe's mesh (its facets turn by about 4
  // degrees: chords within 0.2 mm of the round pipe), so a right cylinder's tilt is up to 4.
  CHECK(s["support_tilt_deg_median"].get<double>() < 5.0);
  CHECK(std::abs(s["support_height_error_m_median"].get<double>()) < 0.002);
  CHECK(s["attribution_accuracy_mean"].get<double>() >= 0.95);
}

TEST_CASE("cli probe experiment: sensing = probe under both protocols (the shared pool stays a probe log)") {
  test::TempDir dir("cli_probe_exp");
  make_db(dir);
  for (const std::string protocol : {"independent", "shared_pool"}) {
    INFO(protocol);
    const Run r = touchstone(dir, "experiment --db db.h5 --objects wedge --runs 1 --steps 20 --pool 20 --set sensing=probe "
                                  "--set protocol=" + protocol + " --json --out " + protocol + ".h5");
    REQUIRE_MESSAGE(r.code == 0, r.err);
    const auto j = nlohmann::json::parse(r.out);
    REQUIRE(j["per_step"].size() == 20);
    CHECK(j["config"]["sensing"] == "probe");
    // 20 touches on the wedge among six objects: recognized, within a few millimetres.
    CHECK(j["per_step"][19]["recognition_rate"] == 1.0);
    CHECK(j["per_step"][19]["position_error_m_median"].get<double>() < 0.005);
  }
}

TEST_CASE("cli recognize --calibration: confidences, and the open-set answer below the threshold") {
  test::TempDir dir("cli_rec_open");
  make_db(dir, "small.h5", {"wedge"});
  REQUIRE(touchstone(dir, "simulate --db small.h5 --object box --grasps 2 --noise ideal --out box.h5").code == 0);
  make_db(dir);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 2 --noise ideal --out wedge.h5").code == 0);
  experiments::Calibration cal;
  cal.database_fingerprint = experiments::file_fingerprint(io::DbReader(dir / "small.h5"));
  cal.features = experiments::confidence_feature_names();
  const std::size_t F = cal.features.size();
  experiments::StepModels m;
  m.object = {std::vector<double>(F, 0.0), std::vector<double>(F, 1.0), std::vector<double>(F + 1, 0.0)};
  m.pose = m.object;   // every confidence 0.5
  cal.ranges = {m};
  experiments::write_calibration(dir / "cal.json", cal);
  // A threshold on the in-database score: every score 0.5 (0.0 bias) from step 2 on, 0.7 at step 1.
  cal.ranges[0].in_database = m.object;
  cal.ranges[0].in_database->coef[0] = std::log(0.7 / 0.3);
  cal.ranges.push_back(cal.ranges[0]);
  cal.ranges[1].first_step = 2;
  cal.ranges[1].in_database->coef[0] = 0.0;
  cal.open_set_threshold = 0.6;
  experiments::write_calibration(dir / "open.json", cal);

  const Run plain = touchstone(dir, "recognize --db small.h5 --log box.h5 --json --calibration cal.json" + kFastFlags);
  REQUIRE_MESSAGE(plain.code == 0, plain.err);
  const auto jp = nlohmann::json::parse(plain.out);  // kept alive: the loop reads into it
  for (const auto& st : jp["steps"]) {
    CHECK(st["confidence"]["object"].get<double>() == doctest::Approx(0.5));
    CHECK(st["confidence"]["in_database"].is_null());   // no open-set model
    CHECK(st["reason"].is_null());
    CHECK(st["object"].is_string());
  }
  // Below the threshold (steps 2 on): "not in the database"; right for the wedge (not in
  // small.h5), wrong for the box (it is). At step 1 the score is 0.7: the object is named.
  for (const auto& [log, outside] : {std::pair{"wedge.h5", true}, {"box.h5", false}}) {
    const Run r = touchstone(dir, std::string("recognize --db small.h5 --log ") + log + " --json --calibration open.json" + kFastFlags);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    const auto j = nlohmann::json::parse(r.out);
    CHECK(j["truth_in_database"] == !outside);
    REQUIRE(j["steps"].size() == 2);
    const auto& first = j["steps"][0];
    CHECK(first["confidence"]["in_database"].get<double>() == doctest::Approx(0.7));
    CHECK(first["object"].is_string());
    CHECK(first["reason"].is_null());
    const auto& st = j["steps"][1];
    CHECK(st["confidence"]["in_database"].get<double>() == doctest::Approx(0.5));
    CHECK(st["object"].is_null());
    CHECK(st["reason"] == "not_in_database");
    CHECK(st["best_guess"].is_string());
    CHECK(st["correct"] == outside);
  }
  // --open-set-threshold overrides the file's (0: always name an object), needs a calibration.
  const Run named = touchstone(dir, "recognize --db small.h5 --log wedge.h5 --json --calibration open.json --open-set-threshold 0" + kFastFlags);
  REQUIRE_MESSAGE(named.code == 0, named.err);
  CHECK(nlohmann::json::parse(named.out)["steps"][0]["object"].is_string());
  const Run lone = touchstone(dir, "recognize --db small.h5 --log wedge.h5 --open-set-threshold 0.5");
  CHECK(lone.code == 1);
  CHECK(lone.err.find("--open-set-threshold") != std::string::npos);
  // A threshold with a calibration that has no open-set model: one error naming the file and key.
  const Run no_model = touchstone(dir, "recognize --db small.h5 --log wedge.h5 --calibration cal.json --open-set-threshold 0.5");
  CHECK(no_model.code == 1);
  CHECK(no_model.err.find("cal.json") != std::string::npos);
  CHECK(no_model.err.find("in_database") != std::string::npos);
  // Another database's calibration: one error naming the file and the key.
  const Run other = touchstone(dir, "recognize --db db.h5 --log wedge.h5 --calibration open.json");
  CHECK(other.code == 1);
  CHECK(other.err.find("open.json") != std::string::npos);
  CHECK(other.err.find("database_fingerprint") != std::string::npos);
}

TEST_CASE("cli params --json: every method parameter is a recognize flag (and each older flag), every parameter an experiment --set key") {
  test::TempDir dir("cli_params");
  make_db(dir);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 2 --noise ideal --out log.h5").code == 0);
  const Run list = touchstone(dir, "params --json");
  REQUIRE_MESSAGE(list.code == 0, list.err);
  const auto params = nlohmann::json::parse(list.out).at("parameters");
  REQUIRE(params.size() >= 60);
  // The simulator and experiment parameters: each a value unlike its default and the JSON the
  // canonical configuration must then record (under other keys for ransac.samples). Every
  // listed parameter must have one here.
  using J = nlohmann::json;
  const std::map<std::string, std::pair<std::string, J>> setting = {
      {"name", {"walk", {{"name", "walk"}}}},
      {"description", {"every key", {{"description", "every key"}}}},
      {"objects", {"wedge", {{"objects", {"wedge"}}}}},
      {"database", {"wedge,box,nut", {{"database", {"wedge", "box", "nut"}}}}},
      {"database_size", {"1", {{"database_size", 1}}}},
      {"hidden", {"nut", {{"hidden", {"nut"}}}}},
      {"runs", {"1", {{"runs", 1}}}},
      {"steps", {"1", {{"steps", 1}}}},
      {"pool", {"2", {{"pool", 2}}}},
      {"protocol", {"shared_pool", {{"protocol", "shared_pool"}}}},
      {"method", {"ransac-icp", {{"method", "ransac-icp"}}}},
      {"preset", {"paper", {{"preset", "paper"}}}},
      {"noise", {"ideal", {{"noise", "ideal"}}}},
      {"noise.arm_position_sigma_m", {"0.001", {{"noise.arm_position_sigma_m", 0.001}}}},
      {"noise.arm_rotation_sigma_deg", {"0.5", {{"noise.arm_rotation_sigma_deg", 0.5}}}},
      {"noise.arm_scale", {"0.5", {{"noise.arm_scale", 0.5}}}},
      {"noise.sensel_noise", {"0.02", {{"noise.sensel_noise", 0.02}}}},
      {"noise.force_noise", {"0.3", {{"noise.force_noise", 0.3}}}},
      {"noise.contact_sigma_m", {"0.0005", {{"noise.contact_sigma_m", 0.0005}}}},
      {"noise.joint_sigma_deg", {"0.2", {{"noise.joint_sigma_deg", 0.2}}}},
      {"sensors", {"6", {{"sensors", 6}}}},
      {"sensing", {"probe", {{"sensing", "probe"}}}},
      {"probe.ball_radius_m", {"0.002", {{"probe.ball_radius_m", 0.002}}}},
      {"probe.tilt_deg", {"30", {{"probe.tilt_deg", 30.0}}}},
      {"probe.quantization_m", {"0.001", {{"probe.quantization_m", 0.001}}}},
      {"fingertips.quantization_m", {"0.001", {{"fingertips.quantization_m", 0.001}}}},
      {"fingertips.normals_deg", {"5", {{"fingertips.normals_deg", 5.0}}}},
      {"scene", {"none", {{"scene", "none"}}}},   // (seabed with this walk's probe is refused: tested apart)
      {"scene.slope_deg", {"10", {{"scene.slope_deg", 10.0}}}},
      {"scene.relief_m", {"0.01", {{"scene.relief_m", 0.01}}}},
      {"scene.relief_wavelength_m", {"0.1", {{"scene.relief_wavelength_m", 0.1}}}},
      {"scene.gap_m", {"0.002", {{"scene.gap_m", 0.002}}}},
      {"scene.off_target", {"0.25", {{"scene.off_target", 0.25}}}},
      {"scene.off_target_radius_m", {"0.2", {{"scene.off_target_radius_m", 0.2}}}},
      {"scene.extent_m", {"0.5", {{"scene.extent_m", 0.5}}}},
      {"scene.pipe_radius_m", {"0.1", {{"scene.pipe_radius_m", 0.1}}}},
      {"scene.neighbours", {"3", {{"scene.neighbours", 3}}}},
      {"scene.neighbour_distance_m", {"0.02", {{"scene.neighbour_distance_m", 0.02}}}},
      {"scene.neighbour_share", {"0.7", {{"scene.neighbour_share", 0.7}}}},
      {"seed", {"7", {{"seed", 7}}}},
      {"ransac.samples", {"3x20", {{"ransac.triplets", 3}, {"ransac.registrations", 20}}}},
      {"memory_budget_mb", {"64", {{"memory_budget_mb", 64.0}}}},
      {"calibration", {"", {{"calibration", ""}}}},
      {"schedule", {"steps", {{"schedule", "steps"}}}}};
  std::size_t others = 0;
  for (const auto& p : params) {
    if (p["kind"] == "method") {
      CHECK(p["commands"] == J({"recognize", "bench_recognize"}));
      continue;
    }
    ++others;
    REQUIRE_MESSAGE(setting.count(p["key"]), p["key"]);
    CHECK(std::find(p["commands"].begin(), p["commands"].end(), "experiment") != p["commands"].end());
    // bench_recognize takes the method, the preset and the pads' simulator parameters
    const bool bench = p["key"] == "method" || p["key"] == "preset" || p["key"] == "noise" ||
                       p["key"] == "sensors" || p["key"].get<std::string>().starts_with("noise.");
    CHECK_MESSAGE((std::find(p["commands"].begin(), p["commands"].end(), "bench_recognize") != p["commands"].end()) ==
                      bench, p["key"]);
  }
  CHECK(others == setting.size());
  // experiment: each by --set KEY=VALUE, and each by its flag (--seed: the common flag).
  for (const bool by_flag : {false, true}) {
    CAPTURE(by_flag);
    std::string args = "experiment --db db.h5 --json --out o" + std::to_string(by_flag) + ".h5";
    for (const auto& p : params) {
      if (p["kind"] == "method") continue;
      const std::string& v = setting.at(p["key"]).first;
      if (by_flag)
        args += " " + p["flag"].get<std::string>() + " '" + v + "'";
      else
        args += " --set '" + p["key"].get<std::string>() + "=" + v + "'";
    }
    const Run e = touchstone(dir, args);
    REQUIRE_MESSAGE(e.code == 0, (args + "\n" + e.err));
    const auto config = nlohmann::json::parse(e.out).at("config");
    for (const auto& [key, s] : setting)
      for (const auto& [k, v] : s.second.items()) {
        REQUIRE_MESSAGE(config.contains(k), k);
        CHECK_MESSAGE(config[k] == v, (std::string(k) + " of " + key));
      }
  }
  // simulate: each simulator parameter it takes by its flag, then by its older flags: the same
  // log, and another without the noise overrides.
  std::vector<std::string> sim_args(3, "simulate --db db.h5 --object wedge --grasps 3 --seed 3");
  for (const auto& p : params) {
    if (std::find(p["commands"].begin(), p["commands"].end(), "simulate") == p["commands"].end()) continue;
    std::vector<std::string> flags{p["flag"].get<std::string>()};
    for (const auto& a : p["aliases"]) flags.push_back(a);
    const std::string key = p["key"];
    const std::string v = key == "sensing" ? "pads" : setting.at(key).first;   // pads: tactile images compared
    for (std::size_t i = 0; i < 3; ++i)
      if (i < 2 || key.rfind("noise.", 0) != 0) sim_args[i] += " " + flags[std::min(i, flags.size() - 1)] + " " + v;
  }
  std::vector<TactileLog> logs;
  for (std::size_t i = 0; i < 3; ++i) {
    const Run r = touchstone(dir, sim_args[i] + " --out s" + std::to_string(i) + ".h5");
    REQUIRE_MESSAGE(r.code == 0, (sim_args[i] + "\n" + r.err));
    logs.push_back(io::read_log(dir / ("s" + std::to_string(i) + ".h5")));
  }
  CHECK(logs[0].noise == "ideal");
  CHECK(logs[0].pads.size() == 6);
  REQUIRE(logs[0].grasps.size() == logs[1].grasps.size());
  REQUIRE(logs[0].grasps.size() == logs[2].grasps.size());
  bool overrides_show = false;
  for (std::size_t g = 0; g < logs[0].grasps.size(); ++g) {
    CHECK(logs[0].grasps[g].tactile == logs[1].grasps[g].tactile);
    CHECK(logs[0].grasps[g].arm_pose.isApprox(logs[1].grasps[g].arm_pose, 0.0));
    overrides_show |= !logs[0].grasps[g].arm_pose.isApprox(logs[2].grasps[g].arm_pose, 1e-12);
  }
  CHECK(overrides_show);   // the ideal profile's arm is exact; the override moves it
  // The method parameters.
  nlohmann::json method_params = nlohmann::json::array();
  for (const auto& p : params)
    if (p["kind"] == "method") method_params.push_back(p);
  REQUIRE(method_params.size() >= 40);
  // Each value: the improved preset's, integers one more and reals 10 % more (within range) so
  // that a flag that does not reach the settings shows; the costly counts kept small.
  const std::map<std::string, double> fast = {{"ransac.triplets", 6}, {"ransac.registrations", 40},
                                              {"ransac.prune", 800}, {"bricpsf.hypotheses", 20}, {"icp.points", 64}};
  std::map<std::string, nlohmann::json> value;
  for (const auto& p : method_params) {
    const std::string key = p["key"];
    nlohmann::json v = p["default"]["improved"];
    if (v.is_object()) v = v["value"];   // an extension of large databases: asked for, on any
    if (fast.count(key)) {
      v = static_cast<long long>(fast.at(key));
    } else if (p["type"] == "integer") {
      v = std::min(v.get<long long>() + 1, static_cast<long long>(p["max"].get<double>()));
    } else if (p["type"] == "real" && v.get<double>() > 0) {
      v = p["max"].is_null() ? v.get<double>() * 1.1 : std::min(v.get<double>() * 1.1, p["max"].get<double>());
    }
    value[key] = v;
  }
  auto text = [](const nlohmann::json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); };
  auto stored = [&](const nlohmann::json& p, const nlohmann::json& v) {
    if (v.is_boolean()) return v.get<bool>() ? 1.0 : 0.0;
    if (v.is_string()) {   // a choice: its index
      const auto& c = p["choices"];
      return static_cast<double>(std::find(c.begin(), c.end(), v) - c.begin());
    }
    return v.get<double>();
  };
  // Round 0: every parameter's flag (--KEY with '_' written '-'); round k: each parameter's k-th
  // older flag where it has one (scripts rely on them).
  for (std::size_t round = 0; round <= 2; ++round) {
    CAPTURE(round);
    std::string args = "recognize --db db.h5 --log log.h5 --steps 1 --out r" + std::to_string(round) + ".h5";
    for (const auto& p : method_params) {
      std::vector<std::string> flags{p["flag"].get<std::string>()};
      for (const auto& a : p["aliases"])
        if (a.get<std::string>().front() == '-') flags.push_back(a);
      const std::string flag = flags[std::min(round, flags.size() - 1)];
      const auto& v = value.at(p["key"]);
      if (v.is_boolean())
        args += " " + (v.get<bool>() ? flag : "--no-" + flag.substr(2));
      else
        args += " " + flag + " " + text(v);
    }
    const Run r = touchstone(dir, args);
    REQUIRE_MESSAGE(r.code == 0, (args + "\n" + r.err));
    std::map<std::string, double> written;
    for (const auto& [k, v] : io::read_result(dir / ("r" + std::to_string(round) + ".h5")).header.params) written[k] = v;
    for (const auto& p : method_params) {
      const std::string key = p["key"];
      REQUIRE_MESSAGE(written.count(key), key);
      CHECK_MESSAGE(written.at(key) == stored(p, value.at(key)), key);   // the text read back exactly
    }
  }
  // experiment --set KEY=VALUE: every key, the canonical configuration records each value.
  std::string args = "experiment --db db.h5 --objects wedge --runs 1 --steps 1 --pool 1 --json --out e.h5";
  for (const auto& [key, v] : value) args += " --set " + key + "=" + text(v);
  const Run e = touchstone(dir, args);
  REQUIRE_MESSAGE(e.code == 0, (args + "\n" + e.err));
  const auto config = nlohmann::json::parse(e.out).at("config");
  for (const auto& [key, v] : value) {
    REQUIRE_MESSAGE(config.contains(key), key);
    if (v.is_number_float())
      CHECK_MESSAGE(config[key].get<double>() == v.get<double>(), key);
    else
      CHECK_MESSAGE(config[key] == v, key);
  }
  // A bad value names the flag; an unknown key is refused.
  const Run bad = touchstone(dir, "recognize --db db.h5 --log log.h5 --ransac.triplets 0");
  CHECK(bad.code == 2);
  CHECK(bad.err.find("--ransac.triplets") != std::string::npos);
  const Run unknown = touchstone(dir, "experiment --db db.h5 --set ransac.tripletz=3 --out u.h5");
  CHECK(unknown.code != 0);
  CHECK(unknown.err.find("did you mean 'ransac.triplets'") != std::string::npos);
}

TEST_CASE("cli recognize --suggest: the N best next grasps in the world frame, the same for any --threads") {
  test::TempDir dir("cli_suggest");
  make_db(dir);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 3 --noise underwater --seed 4 --out log.h5").code == 0);
  const std::string args = "recognize --db db.h5 --log log.h5 --json --suggest 3 --active.candidates 24" + kFastFlags;
  const Run a = touchstone(dir, args + " --threads 1");
  REQUIRE_MESSAGE(a.code == 0, a.err);
  const Run b = touchstone(dir, args + " --threads 2");
  REQUIRE_MESSAGE(b.code == 0, b.err);
  auto ja = nlohmann::json::parse(a.out), jb = nlohmann::json::parse(b.out);
  const auto& s = ja["suggestions"];
  REQUIRE(s.size() == 3);
  CHECK(s == jb["suggestions"]);
  const TactileLog log = io::read_log(dir / "log.h5");
  const std::size_t K = std::min<std::size_t>(16, ja["steps"].back()["hypotheses"].size());
  double previous = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < s.size(); ++i) {
    const auto& g = s[i];
    CHECK(g["rank"] == i + 1);
    CHECK(g["score"].get<double>() <= previous);
    previous = g["score"].get<double>();
    CHECK(g["T_EEF"]["t"].size() == 3);
    CHECK(g["T_EEF"]["q"].size() == 4);
    CHECK(g["T_EEF_matrix"].size() == 16);
    CHECK(g["joints_deg"].size() == static_cast<std::size_t>(log.gripper.joint_count()));
    const double info = g["expected_information_nats"].get<double>();
    CHECK(info >= 0.0);
    CHECK(info <= std::log(static_cast<double>(std::max<std::size_t>(K, 16))) + 1e-9);
    const double object_info = g["expected_object_information_nats"].get<double>();
    CHECK(object_info >= 0.0);
    CHECK(object_info <= info);
    const double coverage = g["coverage"].get<double>();
    CHECK(coverage >= 0.0);
    CHECK(coverage <= 1.0);
    // The hand's pose and the aim agree: the approach is a unit vector, the target within the
    // hand's reach of the EEF origin, and near the explored contacts (the object is under 20 cm).
    const Vec3 t(g["T_EEF"]["t"][0].get<double>(), g["T_EEF"]["t"][1].get<double>(), g["T_EEF"]["t"][2].get<double>());
    const Vec3 target(g["target"][0].get<double>(), g["target"][1].get<double>(), g["target"][2].get<double>());
    const Vec3 approach(g["approach"][0].get<double>(), g["approach"][1].get<double>(), g["approach"][2].get<double>());
    CHECK(approach.norm() == doctest::Approx(1.0).scale(0).epsilon(1e-9));
    CHECK((target - t).norm() <= log.gripper.reach() + 1e-9);
    CHECK((target - log.truth->object_pose.translation()).norm() < 0.3);
  }
  CHECK(ja["suggest_time_s"].get<double>() >= 0.0);
}

TEST_CASE("cli recognize --suggest: bad input is one clear error") {
  test::TempDir dir("cli_suggest_bad");
  make_db(dir);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 2 --noise ideal --seed 4 --out log.h5").code == 0);
  auto expect_error = [&](const std::string& args, const std::string& what) {
    const Run r = touchstone(dir, args);
    INFO(args);
    CHECK(r.code != 0);
    CHECK_MESSAGE(r.err.find(what) != std::string::npos, r.err);
  };
  expect_error("recognize --db db.h5 --log log.h5 --suggest 0" + kFastFlags, "--suggest");
  expect_error("recognize --db db.h5 --log log.h5 --suggest 2 --active.candidates 0" + kFastFlags, "active.candidates");
  {  // no contact yet: every sensel silent
    TactileLog silent = io::read_log(dir / "log.h5");
    for (auto& g : silent.grasps)
      for (auto& e : g.tactile) e = 0.0f;
    io::write_log(dir / "silent.h5", silent);
    expect_error("recognize --db db.h5 --log silent.h5 --suggest 2" + kFastFlags, "no contact yet");
  }
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 2 --sensing probe --noise ideal --out probe.h5").code == 0);
  expect_error("recognize --db db.h5 --log probe.h5 --suggest 2" + kFastFlags, "probe log");
  REQUIRE(touchstone(dir, "log export log.h5 --out c.ply").code == 0);
  expect_error("recognize --db db.h5 --cloud c.ply --suggest 2" + kFastFlags, "--suggest");
  // The oracle diagnostic reads a truth the planner of experiments executes against; recognize
  // only suggests grasps, so it is refused rather than ignored.
  expect_error("recognize --db db.h5 --log log.h5 --suggest 2 --diagnostics.oracle-belief 0.5" + kFastFlags,
               "--diagnostics.oracle-belief");
}

TEST_CASE("cli recognize --scene: each chosen step drawn in the world frame, a PNG and a self-contained page") {
  test::TempDir dir("cli_scene");
  make_db(dir);
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 6 --noise ideal --seed 4 --out log.h5").code == 0);
  const Run a = touchstone(dir, "recognize --db db.h5 --log log.h5 --scene pics --scene-steps 6,3" + kFastFlags);
  REQUIRE_MESSAGE(a.code == 0, a.err);
  for (const char* f : {"scene_log_step3.png", "scene_log_step6.png", "scene_log_step3.html", "scene_log_step6.html"})
    CHECK_MESSAGE(fs::file_size(dir / "pics" / f) > 2000, f);
  CHECK(test::read_bytes(dir / "pics" / "scene_log_step6.png").substr(1, 3) == "PNG");
  const std::string page = test::read_bytes(dir / "pics" / "scene_log_step6.html");
  CHECK(page.find("<canvas") != std::string::npos);
  CHECK(page.find("http://") == std::string::npos);    // nothing fetched at viewing time
  CHECK(page.find("https://") == std::string::npos);
  CHECK(page.find("src=") == std::string::npos);

  const auto scenes = nlohmann::json::parse(test::read_bytes(dir / "pics" / "scenes.json"))["scenes"];
  REQUIRE(scenes.size() == 2);
  CHECK(scenes[0]["step"] == 3);   // ascending, whatever the order asked
  const auto& s = scenes[1];
  CHECK(s["step"] == 6);
  REQUIRE(s["truth"].is_object());
  CHECK(s["truth"]["object"] == "wedge");
  REQUIRE(!s["hypotheses"].empty());
  CHECK(s["hypotheses"].size() <= 3);
  std::set<std::string> objects;
  for (const auto& h : s["hypotheses"]) CHECK(objects.insert(h["object"].get<std::string>()).second);  // one per object
  // The frames agree: the contacts (ideal sensing) lie on the true object's surface points and
  // the truth points around the log's true pose; points farther than the object's size would
  // mean one of them is in another frame.
  auto points = [](const nlohmann::json& a) {
    std::vector<Vec3> out;
    for (const auto& p : a) out.emplace_back(p[0].get<double>(), p[1].get<double>(), p[2].get<double>());
    return out;
  };
  const std::vector<Vec3> contacts = points(s["contacts"]), truth = points(s["truth"]["points"]);
  REQUIRE(contacts.size() > 10);
  REQUIRE(truth.size() > 100);
  double sum = 0.0;
  for (const Vec3& c : contacts) {
    double best = std::numeric_limits<double>::infinity();
    for (const Vec3& t : truth) best = std::min(best, (c - t).norm());
    sum += best;
  }
  CHECK(sum / static_cast<double>(contacts.size()) < 0.004);   // the surface points' spacing, about 2-3 mm
  const TactileLog log = io::read_log(dir / "log.h5");
  Vec3 centre = Vec3::Zero();
  for (const Vec3& t : truth) centre += t;
  centre /= static_cast<double>(truth.size());
  CHECK((centre - log.truth->object_pose.translation()).norm() < 0.05);
  // Every drawn object is its database surface points (evenly spread) moved by the drawn pose:
  // moved back, each point is the database's, to the 0.1 mm the scene rounds to.
  auto pose = [](const nlohmann::json& m) {
    Pose T = Pose::Identity();
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) T.matrix()(i, j) = m[i][j].get<double>();
    return T;
  };
  const Database db(std::make_shared<io::DbReader>((dir / "db.h5").string()));
  std::vector<nlohmann::json> drawn{s["truth"]};
  for (const auto& sc : scenes)
    for (const auto& h : sc["hypotheses"]) drawn.push_back(h);
  for (const auto& d : drawn) {
    const std::size_t i = db.find(d["object"].get<std::string>());
    REQUIRE(i < db.size());
    const std::vector<Vec3> fine = db.load_fine(i).points, pts = points(d["points"]);
    REQUIRE(pts.size() == std::min<std::size_t>(fine.size(), 1500));
    const Pose back = pose(d["pose"]).inverse();
    double worst = 0.0;
    for (std::size_t j = 0; j < pts.size(); ++j)
      worst = std::max(worst, (back * pts[j] - fine[j * fine.size() / pts.size()]).norm());
    CHECK(worst < 1e-4);
  }
  CHECK(s["free"].size() <= 4000);
  CHECK(s["free"].size() <= s["free_total"].get<std::size_t>());

  // A step outside the log: one error naming the flag, nothing drawn.
  const Run bad = touchstone(dir, "recognize --db db.h5 --log log.h5 --scene pics2 --scene-steps 9" + kFastFlags);
  CHECK(bad.code != 0);
  CHECK(bad.err.find("--scene-steps") != std::string::npos);
  CHECK(bad.err.find("log.h5") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "pics2"));
}

// The scene's data (experiments/analysis/scene.hpp) directly: ranked by the number the legend
// shows, the answer always drawn, also when the answer rule chose an object neither ln w nor the
// posterior puts first.
namespace {
Hypothesis scene_hyp(std::uint32_t object, double log_weight, double x) {
  Hypothesis h;
  h.object = object;
  h.log_weight = log_weight;
  h.weight = std::exp(log_weight);
  h.pose = Pose::Identity();
  h.pose.translation() = Vec3(x, 0.0, 0.0);
  return h;
}
}  // namespace

TEST_CASE("Scene: objects ranked by their posterior, the answer always drawn, its confidence only where calibrated") {
  test::TempDir dir("scene_rank");
  make_db(dir);
  const Database db(std::make_shared<io::DbReader>((dir / "db.h5").string()));
  REQUIRE(db.size() >= 3);
  // ln w ranks object 0 first; the posteriors (weights summed per object) rank object 1 first
  // (two hypotheses); the answer rule chose object 2, last by both.
  StepResult r;
  r.step = 4;
  r.valid = true;
  r.hypotheses = {scene_hyp(0, -0.1, 0.01), scene_hyp(1, -0.2, 0.02), scene_hyp(1, -0.25, 0.03), scene_hyp(2, -0.3, 0.04)};
  r.posteriors.assign(db.size(), 0.0);
  r.posteriors[0] = 0.3;
  r.posteriors[1] = 0.5;
  r.posteriors[2] = 0.2;
  r.best = r.hypotheses[3];
  const PointCloud contacts;
  auto drawn = [&](std::size_t limit, std::optional<double> confidence) {
    experiments::SceneLimits limits;
    limits.hypotheses = limit;
    limits.object_points = 10;
    return experiments::scene_json(db, r, contacts, {}, std::nullopt, std::nullopt, "s", "s", confidence, limits);
  };
  const std::string n0 = db.info(0).name, n1 = db.info(1).name, n2 = db.info(2).name;

  const auto all = drawn(3, 0.8);
  CHECK(all["answer"] == n2);
  CHECK(all["ranked_by"] == "posterior");
  REQUIRE(all["hypotheses"].size() == 3);
  const std::vector<std::string> order{n1, n0, n2};
  for (std::size_t k = 0; k < 3; ++k) {
    const auto& h = all["hypotheses"][k];
    CHECK(h["rank"] == k + 1);
    CHECK(h["object"] == order[k]);
    CHECK(h["answer"] == (k == 2));
    if (k == 2) CHECK(h["confidence"] == 0.8);
    else CHECK(h["confidence"].is_null());
  }
  CHECK(all["hypotheses"][0]["posterior"] == 0.5);
  CHECK(all["hypotheses"][0]["log_weight"] == -0.2);   // object 1's best hypothesis
  CHECK(all["hypotheses"][2]["pose"][0][3] == 0.04);   // the answer's own hypothesis

  // Two drawn: the answer takes the last place; the order stays by posterior.
  const auto two = drawn(2, std::nullopt);
  REQUIRE(two["hypotheses"].size() == 2);
  CHECK(two["hypotheses"][0]["object"] == n1);
  CHECK(two["hypotheses"][1]["object"] == n2);
  CHECK(two["hypotheses"][1]["answer"] == true);
  CHECK(two["hypotheses"][1]["confidence"].is_null());   // no calibration: none shown
  CHECK(two["hypotheses"][1]["rank"] == 2);

  // The answer leading by posterior: drawn first, nothing moved.
  r.best = r.hypotheses[1];
  const auto lead = drawn(1, std::nullopt);
  REQUIRE(lead["hypotheses"].size() == 1);
  CHECK(lead["hypotheses"][0]["object"] == n1);
  CHECK(lead["hypotheses"][0]["answer"] == true);

  // A step without hypotheses: nothing named, nothing drawn.
  StepResult none;
  none.step = 1;
  const auto empty = experiments::scene_json(db, none, contacts, {}, std::nullopt, std::nullopt, "s", "s");
  CHECK(empty["answer"].is_null());
  CHECK(empty["hypotheses"].empty());
}

/// The variants of an experiment's store (run with calibration `cal`) whose informative sets were
/// checked: each holds the truth exactly when the truth's gap has a p-value above alpha under the
/// calibration's entry for the variant's simulation. `decided`: the rows another entry of the
/// calibration would have judged otherwise (the variant's own entry decided them).
std::set<int> variants_whose_sets_hold_their_p_values(const fs::path& path, const fs::path& cal_path, double alpha,
                                                      std::size_t* decided = nullptr) {
  const experiments::Calibration cal = experiments::read_calibration(cal_path, "");
  const io::RunStoreContents store = io::RunStore::read(path);
  const auto& v = store.header.step_values;
  auto col = [&](const char* name) { return static_cast<std::size_t>(std::find(v.begin(), v.end(), name) - v.begin()); };
  const std::size_t gap = col("set.truth_score"), covers = col("answer_set.covers"), informative = col("answer_set.informative");
  REQUIRE(informative < v.size());
  std::set<int> checked;
  for (const auto& r : store.runs) {
    const auto* a = cal.answer_sets_for(experiments::simulation_of(
        nlohmann::ordered_json::parse(store.header.variant_configs.at(static_cast<std::size_t>(r.variant)))));
    REQUIRE(a != nullptr);
    for (std::size_t k = 0; k < r.steps.size(); ++k) {
      const auto& x = r.steps[k].values;
      if (x[informative] != 1.0) continue;
      const bool holds = a->at(int(k) + 1).p_value(x[gap]) > alpha;
      CHECK((x[covers] == 1.0) == holds);
      checked.insert(r.variant);
      if (decided)
        for (const auto& other : cal.answer_sets)
          if ((other.at(int(k) + 1).p_value(x[gap]) > alpha) != holds) {
            ++*decided;
            break;
          }
    }
  }
  return checked;
}

TEST_CASE("cli calibrate: fits on run stores, and the fit does not depend on the order they are given in") {
  test::TempDir dir("cli_calibrate");
  make_db(dir);
  const std::string fast = " --runs 2 --steps 3 --pool 6 --set ransac.triplets=6 --set ransac.registrations=40"
                           " --set ransac.prune=800 --set bricpsf.hypotheses=20 --set icp.points=64";
  // Two stores exploring the objects in different orders (the second with each object hidden
  // from its own runs).
  const Run a = touchstone(dir, "experiment --db db.h5 --objects box,nut,ball,wedge --seed 2 --out known.h5" + fast);
  REQUIRE_MESSAGE(a.code == 0, a.err);
  const Run b = touchstone(dir, "experiment --db db.h5 --objects wedge,ball,nut,box --seed 4 --set hidden=each"
                                " --out hidden.h5" + fast);
  REQUIRE_MESSAGE(b.code == 0, b.err);
  const Run ab = touchstone(dir, "calibrate known.h5 hidden.h5 --step-ranges 1,3 --out ab.json --progress lines");
  REQUIRE_MESSAGE(ab.code == 0, ab.err);
  CHECK_MESSAGE(ab.err.find("calibrate: stores 1/2 (50.0 %)") != std::string::npos, ab.err);   // a line per store
  CHECK_MESSAGE(ab.err.find("calibrate: stores 2/2 (100.0 %)") != std::string::npos, ab.err);
  const Run ba = touchstone(dir, "calibrate hidden.h5 known.h5 --step-ranges 1,3 --out ba.json --quiet");
  REQUIRE_MESSAGE(ba.code == 0, ba.err);
  CHECK(ba.err.find("calibrate:") == std::string::npos);
  const auto jab = nlohmann::json::parse(test::read_bytes(dir / "ab.json"));
  const auto jba = nlohmann::json::parse(test::read_bytes(dir / "ba.json"));
  CHECK(jab["format"] == "touchstone-calibration");
  CHECK(jab["database_fingerprint"] == experiments::file_fingerprint(io::DbReader(dir / "db.h5")));
  REQUIRE(jab["steps"].size() > 0);
  CHECK(jab["steps"] == jba["steps"]);
  CHECK(jab["open_set_threshold"] == jba["open_set_threshold"]);
  CHECK(jab["open_set_threshold"].is_number());
  CHECK(jab["provenance"]["step_answers"] == 2 * 4 * 3 * 2);
  // Set answers: the true class's gap at each of the 3 steps on the 8 runs of known objects (the
  // hidden store's runs have no true class in the database), whatever the order of the stores.
  REQUIRE(jab["answer_sets"].size() == 1);   // one simulation
  CHECK(jab["answer_sets"] == jba["answer_sets"]);
  CHECK(jab["answer_sets"][0]["alpha"] == 0.05);
  REQUIRE(jab["answer_sets"][0]["steps"].size() == 3);
  for (const auto& st : jab["answer_sets"][0]["steps"]) CHECK(st["runs"] == 8);
  CHECK(jab["answer_sets"][0]["simulation"]["noise"] == "underwater");
  const Run bad_alpha = touchstone(dir, "calibrate known.h5 --step-ranges 1,3 --alpha 1.5 --out bad.json");
  CHECK(bad_alpha.code != 0);
  CHECK(bad_alpha.err.find("--alpha") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "bad.json"));
  const Run half = touchstone(dir, "calibrate known.h5 --step-ranges 1,3 --alpha 0.5 --out half.json");
  REQUIRE_MESSAGE(half.code == 0, half.err);

  // recognize --calibration: each step's set. 8 runs cannot exclude any class at alpha 0.05
  // (ceil(9 * 0.95) = 9 > 8): "any object", said so. At 0.5 the set holds the leader first.
  REQUIRE(touchstone(dir, "simulate --db db.h5 --object wedge --grasps 3 --noise ideal --out log.h5").code == 0);
  const Run any = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --calibration ab.json" + kFastFlags);
  REQUIRE_MESSAGE(any.code == 0, any.err);
  const auto ja = nlohmann::json::parse(any.out);
  const std::size_t objects = io::DbReader(dir / "db.h5").size();
  for (const auto& st : ja["steps"]) {
    CHECK(st["answer_set"]["informative"] == false);
    CHECK(st["answer_set"]["size"] == objects);
    CHECK(st["answer_set"]["members"].empty());
  }
  const Run set = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --calibration half.json" + kFastFlags);
  REQUIRE_MESSAGE(set.code == 0, set.err);
  const auto js = nlohmann::json::parse(set.out);
  REQUIRE(js["steps"].size() == 3);
  for (const auto& st : js["steps"]) {
    const auto& a = st["answer_set"];
    CHECK(a["alpha"] == 0.5);
    CHECK(a["calibrated_step"] == st["step"]);
    if (!a["informative"].get<bool>()) continue;
    REQUIRE(a["members"].size() == a["size"].get<std::size_t>());
    CHECK(a["members"][0]["log_weight_gap"] == 0.0);   // the answer's class (or one weighted above it)
    CHECK(a["members"][0]["p_value"] == 1.0);
    bool has_answer = false;   // the answer is always in its set
    for (const auto& m : a["members"])
      for (const auto& name : m["objects"])
        has_answer = has_answer || name == (st["object"].is_null() ? st["best_guess"] : st["object"]);
    CHECK(has_answer);
    double last = 0.0;
    bool outside = false;   // members without hypotheses (log_weight_gap null) come after the others
    for (const auto& m : a["members"]) {
      CHECK(m["p_value"].get<double>() > 0.5);
      if (m["log_weight_gap"].is_null()) {
        CHECK(m["prior_gap"].get<double>() >= 0.0);
        outside = true;
        continue;
      }
      CHECK_FALSE(outside);
      CHECK(m["log_weight_gap"].get<double>() >= last);
      last = m["log_weight_gap"].get<double>();
    }
  }
  // The result file carries the same sets: per object its class's p-value and membership.
  const Run stored = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --calibration half.json --out rs.h5" + kFastFlags);
  REQUIRE_MESSAGE(stored.code == 0, stored.err);
  const io::ResultData rd = io::read_result(dir / "rs.h5");
  REQUIRE(rd.header.answer_set_alpha);
  CHECK(*rd.header.answer_set_alpha == 0.5);
  CHECK(rd.header.calibration == "half.json");
  REQUIRE(rd.steps.size() == js["steps"].size());
  for (std::size_t k = 0; k < rd.steps.size(); ++k) {
    const auto& a = js["steps"][k]["answer_set"];
    REQUIRE(rd.steps[k].answer_set);
    const io::ResultAnswerSet& b = *rd.steps[k].answer_set;
    CHECK(b.informative == a["informative"].get<bool>());
    CHECK(b.size == a["size"].get<std::size_t>());
    CHECK(b.calibrated_step == a["calibrated_step"].get<int>());
    std::set<std::string> in_json, in_file;
    for (const auto& m : a["members"])
      for (const auto& name : m["objects"]) {
        in_json.insert(name.get<std::string>());
        const auto i = static_cast<std::size_t>(
            std::find(rd.header.objects.begin(), rd.header.objects.end(), name.get<std::string>()) - rd.header.objects.begin());
        REQUIRE(i < rd.header.objects.size());
        CHECK(b.p_value[i] == m["p_value"].get<double>());
        if (m["log_weight_gap"].is_null())   // outside the state: the stored score is 1e6 + the prior's gap
          CHECK(b.log_weight_gap[i] == kOutsideState + m["prior_gap"].get<double>());
        else
          CHECK(b.log_weight_gap[i] == m["log_weight_gap"].get<double>());
      }
    for (std::size_t i = 0; i < b.in_set.size(); ++i) {
      if (b.in_set[i]) in_file.insert(rd.header.objects[i]);
      else CHECK(b.p_value[i] <= 0.5);   // left out: its p-value does not exceed alpha
    }
    if (b.informative) CHECK(in_file == in_json);
    else CHECK(in_file.size() == objects);
  }
  // Without a calibration the file has none.
  REQUIRE(touchstone(dir, "recognize --db db.h5 --log log.h5 --out plain.h5" + kFastFlags).code == 0);
  const io::ResultData plain = io::read_result(dir / "plain.h5");
  CHECK_FALSE(plain.header.answer_set_alpha);
  for (const auto& st : plain.steps) CHECK_FALSE(st.answer_set);

  // --alpha overrides the file's; it needs a calibration with answer sets, within (0, 1).
  const Run tenth = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --calibration half.json --alpha 0.9" + kFastFlags);
  REQUIRE_MESSAGE(tenth.code == 0, tenth.err);
  const auto jt = nlohmann::json::parse(tenth.out);   // named: a range-for over a temporary's member dangles
  for (const auto& st : jt["steps"]) {
    CHECK(st["answer_set"]["alpha"] == 0.9);
    CHECK(st["answer_set"]["size"].get<std::size_t>() <= objects);
  }
  for (const char* flags : {" --alpha 0.1", " --calibration half.json --alpha 0", " --calibration half.json --alpha 1"}) {
    const Run r = touchstone(dir, std::string("recognize --db db.h5 --log log.h5") + flags);
    CHECK(r.code != 0);
    CHECK(r.err.find("--alpha") != std::string::npos);
  }

  // An experiment with the calibration: the report's coverage and set sizes per step; runs
  // simulated otherwise than the calibration's are refused, naming the key.
  const Run ex = touchstone(dir, "experiment --db db.h5 --objects box,nut,ball,wedge --seed 5 --out sets.h5"
                                 " --set calibration=half.json" + fast);
  REQUIRE_MESSAGE(ex.code == 0, ex.err);
  const Run rep = touchstone(dir, "report sets.h5 --json");
  REQUIRE_MESSAGE(rep.code == 0, rep.err);
  const auto jr = nlohmann::json::parse(rep.out);
  for (const auto& row : jr["per_step"]) {
    const double coverage = row["set_coverage"].get<double>();
    CHECK(coverage >= 0.0);
    CHECK(coverage <= 1.0);
    CHECK(coverage * 8 == doctest::Approx(std::round(coverage * 8)));   // a share of the 8 runs
    CHECK(row["set_size_median"].get<double>() >= 1.0);
    CHECK(row["set_size_median"].get<double>() <= double(objects));
    if (row["set_informative_share"] == 0.0) CHECK(coverage == 1.0);   // "any object" holds the truth
  }
  // Each informative set holds the truth exactly when the truth's gap has a p-value above alpha.
  CHECK(variants_whose_sets_hold_their_p_values(dir / "sets.h5", dir / "half.json", 0.5).size() == 1);
  CHECK(touchstone(dir, "report sets.h5").out.find("Set answers") != std::string::npos);
  const Run other = touchstone(dir, "experiment --db db.h5 --objects box --noise ideal --out other.h5"
                                    " --set calibration=half.json" + fast);
  CHECK(other.code != 0);
  CHECK(other.err.find("calibrate on runs like these") != std::string::npos);
  CHECK(other.err.find("answer_sets") != std::string::npos);
  CHECK(other.err.find("half.json") != std::string::npos);

  // A noise sweep: one entry per level of the arm's error, each variant's sets from its own.
  const Run sweep = touchstone(dir, "experiment --db db.h5 --objects box,nut,ball,wedge --seed 6 --out sweep.h5"
                                    " --set sweep.noise.arm_scale=0,2" + fast);
  REQUIRE_MESSAGE(sweep.code == 0, sweep.err);
  const Run two = touchstone(dir, "calibrate sweep.h5 --step-ranges 1,3 --alpha 0.5 --out sweep.json");
  REQUIRE_MESSAGE(two.code == 0, two.err);
  const auto jw = nlohmann::json::parse(test::read_bytes(dir / "sweep.json"));
  REQUIRE(jw["answer_sets"].size() == 2);
  std::set<double> scales;
  for (const auto& e : jw["answer_sets"]) {
    scales.insert(e["simulation"]["noise.arm_scale"].get<double>());
    for (const auto& st : e["steps"]) CHECK(st["runs"] == 8);   // 4 objects x 2 runs of its level alone
  }
  CHECK(scales == std::set<double>{0.0, 2.0});
  for (const auto& e : jw["answer_sets"]) CHECK(e["tie_nats"] == 0.0);   // none by default
  const Run tie = touchstone(dir, "calibrate sweep.h5 --step-ranges 1,3 --alpha 0.5 --tie-nats 0.001 --out tie.json");
  REQUIRE_MESSAGE(tie.code == 0, tie.err);
  const auto jt2 = nlohmann::json::parse(test::read_bytes(dir / "tie.json"));
  for (const auto& e : jt2["answer_sets"]) CHECK(e["tie_nats"] == 0.001);   // each entry
  const Run tied = touchstone(dir, "experiment --db db.h5 --objects box,nut,ball,wedge --seed 7 --out tied.h5"
                                   " --set sweep.noise.arm_scale=0,2 --set calibration=tie.json" + fast);
  REQUIRE_MESSAGE(tied.code == 0, tied.err);   // its sets as the tie scores them
  CHECK(variants_whose_sets_hold_their_p_values(dir / "tied.h5", dir / "tie.json", 0.5).size() == 2);
  CHECK(touchstone(dir, "calibrate sweep.h5 --tie-nats -1 --out bad_tie.json").code != 0);
  CHECK_FALSE(fs::exists(dir / "bad_tie.json"));
  // The levels' runs differ (an arm error of 0 against 6 mm): so do their scores.
  CHECK(jw["answer_sets"][0]["steps"] != jw["answer_sets"][1]["steps"]);
  const Run judged = touchstone(dir, "experiment --db db.h5 --objects box,nut,ball,wedge --seed 7 --out judged.h5"
                                     " --set sweep.noise.arm_scale=0,2 --set calibration=sweep.json" + fast);
  REQUIRE_MESSAGE(judged.code == 0, judged.err);
  std::size_t decided = 0;   // rows where the other level's entry would have judged otherwise
  CHECK(variants_whose_sets_hold_their_p_values(dir / "judged.h5", dir / "sweep.json", 0.5, &decided).size() == 2);
  CHECK(decided > 0);
  // A level the calibration has no entry for, and data without a simulation, are refused.
  const Run third = touchstone(dir, "experiment --db db.h5 --objects box --out third.h5"
                                    " --set sweep.noise.arm_scale=0,1 --set calibration=sweep.json" + fast);
  CHECK(third.code != 0);
  CHECK(third.err.find("calibrate on runs like these") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "third.h5"));
  // recognize: a log names no simulation. With --alpha, an error naming the simulations; without,
  // the calibration's confidences and no sets, said so.
  const Run log_sets = touchstone(dir, "recognize --db db.h5 --log log.h5 --calibration sweep.json --alpha 0.5" + kFastFlags);
  CHECK(log_sets.code != 0);
  CHECK(log_sets.err.find("2 simulations") != std::string::npos);
  CHECK(log_sets.err.find("noise.arm_scale") != std::string::npos);
  const Run no_sets = touchstone(dir, "recognize --db db.h5 --log log.h5 --json --calibration sweep.json" + kFastFlags);
  REQUIRE_MESSAGE(no_sets.code == 0, no_sets.err);
  CHECK(no_sets.err.find("no set answers") != std::string::npos);
  const auto jn = nlohmann::json::parse(no_sets.out);
  REQUIRE(jn["steps"].size() == 3);
  for (const auto& st : jn["steps"]) {
    CHECK(st["answer_set"].is_null());
    CHECK(st["confidence"]["object"].is_number());
  }
  // Variants that simulate alike but differ otherwise would pool unlike runs: refused.
  const Run method = touchstone(dir, "experiment --db db.h5 --objects box,nut --seed 8 --out method.h5"
                                     " --set sweep.bricpsf.hypotheses=10,20" + fast);
  REQUIRE_MESSAGE(method.code == 0, method.err);
  const Run pooled = touchstone(dir, "calibrate method.h5 --out method.json");
  CHECK(pooled.code != 0);
  CHECK(pooled.err.find("simulate alike") != std::string::npos);
  CHECK(pooled.err.find("/header/variant_labels") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "method.json"));
}
