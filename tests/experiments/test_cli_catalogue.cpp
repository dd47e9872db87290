// `touchstone catalogue` end to end: the built program, its summary and its errors.
#include "datasets/manifest.hpp"
#include "io/mesh_import.hpp"
#include "cli_run.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <filesystem>

namespace fs = std::filesystem;
using ts::test::TempDir;
using ts::test::touchstone;

TEST_CASE("cli catalogue: 12 objects, JSON summary, readable manifest and meshes") {
  TempDir dir("cli_catalogue");
  const auto r = touchstone(dir, "catalogue --count 12 --seed 3 --coarsen 3 --threads 2 --out cat --json");
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["count"] == 12);
  CHECK(j["seed"] == 3);
  CHECK(j["closest_pairs"].size() == 5);
  CHECK(j["families"]["elbow"] == 1);
  const auto entries = ts::datasets::read_manifest(dir / "cat/manifest.tsv");
  REQUIRE(entries.size() == 12);
  for (const auto& e : entries) {
    const auto m = ts::io::import_mesh(e.path);
    CHECK(m.closed);
    CHECK(e.units == 1.0);
  }
  // Human summary, and an existing folder without --force.
  const auto again = touchstone(dir, "catalogue --count 12 --seed 3 --coarsen 3 --out cat");
  CHECK(again.code == 1);
  CHECK(again.err.find("use --force") != std::string::npos);
  const auto forced = touchstone(dir, "catalogue --count 2 --families hex_nut,bracket --coarsen 3 --out cat --force");
  REQUIRE_MESSAGE(forced.code == 0, forced.err);
  CHECK_MESSAGE(forced.err.find("catalogue: objects 2/2 (100.0 %)") != std::string::npos, forced.err);   // not a terminal
  CHECK(forced.out.find("objects per family:") != std::string::npos);
  CHECK(forced.out.find("closest pairs") != std::string::npos);
  CHECK(ts::datasets::read_manifest(dir / "cat/manifest.tsv").size() == 2);
}

TEST_CASE("cli catalogue: bad count, family and configuration ranges") {
  TempDir dir("cli_catalogue");
  auto r = touchstone(dir, "catalogue --count 0 --out x");
  CHECK(r.code == 1);
  CHECK(r.err.find("--count must lie in 1..100000") != std::string::npos);
  r = touchstone(dir, "catalogue --count 5 --out x --families elbow,teapot");
  CHECK(r.code == 1);
  CHECK(r.err.find("unknown family 'teapot'") != std::string::npos);
  ts::test::write_text(dir / "ranges.toml", "[flange_blind]\nthickness_ratio = [1.3, 0.9]\n");
  r = touchstone(dir, "catalogue --count 5 --out x --config ranges.toml");
  CHECK(r.code == 1);
  CHECK(r.err.find("ranges.toml") != std::string::npos);
  CHECK(r.err.find("flange_blind") != std::string::npos);
  CHECK(r.err.find("thickness_ratio") != std::string::npos);
  ts::test::write_text(dir / "ranges.toml", "[valve]\nweight = 0\n[elbow]\nod = [0.05, 0.06]\n");
  r = touchstone(dir, "catalogue --count 3 --families valve,elbow --coarsen 3 --out y --config ranges.toml --json");
  REQUIRE_MESSAGE(r.code == 0, r.err);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["families"]["valve"] == 0);
  CHECK(j["families"]["elbow"] == 3);
  CHECK_FALSE(fs::exists(dir / "x"));
}
