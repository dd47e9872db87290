// The engine tests' fixture cache (recognition_fixture.hpp, make_source): a source read back from
// the bytes it was saved as equals the built source, value for value; a file cut short or of
// another format is refused (the fixture then builds the source again).
#include "engine/recognition_fixture.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <fstream>

using namespace ts;

namespace {
bool same_cloud(const PointCloud& a, const PointCloud& b) { return a.points == b.points && a.normals == b.normals; }
}  // namespace

TEST_CASE("make_source's cache: a source saved and read back equals the built one, bit for bit") {
  const auto built = test::build_source(0.5);
  test::TempDir dir("fixture-cache");
  const auto path = dir / "source.bin";
  test::source_bytes::save(*built, path);
  test::TestSource back(0.5);
  REQUIRE(test::source_bytes::load(back, path));
  REQUIRE(back.size() == built->size());
  REQUIRE(built->size() == 6);
  for (std::size_t i = 0; i < built->size(); ++i) {
    INFO(built->infos[i].name);
    CHECK(back.infos[i].name == built->infos[i].name);
    CHECK(back.infos[i].extent == built->infos[i].extent);
    CHECK(back.infos[i].fine_points == built->infos[i].fine_points);
    CHECK(back.infos[i].coarse_points == built->infos[i].coarse_points);
    CHECK(back.infos[i].closed == built->infos[i].closed);
    CHECK(same_cloud(back.feats[i].coarse, built->feats[i].coarse));
    CHECK(back.feats[i].features == built->feats[i].features);
    CHECK(same_cloud(back.fines[i], built->fines[i]));
    CHECK(back.meshes[i].vertices == built->meshes[i].vertices);
    CHECK(back.meshes[i].faces == built->meshes[i].faces);
    for (auto [a, b] : {std::pair{&back.field_fine[i], &built->field_fine[i]}, std::pair{&back.field_coarse[i], &built->field_coarse[i]}}) {
      CHECK(a->voxel == b->voxel);
      CHECK(a->ijk == b->ijk);
      CHECK(a->value == b->value);
    }
  }
  CHECK(back.db_settings.field.fine_voxel == built->db_settings.field.fine_voxel);

  // Cut short, or another format: refused.
  const auto bytes = std::filesystem::file_size(path);
  std::filesystem::resize_file(path, bytes - 9);
  test::TestSource cut(0.5);
  CHECK_FALSE(test::source_bytes::load(cut, path));
  { std::ofstream(path, std::ios::binary) << "not a source"; }
  test::TestSource other(0.5);
  CHECK_FALSE(test::source_bytes::load(other, path));
}
