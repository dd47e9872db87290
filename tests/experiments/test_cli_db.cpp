// `touchstone db ...` end to end: the built program on small generated meshes.
#include "experiments/allocator.hpp"
#include "io/cloud_io.hpp"
#include "io/db_store.hpp"
#include "io/h5.hpp"
#include "cli_run.hpp"
#include "mesh_fixtures.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <numbers>
#include <thread>
#include <filesystem>

namespace fs = std::filesystem;
using ts::test::TempDir;

namespace {

using Run = ts::test::CliRun;
using ts::test::touchstone;

// Coarse parameters: the tests check plumbing, determinism and errors, not accuracy.
const std::string kFast =
    " --fine-spacing 0.006 --coarse-voxel 0.02 --max-views 24 --normal-radius 0.015"
    " --feature-radius 0.03 --field-voxel 0.01 --field-band 2 --field-coarse-voxel 0.04 --field-margin 0.04";

/// Three small meshes in dir/meshes: a box, an (inside-out) sphere and a thin bar.
void write_meshes(const TempDir& dir) {
  fs::create_directories(dir / "meshes");
  ts::test::write_off(dir / "meshes/box.off", ts::test::box_mesh({0, 0, 0}, {3, 2, 1}));
  ts::test::write_off(dir / "meshes/ball.off", ts::test::flipped(ts::test::icosphere_mesh(5.0, 2, {1, 2, 3})));
  ts::test::write_off(dir / "meshes/bar.off", ts::test::box_mesh({-1, -1, -10}, {1, 1, 10}));
}

bool leftovers(const fs::path& dir) {
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos) return true;
  return false;
}

}  // namespace

TEST_CASE("Machine: the cost of first touching fresh memory is a positive time per MB") {
  // The benchmarks print it beside the machine line. Writing 4 MB of fresh pages takes some
  // time; nothing to write costs nothing.
  const double t = ts::experiments::first_touch_ms_per_mb(4);
  CHECK(std::isfinite(t));
  CHECK(t > 0.0);
  CHECK(t < 1000.0);   // a second per MB would be a broken measurement, not a slow machine
  CHECK(ts::experiments::first_touch_ms_per_mb(0) == 0.0);
}

TEST_CASE("cli db: build is byte-identical for any --threads; info lists every object") {
  TempDir dir("cli");
  write_meshes(dir);
  const auto a = touchstone(dir, "db build --meshes meshes --out t1.h5 --threads 1" + kFast);
  REQUIRE_MESSAGE(a.code == 0, a.err);
  // A process: the machine line names the allocator the program runs on.
  const auto b = ts::test::touchstone_process(dir, "db build --meshes meshes --out t2.h5 --threads 2 --json" + kFast);
  REQUIRE_MESSAGE(b.code == 0, b.err);
  CHECK(ts::test::read_bytes(dir / "t1.h5") == ts::test::read_bytes(dir / "t2.h5"));
  CHECK(b.err.find("per stage") != std::string::npos);
  const auto built = nlohmann::json::parse(b.out);
  CHECK(built["objects"] == nlohmann::json({"ball", "bar", "box"}));
  CHECK(built["times_s"].contains("scan"));
  // The machine line names the allocator the program was built with (TS_SCALABLE_MALLOC).
  const std::string machine = built["machine"].get<std::string>();
  CHECK_MESSAGE(machine.ends_with(std::string(", ") + TS_EXPECT_ALLOCATOR), machine);

  // Progress: plain lines (not a terminal), the last complete; JSON lines; nothing with --quiet.
  CHECK_MESSAGE(a.err.find("db build: objects 3/3 (100.0 %)") != std::string::npos, a.err);
  const auto js = touchstone(dir, "db build --meshes meshes --out t3.h5 --threads 1 --progress json" + kFast);
  REQUIRE_MESSAGE(js.code == 0, js.err);
  std::size_t progress_lines = 0;
  for (std::size_t at = 0, end; (end = js.err.find('\n', at)) != std::string::npos; at = end + 1)
    if (js.err.compare(at, 13, "{\"progress\":\"") == 0) {
      const auto j = nlohmann::json::parse(js.err.substr(at, end - at));
      CHECK(j["progress"] == "db build");
      CHECK(j["total"] == 3);
      ++progress_lines;
    }
  CHECK(progress_lines == 3);   // the first, then 5 % steps: every object of 3
  const auto quiet = touchstone(dir, "db build --meshes meshes --out t4.h5 --threads 1 --quiet" + kFast);
  REQUIRE_MESSAGE(quiet.code == 0, quiet.err);
  CHECK(quiet.err.find("db build:") == std::string::npos);
  CHECK(ts::test::read_bytes(dir / "t1.h5") == ts::test::read_bytes(dir / "t4.h5"));

  const auto info = touchstone(dir, "db info t1.h5 --json");
  REQUIRE(info.code == 0);
  const auto j = nlohmann::json::parse(info.out);
  CHECK(j["schema_version"] == ts::io::kDbSchemaVersion);
  REQUIRE(j["objects"].size() == 3);
  for (const auto& o : j["objects"]) {
    CHECK(o["extent_m"].size() == 3);
    const double largest = std::max({o["extent_m"][0].get<double>(), o["extent_m"][1].get<double>(),
                                     o["extent_m"][2].get<double>()});
    CHECK(largest == doctest::Approx(0.2));
    CHECK(o["fine_points"].get<int>() > 0);
    CHECK(o["coarse_points"].get<int>() > 0);
    CHECK(o["feature_dim"] == 33);
  }
  CHECK(j["objects"][0]["name"] == "ball");
  CHECK(j["params"]["max_extent"] == 0.2);
  CHECK(j["params"]["scan"]["fine_spacing"] == 0.006);
  CHECK(j["params"]["seed"] == 1);

  const auto human = touchstone(dir, "db info t1.h5");
  CHECK(human.code == 0);
  CHECK(human.out.find("3 objects") != std::string::npos);
  CHECK(human.out.find("bar") != std::string::npos);

  // A different seed gives a different database.
  REQUIRE(touchstone(dir, "db build --meshes meshes --out t3.h5 --seed 2" + kFast).code == 0);
  CHECK(ts::test::read_bytes(dir / "t1.h5") != ts::test::read_bytes(dir / "t3.h5"));
}

TEST_CASE("cli db: add builds the object as build would, and refuses duplicates without touching the file") {
  TempDir dir("cli");
  write_meshes(dir);
  REQUIRE(touchstone(dir, "db build --meshes meshes --out all.h5" + kFast).code == 0);
  // A manifest with two of them, in another order.
  ts::test::write_text(dir / "two.tsv", "# two objects\ntest\tmeshes/box.off\tbox\ntest\tmeshes/bar.off\tbar\n");
  REQUIRE(touchstone(dir, "db build --manifest two.tsv --out two.h5" + kFast).code == 0);
  const auto add = touchstone(dir, "db add two.h5 meshes/ball.off --threads 1");
  REQUIRE_MESSAGE(add.code == 0, add.err);
  {
    ts::io::DbReader all(dir / "all.h5"), two(dir / "two.h5");
    REQUIRE(two.size() == 3);
    CHECK(two.info(2).name == "ball");
    CHECK(two.settings().scan.fine_spacing == 0.006);  // built with the database's parameters
    for (const char* name : {"ball", "bar", "box"}) {
      CAPTURE(std::string(name));
      const auto i = all.find(name), k = two.find(name);
      CHECK(all.load_fine(i).points == two.load_fine(k).points);
      CHECK(all.load_features(i).features == two.load_features(k).features);
      CHECK(all.load_mesh(i).vertices == two.load_mesh(k).vertices);
    }
  }
  const auto before = ts::test::read_bytes(dir / "two.h5");
  const auto dup = touchstone(dir, "db add two.h5 meshes/box.off");
  CHECK(dup.code == 1);
  CHECK(dup.err == "touchstone: error: object 'box' already exists in the database (two.h5)\n");
  const auto dup2 = touchstone(dir, "db add two.h5 meshes/ball.off --name bar");
  CHECK(dup2.code == 1);
  CHECK(ts::test::read_bytes(dir / "two.h5") == before);
  const auto missing = touchstone(dir, "db add two.h5 meshes/none.off");
  CHECK(missing.code == 1);
  CHECK(missing.err.find("does not exist") != std::string::npos);
  CHECK(ts::test::read_bytes(dir / "two.h5") == before);
  CHECK_FALSE(leftovers(dir.path()));
}

TEST_CASE("cli db: --scale keep with --units and per-line units; db add keeps the database's scale") {
  TempDir dir("cli");
  fs::create_directories(dir / "meshes");
  ts::test::write_off(dir / "meshes/plate.off", ts::test::box_mesh({0, 0, 0}, {120, 80, 10}));   // mm
  ts::test::write_off(dir / "meshes/peg.off", ts::test::box_mesh({0, 0, 0}, {2, 2, 6}));        // cm
  ts::test::write_text(dir / "m.tsv", "t\tmeshes/plate.off\tplate\nt\tmeshes/peg.off\tpeg\tcm\n");
  const auto b = touchstone(dir, "db build --manifest m.tsv --out k.h5 --scale keep --units mm" + kFast);
  REQUIRE_MESSAGE(b.code == 0, b.err);
  const auto info = nlohmann::json::parse(touchstone(dir, "db info k.h5 --json").out);
  CHECK(info["params"]["scale"] == "keep");
  CHECK(info["objects"][0]["extent_m"][0].get<double>() == doctest::Approx(0.12).epsilon(1e-9).scale(0));
  CHECK(info["objects"][0]["scale"].get<double>() == 0.001);
  CHECK(info["objects"][1]["extent_m"][2].get<double>() == doctest::Approx(0.06).epsilon(1e-9).scale(0));
  CHECK(touchstone(dir, "db info k.h5").out.find("real sizes (scale keep)") != std::string::npos);
  // db add: the database's scale, the mesh's --units.
  const auto add = touchstone(dir, "db add k.h5 meshes/peg.off --name peg_mm --units mm");
  REQUIRE_MESSAGE(add.code == 0, add.err);
  CHECK(ts::io::DbReader(dir / "k.h5").info(2).extent.z() == doctest::Approx(0.006).epsilon(1e-9).scale(0));
  // A units mistake: one error naming the manifest line, exit 1, nothing written.
  const auto bad = touchstone(dir, "db build --manifest m.tsv --out bad.h5 --scale keep --units m" + kFast);
  CHECK(bad.code == 1);
  CHECK(bad.err.find("(m.tsv, line 1, units)") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "bad.h5"));
  const auto word = touchstone(dir, "db build --manifest m.tsv --out bad.h5 --scale keep --units ft" + kFast);
  CHECK(word.code == 2);
  const auto scale = touchstone(dir, "db build --manifest m.tsv --out bad.h5 --scale real" + kFast);
  CHECK(scale.code == 2);
  // Units under fit are only a warning: fitted objects have no size of their own.
  const auto fit = touchstone(dir, "db build --manifest m.tsv --out f.h5 --units cm" + kFast);
  REQUIRE(fit.code == 0);
  CHECK(fit.err.find("--units has no effect under --scale fit") != std::string::npos);
  CHECK(nlohmann::json::parse(touchstone(dir, "db info f.h5 --json").out)["params"]["scale"] == "fit");
}

TEST_CASE("cli db: export writes PLY and PCD clouds with normals") {
  TempDir dir("cli");
  write_meshes(dir);
  REQUIRE(touchstone(dir, "db build --meshes meshes --out db.h5" + kFast).code == 0);
  REQUIRE(touchstone(dir, "db export db.h5 --object box --out box.ply").code == 0);
  REQUIRE(touchstone(dir, "db export db.h5 --object box --cloud coarse --out box.pcd --ascii").code == 0);
  ts::io::DbReader db(dir / "db.h5");
  const auto fine = ts::io::read_cloud(dir / "box.ply");
  CHECK(fine.size() == db.info(db.find("box")).fine_points);
  CHECK(fine.has_normals());
  const auto coarse = ts::io::read_cloud(dir / "box.pcd");
  CHECK(coarse.size() == db.info(db.find("box")).coarse_points);
  CHECK(coarse.has_normals());
  const auto none = touchstone(dir, "db export db.h5 --object nope --out n.ply");
  CHECK(none.code == 1);
  CHECK(none.err.find("no object 'nope'") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "n.ply"));
}

TEST_CASE("cli db: --descriptor pfh|shot|spin builds, info shows it, db add and recognize use it") {
  TempDir dir("cli");
  write_meshes(dir);
  REQUIRE(touchstone(dir, "db build --meshes meshes --out fpfh.h5" + kFast).code == 0);
  const ts::io::DbReader fpfh(dir / "fpfh.h5");
  const std::vector<std::pair<std::string, int>> kinds = {{"pfh", 125}, {"shot", 352}, {"spin", 153}};
  for (const auto& [name, dim] : kinds) {
    CAPTURE(name);
    const std::string db = name + ".h5";
    const auto b = touchstone(dir, "db build --meshes meshes --out " + db + " --descriptor " + name + kFast);
    REQUIRE_MESSAGE(b.code == 0, b.err);
    const auto j = nlohmann::json::parse(touchstone(dir, "db info " + db + " --json").out);
    CHECK(j["params"]["descriptor"] == name);
    for (const auto& o : j["objects"]) CHECK(o["feature_dim"] == dim);
    CHECK(touchstone(dir, "db info " + db).out.find("descriptor " + name) != std::string::npos);

    // Only the features differ from the FPFH database: the same scan; keypoints are scan points
    // (voxel representatives; one without a usable neighbourhood is left out).
    const ts::io::DbReader other(dir / db);
    REQUIRE(other.size() == fpfh.size());
    for (std::size_t i = 0; i < other.size(); ++i) {
      CHECK(other.load_fine(i).points == fpfh.load_fine(i).points);
      const auto a = other.load_features(i), f = fpfh.load_features(i);
      CHECK(a.features.dim() == dim);
      CHECK(a.features.size() == a.coarse.size());
      CHECK(a.coarse.size() > 0);
      const auto fine = other.load_fine(i).points;
      std::size_t on_scan = 0;
      for (const auto& p : a.coarse.points) on_scan += std::find(fine.begin(), fine.end(), p) != fine.end();
      CHECK(on_scan == a.coarse.size());
      CHECK(f.features.dim() == 33);
      bool nonzero = false;
      for (float v : a.features.values()) nonzero = nonzero || v != 0.0f;
      CHECK(nonzero);
    }

    // db add builds the new object with the database's descriptor.
    ts::test::write_text(dir / ("one_" + name + ".tsv"), "test\tmeshes/box.off\tbox\n");
    REQUIRE(touchstone(dir, "db build --manifest one_" + name + ".tsv --out one_" + db + " --descriptor " + name +
                                kFast).code == 0);
    const auto add = touchstone(dir, "db add one_" + db + " meshes/ball.off");
    REQUIRE_MESSAGE(add.code == 0, add.err);
    const ts::io::DbReader grown(dir / ("one_" + db));
    CHECK(grown.settings().descriptor == other.settings().descriptor);
    CHECK(grown.load_features(grown.find("ball")).features == other.load_features(other.find("ball")).features);

    // A query on this database computes the same descriptor at its contacts.
    REQUIRE(touchstone(dir, "simulate --db " + db + " --object box --grasps 4 --noise ideal --seed 3 --out log_" +
                                db).code == 0);
    const auto r = touchstone(dir, "recognize --db " + db + " --log log_" + db +
                                       " --json -N 6 -R 40 -W 800 --n-p 20 --icp-points 64");
    REQUIRE_MESSAGE(r.code == 0, r.err);
    const auto steps = nlohmann::json::parse(r.out)["steps"];
    REQUIRE(steps.size() == 4);
    CHECK(steps[3]["object"].is_string());
  }
  const auto bad = touchstone(dir, "db build --meshes meshes --out bad.h5 --descriptor sift" + kFast);
  CHECK(bad.code != 0);
  CHECK(bad.err.find("sift") != std::string::npos);
  CHECK(!fs::exists(dir / "bad.h5"));
}

TEST_CASE("cli db: bad input gives one error line, exit 1, and no output file") {
  TempDir dir("cli");
  write_meshes(dir);
  ts::test::write_text(dir / "short.tsv", "test\tmeshes/box.off\n");
  auto r = touchstone(dir, "db build --manifest short.tsv --out x.h5");
  CHECK(r.code == 1);
  CHECK(r.err == "touchstone: error: manifest line has 2 fields, expected source<TAB>path<TAB>name[<TAB>units] (short.tsv, line 1)\n");

  ts::test::write_text(dir / "missing.tsv", "test\tmeshes/box.off\tbox\ntest\tmeshes/gone.off\tgone\n");
  r = touchstone(dir, "db build --manifest missing.tsv --out x.h5");
  CHECK(r.code == 1);
  CHECK(r.err.find("mesh file does not exist") != std::string::npos);
  CHECK(r.err.find("missing.tsv, line 2") != std::string::npos);

  ts::test::write_text(dir / "meshes/broken.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n");  // cut short
  r = touchstone(dir, "db build --meshes meshes --out x.h5" + kFast);
  CHECK(r.code == 1);
  CHECK(r.err.find("broken.off") != std::string::npos);
  CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
  fs::remove(dir / "meshes/broken.off");
  CHECK_FALSE(fs::exists(dir / "x.h5"));

  // Corrupt, truncated and foreign files given to db info.
  REQUIRE(touchstone(dir, "db build --meshes meshes --out good.h5" + kFast).code == 0);
  const auto good = ts::test::read_bytes(dir / "good.h5");
  std::string corrupt = good;
  for (std::size_t i = 8; i < 600; ++i) corrupt[i] = static_cast<char>(corrupt[i] ^ 0x3c);
  ts::test::write_text(dir / "corrupt.h5", corrupt);
  r = touchstone(dir, "db info corrupt.h5");
  CHECK(r.code == 1);
  CHECK(r.err.rfind("touchstone: error: ", 0) == 0);
  CHECK(r.err.find("(corrupt.h5") != std::string::npos);
  ts::test::write_text(dir / "cut.h5", good.substr(0, good.size() / 2));
  r = touchstone(dir, "db info cut.h5");
  CHECK(r.code == 1);
  CHECK(r.err.find("truncated") != std::string::npos);
  r = touchstone(dir, "db info missing.tsv");
  CHECK(r.code == 1);
  CHECK(r.err == "touchstone: error: not an HDF5 file (missing.tsv)\n");
  r = touchstone(dir, "db info nothing.h5 --json");
  CHECK(r.code == 1);
  CHECK(r.out.empty());
  CHECK_FALSE(leftovers(dir.path()));
}

TEST_CASE("cli db: build on a folder holding the fuzzed OFF4 mesh gives one error naming it, and no database") {
  // Issue 62: "OFF4 1111111111111..." (94 bytes) made Assimp allocate 48 GB, and db build said
  // "cannot read the mesh: std::bad_alloc" (the corpus file's first byte chose the .off name).
  TempDir dir("cli");
  write_meshes(dir);
  const std::string off4 =
      ts::test::read_bytes(fs::path(TS_SOURCE_DIR) / "tests/fuzz/corpus/mesh/finding-off-keyword-glued-to-count").substr(1);
  ts::test::write_text(dir / "meshes/off4.off", off4);
  const auto r = touchstone(dir, "db build --meshes meshes --out x.h5" + kFast);
  CHECK(r.code == 1);
  CHECK(r.err ==
        "touchstone: error: OFF header declares 1111111111111 faces, more than the 94 bytes of the file can hold "
        "(meshes/off4.off, header, faces)\n");
  CHECK_FALSE(fs::exists(dir / "x.h5"));
  CHECK_FALSE(leftovers(dir.path()));
}

TEST_CASE("cli db: usage errors exit 2") {
  TempDir dir("cli");
  CHECK(touchstone(dir, "db build --meshes m --out x.h5 --frobnicate").code == 2);
  CHECK(touchstone(dir, "db build --out x.h5").code == 2);                          // no source
  CHECK(touchstone(dir, "db build --manifest a.tsv --meshes m --out x.h5").code == 2);  // two sources
  CHECK(touchstone(dir, "db build --meshes m").code == 2);                           // no --out
  CHECK(touchstone(dir, "db build --meshes m --out x.h5 --fine-spacing -1").code == 2);
  CHECK(touchstone(dir, "db info").code == 2);
  CHECK(touchstone(dir, "db export db.h5 --object a --out a.ply --cloud medium").code == 2);
  CHECK(touchstone(dir, "db").code == 2);
  CHECK(touchstone(dir, "db info --help").code == 0);
}

TEST_CASE("cli: --threads and --seed only where they mean something; elsewhere hidden, taken, with a note") {
  TempDir dir("cli");
  write_meshes(dir);
  REQUIRE(touchstone(dir, "db build --meshes meshes --out db.h5 --quiet" + kFast).code == 0);
  const auto help = touchstone(dir, "db info --help");
  CHECK(help.out.find("--seed") == std::string::npos);
  CHECK(help.out.find("--threads") == std::string::npos);
  CHECK(help.out.find("--json") != std::string::npos);
  CHECK(touchstone(dir, "params --help").out.find("--seed") == std::string::npos);
  CHECK(touchstone(dir, "report --help").out.find("--seed") == std::string::npos);
  CHECK(touchstone(dir, "report --help").out.find("--threads") != std::string::npos);   // offered
  CHECK(touchstone(dir, "db build --help").out.find("--seed") != std::string::npos);    // offered
  // Given anyway: the same output, and a note naming the flag and the command.
  const auto plain = touchstone(dir, "db info db.h5 --json");
  const auto given = touchstone(dir, "db info db.h5 --json --seed 7 --threads 1");
  REQUIRE_MESSAGE(given.code == 0, given.err);
  CHECK(given.out == plain.out);
  CHECK_MESSAGE(given.err.find("note: --seed changes nothing in `touchstone db info`") != std::string::npos, given.err);
  CHECK(given.err.find("note: --threads changes nothing") != std::string::npos);
  CHECK(plain.err.find("note:") == std::string::npos);
  // The input named as everywhere else (--db), or positional: the same output.
  const auto named = touchstone(dir, "db info --db db.h5 --json");
  REQUIRE_MESSAGE(named.code == 0, named.err);
  CHECK(named.out == plain.out);
  CHECK(touchstone(dir, "db info db.h5 --db db.h5").code != 0);   // given twice: which one?
  const auto params = touchstone(dir, "params --json --seed 3");
  CHECK(params.code == 0);
  CHECK(params.err.find("note: --seed changes nothing in `touchstone params`") != std::string::npos);
}

TEST_CASE("cli db: build killed at random instants resumes to the same bytes, never a partial database") {
  // `db build` is stopped with SIGKILL after a random delay, again and again; each restart
  // resumes from the objects already written. The database appears only when complete and is
  // byte-identical to an uninterrupted build.
  TempDir dir("cli_db_kill");
  write_meshes(dir);
  const auto t0 = std::chrono::steady_clock::now();
  REQUIRE(touchstone(dir, "db build --meshes meshes --out clean.h5 --threads 1" + kFast).code == 0);
  const auto build_ms = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0).count();
  const std::string clean = ts::test::read_bytes(dir / "clean.h5");
  // What a build killed while creating its parts folder leaves: an unfinished folder beside it.
  fs::create_directories(dir / "killed.h5.parts.new");
  ts::test::write_text(dir / "killed.h5.parts.new" / "fingerprint.tmp-1-0", "touchstone");
  ts::Rng rng(77);
  int kills = 0;
  const std::string cmd = "cd '" + dir.path().string() + "' && exec '" TS_BINARY_DIR
                          "/touchstone' db build --meshes meshes --out killed.h5 --threads 1" + kFast;
  for (int round = 1; round <= 12 && !fs::exists(dir / "killed.h5"); ++round) {
    const std::string quiet = cmd + " >/dev/null 2>&1";
    const pid_t pid = fork();
    REQUIRE(pid >= 0);
    if (pid == 0) {
      execl("/bin/sh", "sh", "-c", quiet.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    // Killed within a growing fraction of the uninterrupted build's time: the first rounds
    // die early on any machine, the later ones may get an object or two written first.
    const auto limit = static_cast<std::size_t>(build_ms) * static_cast<std::size_t>(round + 2) / 40;
    std::this_thread::sleep_for(std::chrono::milliseconds(rng.index(std::max<std::size_t>(limit, 2))));
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    if (WIFSIGNALED(status)) ++kills;
    // The database appears complete or not at all (a kill after the final rename leaves it whole).
    if (fs::exists(dir / "killed.h5")) CHECK(ts::test::read_bytes(dir / "killed.h5") == clean);
  }
  CHECK(kills >= 5);
  // However far the killed rounds got (a loaded machine may kill them all before the first
  // object is written), one run left alone finishes from their leftovers, and the result is the
  // uninterrupted build's bytes.
  if (!fs::exists(dir / "killed.h5")) {
    const auto last = touchstone(dir, "db build --meshes meshes --out killed.h5 --threads 1" + kFast);
    INFO(last.err);
    REQUIRE(last.code == 0);
  }
  REQUIRE(fs::exists(dir / "killed.h5"));
  CHECK(ts::test::read_bytes(dir / "killed.h5") == clean);
}

TEST_CASE("cli db: congruent objects and mirror images are found by build and add, listed by info, added by classes") {
  // At true size (--scale keep, cm): the chiral fixture, the same solid turned and moved, its
  // mirror image, a copy 5 % longer along x, and a box.
  TempDir dir("cli");
  fs::create_directories(dir / "meshes");
  const ts::Mesh arm = ts::test::chiral_mesh();
  const ts::Mat3 turn = (Eigen::AngleAxisd(0.5 * std::numbers::pi, ts::Vec3::UnitZ()) *
                         Eigen::AngleAxisd(0.5 * std::numbers::pi, ts::Vec3::UnitX())).toRotationMatrix();
  ts::test::write_off(dir / "meshes/arm.off", arm);
  ts::test::write_off(dir / "meshes/arm_turned.off", ts::test::moved_mesh(arm, turn, {5, -3, 2}));
  ts::test::write_off(dir / "meshes/arm_mirror.off", ts::test::moved_mesh(arm, ts::Vec3(-1, 1, 1).asDiagonal(), {0, 0, 0}));
  ts::test::write_off(dir / "meshes/arm_long.off", ts::test::moved_mesh(arm, ts::Vec3(1.05, 1, 1).asDiagonal(), {0, 0, 0}));
  ts::test::write_off(dir / "meshes/box.off", ts::test::box_mesh({0, 0, 0}, {9, 6, 3}));
  const std::string keep = " --scale keep --units cm";
  auto build = touchstone(dir, "db build --meshes meshes --out c.h5 --json" + keep + kFast);
  REQUIRE_MESSAGE(build.code == 0, build.err);
  const auto expect_classes = [](const nlohmann::json& c, const nlohmann::json& classes) {
    CHECK(c["known"] == true);
    CHECK(c["tolerance"] == 0.01);
    CHECK(c["classes"] == classes);
    REQUIRE(c["class_largest_distance"].size() == classes.size());
    CHECK(c["class_largest_distance"][0].get<double>() < 1e-4);   // the same solid, moved
    REQUIRE(c["mirror_pairs"].size() == 2);
    CHECK(c["mirror_pairs"][0]["a"] == "arm");
    CHECK(c["mirror_pairs"][0]["b"] == "arm_mirror");
    CHECK(c["mirror_pairs"][1]["a"] == "arm_mirror");
    CHECK(c["mirror_pairs"][1]["b"] == "arm_turned");
  };
  const auto pair = nlohmann::json::array({nlohmann::json::array({"arm", "arm_turned"})});
  expect_classes(nlohmann::json::parse(build.out)["congruence"], pair);
  CHECK(build.err.find("  arm arm_turned  (largest surface distance") != std::string::npos);

  const auto info = touchstone(dir, "db info c.h5 --json");
  REQUIRE(info.code == 0);
  expect_classes(nlohmann::json::parse(info.out)["congruence"], pair);
  const auto human = touchstone(dir, "db info c.h5");
  CHECK(human.out.find("congruent objects (tolerance 0.01 of the size): 1 class\n  arm arm_turned") != std::string::npos);
  CHECK(human.out.find("mirror images: 2\n  arm / arm_mirror") != std::string::npos);

  // db add: only the new object's pairs are searched; it joins the class.
  ts::test::write_off(dir / "copy.off", ts::test::moved_mesh(arm, turn.transpose(), {-1, 0, 7}));
  const auto add = touchstone(dir, "db add c.h5 copy.off --name arm_copy --units cm --json");
  REQUIRE_MESSAGE(add.code == 0, add.err);
  const auto added = nlohmann::json::parse(add.out)["congruence"];
  CHECK(added["search"]["reused"] == true);
  CHECK(added["classes"] == nlohmann::json::array({nlohmann::json::array({"arm", "arm_turned", "arm_copy"})}));
  CHECK(added["mirror_pairs"].size() == 3);

  // A tolerance <= 0: one error line naming the flag, nothing written.
  const auto before = ts::test::read_bytes(dir / "c.h5");
  for (const std::string& cmd : {"db build --meshes meshes --out bad.h5 --congruence-tolerance 0" + keep,
                                 std::string("db add c.h5 meshes/box.off --name box2 --congruence-tolerance -0.5"),
                                 std::string("db classes c.h5 --congruence-tolerance 0")}) {
    CAPTURE(cmd);
    const auto r = touchstone(dir, cmd);
    CHECK(r.code == 1);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
    CHECK(r.err.find("--congruence-tolerance must be a positive number") != std::string::npos);
  }
  CHECK_FALSE(fs::exists(dir / "bad.h5"));
  CHECK(ts::test::read_bytes(dir / "c.h5") == before);

  // A database written before classes were recorded: opens, no classes known; db classes adds
  // them (the objects untouched), and a larger tolerance takes the stretched copy in too.
  fs::copy_file(dir / "c.h5", dir / "old.h5");
  {
    auto f = ts::io::h5::File::open(dir / "old.h5", ts::io::h5::File::Access::read_write);
    f.root().remove("congruence");
    f.close();
  }
  const auto old_info = touchstone(dir, "db info old.h5 --json");
  REQUIRE(old_info.code == 0);
  CHECK(nlohmann::json::parse(old_info.out)["congruence"] == nlohmann::json({{"known", false}}));
  CHECK(touchstone(dir, "db info old.h5").out.find("congruent objects: not known") != std::string::npos);
  const auto dry = touchstone(dir, "db classes old.h5 --dry-run --json");
  REQUIRE_MESSAGE(dry.code == 0, dry.err);
  CHECK(nlohmann::json::parse(dry.out)["written"] == false);
  CHECK(nlohmann::json::parse(touchstone(dir, "db info old.h5 --json").out)["congruence"]["known"] == false);
  const auto classes = touchstone(dir, "db classes old.h5 --json");
  REQUIRE_MESSAGE(classes.code == 0, classes.err);
  CHECK(nlohmann::json::parse(classes.out)["congruence"]["classes"] == added["classes"]);
  {
    ts::io::DbReader a(dir / "c.h5"), b(dir / "old.h5");
    REQUIRE(b.congruence() != nullptr);
    CHECK(a.congruence()->pairs.size() == b.congruence()->pairs.size());
    CHECK(a.load_fine(2).points == b.load_fine(2).points);
  }
  const auto loose = touchstone(dir, "db classes old.h5 --congruence-tolerance 0.05 --json");
  REQUIRE(loose.code == 0);
  CHECK(nlohmann::json::parse(loose.out)["congruence"]["classes"] ==
        nlohmann::json::array({nlohmann::json::array({"arm", "arm_long", "arm_turned", "arm_copy"})}));
  CHECK_FALSE(leftovers(dir.path()));
}
