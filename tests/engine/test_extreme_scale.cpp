// Objects far below the usual size with every length scaled: what the stress study (study 10,
// docs/testing.md; its record in CHANGELOG.md) found. A 1 mm object's distance field needs voxels of about 13 micrometres,
// which OpenVDB refused to make (ArithmeticError: its transform's scale must exceed 1.44e-5 m).
#include "engine/geometry/distance_field.hpp"
#include "engine/geometry/mesh.hpp"
#include "recognition_fixture.hpp"

#include <doctest/doctest.h>

#include <cmath>

using namespace ts;

namespace {

DistanceField scaled_box_field(double f) {
  DistanceFieldSettings s;
  s.fine_voxel = 0.002 * f;
  s.coarse_voxel = 0.01 * f;
  s.coarse_margin = 0.05 * f;
  const Mesh m = test::box_mesh(Vec3(0.12, 0.08, 0.05) * f);
  return DistanceField::build(m, true, s);
}

}  // namespace

TEST_CASE("A 0.5 mm box's distance field (8 micrometre voxels) is the 12 cm one scaled") {
  // The box's largest side becomes 0.5 mm, its fine voxel 8.3 um (OpenVDB's smallest: 14 um).
  const double f = 0.0005 / 0.12;
  const DistanceField big = scaled_box_field(1.0);
  DistanceField small;
  REQUIRE_NOTHROW(small = scaled_box_field(f));
  REQUIRE_FALSE(small.empty());
  // Known distances: the centre is 25 mm (scaled) inside, a point 1 mm off the +x face outside.
  CHECK(std::abs(big.distance(Vec3::Zero()) + 0.025) < 1e-5);
  CHECK(std::abs(small.distance(Vec3::Zero()) + 0.025 * f) < 1e-5 * f);
  CHECK(std::abs(small.distance(Vec3(0.061, 0.01, 0.0) * f) - 0.001 * f) < 1e-6 * f);
  // Everywhere within the band and the coarse grid: the big field's values, scaled.
  for (int i = -20; i <= 20; ++i)
    for (int j = -7; j <= 7; ++j) {
      const Vec3 p(0.0031 * i, 0.0047 * j, 0.0252 + 0.0003 * (i % 3));
      const double a = big.distance(p), b = small.distance(p * f);
      CAPTURE(p.transpose());
      CHECK(std::abs(b / f - a) < 1e-5);
    }
}
