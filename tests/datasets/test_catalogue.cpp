// The parametric catalogue generator (datasets/catalogue): valid meshes, analytic volumes,
// determinism, congruence rejection, configuration errors and readable output.
#include "datasets/catalogue/catalogue.hpp"
#include "datasets/manifest.hpp"
#include "engine/geometry/mesh.hpp"
#include "io/mesh_import.hpp"
#include "mesh_fixtures.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <sys/wait.h>
#include <unistd.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <numbers>

namespace fs = std::filesystem;
namespace cat = ts::catalogue;
using ts::test::TempDir;

namespace {

/// Coarse meshes: these tests check construction and plumbing, not resolution.
cat::BuildSettings coarse() {
  cat::BuildSettings b;
  b.feature_voxels = 1.5;
  b.max_voxel_fraction = 1.0 / 40;
  b.preview_voxel_fraction = 1.0 / 16;
  b.target_triangles = 3000;
  return b;
}

cat::CatalogueSettings fast_settings(std::size_t count, std::uint64_t seed = 1) {
  cat::CatalogueSettings s;
  s.count = count;
  s.seed = seed;
  s.build = coarse();
  return s;
}

/// Every file of a folder tree, relative path -> bytes.
std::map<std::string, std::string> folder_bytes(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out[fs::relative(e.path(), dir).string()] = ts::test::read_bytes(e.path());
  return out;
}

const cat::Family& family(const std::string& name) {
  const auto* f = cat::find_family(name);
  REQUIRE(f != nullptr);
  return *f;
}

}  // namespace

TEST_CASE("catalogue: at least 12 families, every one builds a closed, outward-wound mesh") {
  const auto& families = cat::all_families();
  CHECK(families.size() >= 12);
  for (std::size_t k = 0; k < families.size(); ++k) {
    const auto& f = families[k];
    CAPTURE(f.name);
    ts::Rng rng(3, 77, k);
    const auto params = cat::draw_params(f, rng);
    const auto built = cat::build_object(f, params, coarse());
    CHECK(built.check.valid());
    CHECK(built.check.volume > 0.0);
    CHECK(ts::mesh_topology(built.mesh).closed());  // the engine's own check agrees
    CHECK(ts::mesh_signed_volume(built.mesh) > 0.0);
    CHECK(built.mesh.faces.size() >= 500);
    CHECK(built.extent > 0.02);   // true size: 2 cm ..
    CHECK(built.extent < 0.6);    // .. 60 cm
  }
}

TEST_CASE("catalogue: hex nut and blind flange volumes match the analytic solids") {
  SUBCASE("hex nut: hexagonal prism minus the bore") {
    // size index 2 of the nut series = M24; across flats 1.5 d, height 0.9 d.
    const auto& f = family("hex_nut");
    const auto p = cat::make_params(f, {2, 1.5, 0.9});
    const double d = 0.024, s = 1.5 * d, h = 0.9 * d;
    const double analytic = (std::sqrt(3.0) / 2.0 * s * s - std::numbers::pi * d * d / 4.0) * h;
    const auto built = cat::build_object(f, p);
    CAPTURE(built.voxel);
    CHECK(built.check.valid());
    CHECK(built.check.volume == doctest::Approx(analytic).epsilon(0.01).scale(0));   // 1 %
    // At voxel accuracy: the error is below a tenth of a voxel layer over the surface.
    const double area = ts::mesh_area(built.mesh);
    CHECK(std::abs(built.check.volume - analytic) < 0.1 * built.voxel * area);
  }
  SUBCASE("blind flange DN100: disc plus raised face minus eight bolt holes") {
    const auto& f = family("flange_blind");
    const auto p = cat::make_params(f, {8, 1.0, 0.003, 1.0});  // DN100, nominal thickness, 3 mm face
    const double D = 0.220, K = 0.180, hole = 0.018, pr = 0.1143 / 2, n = 8;
    const double T = 0.012 + 0.045 * D, h = 0.003, rf = pr + 0.6 * (K / 2 - hole / 2 - pr);
    const double pi = std::numbers::pi;
    const double analytic = pi * D * D / 4 * T + pi * rf * rf * h - n * pi * hole * hole / 4 * T;
    const auto built = cat::build_object(f, p);
    CAPTURE(built.voxel);
    CHECK(built.check.valid());
    CHECK(built.check.volume == doctest::Approx(analytic).epsilon(0.015).scale(0));   // 1.5 %
    const auto box = ts::mesh_bounds(built.mesh);
    CHECK(std::abs(box.sizes().x() - D) < 0.002);   // within about a voxel
    CHECK(std::abs(box.sizes().z() - (T + h)) < 0.002);
  }
}

TEST_CASE("catalogue: mesh check finds open, non-manifold and inconsistently wound meshes") {
  auto box = ts::test::box_mesh({0, 0, 0}, {1, 2, 3});
  CHECK(cat::check_mesh(box).valid());
  CHECK(cat::check_mesh(box).volume == doctest::Approx(6.0));
  auto open = box;
  open.faces.pop_back();
  CHECK(cat::check_mesh(open).boundary_edges == 3);
  CHECK_FALSE(cat::check_mesh(open).valid());
  auto flipped_face = box;
  std::swap(flipped_face.faces[0][1], flipped_face.faces[0][2]);
  CHECK(cat::check_mesh(flipped_face).misoriented_edges == 3);
  auto inward = box;
  for (auto& f : inward.faces) std::swap(f[1], f[2]);
  CHECK(cat::check_mesh(inward).volume < 0);
  CHECK_FALSE(cat::check_mesh(inward).valid());
  auto degenerate = box;
  degenerate.faces.emplace_back(0, 0, 1);
  CHECK(cat::check_mesh(degenerate).degenerate_faces == 1);
}

TEST_CASE("catalogue: an impossible construction is one error naming the family and parameters") {
  cat::Family broken = family("hex_nut");
  broken.name = "broken_nut";
  broken.build = [](const cat::Params&, double) { return cat::Construction{cat::Shape{}, 0.0, 0.0}; };
  const auto p = cat::make_params(broken, {2, 1.5, 0.9});
  CHECK_THROWS_WITH_AS(cat::build_object(broken, p), doctest::Contains("family 'broken_nut' (size=M24, flats_ratio=1.5, height_ratio=0.9)"),
                       ts::Error);
}

TEST_CASE("catalogue: the signature ignores rigid motions and separates near twins") {
  const auto& f = family("flange_blind");
  const auto dn50 = cat::build_object(f, cat::make_params(f, {5, 1.0, 0.003, 1.0}), coarse());
  const auto dn65 = cat::build_object(f, cat::make_params(f, {6, 1.0, 0.003, 1.0}), coarse());
  auto moved = dn50.mesh;
  const Eigen::Quaterniond q = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, ts::Vec3(1, 2, 3).normalized()));
  for (auto& v : moved.vertices) v = q * v + ts::Vec3(5, -3, 20);
  const auto s50 = cat::shape_signature(dn50.mesh);
  CHECK(cat::signature_distance(s50, cat::shape_signature(moved)) < 1e-6);
  CHECK(cat::signature_distance(s50, cat::shape_signature(dn65.mesh)) > 0.05);

  // Meshing noise (the same solid at a 13 % finer voxel) stays around the tolerance that calls two
  // objects congruent or below it (measured at full resolution: 0.0007 .. 0.011, see
  // CatalogueSettings::tolerance; coarse test meshes are noisier).
  const double tolerance = cat::CatalogueSettings{}.tolerance;
  for (const char* name : {"reducer", "flange_blind", "t_handle"}) {
    CAPTURE(std::string(name));
    const auto& fam = family(name);
    ts::Rng rng(9);
    const auto p = cat::draw_params(fam, rng);
    cat::BuildSettings finer;
    finer.coarsen = 0.87;
    const auto sa = cat::shape_signature(cat::build_object(fam, p, cat::BuildSettings{}).mesh);
    const auto sb = cat::shape_signature(cat::build_object(fam, p, finer).mesh);
    CHECK(cat::signature_distance(sa, sb) < tolerance);
  }

  // Index order decides which of two congruent objects is "earlier".
  const cat::Signature a{1, 2, 3, 4, 5}, b{1.001, 2, 3, 4, 5}, c{1.1, 2, 3, 4, 5};
  const auto twin = cat::congruent_to_earlier({a, c, b, a}, 0.005);
  CHECK(twin == std::vector<long>{-1, -1, 0, 0});
  const auto pairs = cat::closest_pairs({a, c, b, a}, 2);
  REQUIRE(pairs.size() == 2);
  CHECK(pairs[0].a == 0);
  CHECK(pairs[0].b == 3);
  CHECK(pairs[0].distance == 0.0);
  CHECK(pairs[1].a == 0);
  CHECK(pairs[1].b == 2);
}

TEST_CASE("catalogue: same seed, same bytes for any thread count; another seed differs") {
  TempDir dir("catalogue");
  auto s = fast_settings(9);
  tbb::task_arena one(1), two(2);
  const auto r1 = one.execute([&] { return cat::generate_catalogue(dir / "a", s); });
  two.execute([&] { cat::generate_catalogue(dir / "b", s); });
  const auto a = folder_bytes(dir / "a"), b = folder_bytes(dir / "b");
  CHECK(a.size() == 9 + 3);
  CHECK(a == b);
  CHECK(r1.objects.size() == 9);
  CHECK(r1.closest.size() == 5);
  CHECK(r1.closest[0].distance > s.tolerance);

  s.seed = 2;
  s.count = 1;
  cat::generate_catalogue(dir / "c", s);
  const auto c = folder_bytes(dir / "c");
  CHECK(c.at("meshes/elbow_0000.ply") != a.at("meshes/elbow_0000.ply"));
  CHECK(c.at("catalogue.tsv").find("seed=2") != std::string::npos);
}

TEST_CASE("catalogue: temporary folders of runs that died are removed, those of live runs kept") {
  TempDir dir("catalogue");
  const pid_t child = ::fork();   // a process that has ended: its pid names a dead run
  REQUIRE(child >= 0);
  if (child == 0) ::_exit(0);
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  const fs::path dead = dir / ("d.tmp-" + std::to_string(child));
  const fs::path alive = dir / ("d.tmp-" + std::to_string(::getppid()));   // the test's parent runs
  const fs::path other = dir / "d.tmp-notapid";
  for (const auto& p : {dead, alive, other}) fs::create_directories(p / "meshes");
  auto s = fast_settings(1);
  cat::generate_catalogue(dir / "d", s);
  CHECK(fs::exists(dir / "d/manifest.tsv"));
  CHECK_FALSE(fs::exists(dead));
  CHECK(fs::exists(alive));
  CHECK(fs::exists(other));
}

TEST_CASE("catalogue: congruent duplicates are redrawn, or the generator stops with an error") {
  TempDir dir("catalogue");
  SUBCASE("narrow ranges force redraws; the result has no congruent pair") {
    auto s = fast_settings(16);
    s.families = cat::FamilySet::select("hex_nut");
    s.families.set_range("hex_nut", "size", 0, 0);           // M16 only
    s.families.set_range("hex_nut", "flats_ratio", 1.5, 1.5);
    s.families.set_range("hex_nut", "height_ratio", 0.6, 1.0);  // only the height varies
    const auto r = cat::generate_catalogue(dir / "nuts", s);
    CHECK(r.redraws > 0);
    std::vector<cat::Signature> sigs;
    for (const auto& o : r.objects) sigs.push_back(o.signature);
    for (long t : cat::congruent_to_earlier(sigs, s.tolerance)) CHECK(t == -1);
    CHECK(cat::closest_pairs(sigs, 1).at(0).distance > s.tolerance);
  }
  SUBCASE("a range collapsed to one shape cannot give two objects; an existing folder is kept") {
    fs::create_directories(dir / "out");
    ts::test::write_text(dir / "out/keep.txt", "finished earlier");
    auto s = fast_settings(2);
    s.force = true;
    s.max_attempts = 3;
    s.families = cat::FamilySet::select("hex_nut");
    s.families.set_range("hex_nut", "size", 0, 0);
    s.families.set_range("hex_nut", "flats_ratio", 1.5, 1.5);
    s.families.set_range("hex_nut", "height_ratio", 0.8, 0.8);
    CHECK_THROWS_WITH_AS(cat::generate_catalogue(dir / "out", s),
                         doctest::Contains("hex_nut_0001: still congruent to hex_nut_0000"), ts::Error);
    CHECK(ts::test::read_bytes(dir / "out/keep.txt") == "finished earlier");
    for (const auto& e : fs::directory_iterator(dir.path()))
      CHECK(e.path().filename().string().find(".tmp-") == std::string::npos);
  }
}

TEST_CASE("catalogue: bad counts, families, ranges and an existing folder are clear errors") {
  TempDir dir("catalogue");
  auto s = fast_settings(0);
  CHECK_THROWS_WITH_AS(cat::generate_catalogue(dir / "x", s), doctest::Contains("count must lie in 1..100000"), ts::Error);
  s.count = 100001;
  CHECK_THROWS_AS(cat::generate_catalogue(dir / "x", s), ts::Error);
  CHECK_THROWS_WITH_AS(cat::FamilySet::select("flange_blind,teapot"), doctest::Contains("unknown family 'teapot'"), ts::Error);

  auto set = cat::FamilySet::select();
  CHECK_THROWS_WITH_AS(set.set_range("flange_blind", "thickness_ratio", 1.2, 0.9, "cat.toml"),
                       doctest::Contains("family 'flange_blind' parameter 'thickness_ratio': minimum 1.2 is greater than "
                                         "maximum 0.9 (cat.toml, flange_blind.thickness_ratio)"),
                       ts::Error);
  CHECK_THROWS_WITH_AS(set.set_range("elbow", "od", -0.1, 0.2, "cat.toml"),
                       doctest::Contains("family 'elbow' parameter 'od': sizes must be positive"), ts::Error);
  CHECK_THROWS_WITH_AS(set.set_range("elbow", "colour", 1, 2, "cat.toml"),
                       doctest::Contains("family 'elbow' has no parameter 'colour'"), ts::Error);
  CHECK_THROWS_WITH_AS(set.set_range("hex_bolt", "size", 0, 40, "cat.toml"), doctest::Contains("choice indices"), ts::Error);
  CHECK_THROWS_WITH_AS(set.set_range("gizmo", "od", 1, 2, "cat.toml"), doctest::Contains("unknown family 'gizmo'"), ts::Error);
  auto subset = cat::FamilySet::select("elbow");  // unselected families are checked too
  CHECK_THROWS_WITH_AS(subset.set_range("tee", "od", 0.3, 0.1, "cat.toml"), doctest::Contains("family 'tee' parameter 'od'"),
                       ts::Error);
  set.set_range("elbow", "od", 0.05, 0.06);  // a valid override is kept
  CHECK(set.families[0].params[0].lo == 0.05);

  s = fast_settings(1);
  fs::create_directories(dir / "exists");
  CHECK_THROWS_WITH_AS(cat::generate_catalogue(dir / "exists", s), doctest::Contains("use --force"), ts::Error);
  s.force = true;
  cat::generate_catalogue(dir / "exists", s);
  CHECK(fs::exists(dir / "exists/manifest.tsv"));
}

TEST_CASE("catalogue: the output is a manifest of meshes that the importer reads at true size") {
  TempDir dir("catalogue");
  const auto r = cat::generate_catalogue(dir / "cat", fast_settings(12, 5));
  const auto entries = ts::datasets::read_manifest(dir / "cat/manifest.tsv");
  REQUIRE(entries.size() == 12);
  for (std::size_t i = 0; i < entries.size(); ++i) {
    CAPTURE(entries[i].name);
    CHECK(entries[i].name == r.objects[i].name);
    CHECK(entries[i].source == "catalogue");
    CHECK(entries[i].units == 1.0);
    const auto mesh = ts::io::import_mesh(entries[i].path);
    CHECK(mesh.closed);
    CHECK_FALSE(mesh.flipped);
    CHECK(mesh.mesh.faces.size() == r.objects[i].triangles);
    CHECK(mesh.warnings.empty());
  }
  const auto text = ts::test::read_bytes(dir / "cat/manifest.tsv");
  CHECK(text.rfind("# touchstone catalogue: count=12 seed=5 generator=catalogue-1", 0) == 0);
  const auto table = ts::test::read_bytes(dir / "cat/catalogue.tsv");
  CHECK(table.find("elbow_0000\telbow\t1\t") != std::string::npos);
  CHECK(table.find("od=") != std::string::npos);
  CHECK(fs::exists(dir / "cat/closest_pairs.tsv"));
}
