// Contact fusion (Eq. 1-2, Section 4.1.2) on hand-built logs: exact contact points, the
// cumulative voxel-filtered cloud, incremental = batch, zero-contact grasps, far coordinates.
#include "engine/geometry/cloud.hpp"
#include "engine/recognition/scene.hpp"
#include "engine/touch/free_space.hpp"
#include "engine/touch/fusion.hpp"

#include <doctest/doctest.h>

#include <cmath>

using namespace ts;

namespace {
// One logged pad (middle distal), known signals: sensel j compressed by comp[j] metres.
TactileLog hand_log(const Vec3& origin, std::size_t grasps) {
  TactileLog log;
  log.object = "plate";
  log.pads = {1};
  const auto& s = log.gripper.sensor();
  for (int j = 0; j < s.sensels(); ++j) log.gains.push_back(j % 2 ? 0.9f : 1.1f);
  for (std::size_t g = 0; g < grasps; ++g) {
    GraspRecord r;
    r.time = 10.0 * g;
    r.arm_pose.linear() = Eigen::AngleAxisd(0.3 * g, Vec3(0, 0, 1)).toRotationMatrix();
    r.arm_pose.translation() = origin + Vec3(0.01 * g, 0, 0);
    r.joints = std::vector<double>(6, 0.2);
    for (int j = 0; j < s.sensels(); ++j) {
      const double c = (g == 1) ? 0.0 : (j < 24 ? 0.001 + 0.00008 * j : 0.0);  // up to 2.84 mm  // grasp 1: no contact
      r.tactile.push_back(static_cast<float>(sensel_signal(s, log.gain(0, j), c)));
      r.past_peak.push_back(static_cast<std::uint8_t>(FoldHint::rising));
    }
    log.grasps.push_back(r);
  }
  return log;
}
}  // namespace

TEST_CASE("contacts follow Eq. 1 and Eq. 2 exactly") {
  for (const Vec3& origin : {Vec3(0, 0, 0), Vec3(1e5, 2e5, -4000.0)}) {
    const TactileLog log = hand_log(origin, 3);
    CHECK_NOTHROW(validate(log));
    const auto& s = log.gripper.sensor();
    const GraspContacts c = grasp_contacts(log, 0);
    REQUIRE(c.points.size() == 24);
    const Pose T = log.grasps[0].arm_pose * log.gripper.pad_pose(log.grasps[0].joints, 1);
    for (int j = 0; j < 24; ++j) {
      Vec3 PL = s.sensel_position(j);
      PL.z() = s.foam_thickness - (0.001 + 0.00008 * j);  // z_j = z_max - compression
      // float32 signals: well below a micrometre even 100 km from the origin
      CHECK((c.points[j] - T * PL).norm() < 1e-6);
    }
    CHECK(grasp_contacts(log, 1).points.empty());
  }
}

TEST_CASE("unknown fold side: ambiguous sensels are counted and optionally dropped") {
  TactileLog log = hand_log(Vec3::Zero(), 1);
  const auto& s = log.gripper.sensor();
  log.grasps[0].past_peak[30] = static_cast<std::uint8_t>(FoldHint::unknown);  // no flag for sensel 30
  log.grasps[0].tactile[30] = static_cast<float>(sensel_signal(s, log.gain(0, 30), 0.0036));  // beyond the peak
  const auto kept = grasp_contacts(log, 0);
  CHECK(kept.ambiguous == 1);
  CHECK(kept.points.size() == 25);
  ContactSettings strict;
  strict.keep_ambiguous = false;
  const auto dropped = grasp_contacts(log, 0, strict);
  CHECK(dropped.ambiguous == 1);
  CHECK(dropped.points.size() == 24);
}

TEST_CASE("exploration: incremental equals batch; a contact-less grasp adds free space only") {
  const TactileLog log = hand_log(Vec3(3e4, -1e4, 500.0), 4);
  ExplorationSettings es;
  Exploration ex(log, es);
  ex.advance_to(1);
  const std::size_t free1 = ex.grid().free_count();
  const auto contacts1 = ex.raw_contacts().size();
  ex.advance_to(2);  // grasp 1 has no contact
  CHECK(ex.raw_contacts().size() == contacts1);
  CHECK(ex.grid().free_count() > free1);
  CHECK(ex.contacts_per_grasp() == std::vector<std::size_t>{24, 0});
  for (std::size_t k = 0; k <= 4; ++k) {
    Exploration step(log, es);
    for (std::size_t i = 1; i <= k; ++i) step.advance_to(i);
    const ExplorationClouds batch = exploration_clouds(log, k, es);
    CHECK(step.contact_cloud().points == batch.contacts.points);
    CHECK(step.free_cloud().points == batch.free.points);
    CHECK(batch.raw_contacts == step.raw_contacts().size());
  }
  const auto all = exploration_clouds(log, 99, es);  // clamped to the log
  CHECK(all.contacts_per_grasp.size() == 4);
  // The voxel filter merged nothing it should not: points 5 mm apart survive a 2 mm filter.
  CHECK(all.contacts.size() == all.raw_contacts);
  // Free-space points lie in box B of Eq. 3 and are free voxel centres.
  Exploration ex4(log, es);
  ex4.advance_to(4);
  const auto B = free_space_box(ex4.raw_contacts(), es.free.s_obj_max);
  REQUIRE(!all.free.empty());
  for (const Vec3& p : all.free.points) {
    CHECK(B.contains(p));
    CHECK(ex4.grid().state(p) == Occupancy::free);
  }
  // Contacts are occupied voxels.
  for (const Vec3& p : ex4.raw_contacts()) CHECK(ex4.grid().state(p) == Occupancy::occupied);
}

TEST_CASE("exploration: grasp groups hold each grasp's own voxel-filtered contacts") {
  const TactileLog log = hand_log(Vec3(3e4, -1e4, 500.0), 4);
  ExplorationSettings es;
  es.contact_voxel = 0.011;  // coarser than the 5 mm sensels: the filter merges within a grasp
  Exploration ex(log, es);
  ex.advance_to(4);
  const GraspGroups g = ex.grasp_groups();
  REQUIRE(g.grasps() == 4);
  CHECK(g.first.back() == g.points.size());
  std::size_t base = 0;
  for (std::size_t k = 0; k < 4; ++k) {
    CAPTURE(k);
    // The oracle: that grasp's contacts alone through the same filter.
    const GraspContacts c = grasp_contacts(log, k);
    PointCloud own;
    for (const Vec3& p : c.points) own.points.push_back(p - ex.origin());
    std::vector<Vec3> expect;
    if (!own.empty())
      for (const Vec3& p : voxel_filter(own, es.contact_voxel).points) expect.push_back(p + ex.origin());
    const std::vector<Vec3> got(g.points.begin() + g.first[k], g.points.begin() + g.first[k + 1]);
    CHECK(got == expect);
    CHECK(got.size() <= ex.contacts_per_grasp()[k]);
    base += c.points.size();
  }
  CHECK(base == ex.raw_contacts().size());
  CHECK(g.grasps() == exploration_clouds(log, 4, es).grasps.grasps());
  CHECK(g.points.size() < ex.raw_contacts().size());  // the filter merged something
  // Each grasp also carries its hand's final leading faces and its measured wrist.
  REQUIRE(g.free_first.size() == g.first.size());
  REQUIRE(g.pivots.size() == 4);
  for (std::size_t k = 0; k < 4; ++k) {
    const GraspRecord& r = log.grasps[k];
    const std::vector<Vec3> hand = hand_surface_samples(log.gripper, r.arm_pose, r.joints, es.hand_free_spacing, es.free);
    CHECK(std::vector<Vec3>(g.free.begin() + g.free_first[k], g.free.begin() + g.free_first[k + 1]) == hand);
    CHECK(g.pivots[k] == Vec3(r.arm_pose.translation()));
  }
  // In a scene's local frame: all three moved by its origin; a grasp without contacts dropped
  // with its hand samples and pivot, the others kept in order.
  GraspGroups with_empty;
  for (std::size_t k = 0; k < 4; ++k) {
    const std::vector<Vec3> pts(g.points.begin() + g.first[k], g.points.begin() + g.first[k + 1]);
    const std::vector<Vec3> hand(g.free.begin() + g.free_first[k], g.free.begin() + g.free_first[k + 1]);
    with_empty.add(k == 1 ? std::vector<Vec3>{} : pts, hand, g.pivots[k]);
  }
  Scene sc;
  sc.origin = ex.origin();
  set_grasps(sc, with_empty);
  REQUIRE(sc.grasps.grasps() == 3);
  REQUIRE(sc.grasps.pivots.size() == 3);
  const std::size_t kept[3] = {0, 2, 3};
  for (std::size_t i = 0; i < 3; ++i) {
    const std::size_t k = kept[i];
    CHECK((sc.grasps.pivots[i] - (g.pivots[k] - ex.origin())).norm() < 1e-9);
    REQUIRE(sc.grasps.free_first[i + 1] - sc.grasps.free_first[i] == g.free_first[k + 1] - g.free_first[k]);
    CHECK((sc.grasps.free[sc.grasps.free_first[i]] - (g.free[g.free_first[k]] - ex.origin())).norm() < 1e-9);
    CHECK((sc.grasps.points[sc.grasps.first[i]] - (g.points[g.first[k]] - ex.origin())).norm() < 1e-9);
  }
}

TEST_CASE("validate names the bad field") {
  auto expect = [](const TactileLog& log, const std::string& field) {
    try {
      validate(log, "log.h5");
      FAIL("no error");
    } catch (const Error& e) {
      INFO(e.what());
      CHECK(e.file() == "log.h5");
      CHECK(e.field() == field);
    }
  };
  TactileLog log = hand_log(Vec3::Zero(), 3);
  log.grasps[2].tactile[5] = -1.0f;
  expect(log, "/grasps/tactile[2][0][5]");
  log = hand_log(Vec3::Zero(), 3);
  log.grasps[1].tactile[7] = 256.0f;
  expect(log, "/grasps/tactile[1][0][7]");
  log = hand_log(Vec3::Zero(), 3);
  log.grasps[1].tactile.pop_back();
  expect(log, "/grasps/tactile[1]");
  log = hand_log(Vec3::Zero(), 3);
  log.grasps[0].arm_pose.matrix()(0, 3) = std::nan("");
  expect(log, "/grasps/arm_pose[0]");
  log = hand_log(Vec3::Zero(), 3);
  log.grasps[2].joints.pop_back();
  expect(log, "/grasps/joints[2]");
  log = hand_log(Vec3::Zero(), 3);
  log.pads = {7};
  expect(log, "/sensors/pad_index[0]");
  log = hand_log(Vec3::Zero(), 3);
  log.gains[3] = 0.0f;
  expect(log, "/sensors/gain[0][3]");
}
