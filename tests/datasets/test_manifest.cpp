#include "datasets/manifest.hpp"
#include "engine/core.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;

namespace {
/// Files of a test in their own directory, removed with it.
struct Files {
  ts::test::TempDir dir{"manifest"};
  fs::path write(const std::string& name, const std::string& text) {
    const fs::path p = dir / name;
    std::ofstream(p) << text;
    return p;
  }
};
}  // namespace

TEST_CASE("manifest lines resolve archive members relative to the manifest") {
  Files f;
  const auto p = f.write("m1.tsv",
                            "# comment\n"
                            "pkg\tcache/a.tar.gz:data/meshes/x.off\tx\n"
                            "\n"
                            "local\t/abs/y.obj\ty\n");
  const auto m = ts::datasets::read_manifest(p);
  REQUIRE(m.size() == 2);
  CHECK(m[0].name == "x");
  CHECK(m[0].member == "data/meshes/x.off");
  CHECK(m[0].path == p.parent_path() / "cache/a.tar.gz");
  CHECK(m[0].line == 2);
  CHECK(m[1].member.empty());
  CHECK(m[1].path == fs::path("/abs/y.obj"));
}

TEST_CASE("manifest errors name the file and the line") {
  Files f;
  const auto short_line = f.write("m2.tsv", "pkg\tonly-two\n");
  CHECK_THROWS_WITH_AS(ts::datasets::read_manifest(short_line),
                       doctest::Contains("line 1"), ts::Error);
  const auto dup = f.write("m3.tsv", "a\tx.off\tsame\nb\ty.off\tsame\n");
  CHECK_THROWS_WITH_AS(ts::datasets::read_manifest(dup), doctest::Contains("duplicate"), ts::Error);
  CHECK_THROWS_AS(ts::datasets::read_manifest("/nonexistent/manifest.tsv"), ts::Error);
}

TEST_CASE("manifest units column: m, cm, mm, in per line, another word names the line") {
  Files f;
  const auto p = f.write("u.tsv", "a\tx.off\tx\tcm\nb\ty.off\ty\nc\tz.off\tz\tin\n");
  const auto m = ts::datasets::read_manifest(p);
  REQUIRE(m.size() == 3);
  CHECK(m[0].units == 0.01);
  CHECK(m[1].units == 0.0);   // not given: the build's --units
  CHECK(m[2].units == 0.0254);
  const auto bad = f.write("u2.tsv", "a\tx.off\tx\tm\nb\ty.off\ty\tfeet\n");
  CHECK_THROWS_WITH_AS(ts::datasets::read_manifest(bad), doctest::Contains("line 2, units"), ts::Error);
  CHECK_THROWS_WITH_AS(ts::datasets::read_manifest(bad), doctest::Contains("'feet'"), ts::Error);
  const auto five = f.write("u3.tsv", "a\tx.off\tx\tm\textra\n");
  CHECK_THROWS_WITH_AS(ts::datasets::read_manifest(five), doctest::Contains("5 fields"), ts::Error);
}

TEST_CASE("the shipped default manifest lists 45 distinct objects") {
  Files f;
  const auto m = ts::datasets::read_manifest(fs::path(TS_SOURCE_DIR) / "datasets/dev45.tsv");
  CHECK(m.size() == 45);
}
