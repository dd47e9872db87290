// The support under the object (engine/recognition/support.hpp): a box resting on a seabed is
// found with its plane (normal and height); a box alone is not (its faces have the box behind
// them); a block on a plate the hand went round is not (free space under the plate); a
// points-only cloud finds it through triplets; its contacts are set aside, with those a little
// below it; where none is found, the verdict names the test its largest candidate failed; bad
// settings named.
#include "engine/recognition/support.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <utility>
#include <vector>

using namespace ts;

namespace {

// One grasp's patch: a 5 x 5 grid of contacts (2 mm apart) about `centre` in the plane with
// normal `n`, and the hand's free points 2 and 4 cm out along n.
void patch(GraspGroups& g, PointCloud& cloud, const Vec3& centre, const Vec3& n) {
  const Vec3 a = (std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(n).normalized();
  const Vec3 b = n.cross(a);
  std::vector<Vec3> pts, free;
  for (int i = -2; i <= 2; ++i)
    for (int j = -2; j <= 2; ++j) pts.push_back(centre + 0.002 * i * a + 0.002 * j * b);
  for (double d : {0.02, 0.04})
    for (int i = -1; i <= 1; ++i) free.push_back(centre + d * n + 0.01 * i * a);
  g.add(pts, free);
  for (const Vec3& p : pts) {
    cloud.points.push_back(p);
    cloud.normals.push_back(n);
  }
}

// A box of half-sizes h resting on z = 0 (its centre at z = h.z), touched on its top and sides.
void box_on_floor(GraspGroups& g, PointCloud& cloud, const Vec3& h) {
  patch(g, cloud, Vec3(0, 0, 2 * h.z()), Vec3::UnitZ());
  patch(g, cloud, Vec3(0.3 * h.x(), -0.2 * h.y(), 2 * h.z()), Vec3::UnitZ());
  for (int s : {-1, 1}) {
    patch(g, cloud, Vec3(s * h.x(), 0.1 * h.y(), 1.3 * h.z()), Vec3(s, 0, 0));
    patch(g, cloud, Vec3(0.2 * h.x(), s * h.y(), 1.2 * h.z()), Vec3(0, s, 0));
  }
}

// Free space: a lattice above z = 0 around the box (outside it), 2 cm apart.
std::vector<Vec3> free_above(const Vec3& h, double below = 0.0) {
  std::vector<Vec3> out;
  for (double x = -0.2; x <= 0.2; x += 0.02)
    for (double y = -0.2; y <= 0.2; y += 0.02)
      for (double z = below + 0.01; z <= 0.2; z += 0.02) {
        const bool inside = std::abs(x) < h.x() + 0.005 && std::abs(y) < h.y() + 0.005 && z < 2 * h.z() + 0.005;
        if (!inside) out.emplace_back(x, y, z);
      }
  return out;
}

}  // namespace

TEST_CASE("support: a box on a seabed; its plane, the contacts set aside") {
  const Vec3 h(0.05, 0.04, 0.03);
  GraspGroups g;
  PointCloud cloud;
  box_on_floor(g, cloud, h);
  const std::size_t object_contacts = cloud.points.size();
  for (const Vec3& c : {Vec3(0.1, 0.02, 0), Vec3(-0.09, -0.07, 0), Vec3(0.02, 0.11, 0)})   // the seabed
    patch(g, cloud, c, Vec3::UnitZ());
  const std::vector<Vec3> free = free_above(h);
  SupportSettings s;
  s.mode = SupportMode::plane;
  const SupportSurface p = estimate_support(cloud, g, free, s, 1, 1);
  REQUIRE(p.found);
  CHECK(p.verdict == SupportVerdict::found);
  CHECK(p.normal.dot(Vec3::UnitZ()) > std::cos(0.5 * 3.14159265 / 180));
  CHECK(std::abs(p.offset) < 1e-9);
  // It explains contacts within the tolerance above it and up to kBelow tolerances below it (a
  // grasp on it moved by the arm's error), not beyond.
  CHECK(p.explains(Vec3(0.3, 0.3, 0.9 * s.tolerance), s.tolerance));
  CHECK_FALSE(p.explains(Vec3(0.3, 0.3, 1.1 * s.tolerance), s.tolerance));
  CHECK(p.explains(Vec3(0.3, 0.3, -0.9 * SupportSurface::kBelow * s.tolerance), s.tolerance));
  CHECK_FALSE(p.explains(Vec3(0.3, 0.3, -1.1 * SupportSurface::kBelow * s.tolerance), s.tolerance));
  CHECK(p.grasps_on == 3);
  CHECK(p.contacts_on == 75);   // the seabed's three patches; the box's lowest contacts are 6 mm up
  CHECK(p.contacts_above == object_contacts);
  const PointCloud rest = without_support(cloud, p, s.tolerance);
  CHECK(rest.points.size() == object_contacts);
  CHECK(rest.normals.size() == object_contacts);
  for (const Vec3& q : rest.points) CHECK(q.z() > 0.01);
  const GraspGroups rest_g = without_support(g, p, s.tolerance);
  CHECK(rest_g.grasps() == g.grasps());
  CHECK(rest_g.points.size() == object_contacts);
  CHECK(rest_g.free.size() == g.free.size());

  // Tilted by 20 degrees about x and moved: the same plane, moved.
  const Pose T(Eigen::Translation3d(0.3, -1.0, 2.0) * Eigen::AngleAxisd(0.35, Vec3::UnitX()));
  PointCloud moved = cloud;
  for (Vec3& q : moved.points) q = T * q;
  for (Vec3& n : moved.normals) n = T.linear() * n;
  GraspGroups mg = g;
  for (Vec3& q : mg.points) q = T * q;
  for (Vec3& q : mg.free) q = T * q;
  std::vector<Vec3> mfree = free;
  for (Vec3& q : mfree) q = T * q;
  const SupportSurface tp = estimate_support(moved, mg, mfree, s, 1, 1);
  REQUIRE(tp.found);
  CHECK(tp.normal.dot(T.linear() * Vec3::UnitZ()) > std::cos(0.5 * 3.14159265 / 180));
  CHECK(std::abs(tp.signed_distance(T.translation())) < 1e-9);

  // Without grasp groups (a points-only cloud): seeded triplets find it too.
  const SupportSurface pts = estimate_support(cloud, {}, free, s, 1, 1);
  REQUIRE(pts.found);
  CHECK(pts.normal.dot(Vec3::UnitZ()) > std::cos(0.5 * 3.14159265 / 180));
  CHECK(pts.contacts_on == 75);
}

TEST_CASE("support: a box alone, and a block on a plate the hand went round, have none") {
  const Vec3 h(0.05, 0.04, 0.03);
  GraspGroups g;
  PointCloud cloud;
  box_on_floor(g, cloud, h);
  // The box's bottom face touched too, from below, and free space all round: no support (every
  // face has the box behind it).
  patch(g, cloud, Vec3(0.01, 0.0, 0.0), -Vec3::UnitZ());
  patch(g, cloud, Vec3(-0.02, 0.01, 0.0), -Vec3::UnitZ());
  patch(g, cloud, Vec3(0.02, -0.01, 0.0), -Vec3::UnitZ());
  SupportSettings s;
  s.mode = SupportMode::plane;
  std::vector<Vec3> free = free_above(h, -0.2);
  const SupportSurface alone = estimate_support(cloud, g, free, s, 1, 1);
  CHECK_FALSE(alone.found);
  // Its largest candidate, the bottom (75 contacts), has its free side down and the box above it.
  CHECK(alone.verdict == SupportVerdict::rest_not_above);
  CHECK(alone.contacts_on == 75);

  // A plate (z = 0) with the block on it, the plate's top touched beside the block, and free
  // space under the plate (the hand went round its rim): the plate's top is no support.
  GraspGroups pg;
  PointCloud plate;
  box_on_floor(pg, plate, h);
  for (const Vec3& c : {Vec3(0.09, 0.02, 0), Vec3(-0.09, -0.07, 0), Vec3(0.02, 0.1, 0)}) patch(pg, plate, c, Vec3::UnitZ());
  std::vector<Vec3> round = free_above(h);
  for (double x = -0.2; x <= 0.2; x += 0.02)
    for (double y = -0.2; y <= 0.2; y += 0.02) round.emplace_back(x, y, -0.05);
  const SupportSurface plate_top = estimate_support(plate, pg, round, s, 1, 1);
  CHECK_FALSE(plate_top.found);
  CHECK(plate_top.verdict == SupportVerdict::free_behind);
  // The same contacts with free space above only: a support.
  CHECK(estimate_support(plate, pg, free_above(h), s, 1, 1).found);
  // Touched on its underside too (contacts below the plane): no support.
  for (const Vec3& c : {Vec3(0.08, 0.0, -0.02), Vec3(-0.05, 0.05, -0.02)}) patch(pg, plate, c, -Vec3::UnitZ());
  const SupportSurface under = estimate_support(plate, pg, free_above(h), s, 1, 1);
  CHECK_FALSE(under.found);
  CHECK(under.verdict == SupportVerdict::rest_not_above);
}

namespace {

// A pipe along x (radius r, its top along z = 0): patches on it at the given angles from its top
// (radians, about x) and positions along it.
void pipe_patches(GraspGroups& g, PointCloud& cloud, double r, const std::vector<std::pair<double, double>>& at) {
  for (const auto& [angle, x] : at) {
    const Vec3 n(0, std::sin(angle), std::cos(angle));
    patch(g, cloud, Vec3(x, 0, -r) + r * n, n);
  }
}

// Free space: a lattice round a box on the pipe, outside both (and inside the pipe too when
// `inside`), 2 cm apart.
std::vector<Vec3> free_round_pipe(const Vec3& h, double r, bool inside = false) {
  std::vector<Vec3> out;
  for (double x = -0.2; x <= 0.2; x += 0.02)
    for (double y = -0.2; y <= 0.2; y += 0.02)
      for (double z = -0.25; z <= 0.2; z += 0.02) {
        const bool in_box = std::abs(x) < h.x() + 0.005 && std::abs(y) < h.y() + 0.005 && z > -0.005 && z < 2 * h.z() + 0.005;
        const double axis = std::hypot(y, z + r);
        if (in_box || (axis < r + 0.005 && !(inside && axis < 0.5 * r))) continue;
        out.emplace_back(x, y, z);
      }
  return out;
}

}  // namespace

TEST_CASE("support: a box on a pipe; its cylinder (axis, radius), the contacts set aside") {
  const Vec3 h(0.05, 0.04, 0.03);
  const double r = 0.08;
  GraspGroups g;
  PointCloud cloud;
  box_on_floor(g, cloud, h);
  const std::size_t object_contacts = cloud.points.size();
  pipe_patches(g, cloud, r, {{0.6, 0.1}, {-0.7, -0.08}, {0.9, -0.12}, {-0.4, 0.14}});
  SupportSettings s;
  s.mode = SupportMode::cylinder;
  const std::vector<Vec3> free = free_round_pipe(h, r);
  const SupportSurface c = estimate_support(cloud, g, free, s, 1, 1);
  REQUIRE(c.found);
  CHECK(c.shape == SupportSurface::Shape::cylinder);
  CHECK(std::abs(c.axis.dot(Vec3::UnitX())) > std::cos(1.0 * 3.14159265 / 180));
  CHECK(std::abs(c.radius - r) < 5e-4);
  const Vec3 off = c.point - Vec3(0, 0, -r);   // from the true axis, across it
  CHECK((off - off.dot(Vec3::UnitX()) * Vec3::UnitX()).norm() < 5e-4);
  CHECK(c.grasps_on == 4);
  CHECK(c.contacts_on == 100);
  CHECK(c.contacts_above == object_contacts);
  CHECK(std::abs(c.signed_distance(Vec3(0, 0, 0.05)) - 0.05) < 5e-4);
  CHECK(c.normal_at(Vec3(0.3, 0, 0.05)).dot(Vec3::UnitZ()) > 0.999);
  const PointCloud rest = without_support(cloud, c, s.tolerance);
  CHECK(rest.points.size() == object_contacts);

  // The plane finds no seabed there: the pipe's patches are not one plane with the rest above.
  s.mode = SupportMode::plane;
  CHECK_FALSE(estimate_support(cloud, g, free, s, 1, 1).found);
  s.mode = SupportMode::cylinder;

  // Without grasp groups (points with normals): seeded pairs of contacts find it too.
  const SupportSurface pts = estimate_support(cloud, {}, free, s, 1, 1);
  REQUIRE(pts.found);
  CHECK(std::abs(pts.radius - r) < 5e-4);
  CHECK(std::abs(pts.axis.dot(Vec3::UnitX())) > std::cos(1.0 * 3.14159265 / 180));
  const Vec3 pts_off = pts.point - Vec3(0, 0, -r);
  CHECK((pts_off - pts_off.dot(Vec3::UnitX()) * Vec3::UnitX()).norm() < 5e-4);
  CHECK(pts.contacts_on == 100);

  // Free space inside it (the hand went through): no pipe.
  CHECK_FALSE(estimate_support(cloud, g, free_round_pipe(h, r, true), s, 1, 1).found);
}

TEST_CASE("support: a bar alone, touched round and on its ends, is no pipe") {
  // An anode bar along x (radius 3 cm, ends at x = +-0.1): its round face is a cylinder, but its
  // ends' contacts lie inside it (the object behind the face).
  const double r = 0.03;
  GraspGroups g;
  PointCloud cloud;
  for (const auto& [angle, x] : std::vector<std::pair<double, double>>{{0.3, 0.05}, {1.4, -0.04}, {2.6, 0.0}, {-1.0, 0.07}}) {
    const Vec3 n(0, std::sin(angle), std::cos(angle));
    patch(g, cloud, Vec3(x, 0, 0) + r * n, n);
  }
  for (int e : {-1, 1}) patch(g, cloud, Vec3(e * 0.1, 0.005, -0.004), Vec3(e, 0, 0));
  std::vector<Vec3> free;
  for (double x = -0.2; x <= 0.2; x += 0.02)
    for (double y = -0.1; y <= 0.1; y += 0.02)
      for (double z = -0.1; z <= 0.1; z += 0.02)
        if (std::abs(x) > 0.105 || std::hypot(y, z) > r + 0.005) free.emplace_back(x, y, z);
  SupportSettings s;
  s.mode = SupportMode::cylinder;
  s.min_radius = 0.02;   // (the default, 4 cm, would refuse the bar for its radius alone)
  CHECK_FALSE(estimate_support(cloud, g, free, s, 1, 1).found);
  // Its round face alone says nothing either way: too few contacts off it to decide.
  GraspGroups round;
  PointCloud round_cloud;
  for (double angle : {0.3, 1.4, 2.6, -1.0}) {
    const Vec3 n(0, std::sin(angle), std::cos(angle));
    patch(round, round_cloud, r * n, n);
  }
  CHECK_FALSE(estimate_support(round_cloud, round, free, s, 1, 1).found);
}

TEST_CASE("support: settings out of range are named") {
  SupportSettings s;
  s.tolerance = 0;
  try {
    estimate_support({}, {}, {}, s, 1, 1);
    FAIL("accepted tolerance 0");
  } catch (const Error& e) {
    CHECK(e.field() == "support.tolerance");
  }
  s = {};
  s.above_share = 0.4;
  CHECK_THROWS_AS(estimate_support({}, {}, {}, s, 1, 1), Error);
  s = {};
  s.min_radius = 0;
  try {
    estimate_support({}, {}, {}, s, 1, 1);
    FAIL("accepted min_radius 0");
  } catch (const Error& e) {
    CHECK(e.field() == "support.min_radius");
  }
  for (auto [key, bad] : {std::pair<const char*, SupportSettings>{"support.sink", [] {
                                                                    SupportSettings b;
                                                                    b.sink = -0.01;
                                                                    return b;
                                                                  }()},
                          {"support.sink_cost", [] {
                             SupportSettings b;
                             b.sink_cost = std::nan("");
                             return b;
                           }()}}) {
    try {
      estimate_support({}, {}, {}, bad, 1, 1);
      FAIL("accepted a bad " << key);
    } catch (const Error& e) {
      CHECK(e.field() == key);
    }
  }
  s = {};
  CHECK_FALSE(estimate_support({}, {}, {}, s, 1, 1).found);   // nothing to decide on
}
