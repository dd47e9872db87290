#include "datasets/archive.hpp"
#include "engine/core.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cstdlib>
#include <filesystem>

namespace fs = std::filesystem;
using ts::test::TempDir;

namespace {
// Archives made by the system's tar (the oracle), in GNU and pax formats.
void make_tree(const fs::path& root) {
  fs::create_directories(root / "data/meshes");
  ts::test::write_text(root / "data/meshes/a.off", "OFF\nalpha\n");
  ts::test::write_text(root / "data/meshes/b.off", std::string(70000, 'b'));  // several blocks
  const std::string deep = "data/" + std::string(60, 'd') + "/" + std::string(70, 'e');
  fs::create_directories(root / deep);
  ts::test::write_text(root / deep / "long-name-member.off", "deep");
  ts::test::write_text(root / "empty.txt", "");
}
int run(const std::string& cmd) { return std::system((cmd + " >/dev/null 2>&1").c_str()); }
}  // namespace

TEST_CASE("archive: members of .tar.gz, .tgz and .tar in GNU and pax formats") {
  TempDir dir("tar");
  make_tree(dir / "src");
  const std::string src = (dir / "src").string();
  REQUIRE(run("tar -C " + src + " --format=gnu -czf " + (dir / "a.tar.gz").string() + " data empty.txt") == 0);
  REQUIRE(run("tar -C " + src + " --format=pax -czf " + (dir / "a.tgz").string() + " ./data ./empty.txt") == 0);
  REQUIRE(run("tar -C " + src + " --format=ustar -cf " + (dir / "a.tar").string() + " data empty.txt") == 0);
  const std::string deep = "data/" + std::string(60, 'd') + "/" + std::string(70, 'e') + "/long-name-member.off";
  for (const char* name : {"a.tar.gz", "a.tgz", "a.tar"}) {
    CAPTURE(std::string(name));
    const auto arc = dir / name;
    CHECK(ts::datasets::read_archive_member(arc, "data/meshes/a.off") == "OFF\nalpha\n");
    CHECK(ts::datasets::read_archive_member(arc, "./data/meshes/b.off") == std::string(70000, 'b'));
    CHECK(ts::datasets::read_archive_member(arc, deep) == "deep");
    CHECK(ts::datasets::read_archive_member(arc, "empty.txt").empty());
    const auto both = ts::datasets::read_archive_members(arc, {"data/meshes/a.off", "empty.txt"});
    CHECK(both.size() == 2);
    const auto names = ts::datasets::list_archive(arc);
    CHECK(names.size() == 4);
    CHECK(std::find(names.begin(), names.end(), deep) != names.end());
    CHECK_THROWS_WITH_AS(ts::datasets::read_archive_member(arc, "data/meshes/c.off"),
                         doctest::Contains("archive has no member 'data/meshes/c.off'"), ts::Error);
  }
}

TEST_CASE("archive: missing, foreign, corrupt and truncated archives give one clear error") {
  TempDir dir("tar");
  make_tree(dir / "src");
  const auto arc = dir / "a.tar.gz";
  REQUIRE(run("tar -C " + (dir / "src").string() + " -czf " + arc.string() + " data") == 0);
  const auto bytes = ts::test::read_bytes(arc);

  CHECK_THROWS_WITH_AS(ts::datasets::read_archive_member(dir / "none.tar.gz", "x"),
                       doctest::Contains("archive does not exist"), ts::Error);
  ts::test::write_text(dir / "text.tar.gz", std::string(2000, 'x'));
  CHECK_THROWS_WITH_AS(ts::datasets::read_archive_member(dir / "text.tar.gz", "x"),
                       doctest::Contains("not a tar archive"), ts::Error);

  ts::test::write_text(dir / "cut.tar.gz", bytes.substr(0, bytes.size() / 2));
  CHECK_THROWS_AS(ts::datasets::list_archive(dir / "cut.tar.gz"), ts::Error);

  std::string bad = bytes;
  for (std::size_t i = bad.size() / 3; i < bad.size() / 3 + 64; ++i) bad[i] = static_cast<char>(bad[i] ^ 0x5a);
  ts::test::write_text(dir / "bad.tar.gz", bad);
  CHECK_THROWS_WITH_AS(ts::datasets::list_archive(dir / "bad.tar.gz"), doctest::Contains("bad.tar.gz"), ts::Error);

  // A plain tar cut inside a member's data.
  REQUIRE(run("tar -C " + (dir / "src").string() + " -cf " + (dir / "p.tar").string() + " data") == 0);
  const auto plain = ts::test::read_bytes(dir / "p.tar");
  ts::test::write_text(dir / "pcut.tar", plain.substr(0, 1024 + 700));
  CHECK_THROWS_WITH_AS(ts::datasets::list_archive(dir / "pcut.tar"), doctest::Contains("truncated"), ts::Error);
}
