#include "datasets/db_builder.hpp"
#include "io/db_store.hpp"
#include "mesh_fixtures.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <cstdlib>

namespace fs = std::filesystem;
using ts::test::TempDir;

namespace {
/// Coarse settings: these tests check plumbing, not accuracy.
ts::DatabaseSettings fast_settings() {
  ts::DatabaseSettings s;
  s.scan.fine_spacing = 0.006;
  s.scan.coarse_voxel = 0.02;
  s.scan.max_views = 24;
  s.fpfh.normal_radius = 0.015;
  s.fpfh.feature_radius = 0.03;
  s.field.fine_voxel = 0.01;
  s.field.fine_band_voxels = 2;
  s.field.coarse_voxel = 0.04;
  s.field.coarse_margin = 0.04;
  return s;
}
}  // namespace

TEST_CASE("db builder: a folder lists its mesh files, sorted, named by stem") {
  TempDir dir("builder");
  ts::test::write_off(dir / "b.off", ts::test::box_mesh({0, 0, 0}, {1, 1, 1}));
  ts::test::write_text(dir / "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  ts::test::write_text(dir / ".hidden.off", "OFF\n");
  ts::test::write_text(dir / "notes.txt", "not a mesh");
  fs::create_directories(dir / "sub.off");
  const auto inputs = ts::datasets::inputs_from_folder(dir.path());
  REQUIRE(inputs.size() == 2);
  CHECK(inputs[0].name == "a");
  CHECK(inputs[1].name == "b");
  CHECK(inputs[1].source == "file: b.off");
  CHECK(inputs[1].member.empty());

  ts::test::write_text(dir / "a.stl", "solid a\nendsolid a\n");
  CHECK_THROWS_WITH_AS(ts::datasets::inputs_from_folder(dir.path()), doctest::Contains("two meshes would be named 'a'"),
                       ts::Error);
  TempDir empty("builder");
  CHECK_THROWS_WITH_AS(ts::datasets::inputs_from_folder(empty.path()), doctest::Contains("no mesh files"), ts::Error);
  CHECK_THROWS_WITH_AS(ts::datasets::inputs_from_folder(dir / "none"), doctest::Contains("does not exist"), ts::Error);
}

TEST_CASE("db builder: paths given on the command line and manifest lines") {
  const auto a = ts::datasets::input_from_path("pkg/data.tar.gz:data/meshes/cow.off");
  CHECK(a.path == fs::path("pkg/data.tar.gz"));
  CHECK(a.member == "data/meshes/cow.off");
  CHECK(a.name == "cow");
  CHECK(a.display() == "pkg/data.tar.gz:data/meshes/cow.off");
  CHECK(ts::datasets::input_from_path("x/bunny.ply", "rabbit").name == "rabbit");
  CHECK_THROWS_WITH_AS(ts::datasets::input_from_path("x/bunny.ply", "a/b"), doctest::Contains("invalid object name"),
                       ts::Error);

  TempDir dir("builder");
  ts::test::write_text(dir / "m.tsv", "# x\nsrc\tcache/a.tar.gz:m/x.off\tx\n\nsrc\ty.obj\ty\n");
  const auto in = ts::datasets::inputs_from_manifest(dir / "m.tsv");
  REQUIRE(in.size() == 2);
  CHECK(in[0].source == "src: a.tar.gz:m/x.off");
  CHECK(in[0].origin_field == "line 2");
  CHECK(in[1].origin_field == "line 4");
  ts::test::write_text(dir / "bad.tsv", "src\ty.obj\tbad/name\n");
  CHECK_THROWS_WITH_AS(ts::datasets::inputs_from_manifest(dir / "bad.tsv"), doctest::Contains("line 1"), ts::Error);
}

TEST_CASE("db builder: meshes inside an archive; the first bad mesh in input order is the error") {
  TempDir dir("builder");
  fs::create_directories(dir / "src/m");
  ts::test::write_off(dir / "src/m/box.off", ts::test::box_mesh({0, 0, 0}, {2, 1, 1}));
  ts::test::write_off(dir / "src/m/ball.off", ts::test::icosphere_mesh(1.0, 1));
  REQUIRE(std::system(("tar -C '" + (dir / "src").string() + "' -czf '" + (dir / "meshes.tar.gz").string() +
                       "' m >/dev/null 2>&1")
                          .c_str()) == 0);
  ts::test::write_text(dir / "m.tsv", "pkg\tmeshes.tar.gz:m/ball.off\tball\npkg\tmeshes.tar.gz:m/box.off\tbox\n");
  ts::datasets::BuildSettings settings;
  settings.database = fast_settings();
  std::size_t progress_calls = 0;
  settings.progress = [&](const ts::datasets::BuildProgress& p) {
    ++progress_calls;
    CHECK(p.done <= p.total);
    CHECK(p.resumed == 0);
  };
  tbb::task_arena arena(2);
  const auto report = arena.execute(
      [&] { return ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "m.tsv"), dir / "db.h5", settings); });
  CHECK(progress_calls == 2);
  CHECK(report.names == std::vector<std::string>{"ball", "box"});
  CHECK(report.times.wall_s > 0.0);
  ts::io::DbReader db(dir / "db.h5");
  REQUIRE(db.size() == 2);
  CHECK(db.info(1).source == "pkg: meshes.tar.gz:m/box.off");
  CHECK(db.info(1).extent.isApprox(ts::Vec3(0.2, 0.1, 0.1)));
  CHECK(db.info(0).closed);

  // Two bad inputs: the error is the first one's, whatever the threads did.
  ts::test::write_text(dir / "src/bad1.off", "OFF\n3 1 0\n0 0 0\n");
  ts::test::write_text(dir / "src/bad2.off", "OFF\n3 1 0\n1 1 1\n");
  std::vector<ts::datasets::MeshInput> inputs = {ts::datasets::input_from_path((dir / "src/m/box.off").string()),
                                                 ts::datasets::input_from_path((dir / "src/bad2.off").string()),
                                                 ts::datasets::input_from_path((dir / "src/bad1.off").string())};
  for (int rep = 0; rep < 3; ++rep)
    CHECK_THROWS_WITH_AS(arena.execute([&] { return ts::datasets::build_database(inputs, dir / "x.h5", settings); }),
                         doctest::Contains("bad2.off"), ts::Error);
  CHECK_FALSE(fs::exists(dir / "x.h5"));
  inputs.pop_back();
  inputs[1] = ts::datasets::input_from_path((dir / "src/m/ball.off").string(), "box");
  CHECK_THROWS_WITH_AS(ts::datasets::build_database(inputs, dir / "x.h5", settings), doctest::Contains("duplicate"),
                       ts::Error);
}

TEST_CASE("db builder: a stopped build keeps its finished objects and resumes to the same bytes") {
  TempDir dir("builder");
  ts::test::write_off(dir / "box.off", ts::test::box_mesh({0, 0, 0}, {2, 1, 1}));
  ts::test::write_off(dir / "ball.off", ts::test::icosphere_mesh(1.0, 1));
  ts::test::write_off(dir / "slab.off", ts::test::box_mesh({0, 0, 0}, {3, 2, 0.5}));
  ts::test::write_text(dir / "m.tsv", "pkg\tbox.off\tbox\npkg\tball.off\tball\npkg\tslab.off\tslab\n");
  const auto inputs = ts::datasets::inputs_from_manifest(dir / "m.tsv");
  ts::datasets::BuildSettings settings;
  settings.database = fast_settings();
  tbb::task_arena one(1);
  one.execute([&] { ts::datasets::build_database(inputs, dir / "whole.h5", settings); });
  CHECK_FALSE(fs::exists(dir / "whole.h5.parts"));   // removed after the merge

  // Stop after the first object (as a kill would, between objects): nothing under the real
  // name, the finished object kept.
  ts::datasets::BuildSettings stopping = settings;
  stopping.progress = [](const ts::datasets::BuildProgress& p) {
    if (p.done == 1) throw ts::Error("stopped by the test");
  };
  CHECK_THROWS_WITH_AS(one.execute([&] { ts::datasets::build_database(inputs, dir / "db.h5", stopping); }),
                       doctest::Contains("1 of 3 objects finished, kept in"), ts::Error);
  CHECK_FALSE(fs::exists(dir / "db.h5"));
  REQUIRE(fs::exists(dir / "db.h5.parts/fingerprint"));

  // A resume with other inputs is refused, naming the manifest; the parts stay.
  ts::test::write_text(dir / "m2.tsv", "pkg\tbox.off\tbox\npkg\tslab.off\tball\npkg\tball.off\tslab\n");
  CHECK_THROWS_WITH_AS(ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "m2.tsv"), dir / "db.h5", settings),
                       doctest::Contains("was started with other inputs, parameters or seed"), ts::Error);
  CHECK_THROWS_WITH_AS(ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "m2.tsv"), dir / "db.h5", settings),
                       doctest::Contains(('(' + (dir / "m2.tsv").string() + ", fingerprint)").c_str()), ts::Error);
  ts::datasets::BuildSettings other_seed = settings;
  other_seed.seed = 2;
  CHECK_THROWS_WITH_AS(ts::datasets::build_database(inputs, dir / "db.h5", other_seed),
                       doctest::Contains("was started with other inputs"), ts::Error);
  REQUIRE(fs::exists(dir / "db.h5.parts/fingerprint"));

  // The same inputs resume: only what is missing is built, and the database is the same bytes
  // as the uninterrupted build (with 2 threads: the thread count does not matter either).
  std::size_t built = 0;
  ts::datasets::BuildSettings resuming = settings;
  resuming.progress = [&](const ts::datasets::BuildProgress& p) {
    ++built;
    CHECK(p.resumed == 1);
  };
  tbb::task_arena two(2);
  const auto report = two.execute([&] { return ts::datasets::build_database(inputs, dir / "db.h5", resuming); });
  CHECK(report.resumed == 1);
  CHECK(built == 2);
  CHECK(report.names == std::vector<std::string>{"box", "ball", "slab"});
  CHECK_FALSE(fs::exists(dir / "db.h5.parts"));
  CHECK(ts::test::read_bytes(dir / "db.h5") == ts::test::read_bytes(dir / "whole.h5"));

  // A damaged part (a crash of the disk, not of the build: parts are written atomically) is
  // built again.
  CHECK_THROWS(one.execute([&] { ts::datasets::build_database(inputs, dir / "db2.h5", stopping); }));
  const auto part = dir / "db2.h5.parts/0000000.h5";
  REQUIRE(fs::exists(part));
  fs::resize_file(part, fs::file_size(part) / 2);
  const auto again = one.execute([&] { return ts::datasets::build_database(inputs, dir / "db2.h5", settings); });
  CHECK(again.resumed == 0);
  CHECK(ts::test::read_bytes(dir / "db2.h5") == ts::test::read_bytes(dir / "whole.h5"));
}

TEST_CASE("db builder: --scale keep builds objects at their real sizes, in their units") {
  TempDir dir("builder");
  // A 6 x 3 x 3 cm block in centimetres and a 10 cm ball (radius 0.05) in metres.
  ts::test::write_off(dir / "block.off", ts::test::box_mesh({0, 0, 0}, {6, 3, 3}));
  ts::test::write_off(dir / "ball.off", ts::test::icosphere_mesh(0.05, 2));
  ts::test::write_text(dir / "m.tsv", "pkg\tblock.off\tblock\tcm\npkg\tball.off\tball\n");
  ts::datasets::BuildSettings settings;
  settings.database = fast_settings();
  settings.database.scale = ts::ObjectScale::keep;
  settings.database.field.fine_voxel = 0.005;
  settings.database.scan.coarse_voxel = 0.01;
  ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "m.tsv"), dir / "db.h5", settings);
  ts::io::DbReader db(dir / "db.h5");
  CHECK(db.settings().scale == ts::ObjectScale::keep);
  REQUIRE(db.size() == 2);
  CHECK((db.info(0).extent - ts::Vec3(0.06, 0.03, 0.03)).cwiseAbs().maxCoeff() < 1e-9);
  CHECK(db.info(0).scale == 0.01);
  CHECK(db.info(1).extent.maxCoeff() == doctest::Approx(0.1).epsilon(0.01).scale(0));
  CHECK(db.info(1).scale == 1.0);
  // Eq. 3's s_obj_max follows the largest object, not max_extent.
  CHECK(ts::largest_object_extent(db) == doctest::Approx(db.info(1).extent.maxCoeff()).epsilon(1e-12).scale(0));
  // The stored fine cloud lies on the real-size block: within its box (plus a scan spacing).
  const auto fine = db.load_fine(0);
  REQUIRE(fine.size() > 0);
  Eigen::AlignedBox3d box;
  for (const auto& q : fine.points) box.extend(q);
  CHECK(box.sizes().x() == doctest::Approx(0.06).epsilon(0.007).scale(0));
  CHECK(box.sizes().y() == doctest::Approx(0.03).epsilon(0.007).scale(0));

  // Under fit the same manifest gives two objects of the same largest side.
  ts::datasets::BuildSettings fit = settings;
  fit.database.scale = ts::ObjectScale::fit;
  ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "m.tsv"), dir / "fit.h5", fit);
  ts::io::DbReader fitted(dir / "fit.h5");
  CHECK(fitted.settings().scale == ts::ObjectScale::fit);
  CHECK(fitted.info(0).extent.maxCoeff() == doctest::Approx(0.2).epsilon(1e-9).scale(0));
  CHECK(fitted.info(1).extent.maxCoeff() == doctest::Approx(0.2).epsilon(1e-9).scale(0));
  CHECK(ts::largest_object_extent(fitted) == fitted.settings().max_extent);

  // A units mistake (the block's centimetres read as millimetres: 6 mm is fine, but as metres
  // it is 6 m long) names the manifest line, and nothing is written.
  ts::test::write_text(dir / "bad.tsv", "pkg\tblock.off\tblock\tm\npkg\tball.off\tball\n");
  CHECK_THROWS_WITH_AS(
      ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "bad.tsv"), dir / "bad.h5", settings),
      doctest::Contains(('(' + (dir / "bad.tsv").string() + ", line 1, units)").c_str()), ts::Error);
  CHECK_FALSE(fs::exists(dir / "bad.h5"));
}

TEST_CASE("db builder: a resumed keep build whose units changed is refused (fingerprint)") {
  TempDir dir("builder");
  ts::test::write_off(dir / "block.off", ts::test::box_mesh({0, 0, 0}, {6, 3, 3}));
  ts::test::write_off(dir / "slab.off", ts::test::box_mesh({0, 0, 0}, {8, 4, 1}));
  ts::test::write_text(dir / "cm.tsv", "pkg\tblock.off\tblock\tcm\npkg\tslab.off\tslab\tcm\n");
  ts::test::write_text(dir / "in.tsv", "pkg\tblock.off\tblock\tin\npkg\tslab.off\tslab\tcm\n");
  ts::datasets::BuildSettings settings;
  settings.database = fast_settings();
  settings.database.scale = ts::ObjectScale::keep;
  settings.database.field.fine_voxel = 0.005;
  ts::datasets::BuildSettings stopping = settings;
  stopping.progress = [](const ts::datasets::BuildProgress& p) {
    if (p.done == 1) throw ts::Error("stopped by the test");
  };
  tbb::task_arena one(1);
  CHECK_THROWS(one.execute([&] { ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "cm.tsv"), dir / "db.h5", stopping); }));
  REQUIRE(fs::exists(dir / "db.h5.parts/fingerprint"));
  CHECK_THROWS_WITH_AS(ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "in.tsv"), dir / "db.h5", settings),
                       doctest::Contains("fingerprint"), ts::Error);
  ts::datasets::BuildSettings fitted = settings;
  fitted.database.scale = ts::ObjectScale::fit;
  CHECK_THROWS_WITH_AS(ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "cm.tsv"), dir / "db.h5", fitted),
                       doctest::Contains("fingerprint"), ts::Error);
  // The same declaration resumes.
  const auto report = ts::datasets::build_database(ts::datasets::inputs_from_manifest(dir / "cm.tsv"), dir / "db.h5", settings);
  CHECK(report.resumed == 1);
  CHECK(ts::io::DbReader(dir / "db.h5").info(0).extent.x() == doctest::Approx(0.06).epsilon(1e-9).scale(0));
}
