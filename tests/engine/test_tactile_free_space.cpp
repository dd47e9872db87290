// Occupancy grid and free-space cloud (Section 4.1.2, Eq. 3) against brute force, far from the
// origin too, and the swept volume of the gripper.
#include "engine/free_cloud_oracle.hpp"
#include "engine/touch/free_space.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <set>

using namespace ts;

namespace {
bool in_box(const Pose& T_world_box, const Vec3& lo, const Vec3& hi, const Vec3& p) {
  const Vec3 q = T_world_box.inverse() * p;
  return (q.array() >= lo.array() - 1e-9).all() && (q.array() <= hi.array() + 1e-9).all();
}
}  // namespace

TEST_CASE("mark_free_box marks exactly the voxel centres inside an oriented box") {
  for (const Vec3& origin : {Vec3(0, 0, 0), Vec3(1e5, -2.5e4, -3000.0)}) {
    const double v = 0.004;
    OccupancyGrid grid(v, origin);
    Pose T = Pose::Identity();
    T.linear() = Eigen::AngleAxisd(0.7, Vec3(1, 2, -1).normalized()).toRotationMatrix();
    T.translation() = origin + Vec3(0.0123, -0.031, 0.007);
    const Vec3 lo(-0.01, -0.0175, 0.0), hi(0.01, 0.0175, 0.075);
    grid.mark_free_box(T, lo, hi);
    // Brute force over a region around the box.
    std::size_t expected = 0;
    for (int i = -40; i <= 40; ++i)
      for (int j = -40; j <= 40; ++j)
        for (int k = -40; k <= 40; ++k) {
          const Vec3 c = origin + v * Vec3(i, j, k);
          const bool inside = in_box(T, lo, hi, c);
          expected += inside;
          REQUIRE((grid.state(c) == Occupancy::free) == inside);
        }
    CHECK(grid.free_count() == expected);
    CHECK(expected > 500);
  }
}

TEST_CASE("occupied wins, updates commute, merge equals sequential updates") {
  const Vec3 origin(2e4, 3e4, -100.0);
  const double v = 0.005;
  Pose A = Pose::Identity(), B = Pose::Identity();
  A.translation() = origin;
  B.linear() = Eigen::AngleAxisd(0.4, Vec3::UnitZ()).toRotationMatrix();
  B.translation() = origin + Vec3(0.02, 0.0, 0.01);
  const Vec3 lo(-0.03, -0.03, -0.03), hi(0.03, 0.03, 0.03);
  const Vec3 contact = origin + Vec3(0.011, 0.002, -0.004);

  OccupancyGrid seq(v, origin);
  seq.mark_free_box(A, lo, hi);
  seq.mark_occupied(contact);
  seq.mark_free_box(B, lo, hi);  // does not clear the contact
  CHECK(seq.state(contact) == Occupancy::occupied);
  CHECK(seq.occupied_count() == 1);

  OccupancyGrid g1(v, origin), g2(v, origin);
  g1.mark_occupied(contact);
  g1.mark_free_box(B, lo, hi);
  g2.mark_free_box(A, lo, hi);
  OccupancyGrid m12 = g1, m21 = g2;
  m12.merge(g2);
  m21.merge(g1);
  CHECK(m12.free_centres() == seq.free_centres());
  CHECK(m21.free_centres() == seq.free_centres());
  CHECK(m21.state(contact) == Occupancy::occupied);
  CHECK(seq.state(origin + Vec3(1, 1, 1)) == Occupancy::unknown);
  OccupancyGrid other(0.004, origin);
  CHECK_THROWS_AS(m12.merge(other), Error);
}

TEST_CASE("free-space cloud: one real free voxel centre per res_free cube, inside box B") {
  // (the representative is the free voxel nearest to the cube's centre; see the last check)
  const Vec3 origin(1e5, 0, 0);
  OccupancyGrid grid(0.004, origin);
  Pose T = Pose::Identity();
  T.translation() = origin;
  // x < 0.013 m: the cubes at x in [0, 0.04) are partly free, their centres are not
  grid.mark_free_box(T, Vec3(-0.1, -0.1, -0.1), Vec3(0.013, 0.1, 0.1));
  // Eq. 3: B = bbox of contacts + 2 s_obj_max, centred on their centroid.
  const std::vector<Vec3> contacts = {origin + Vec3(0.01, 0, 0), origin + Vec3(0.03, 0.02, 0)};
  const auto B = free_space_box(contacts, 0.05);
  CHECK((B.sizes() - Vec3(0.02 + 0.1, 0.02 + 0.1, 0.1)).norm() < 1e-9);
  CHECK((B.center() - (origin + Vec3(0.02, 0.01, 0))).norm() < 1e-9);
  CHECK(free_space_box({}, 0.2).isEmpty());
  const auto cloud = grid.free_cloud(B, 0.04);
  REQUIRE(!cloud.empty());
  const auto free = grid.free_centres();
  std::set<std::array<long, 3>> cubes;
  for (const Vec3& p : cloud) {
    CHECK(grid.state(p) == Occupancy::free);
    CHECK(B.contains(p));
    CHECK(std::find(free.begin(), free.end(), p) != free.end());
    const Vec3 l = Vec3(((p - origin) / 0.004).array().round()) * 0.004 / 0.04;  // voxel index -> cube
    CHECK(cubes.insert({std::lround(std::floor(l.x())), std::lround(std::floor(l.y())),
                        std::lround(std::floor(l.z()))}).second);
  }
  // Every res cube of B that holds a free voxel has its point.
  std::set<std::array<long, 3>> expected;
  for (const Vec3& p : free)
    if (B.contains(p)) {
      const Vec3 l = Vec3(((p - origin) / 0.004).array().round()) * 0.004 / 0.04;  // voxel index -> cube
      expected.insert({std::lround(std::floor(l.x())), std::lround(std::floor(l.y())),
                       std::lround(std::floor(l.z()))});
    }
  CHECK(cubes == expected);
  // Updates after the first call keep the cached per-cube counts current.
  const Vec3 c0 = cloud.front();
  grid.mark_occupied(c0);
  const auto again = grid.free_cloud(B, 0.04);
  CHECK(again.size() == cloud.size());
  CHECK(std::find(again.begin(), again.end(), c0) == again.end());
  for (const Vec3& p : again) CHECK(grid.state(p) == Occupancy::free);
  // The representative is the free voxel nearest to its cube's centre.
  for (const Vec3& p : again) {
    const Vec3 ijk = ((p - origin) / 0.004).array().round();
    const Vec3 key = (ijk * 0.004 / 0.04).array().floor();
    const Vec3 centre = (key + Vec3::Constant(0.5)) * 0.04;
    const double d = (ijk * 0.004 - centre).norm();
    for (const Vec3& q : free) {
      const Vec3 qi = ((q - origin) / 0.004).array().round();
      if (((qi * 0.004 / 0.04).array().floor() == key.array()).all() && B.contains(q) && grid.state(q) == Occupancy::free)
        REQUIRE((qi * 0.004 - centre).norm() >= d - 1e-12);
    }
  }
}

TEST_CASE("full free cloud: the centres of entirely free cubes, equal to brute force after updates") {
  const Vec3 origin(-3e4, 2e4, 7.5);  // far from the world origin, as in dive logs
  OccupancyGrid grid(0.004, origin);
  Pose T = Pose::Identity();
  T.translation() = origin;
  // A rotated slab: many cubes entirely free, many partly free along its faces.
  Pose R = T;
  R.linear() = Eigen::AngleAxisd(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  grid.mark_free_box(R, Vec3(-0.15, -0.12, -0.06), Vec3(0.15, 0.12, 0.07));
  const Eigen::AlignedBox3d B(origin - Vec3::Constant(0.2), origin + Vec3(0.2, 0.1, 0.2));
  const auto fast = grid.full_free_cloud(B, 0.04);
  const auto oracle = test::full_free_cloud(grid, B, 0.04);
  REQUIRE(oracle.size() > 10);
  CHECK(fast == oracle);
  CHECK(fast.size() < grid.free_cloud(B, 0.04).size());  // partly free cubes are left out
  for (const Vec3& c : fast) {  // the corner voxels of each cube (centres at +0 and +0.036) are free
    CHECK(B.contains(c));
    for (double dx : {-0.02, 0.016})
      for (double dy : {-0.02, 0.016})
        for (double dz : {-0.02, 0.016}) CHECK(grid.state(c + Vec3(dx, dy, dz)) == Occupancy::free);
  }
  // Occupying a voxel empties its cube; the cached counts follow updates.
  grid.mark_occupied(fast.front() + Vec3(0.01, -0.01, 0.005));
  const auto after = grid.full_free_cloud(B, 0.04);
  CHECK(after.size() + 1 == fast.size());
  CHECK(after == test::full_free_cloud(grid, B, 0.04));
  CHECK(grid.full_free_cloud(Eigen::AlignedBox3d(), 0.04).empty());
}

TEST_CASE("swept volume: the links along the closing path, no voxel elsewhere") {
  Gripper g;
  Pose T_eef = Pose::Identity();
  T_eef.translation() = Vec3(5e4, 1e4, -2000.0);
  std::vector<double> q = {0.6, 0.5, 0.3, 0.0, 1.2, 0.2};
  FreeSpaceSettings fs;
  fs.voxel = 0.005;
  OccupancyGrid grid(fs.voxel, T_eef.translation());
  mark_swept_volume(grid, g, T_eef, q, fs);
  // Every free voxel centre lies in some link box at some configuration along the path, or in
  // the palm; checked against a much finer sampling of the path.
  const auto waypoints = g.closing_waypoints(q);
  std::vector<std::vector<Pose>> samples;
  for (std::size_t w = 1; w < waypoints.size(); ++w)
    for (int s = 0; s <= 400; ++s) {
      std::vector<double> x(q.size());
      for (std::size_t j = 0; j < q.size(); ++j)
        x[j] = waypoints[w - 1][j] + (waypoints[w][j] - waypoints[w - 1][j]) * s / 400.0;
      samples.push_back(g.link_poses(x));
    }
  const auto free = grid.free_centres();
  CHECK(free.size() > 1000);
  for (std::size_t i = 0; i < free.size(); i += 7) {
    const Vec3 p = T_eef.inverse() * free[i];
    bool covered = p.z() <= 0.0 && p.z() >= -g.spec().palm.thickness &&
                   p.head<2>().norm() <= g.spec().palm.radius;
    for (std::size_t s = 0; s < samples.size() && !covered; ++s)
      for (int j = 0; j < g.joint_count() && !covered; ++j) {
        const LinkSpec& l = g.link(j);
        const Vec3 lo(-0.5 * l.thickness, -0.5 * l.width, 0), hi(0.5 * l.thickness, 0.5 * l.width, l.length);
        // the coarse path sampling may cut corners by at most half a voxel
        covered = in_box(samples[s][j], lo - Vec3::Constant(0.5 * fs.voxel), hi + Vec3::Constant(0.5 * fs.voxel), p);
      }
    REQUIRE(covered);
  }
  // The final and the open links are swept: their centres are free.
  for (const auto& joints : {q, g.open_angles()}) {
    const auto links = g.link_poses(joints);
    for (int j = 0; j < g.joint_count(); ++j) {
      const Vec3 c = T_eef * links[j] * Vec3(0, 0, 0.5 * g.link(j).length);
      CHECK(grid.state(c) == Occupancy::free);
    }
  }
}

TEST_CASE("hand surface samples: the final links' inner faces and tips and the palm's front disc, none missing") {
  Gripper g;
  Pose T_eef = Pose::Identity();
  T_eef.linear() = Eigen::AngleAxisd(0.7, Vec3(1, -2, 0.5).normalized()).toRotationMatrix();
  T_eef.translation() = Vec3(5e4, 1e4, -2000.0);   // a dive site far from the origin
  const std::vector<double> q = {0.6, 0.5, 0.3, 0.0, 1.2, 0.2};
  FreeSpaceSettings fs;
  const double spacing = 0.01;
  const std::vector<Vec3> s = hand_surface_samples(g, T_eef, q, spacing, fs);
  const auto links = g.link_poses(q);
  // Each sample lies on the inner face or the tip of some final link box (within 1e-9 m), or on
  // the palm's disc; none on an outer face or a side.
  std::size_t palm = 0;
  auto on_hand = [&](const Vec3& p_world) {
    const Vec3 p = T_eef.inverse() * p_world;
    if (std::abs(p.z()) < 1e-9 && p.head<2>().norm() <= g.spec().palm.radius + 1e-9) {
      ++palm;
      return true;
    }
    for (int j = 0; j < g.joint_count(); ++j) {
      const LinkSpec& l = g.link(j);
      const Vec3 x = links[j].inverse() * p;
      const Vec3 lo(-0.5 * l.thickness, -0.5 * l.width, 0), hi(0.5 * l.thickness, 0.5 * l.width, l.length);
      const bool inside = (x.array() >= lo.array() - 1e-9).all() && (x.array() <= hi.array() + 1e-9).all();
      const bool leading = std::abs(x.x() - lo.x()) < 1e-9 || std::abs(x.z() - hi.z()) < 1e-9;
      if (inside && leading) return true;
    }
    return false;
  };
  for (const Vec3& p : s) REQUIRE(on_hand(p));
  CHECK(palm > 50);
  // Coverage: every point of every inner face and tip (a fine sampling) has a sample within
  // spacing / sqrt(2).
  std::size_t checked = 0;
  for (int j = 0; j < g.joint_count(); ++j) {
    const LinkSpec& l = g.link(j);
    for (int i = 0; i < 200; ++i) {
      const double u = (i % 13) / 12.0, v = (i % 17) / 16.0;
      const Vec3 x = i % 2 ? Vec3(-0.5 * l.thickness, -0.5 * l.width + u * l.width, v * l.length)   // inner face
                           : Vec3(-0.5 * l.thickness + u * l.thickness, -0.5 * l.width + v * l.width, l.length);  // tip
      const Vec3 p = T_eef * links[j] * x;
      double nearest = 1e9;
      for (const Vec3& q_s : s) nearest = std::min(nearest, (q_s - p).norm());
      REQUIRE(nearest <= spacing / std::sqrt(2.0) + 1e-9);
      ++checked;
    }
  }
  CHECK(checked == 1200);
  // Without the palm, only link faces; a bad spacing or joint count is an error.
  FreeSpaceSettings no_palm = fs;
  no_palm.palm = false;
  CHECK(hand_surface_samples(g, T_eef, q, spacing, no_palm).size() == s.size() - palm);
  CHECK_THROWS_AS(hand_surface_samples(g, T_eef, q, 0.0, fs), Error);
  CHECK_THROWS_AS(hand_surface_samples(g, T_eef, {0.1}, spacing, fs), Error);
}
