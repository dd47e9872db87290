// `touchstone simulate`, `log info`, `log export` run as a user runs them: JSON keys of the
// interface contract, byte-identical logs for any --threads, exported clouds, clear errors.
#include "io/cloud_io.hpp"
#include "io/db_store.hpp"
#include "io/h5.hpp"
#include "io/log_store.hpp"
#include "cli_run.hpp"
#include "mesh_fixtures.hpp"
#include "ros2_recording.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <fstream>
#include <sys/wait.h>

using namespace ts;

namespace {
using Run = ts::test::CliRun;
using ts::test::touchstone;

BuiltObject object(const std::string& name, Mesh mesh) {
  BuiltObject o;
  o.info.name = name;
  o.info.source = "test";
  o.info.mesh_sha256 = std::string(64, '0');
  o.info.closed = true;
  o.info.extent = mesh_bounds(mesh).sizes();
  o.mesh = std::move(mesh);
  SparseGrid g;
  g.voxel = 0.01;
  g.ijk = {{0, 0, 0}};
  g.value = {0.0f};
  o.field = DistanceField::from_sparse(g, g, true, 0.2);
  return o;
}

std::filesystem::path make_db(const test::TempDir& dir) {
  const auto path = dir / "db.h5";
  std::vector<BuiltObject> objects;
  objects.push_back(object("ball", test::icosphere_mesh(0.05, 2)));
  objects.push_back(object("brick", test::box_mesh({-0.08, -0.04, -0.03}, {0.08, 0.04, 0.03})));
  std::vector<io::StoredObject> stored;
  for (const auto& o : objects) stored.push_back({&o, 1});
  io::write_database(path, stored, DatabaseSettings{}, 1);
  return path;
}
}  // namespace

TEST_CASE("simulate -> log info -> log export") {
  test::TempDir dir("cli");
  const auto db = make_db(dir);
  const auto log = dir / "ball.h5";
  Run r = touchstone(dir, "simulate --db " + db.string() + " --object ball --grasps 12 --noise underwater --seed 4 --out " +
                              log.string() + " --json");
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const auto sim = nlohmann::json::parse(r.out);
  CHECK(sim["grasps"] == 12);
  CHECK(sim["sensors"] == 1);

  r = touchstone(dir, "log info " + log.string() + " --json");
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const auto info = nlohmann::json::parse(r.out);
  for (const char* key : {"object", "grasps", "contacts_per_grasp", "ground_truth", "noise", "sensors"})
    CHECK_MESSAGE(info.contains(key), key);
  CHECK(info["object"] == "ball");
  CHECK(info["grasps"] == 12);
  CHECK(info["noise"] == "underwater");
  CHECK(info["sensors"] == 1);
  REQUIRE(info["contacts_per_grasp"].size() == 12);
  std::size_t contacts = 0;
  for (const auto& n : info["contacts_per_grasp"]) contacts += n.get<std::size_t>();
  CHECK(contacts == sim["contacts"].get<std::size_t>());
  CHECK(info["ground_truth"]["t"].size() == 3);
  CHECK(info["ground_truth"]["q"].size() == 4);
  const TactileLog read = io::read_log(log);
  CHECK(info["ground_truth"]["t"][0].get<double>() == doctest::Approx(read.truth->object_pose.translation().x()));

  r = touchstone(dir, "log info " + log.string());
  CHECK(r.code == 0);
  CHECK(r.out.find("underwater") != std::string::npos);

  const auto ply = dir / "c.ply", pcd = dir / "f.pcd";
  r = touchstone(dir, "log export " + log.string() + " --grasps 8 --out " + ply.string() + " --free " + pcd.string() + " --json");
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const auto ex = nlohmann::json::parse(r.out);
  CHECK(ex["grasps"] == 8);
  const PointCloud c = io::read_cloud(ply), f = io::read_cloud(pcd);
  CHECK(c.size() == ex["contacts"].get<std::size_t>());
  CHECK(f.size() == ex["free_points"].get<std::size_t>());
  CHECK(c.size() > 0);
  CHECK(f.size() > 0);
  const auto clouds = exploration_clouds(read, 8);
  CHECK(c.points.size() == clouds.contacts.points.size());
}

TEST_CASE("same seed: byte-identical logs for --threads 1 and 2") {
  test::TempDir dir("cli");
  const auto db = make_db(dir);
  for (const char* threads : {"1", "2"}) {
    const Run r = touchstone(dir, "simulate --db " + db.string() + " --object brick --grasps 8 --sensors 6 --noise deepsea --seed 9 --threads " +
                                      threads + " --out " + (dir / (std::string("t") + threads + ".h5")).string());
    REQUIRE_MESSAGE(r.code == 0, r.err);
  }
  CHECK(test::read_bytes(dir / "t1.h5") == test::read_bytes(dir / "t2.h5"));
}

TEST_CASE("simulate's noise overrides reach the log, and its source reproduces it") {
  test::TempDir dir("cli");
  const auto db = make_db(dir);
  const std::string base = "simulate --db " + db.string() + " --object brick --grasps 6 --noise underwater --seed 3";
  Run r = touchstone(dir, base + " --out " + (dir / "plain.h5").string());
  REQUIRE_MESSAGE(r.code == 0, r.err);
  r = touchstone(dir, base + " --joint-sigma 0.5 --lateral-sigma 0.001 --out " + (dir / "noisy.h5").string());
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const TactileLog plain = io::read_log(dir / "plain.h5"), noisy = io::read_log(dir / "noisy.h5");
  REQUIRE(plain.grasps.size() == noisy.grasps.size());
  bool joints_differ = false, tactile_differ = false;
  for (std::size_t g = 0; g < plain.grasps.size(); ++g) {
    joints_differ = joints_differ || plain.grasps[g].joints != noisy.grasps[g].joints;
    tactile_differ = tactile_differ || plain.grasps[g].tactile != noisy.grasps[g].tactile;
  }
  CHECK(joints_differ);    // --joint-sigma: the finger joint readings
  CHECK(tactile_differ);   // --lateral-sigma: where the sensels sample the surface
  const std::string source = io::h5::File::open(dir / "noisy.h5").root().string_attribute("source");
  CHECK(source.find("--joint-sigma 0.5") != std::string::npos);
  CHECK(source.find("--lateral-sigma 0.001") != std::string::npos);
  // The recorded command, run again with the database and output added, writes the same bytes.
  const std::string again = source.substr(std::string("touchstone ").size());
  r = touchstone(dir, again.substr(0, again.find(" --object")) + " --db " + db.string() +
                          again.substr(again.find(" --object")) + " --out " + (dir / "again.h5").string());
  REQUIRE_MESSAGE(r.code == 0, r.err);
  CHECK(test::read_bytes(dir / "again.h5") == test::read_bytes(dir / "noisy.h5"));
}

TEST_CASE("bad input: one error line, exit 1 (usage: 2), no output left behind") {
  test::TempDir dir("cli");
  const auto db = make_db(dir);
  const auto out = dir / "x.h5";
  Run r = touchstone(dir, "simulate --db " + db.string() + " --object teapot --grasps 3 --out " + out.string());
  CHECK(r.code == 1);
  CHECK(r.err.rfind("touchstone: error: unknown object 'teapot'", 0) == 0);
  CHECK(r.err.find(db.string()) != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(out));
  r = touchstone(dir, "simulate --db " + (dir / "none.h5").string() + " --object ball --grasps 3 --out " + out.string());
  CHECK(r.code == 1);
  CHECK_FALSE(std::filesystem::exists(out));
  r = touchstone(dir, "simulate --db " + db.string() + " --object ball --grasps 3 --sensors 3 --out " + out.string());
  CHECK(r.code == 2);
  r = touchstone(dir, "simulate --db " + db.string() + " --object ball --grasps 3 --noise murky --out " + out.string());
  CHECK(r.code == 2);
  test::write_text(dir / "g.json", "{\"name\": \"broken\", \"fingers\": [");
  r = touchstone(dir, "simulate --db " + db.string() + " --object ball --grasps 3 --gripper " + (dir / "g.json").string() +
                          " --out " + out.string());
  CHECK(r.code == 1);
  CHECK(r.err.find("g.json") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(out));
  // A database is not a log.
  r = touchstone(dir, "log info " + db.string());
  CHECK(r.code == 1);
  CHECK(r.err.rfind("touchstone: error: not a Touchstone tactile log", 0) == 0);
  r = touchstone(dir, "log export " + db.string() + " --out " + (dir / "c.ply").string());
  CHECK(r.code == 1);
  CHECK_FALSE(std::filesystem::exists(dir / "c.ply"));
  r = touchstone(dir, "log export " + db.string() + " --out " + (dir / "c.xyz").string());
  CHECK(r.code == 1);
}

TEST_CASE("log topics lists a ROS 2 recording's channels (MCAP), and names a damaged one") {
  ts::test::TempDir dir("topics");
  const std::string corpus = TS_SOURCE_DIR "/tests/fuzz/corpus/mcap/";
  const Run r = touchstone(dir, "log topics --json '" + corpus + "chunk-zstd.mcap'");
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["profile"] == "ros2");
  CHECK(j["messages"] == 12);
  CHECK(j["chunks"] == 1);
  REQUIRE(j["topics"].size() == 1);
  CHECK(j["topics"][0]["topic"] == "/touch");
  CHECK(j["topics"][0]["schema"] == "std_msgs/msg/UInt8MultiArray");
  CHECK(j["topics"][0]["messages"] == 12);
  CHECK(j["topics"][0]["first_log_time_ns"] == 100);
  CHECK(j["topics"][0]["last_log_time_ns"] == 111);
  CHECK(j["data_section_crc_checked"] == true);
  const Run text = touchstone(dir, "log topics '" + corpus + "plain-attachment-metadata.mcap'");
  CHECK(text.code == 0);
  CHECK(text.out.find("/arm/eef_pose") != std::string::npos);
  // Cut short: one error line naming the file, exit 1.
  const std::string full = ts::test::read_bytes(corpus + "chunk-zstd.mcap");
  ts::test::write_text(dir / "cut.mcap", full.substr(0, full.size() / 2));
  const Run cut = touchstone(dir, "log topics cut.mcap");
  CHECK(cut.code == 1);
  CHECK(cut.err.find("cut.mcap") != std::string::npos);
  CHECK(cut.err.find("truncated") != std::string::npos);
}

TEST_CASE("log import: a recording of a simulated log becomes that log again") {
  ts::test::TempDir dir("import");
  const Run sim = touchstone(dir, "simulate --db '" + make_db(dir).string() + "' --object brick --grasps 5 --noise underwater --seed 2 --out sim.h5");
  REQUIRE(sim.code == 0);
  const TactileLog log = io::read_log(dir / "sim.h5");
  ts::test::record_ros2(log, dir / "rec.mcap");
  const Run r = touchstone(dir, "log import rec.mcap --map '" TS_SOURCE_DIR "/datasets/ros2/map.toml' --out imported.h5 --json");
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["grasps"] == 5);
  {  // The output against docs/schemas/log-import.schema.json (flat: its required keys and their
     // types; tests/scripts/test_schemas.py validates every other command's output in full).
    std::ifstream in(TS_SOURCE_DIR "/docs/schemas/log-import.schema.json");
    const auto schema = nlohmann::json::parse(in);
    auto type_of = [](const nlohmann::json& v) -> std::string {
      return v.is_null() ? "null" : v.is_boolean() ? "boolean" : v.is_number_integer() ? "integer"
           : v.is_number() ? "number" : v.is_string() ? "string" : v.is_array() ? "array" : "object";
    };
    REQUIRE(!schema["required"].empty());
    for (const auto& key : schema["required"]) {
      REQUIRE_MESSAGE(j.contains(key.get<std::string>()), key);
      auto allowed = schema["properties"][key.get<std::string>()]["type"];
      if (!allowed.is_array()) allowed = nlohmann::json::array({allowed});
      const std::string t = type_of(j[key.get<std::string>()]);
      bool ok = false;
      for (const auto& a : allowed) ok = ok || a == t || (a == "number" && t == "integer");
      CHECK_MESSAGE(ok, key << " is " << t);
    }
  }
  const TactileLog back = io::read_log(dir / "imported.h5");
  REQUIRE(back.grasps.size() == 5);
  for (std::size_t g = 0; g < 5; ++g) {
    CHECK((back.grasps[g].arm_pose.matrix() - log.grasps[g].arm_pose.matrix()).cwiseAbs().maxCoeff() < 1e-12);
    CHECK(back.grasps[g].tactile == log.grasps[g].tactile);
  }
  // A map naming a topic the recording lacks: one error naming the recording, nothing written.
  ts::test::write_text(dir / "map.toml", "[arm]\ntopic = \"/arm/eef_pose\"\n[joints]\ntopic = \"/hand/joint_states\"\n"
                                         "[tactile]\ntopic = \"/hand/touch\"\n");
  const Run missing = touchstone(dir, "log import rec.mcap --map map.toml --out missing.h5");
  CHECK(missing.code == 1);
  CHECK(missing.err.find("rec.mcap") != std::string::npos);
  CHECK(missing.err.find("/hand/touch") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir / "missing.h5"));
}
