#include "engine/database/database.hpp"
#include "io/db_store.hpp"
#include "io/h5.hpp"
#include "mesh_fixtures.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include <thread>

namespace fs = std::filesystem;
namespace h5 = ts::io::h5;
using ts::test::TempDir;

namespace {

ts::PointCloud random_cloud(ts::Rng& rng, std::size_t n) {
  ts::PointCloud c;
  for (std::size_t i = 0; i < n; ++i) {
    c.points.emplace_back(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1));
    c.normals.push_back(rng.unit_vector());
  }
  return c;
}

ts::SparseGrid random_grid(ts::Rng& rng, double voxel, int n) {
  ts::SparseGrid g;
  g.voxel = voxel;
  for (int i = 0; i < n; ++i) {  // sorted by (i, j, k), as the field stores them
    g.ijk.push_back({i / 9 - 2, (i / 3) % 3 - 1, i % 3 - 1});
    g.value.push_back(static_cast<float>(rng.uniform(-0.01, 0.01)));
  }
  return g;
}

/// A synthetic object: every array has distinctive contents (no engine computation needed).
ts::BuiltObject synthetic_object(const std::string& name, std::uint64_t seed) {
  ts::Rng rng(seed);
  ts::BuiltObject o;
  o.info.name = name;
  o.info.source = "test\t" + name + ".off";
  o.info.mesh_sha256 = std::string(64, 'a');
  o.info.scale = rng.uniform(0.1, 2.0);
  o.info.centre = ts::Vec3(rng.uniform(), rng.uniform(), rng.uniform());
  o.info.extent = ts::Vec3(0.2, 0.1, 0.05);
  o.info.closed = seed % 2 == 0;
  o.info.coverage = 0.995;
  o.mesh = ts::test::box_mesh({-0.1, -0.05, -0.025}, {0.1, 0.05, 0.025});
  o.fine = random_cloud(rng, 200 + seed);
  o.features.coarse = random_cloud(rng, 20 + seed);
  for (std::size_t i = 0; i < o.features.coarse.size(); ++i) {
    ts::Feature f;
    for (auto& v : f) v = static_cast<float>(rng.uniform(0, 100));
    o.features.features.push_back(f);
  }
  o.info.fine_points = o.fine.size();
  o.info.coarse_points = o.features.coarse.size();
  o.field = ts::DistanceField::from_sparse(random_grid(rng, 0.002, 27), random_grid(rng, 0.01, 45), o.info.closed, 0.2);
  return o;
}

ts::DatabaseSettings custom_settings() {
  ts::DatabaseSettings s;
  s.max_extent = 0.3;
  s.scan.fine_spacing = 0.002;
  s.scan.max_views = 17;
  s.fpfh.feature_radius = 0.025;
  s.field.fine_band_voxels = 4;
  return s;
}

std::vector<ts::io::StoredObject> stored(const std::vector<ts::BuiltObject>& objects) {
  std::vector<ts::io::StoredObject> out;
  for (const auto& o : objects) out.push_back({&o, ts::io::object_seed(5, o.info.name)});
  return out;
}
std::vector<ts::io::StoredObject> stored_one(const ts::BuiltObject& o) {
  return {{&o, ts::io::object_seed(5, o.info.name)}};
}

void check_same(const ts::io::DbReader& db, std::size_t i, const ts::BuiltObject& o) {
  const auto& info = db.info(i);
  CHECK(info.name == o.info.name);
  CHECK(info.source == o.info.source);
  CHECK(info.mesh_sha256 == o.info.mesh_sha256);
  CHECK(info.scale == o.info.scale);
  CHECK(info.centre == o.info.centre);
  CHECK(info.extent == o.info.extent);
  CHECK(info.closed == o.info.closed);
  CHECK(info.coverage == o.info.coverage);
  CHECK(info.fine_points == o.fine.size());
  CHECK(info.coarse_points == o.features.coarse.size());
  CHECK(db.object_seed(i) == ts::io::object_seed(5, o.info.name));
  const auto fine = db.load_fine(i);
  CHECK(fine.points == o.fine.points);
  CHECK(fine.normals == o.fine.normals);
  const auto feat = db.load_features(i);
  CHECK(feat.coarse.points == o.features.coarse.points);
  CHECK(feat.coarse.normals == o.features.coarse.normals);
  CHECK(feat.features == o.features.features);
  const auto mesh = db.load_mesh(i);
  CHECK(mesh.vertices == o.mesh.vertices);
  CHECK(mesh.faces == o.mesh.faces);
  const auto field = db.load_field(i);
  CHECK(field.is_signed() == o.field.is_signed());
  CHECK(field.coarse_margin() == o.field.coarse_margin());
  CHECK(field.fine_sparse().ijk == o.field.fine_sparse().ijk);
  CHECK(field.fine_sparse().value == o.field.fine_sparse().value);
  CHECK(field.coarse_sparse().voxel == o.field.coarse_sparse().voxel);
  CHECK(field.coarse_sparse().value == o.field.coarse_sparse().value);
}

}  // namespace

TEST_CASE("db store: write, read back everything, identical bytes") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  objects.push_back(synthetic_object("cube", 1));
  objects.push_back(synthetic_object("sphere", 2));
  const auto settings = custom_settings();
  ts::io::write_database(dir / "a.h5", stored(objects), settings, 5);
  ts::io::write_database(dir / "b.h5", stored(objects), settings, 5);
  CHECK(ts::test::read_bytes(dir / "a.h5") == ts::test::read_bytes(dir / "b.h5"));

  ts::io::DbReader db(dir / "a.h5");
  CHECK(db.schema_version() == ts::io::kDbSchemaVersion);
  CHECK(db.feature_dim() == 33);
  CHECK(db.build_seed() == 5);
  REQUIRE(db.size() == 2);
  CHECK(db.find("sphere") == 1);
  CHECK(db.find("torus") == 2);
  CHECK(db.settings().max_extent == 0.3);
  CHECK(db.settings().scan.fine_spacing == 0.002);
  CHECK(db.settings().scan.max_views == 17);
  CHECK(db.settings().scan.coverage_radius == ts::ScanSettings{}.coverage_radius);
  CHECK(db.settings().fpfh.feature_radius == 0.025);
  CHECK(db.settings().field.fine_band_voxels == 4);
  check_same(db, 0, objects[0]);
  check_same(db, 1, objects[1]);
  CHECK(db.mesh_faces(0) == 12);

  // The engine's lazy cache over the file.
  ts::Database cache(std::make_shared<ts::io::DbReader>(dir / "a.h5"));
  CHECK(cache.find("cube") == 0);
  CHECK_FALSE(cache.geometry_loaded(1));
  CHECK(cache.geometry(1)->fine.points == objects[1].fine.points);
  CHECK(cache.geometry_loads() == 1);
}

TEST_CASE("db store: compressed databases read the same") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  objects.push_back(synthetic_object("a", 3));
  ts::io::write_database(dir / "z.h5", stored(objects), {}, 5, {.deflate = 4});
  ts::io::DbReader db(dir / "z.h5");
  check_same(db, 0, objects[0]);
}

TEST_CASE("db store: append keeps the others, and a failed append leaves the file as it was") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  objects.push_back(synthetic_object("a", 1));
  objects.push_back(synthetic_object("b", 2));
  ts::io::write_database(dir / "db.h5", stored_one(objects[0]), custom_settings(), 5);
  ts::io::append_to_database(dir / "db.h5", stored_one(objects[1]));
  {
    ts::io::DbReader db(dir / "db.h5");
    REQUIRE(db.size() == 2);
    CHECK(db.settings().max_extent == 0.3);
    check_same(db, 0, objects[0]);
    check_same(db, 1, objects[1]);
  }
  const auto before = ts::test::read_bytes(dir / "db.h5");
  auto dup = synthetic_object("b", 7);
  CHECK_THROWS_WITH_AS(ts::io::append_to_database(dir / "db.h5", {{&dup, 1}}),
                       doctest::Contains("object 'b' already exists in the database"), ts::Error);
  CHECK(ts::test::read_bytes(dir / "db.h5") == before);
  auto bad = synthetic_object("c", 8);
  bad.features.features.resize(bad.features.features.size() - 1);  // inconsistent: fails half-way through writing
  CHECK_THROWS_WITH_AS(ts::io::append_to_database(dir / "db.h5", {{&bad, 1}}), doctest::Contains("features for"),
                       ts::Error);
  CHECK(ts::test::read_bytes(dir / "db.h5") == before);
  for (const auto& e : fs::directory_iterator(dir.path())) CHECK(e.path().filename() == "db.h5");
  CHECK_THROWS_WITH_AS(ts::io::append_to_database(dir / "none.h5", {{&bad, 1}}), doctest::Contains("does not exist"),
                       ts::Error);
}

TEST_CASE("db store: info is lazy; loads check every shape") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  objects.push_back(synthetic_object("a", 1));
  objects.push_back(synthetic_object("b", 2));
  ts::io::write_database(dir / "db.h5", stored(objects), {}, 5);
  {
    auto f = h5::File::open(dir / "db.h5", h5::File::Access::read_write);
    auto a = f.group("objects/a");
    a.remove("fine/points");            // point data gone...
    a.remove("fine/normals");
    std::vector<double> two(2 * objects[0].fine.size(), 0.0);
    a.write("fine/normals", two.data(), {objects[0].fine.size(), 2});
    a.remove("features");
    f.close();
  }
  {
    ts::io::DbReader db(dir / "db.h5");  // ...yet the summary opens
    CHECK(db.info(0).fine_points == objects[0].fine.size());
    CHECK_THROWS_WITH_AS(db.load_fine(0), doctest::Contains("dataset is missing"), ts::Error);
    CHECK_THROWS_WITH_AS(db.load_fine(0), doctest::Contains("/objects/a/fine/points)"), ts::Error);
    CHECK_THROWS_WITH_AS(db.load_features(0), doctest::Contains("/objects/a/features"), ts::Error);
    check_same(db, 1, objects[1]);
  }

  // A count attribute that disagrees with the data is caught at load.
  {
    auto f = h5::File::open(dir / "db.h5", h5::File::Access::read_write);
    f.group("objects/b").set_attribute("fine_points", std::int64_t{3});
    f.close();
  }
  ts::io::DbReader db2(dir / "db.h5");
  const std::string expected = "dataset has shape [" + std::to_string(objects[1].fine.size()) +
                               ",3], expected [3,3] (" + (dir / "db.h5").string() + ", /objects/b/fine/points)";
  CHECK_THROWS_WITH_AS(db2.load_fine(1), expected.c_str(), ts::Error);
}

TEST_CASE("db store: foreign, truncated and incompatible files are refused") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  objects.push_back(synthetic_object("a", 1));
  ts::io::write_database(dir / "db.h5", stored(objects), {}, 5);
  const auto bytes = ts::test::read_bytes(dir / "db.h5");
  ts::test::write_text(dir / "cut.h5", bytes.substr(0, bytes.size() - 100));
  CHECK_THROWS_WITH_AS(ts::io::DbReader(dir / "cut.h5"), doctest::Contains("truncated"), ts::Error);
  ts::test::write_text(dir / "text.h5", "hello");
  CHECK_THROWS_WITH_AS(ts::io::DbReader(dir / "text.h5"), doctest::Contains("not an HDF5 file"), ts::Error);
  {
    auto f = h5::File::create(dir / "other.h5");
    f.root().write("x", std::vector<double>{1.0});
    f.close();
  }
  CHECK_THROWS_WITH_AS(ts::io::DbReader(dir / "other.h5"), doctest::Contains("not a Touchstone object database"),
                       ts::Error);
  {
    auto f = h5::File::open(dir / "db.h5", h5::File::Access::read_write);
    f.root().set_attribute("schema_version", std::int64_t{99});
    f.close();
  }
  CHECK_THROWS_WITH_AS(ts::io::DbReader(dir / "db.h5"), doctest::Contains("schema version 99 is not supported"),
                       ts::Error);
}

TEST_CASE("db store: schema 1 databases (sparse float fields) still read; appending to them is refused") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  objects.push_back(synthetic_object("a", 1));
  objects.push_back(synthetic_object("b", 2));
  ts::io::write_database(dir / "db.h5", stored(objects), {}, 5);
  {  // rewrite the file as schema 1 wrote it: field/{fine,coarse}_{ijk,value}, no quantum
    auto f = h5::File::open(dir / "db.h5", h5::File::Access::read_write);
    f.root().set_attribute("schema_version", std::int64_t{1});
    for (const auto& o : objects) {
      auto field = f.group("objects/" + o.info.name + "/field");
      for (const char* level : {"fine", "coarse"}) {
        const std::string l = level;
        field.remove(l + "_bricks");
        field.remove(l + "_values");
        const ts::SparseGrid g = l == "fine" ? o.field.fine_sparse() : o.field.coarse_sparse();
        field.write(l + "_ijk", g.ijk.data()->data(), {g.ijk.size(), 3});
        field.write(l + "_value", g.value.data(), {g.value.size()});
      }
    }
    f.close();
  }
  {
    ts::io::DbReader db(dir / "db.h5");
    CHECK(db.schema_version() == 1);
    for (std::size_t i = 0; i < objects.size(); ++i) check_same(db, i, objects[i]);
  }
  const auto before = ts::test::read_bytes(dir / "db.h5");
  auto c = synthetic_object("c", 3);
  CHECK_THROWS_WITH_AS(ts::io::append_to_database(dir / "db.h5", stored_one(c), {}),
                       doctest::Contains("schema version 1 cannot take new objects"), ts::Error);
  CHECK(ts::test::read_bytes(dir / "db.h5") == before);
}

TEST_CASE("db store: crafted distance fields are refused, naming the file and the dataset") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  objects.push_back(synthetic_object("a", 1));
  ts::io::write_database(dir / "db.h5", stored(objects), {}, 5);
  const auto pristine = ts::test::read_bytes(dir / "db.h5");
  const std::string file = (dir / "db.h5").string();
  auto craft = [&](const std::function<void(h5::Group&)>& edit) {
    ts::test::write_text(dir / "db.h5", pristine);
    auto f = h5::File::open(dir / "db.h5", h5::File::Access::read_write);
    auto field = f.group("objects/a/field");
    edit(field);
    f.close();
    return ts::io::DbReader(dir / "db.h5");
  };
  const ts::CompactGrid fine = objects[0].field.fine_compact();
  REQUIRE(fine.bricks.size() >= 2);
  {  // bricks out of order
    auto bricks = fine.bricks;
    std::swap(bricks[0], bricks[1]);
    const auto db = craft([&](h5::Group& g) {
      g.remove("fine_bricks");
      g.write("fine_bricks", bricks.data()->data(), {bricks.size(), 3});
    });
    CHECK_THROWS_WITH_AS(db.load_field(0), ("distance field: bricks not in increasing order (" + file +
                                            ", /objects/a/field/fine/bricks)").c_str(), ts::Error);
  }
  {  // a brick so far away that its index would not fit in memory
    auto bricks = fine.bricks;
    bricks.back() = {40000000, 0, 0};
    const auto db = craft([&](h5::Group& g) {
      g.remove("fine_bricks");
      g.write("fine_bricks", bricks.data()->data(), {bricks.size(), 3});
    });
    CHECK_THROWS_WITH_AS(db.load_field(0), doctest::Contains("/objects/a/field/fine/bricks"), ts::Error);
  }
  {  // values not 64 a brick
    const auto db = craft([&](h5::Group& g) {
      g.remove("coarse_values");
      std::vector<std::int16_t> v(10, 0);
      g.write("coarse_values", v.data(), {10});
    });
    CHECK_THROWS_WITH_AS(db.load_field(0), doctest::Contains("/objects/a/field/coarse_values"), ts::Error);
  }
  {  // a quantum that is not a positive number
    const auto db = craft([&](h5::Group& g) { g.set_attribute("fine_quantum", -1.0); });
    CHECK_THROWS_WITH_AS(db.load_field(0), doctest::Contains("/objects/a/field@fine_quantum"), ts::Error);
  }
}

TEST_CASE("db store: object names and seeds") {
  for (const char* bad : {"", ".", "..", "a/b", " a", "a ", "tab\there"})
    CHECK_THROWS_WITH_AS(ts::io::check_object_name(bad, "m.tsv", "line 3"), doctest::Contains("invalid object name"),
                         ts::Error);
  CHECK_NOTHROW(ts::io::check_object_name("bunny_2 (scan)"));
  CHECK(ts::io::object_seed(1, "cube") == ts::io::object_seed(1, "cube"));
  CHECK(ts::io::object_seed(1, "cube") != ts::io::object_seed(2, "cube"));
  CHECK(ts::io::object_seed(1, "cube") != ts::io::object_seed(1, "cuba"));

  TempDir dir("db");
  auto a = synthetic_object("a", 1);
  auto b = synthetic_object("a", 2);
  CHECK_THROWS_WITH_AS(ts::io::write_database(dir / "d.h5", {{&a, 1}, {&b, 2}}, {}, 1),
                       doctest::Contains("object 'a' already exists"), ts::Error);
  CHECK_FALSE(fs::exists(dir / "d.h5"));
}

TEST_CASE("db store: concurrent loads from one reader") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  for (int k = 0; k < 4; ++k) {
    std::string name = "o";
    name += std::to_string(k);
    objects.push_back(synthetic_object(name, static_cast<std::uint64_t>(k)));
  }
  ts::io::write_database(dir / "db.h5", stored(objects), {}, 5);
  ts::io::DbReader db(dir / "db.h5");
  std::vector<int> ok(4, 0);
  std::vector<std::thread> threads;
  for (int k = 0; k < 4; ++k)
    threads.emplace_back([&, k] {
      bool good = true;
      for (int rep = 0; rep < 10; ++rep) {
        const auto i = static_cast<std::size_t>((k + rep) % 4);
        good = good && db.load_fine(i).points == objects[i].fine.points &&
               db.load_features(i).features == objects[i].features.features;
      }
      ok[static_cast<std::size_t>(k)] = good;
    });
  for (auto& t : threads) t.join();
  CHECK(ok == std::vector<int>(4, 1));
}

TEST_CASE("db store: the congruence record round-trips; databases without one open with no classes known") {
  TempDir dir("db");
  std::vector<ts::BuiltObject> objects;
  for (const char* name : {"a", "b", "c"}) objects.push_back(synthetic_object(name, objects.size() + 1));
  ts::io::write_database(dir / "old.h5", stored(objects), custom_settings(), 5);
  {
    ts::io::DbReader old(dir / "old.h5");   // written without a record (as before it existed)
    CHECK(old.congruence() == nullptr);
  }
  ts::io::CongruenceRecord rec;
  rec.settings.tolerance = 0.02;
  rec.settings.samples = 500;
  for (int i = 0; i < 3; ++i) rec.signatures.push_back({0.2 + i, {0.01, 0.02 + i, 0.05}});
  rec.pairs = {{0, 2, ts::Congruence::congruent, 1e-5}, {1, 2, ts::Congruence::mirror, 0.003}};
  ts::io::write_database(dir / "new.h5", stored(objects), custom_settings(), 5, {}, &rec);
  auto check_record = [&](const ts::io::DbReader& db) {
    const auto* c = db.congruence();
    REQUIRE(c != nullptr);
    CHECK(c->settings.tolerance == 0.02);
    CHECK(c->settings.samples == 500);
    REQUIRE(c->signatures.size() == 3);
    CHECK(c->signatures[2].size == 2.2);
    CHECK(c->signatures[2].spread[1] == 2.02);
    REQUIRE(c->pairs.size() == 2);
    CHECK(c->pairs[1].kind == ts::Congruence::mirror);
    CHECK(c->pairs[1].distance == 0.003);
    CHECK(c->classes() == std::vector<std::vector<std::size_t>>{{0, 2}});
    REQUIRE(c->mirrors().size() == 1);
    CHECK(c->mirrors()[0].a == 1);
  };
  check_record(ts::io::DbReader(dir / "new.h5"));
  // A motion that is not rigid (as the 4 500-object catalogue's build once produced) is refused
  // before anything is written, since the reader would refuse the file; nothing is left behind.
  auto skew = rec;
  skew.pairs[0].linear(2, 2) = 1.0 + 1e-5;
  CHECK_THROWS_WITH_AS(ts::io::write_database(dir / "skew.h5", stored(objects), custom_settings(), 5, {}, &skew),
                       doctest::Contains("row 0 is not a rigid motion"), ts::Error);
  CHECK_FALSE(std::filesystem::exists(dir / "skew.h5"));
  skew.pairs[0].linear(2, 2) = 1.0 + 1e-9;   // within the reader's 1e-6: written and read back
  ts::io::write_database(dir / "skew.h5", stored(objects), custom_settings(), 5, {}, &skew);
  CHECK(ts::io::DbReader(dir / "skew.h5").congruence()->pairs.size() == 2);
  // Added to the old database in place (on a copy): the objects' bytes are untouched.
  ts::io::write_congruence(dir / "old.h5", rec);
  check_record(ts::io::DbReader(dir / "old.h5"));
  {
    ts::io::DbReader db(dir / "old.h5");
    check_same(db, 1, objects[1]);
  }
  // A record that does not cover every object is refused, and the file stays as it was.
  const auto before = ts::test::read_bytes(dir / "old.h5");
  auto short_rec = rec;
  short_rec.signatures.pop_back();
  CHECK_THROWS_WITH_AS(ts::io::write_congruence(dir / "old.h5", short_rec), doctest::Contains("2 signatures for 3 objects"),
                       ts::Error);
  CHECK(ts::test::read_bytes(dir / "old.h5") == before);
  // Appending replaces the record.
  auto d = synthetic_object("d", 9);
  auto rec4 = rec;
  rec4.signatures.push_back({0.5, {0.1, 0.2, 0.3}});
  rec4.pairs.push_back({0, 3, ts::Congruence::congruent, 0.0});
  ts::io::append_to_database(dir / "new.h5", stored_one(d), {}, &rec4);
  {
    ts::io::DbReader db(dir / "new.h5");
    REQUIRE(db.congruence() != nullptr);
    CHECK(db.congruence()->classes() == std::vector<std::vector<std::size_t>>{{0, 2, 3}});
  }
  // Damaged records name the file and the dataset.
  auto edit = [&](const std::function<void(h5::Group&)>& change) {
    fs::copy_file(dir / "new.h5", dir / "bad.h5", fs::copy_options::overwrite_existing);
    {
      auto f = h5::File::open(dir / "bad.h5", h5::File::Access::read_write);
      auto g = f.root().open_group("congruence");
      change(g);
      f.close();
    }
  };
  edit([](h5::Group& g) {
    g.remove("kind");
    g.write("kind", std::vector<std::int64_t>{1, 2, 7});
  });
  CHECK_THROWS_WITH_AS(ts::io::DbReader(dir / "bad.h5"), doctest::Contains("/congruence/kind"), ts::Error);
  edit([](h5::Group& g) {
    g.remove("pairs");
    const std::vector<std::int64_t> p = {0, 2, 1, 2, 3, 4};   // object 4 does not exist
    g.write("pairs", p.data(), {3, 2});
  });
  CHECK_THROWS_WITH_AS(ts::io::DbReader(dir / "bad.h5"), doctest::Contains("not a pair of objects"), ts::Error);
  edit([](h5::Group& g) { g.set_attribute("tolerance", 0.0); });
  CHECK_THROWS_WITH_AS(ts::io::DbReader(dir / "bad.h5"), doctest::Contains("/congruence@tolerance"), ts::Error);
}

TEST_CASE("db store: the descriptor is a build parameter; its rows have its dimension") {
  TempDir dir("db");
  for (const ts::Descriptor d : {ts::Descriptor::pfh, ts::Descriptor::shot, ts::Descriptor::spin}) {
    CAPTURE(ts::descriptor_name(d));
    const int dim = ts::descriptor_dim(d);
    std::vector<ts::BuiltObject> objects;
    objects.push_back(synthetic_object("a", 1));
    objects.push_back(synthetic_object("b", 2));
    ts::Rng rng(3);
    for (auto& o : objects) {
      o.features.features = ts::FeatureRows(dim, o.features.coarse.size());
      for (float& v : o.features.features.values()) v = static_cast<float>(rng.uniform(0, 1));
    }
    ts::DatabaseSettings s;
    s.descriptor = d;
    const auto path = dir / (ts::descriptor_name(d) + ".h5");
    ts::io::write_database(path, stored(objects), s, 5);
    {
      ts::io::DbReader db(path);
      CHECK(db.settings().descriptor == d);
      CHECK(db.feature_dim() == dim);
      for (std::size_t i = 0; i < objects.size(); ++i) {
        const auto feat = db.load_features(i);
        CHECK(feat.features.dim() == dim);
        CHECK(feat.features == objects[i].features.features);
      }
    }
    // Rows of another descriptor's dimension are refused, and the file stays as it was.
    const auto before = ts::test::read_bytes(path);
    auto fpfh_rows = synthetic_object("c", 4);   // 33 values per row
    const std::string why = "features of 33 values per row; the database's descriptor has " + std::to_string(dim);
    CHECK_THROWS_WITH_AS(ts::io::append_to_database(path, {{&fpfh_rows, 1}}), doctest::Contains(why.c_str()),
                         ts::Error);
    CHECK(ts::test::read_bytes(path) == before);
    // A descriptor name nobody knows is one error naming the attribute.
    {
      auto f = h5::File::open(path, h5::File::Access::read_write);
      f.group("params").set_attribute("descriptor", std::string("sift"));
      f.close();
    }
    CHECK_THROWS_WITH_AS(ts::io::DbReader{path}, doctest::Contains("/params@descriptor"), ts::Error);
    CHECK_THROWS_WITH_AS(ts::io::DbReader{path}, doctest::Contains("sift"), ts::Error);
    // The stored descriptor and the rows' dimension must agree.
    {
      auto f = h5::File::open(path, h5::File::Access::read_write);
      f.group("params").set_attribute("descriptor", std::string(d == ts::Descriptor::pfh ? "shot" : "pfh"));
      f.close();
    }
    CHECK_THROWS_WITH_AS(ts::io::DbReader{path}, doctest::Contains("feature_dim"), ts::Error);
  }
}

TEST_CASE("db store: databases written before the descriptor was stored are FPFH databases") {
  const auto path = std::filesystem::path(TS_SOURCE_DIR) / "tests/fuzz/base/box_db.h5";
  ts::io::DbReader db(path);   // written without /params@descriptor
  CHECK(db.settings().descriptor == ts::Descriptor::fpfh);
  CHECK(db.feature_dim() == 33);
  CHECK(db.load_features(0).features.dim() == 33);
}

TEST_CASE("db store: build parameters set by name, within their ranges") {
  using ts::DatabaseSettings;
  // Every stored parameter can be set by its name, to its default and to a changed value that
  // reads back; the ranges refuse what `db build` refuses, naming the key.
  const DatabaseSettings defaults;
  for (const auto& v : ts::io::settings_values(defaults)) {
    const std::string key = v.group.empty() ? v.name : v.group + "." + v.name;
    CAPTURE(key);
    DatabaseSettings s;
    ts::io::set_setting_value(s, key, v.value, "x.h5");
    CHECK(ts::io::settings_values(s).size() == ts::io::settings_values(defaults).size());
    const double changed = v.integer ? v.value + 1 : v.value * 0.5 + (v.value == 0 ? 0.1 : 0.0);
    ts::io::set_setting_value(s, key, changed, "x.h5");
    bool found = false;
    for (const auto& w : ts::io::settings_values(s))
      if ((w.group.empty() ? w.name : w.group + "." + w.name) == key) {
        found = true;
        CHECK(w.value == changed);
      }
    CHECK(found);
  }
  auto refused = [](const std::string& key, double value) {
    DatabaseSettings s;
    try {
      ts::io::set_setting_value(s, key, value, "x.h5");
    } catch (const ts::Error& e) {
      return e.file() == "x.h5" && e.field() == key;
    }
    return false;
  };
  CHECK(refused("scan.bogus", 1.0));
  CHECK(refused("scan.fine_spacing", 0.0));
  CHECK(refused("scan.fine_spacing", -0.001));
  CHECK(refused("max_extent", std::numeric_limits<double>::infinity()));
  CHECK(refused("scan.target_coverage", 1.5));
  CHECK(refused("scan.max_views", 2.5));
  CHECK(refused("scan.max_views", 100001));
  CHECK(refused("scan.random_every", 0));
  CHECK(refused("field.fine_band_voxels", 1001));
  CHECK(refused("scan.max_incidence_deg", 95));
  CHECK(refused("fpfh.feature_radius", std::nan("")));
  CHECK_FALSE(refused("field.coarse_margin", 0.0));
  CHECK_FALSE(refused("scan.target_coverage", 0.0));
  CHECK_FALSE(refused("field.fine_band_voxels", 1000));
}
