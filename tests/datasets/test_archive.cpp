#include "datasets/archive.hpp"
#include "engine/core.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <utility>

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

namespace {
/// A ustar header for a regular file `name` whose size field holds `size` (12 bytes: octal, or
/// GNU base-256 when it starts with 0x80), its checksum right.
std::string tar_header(const std::string& name, const std::string& size) {
  std::string h(512, '\0');
  h.replace(0, name.size(), name);
  h.replace(100, 8, "0000644", 8);
  h.replace(108, 8, "0000000", 8);
  h.replace(116, 8, "0000000", 8);
  h.replace(124, 12, size);
  h.replace(136, 12, "00000000000", 12);
  h[156] = '0';
  h.replace(257, 8, std::string("ustar\0" "00", 8));
  unsigned sum = 0;
  for (std::size_t i = 0; i < 512; ++i) sum += (i >= 148 && i < 156) ? ' ' : static_cast<unsigned char>(h[i]);
  char text[8];
  std::snprintf(text, sizeof text, "%06o", sum);
  h.replace(148, 8, std::string(text, 6) + std::string("\0 ", 2));
  return h;
}
}  // namespace

TEST_CASE("archive: a member declaring more bytes than the archive holds is refused, naming it and the archive") {
  // Issue 57: a header declaring gigabytes in a 1.5 kB archive made db build allocate them
  // (std::bad_alloc, or a hang while the pages were filled).
  TempDir dir("tar");
  const std::string data = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  char octal[13];
  std::snprintf(octal, sizeof octal, "%011o", static_cast<unsigned>(data.size()));
  const std::string good = tar_header("ok.off", std::string(octal, 12)) + data + std::string(512 - data.size(), '\0');
  const std::string end(1024, '\0');
  ts::test::write_text(dir / "good.tar", good + end);
  CHECK(ts::datasets::read_archive_member(dir / "good.tar", "ok.off") == data);   // the header is right
  const std::string gnu_huge = std::string(1, '\x80') + std::string(3, '\0') + std::string("\x40\0\0\0\0\0\0\0", 8);   // 2^62
  for (const auto& [size, declared] : {std::pair{std::string("77777777777") + '\0', std::string("8589934591")},
                                       std::pair{gnu_huge, std::string("4611686018427387904")}}) {
    CAPTURE(declared);
    const std::string tar = good + tar_header("big.off", size) + data + std::string(512 - data.size(), '\0') + end;
    REQUIRE(tar.size() == 3072);
    ts::test::write_text(dir / "big.tar", tar);
    const std::string plain = "archive is truncated or corrupt: member 'big.off' declares " + declared +
                              " bytes, more than the 1536 bytes left in the archive (" + (dir / "big.tar").string() +
                              ", member 'big.off')";
    CHECK_THROWS_WITH_AS(ts::datasets::read_archive_members(dir / "big.tar", {"ok.off", "big.off"}), plain.c_str(), ts::Error);
    CHECK_THROWS_WITH_AS(ts::datasets::list_archive(dir / "big.tar"), doctest::Contains("member 'big.off' declares"), ts::Error);
    // Compressed, the bytes left are not known before they are read: the member is read as it
    // arrives and refused where the archive ends.
    REQUIRE(run("gzip -kf " + (dir / "big.tar").string()) == 0);
    const std::string compressed = "archive is truncated: member 'big.off' declares " + declared +
                                   " bytes, and the archive ends after 1536 of them (" + (dir / "big.tar.gz").string() +
                                   ", member 'big.off')";
    CHECK_THROWS_WITH_AS(ts::datasets::read_archive_member(dir / "big.tar.gz", "big.off"), compressed.c_str(), ts::Error);
  }
}
