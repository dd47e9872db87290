// The ICP normal equations as a diagnostic (icp_system): singular on a flat patch, well
// conditioned with patches all round, and unitless (the same for a scaled copy of the scene).
#include "engine/recognition/icp.hpp"
#include "recognition_fixture.hpp"

#include <doctest/doctest.h>

#include <cmath>

using namespace ts;

namespace {

struct Conditioned {
  IcpSystem sys;
  std::size_t contacts = 0;
};

/// icp_system of `patches` patches of the wedge (object 4) at the true pose, at `scale`.
Conditioned wedge_system(double scale, int patches) {
  auto src = test::make_source(scale);
  Database db(src);
  const Pose T = test::random_pose(41, Vec3(0.3, -0.2, 0.1) * scale);
  const PointCloud c = test::touch(src->fines[4], T, patches, 9, 0.0, 0.0, scale);
  const Scene scene = prepare_scene(c, {}, db.settings().fpfh, {}, 1, 1);
  Pose T_scene = T;
  T_scene.translation() -= scene.origin;
  IcpSettings s;
  const GeometryRef geo = db.geometry(4);
  return {icp_system(scene, *geo, T_scene, s), c.size()};
}

}  // namespace

TEST_CASE("ICP system: a flat patch is singular in 3 DOF, patches all round are not") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(42, Vec3(0.1, 0.2, 0.3));
  PointCloud flat;  // a taxel grid on the box's large face (z = +0.025)
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 6; ++j) flat.points.push_back(T * Vec3(-0.015 + 0.004 * i, -0.01 + 0.004 * j, 0.025));
  const Scene scene = prepare_scene(flat, {}, db.settings().fpfh, {}, 1, 1);
  Pose T_scene = T;
  T_scene.translation() -= scene.origin;
  const GeometryRef geo = db.geometry(0);
  const IcpSystem f = icp_system(scene, *geo, T_scene, {});
  CHECK(f.pairs == flat.size());
  CHECK(f.unobservable_dof == 3);
  CHECK(f.condition > 1e8);
  CHECK_FALSE(f.valid);
  CHECK(std::isfinite(f.condition));
  CHECK(std::isfinite(f.condition_raw));

  const Conditioned round = wedge_system(1.0, 12);
  CHECK(round.sys.valid);
  CHECK(round.sys.unobservable_dof == 0);
  CHECK(round.sys.condition > 1.0);
  CHECK(round.sys.condition < 1e3);
  CHECK(round.sys.pairs == std::min<std::size_t>(round.contacts, IcpSettings{}.max_points));
}

TEST_CASE("ICP system: the condition is unitless, the raw one is not") {
  const Conditioned a = wedge_system(1.0, 8), b = wedge_system(15.0, 8);
  REQUIRE(a.sys.valid);
  REQUIRE(b.sys.valid);
  CHECK(std::abs(b.sys.radius / a.sys.radius / 15.0 - 1.0) < 0.05);
  // The same contacts up to scale (the fixture samples at scaled voxels): within a few %.
  CHECK(std::abs(b.sys.condition / a.sys.condition - 1.0) < 0.05);
  // Raw: rotations in radians against translations in metres. At 15x the rotation block grows
  // 225-fold; the raw condition of the small wedge is dominated by that unit mismatch.
  CHECK(a.sys.condition_raw > 10.0 * a.sys.condition);
  CHECK(std::abs(std::log10(b.sys.condition_raw / a.sys.condition_raw)) > 0.5);
}

TEST_CASE("ICP system: degenerate input gives no system, never NaN") {
  auto src = test::make_source();
  Database db(src);
  const GeometryRef geo = db.geometry(4);
  PointCloud two;
  two.points = {Vec3(0, 0, 0), Vec3(0.01, 0, 0)};
  const Scene scene = prepare_scene(two, {}, db.settings().fpfh, {}, 1, 1);
  const IcpSystem s = icp_system(scene, *geo, Pose::Identity(), {});
  CHECK_FALSE(s.valid);
  CHECK(s.condition == kIcpSingular);
  CHECK(s.condition_raw == kIcpSingular);
  Pose bad = Pose::Identity();
  bad.translation().x() = std::nan("");
  const Conditioned ok = wedge_system(1.0, 4);
  CHECK(ok.sys.pairs > 0);
  CHECK_FALSE(icp_system(scene, *geo, bad, {}).valid);
}
