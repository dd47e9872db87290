#include "io/mesh_export.hpp"
#include "io/mesh_import.hpp"
#include "mesh_fixtures.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <bit>
#include <cstdint>

using ts::test::TempDir;

TEST_CASE("mesh export: binary PLY reads back through Assimp, even when a value starts with a blank byte") {
  TempDir dir("mesh_export");
  // Assimp skips white space after end_header: a first vertex whose x starts with byte 0x0a,
  // 0x0d, 0x20... would shift the whole binary body. Make every such first byte happen.
  for (std::uint32_t low : {0x09u, 0x0au, 0x0bu, 0x0cu, 0x0du, 0x20u, 0x41u}) {
    CAPTURE(low);
    ts::Mesh m = ts::test::box_mesh({0, 0, 0}, {0.3, 0.2, 0.1});
    // Vertex 0 at x slightly off 0.0: bits 0x3c000000 | low (about 0.0078 m).
    const float x0 = std::bit_cast<float>(0x3c000000u | low);
    m.vertices[0].x() = x0;
    const auto file = dir / ("box_" + std::to_string(low) + ".ply");
    ts::io::write_ply(m, file, "test box");
    const auto back = ts::io::import_mesh(file, {.scale = ts::ObjectScale::keep, .units = 1.0});
    REQUIRE(back.mesh.faces.size() == 12);
    // The same solid: volume and bounding box (float precision).
    CHECK(ts::mesh_signed_volume(back.mesh) ==
          doctest::Approx(ts::mesh_signed_volume(m)).epsilon(1e-5).scale(0));
    const auto box = ts::mesh_bounds(back.mesh);
    const auto want = ts::mesh_bounds(m);
    CHECK((box.sizes() - want.sizes()).cwiseAbs().maxCoeff() < 1e-6);
    CHECK(back.closed);
  }
}
