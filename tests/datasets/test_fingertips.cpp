// The simulator's fingertip hand (sensing = fingertips): one contact per fingertip that
// touched, on the true surface when noise-free; the arm's error and 1 mm rounding in what is
// reported; normals only when asked for; the log written and read back (format_version 3),
// identical for 1 and 2 threads; a grasp whose finger count does not match the gripper refused.
#include "datasets/simulator.hpp"
#include "engine/recognition_fixture.hpp"
#include "engine/touch/fusion.hpp"
#include "io/h5.hpp"
#include "io/log_store.hpp"
#include "simulated_log.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cmath>

using namespace ts;

namespace {

datasets::SimulatorSettings tip_settings(std::size_t grasps, const std::string& noise, std::uint64_t seed) {
  datasets::SimulatorSettings s;
  s.grasps = grasps;
  s.noise = datasets::noise_profile(noise);
  s.seed = seed;
  s.sensing = Sensing::fingertips;
  return s;
}

// Signed distance to the axis-aligned box of half-sizes h, from a world point.
struct BoxDistance {
  Pose T_object_world;
  Vec3 h;
  double operator()(const Vec3& p_world) const {
    const Vec3 q = (T_object_world * p_world).cwiseAbs() - h;
    return q.maxCoeff() > 0 ? q.cwiseMax(0.0).norm() : q.maxCoeff();
  }
};

}  // namespace

TEST_CASE("fingertips, ideal noise: contacts on the surface, one per touching fingertip, no normals") {
  const Vec3 h(0.05, 0.035, 0.03);
  const datasets::Simulator sim(test::box_mesh(2.0 * h), "box", Gripper(), tip_settings(30, "ideal", 4));
  const auto res = sim.run();
  const TactileLog& log = res.log;
  REQUIRE(log.sensing == Sensing::fingertips);
  CHECK(log.pads.empty());
  CHECK_FALSE(log.fingertip_normals);
  const BoxDistance distance{sim.object_pose().inverse(), h};
  const auto F = static_cast<std::size_t>(log.gripper.finger_count());
  std::size_t contacts = 0, multi = 0;
  for (std::size_t g = 0; g < log.grasps.size(); ++g) {
    const GraspRecord& r = log.grasps[g];
    REQUIRE(r.fingertip_touched.size() == F);
    CHECK(r.fingertip_normals.empty());
    CHECK(r.tactile.empty());
    const GraspContacts c = grasp_contacts(log, g);
    CHECK(c.points.size() == static_cast<std::size_t>(res.diagnostics[g].contact_sensels));
    for (std::size_t i = 0; i < c.points.size(); ++i) {
      CHECK(std::abs(distance(c.points[i])) < 1e-9);   // the true surface point, as reported
      CHECK(r.fingertip_touched[static_cast<std::size_t>(c.pad_slot[i])] == 1);
      // Near the hand: within its reach of the arm pose.
      CHECK((c.points[i] - r.arm_pose.translation()).norm() < log.gripper.reach() + 0.01);
    }
    contacts += c.points.size();
    multi += c.points.size() >= 2;
  }
  CHECK(res.grasps_with_contact >= 24);   // a box the hand closes on: most grasps touch
  CHECK(multi >= 10);                     // and often with more than one fingertip
  CHECK(contacts <= 3 * log.grasps.size());
  Exploration ex(log);
  ex.advance_to(log.grasps.size());
  const PointCloud cloud = ex.contact_cloud();
  CHECK_FALSE(cloud.has_normals());
  CHECK(cloud.size() >= contacts - 4);   // two contacts rarely share a 2 mm voxel
  CHECK(cloud.size() <= contacts);
  // Free space: the swept fingers, never deeper in the box than the foam gives.
  const PointCloud free = ex.free_cloud();
  CHECK(free.size() > 20);
  for (const Vec3& p : free.points) CHECK(distance(p) > -0.004);
}

TEST_CASE("fingertips with normals: unit, outward, the face's normal when noise-free") {
  const Vec3 h(0.05, 0.05, 0.04);
  auto s = tip_settings(20, "ideal", 9);
  s.fingertips.normal_sigma_deg = 0.0;
  const datasets::Simulator sim(test::box_mesh(2.0 * h), "box", Gripper(), s);
  const TactileLog log = sim.run().log;
  REQUIRE(log.fingertip_normals);
  const Pose T_object_world = sim.object_pose().inverse();
  int on_face = 0;
  for (const GraspRecord& r : log.grasps)
    for (std::size_t f = 0; f < r.fingertip_touched.size(); ++f) {
      if (!r.fingertip_touched[f]) continue;
      const Vec3 q = T_object_world * r.fingertip_points[f];
      const Vec3 n = T_object_world.linear() * r.fingertip_normals[f];
      CHECK(std::abs(n.norm() - 1.0) < 1e-9);
      // Away from the edges the face's outward normal: the axis where q sits at +-h.
      const Vec3 rel = q.cwiseAbs().cwiseQuotient(h);
      int axis = 0;
      rel.maxCoeff(&axis);
      if ((h - q.cwiseAbs()).minCoeff() < -1e-9 || (rel.array() > 0.9).count() > 1) continue;
      ++on_face;
      CHECK(n[axis] * (q[axis] > 0 ? 1.0 : -1.0) > 0.9999);
    }
  CHECK(on_face >= 10);
  Exploration ex(log);
  ex.advance_to(log.grasps.size());
  CHECK(ex.contact_cloud().has_normals());
}

TEST_CASE("fingertip noise: the arm's error and 1 mm rounding in what is reported, the truth unchanged") {
  const Mesh m = test::box_mesh(Vec3(0.1, 0.08, 0.07));
  auto s = tip_settings(30, "underwater", 8);
  s.fingertips.quantization = 0.001;
  const TactileLog noisy = datasets::Simulator(m, "block", Gripper(), s).run().log;
  const TactileLog ideal = datasets::Simulator(m, "block", Gripper(), tip_settings(30, "ideal", 8)).run().log;
  double sum2 = 0.0;
  int n = 0;
  for (std::size_t g = 0; g < 30; ++g) {
    CHECK((noisy.truth->arm_poses[g].matrix() - ideal.truth->arm_poses[g].matrix()).norm() < 1e-12);
    CHECK(noisy.grasps[g].fingertip_touched == ideal.grasps[g].fingertip_touched);
    for (std::size_t f = 0; f < noisy.grasps[g].fingertip_touched.size(); ++f) {
      if (!noisy.grasps[g].fingertip_touched[f]) continue;
      const Vec3 p = noisy.grasps[g].fingertip_points[f];
      for (int k = 0; k < 3; ++k) CHECK(std::abs(p[k] * 1000.0 - std::round(p[k] * 1000.0)) < 1e-6);
      sum2 += (p - ideal.grasps[g].fingertip_points[f]).squaredNorm();
      ++n;
    }
  }
  REQUIRE(n >= 30);
  const double rms_axis = std::sqrt(sum2 / (3.0 * n));
  CHECK(rms_axis > 0.002);    // 3 mm per axis of arm position, 1 degree of rotation at the
  CHECK(rms_axis < 0.0065);   // fingertip's lever arm, 1 mm rounding
}

TEST_CASE("fingertip logs: written and read back (format_version 3), same bytes for 1 and 2 threads") {
  test::TempDir dir;
  const Mesh m = test::box_mesh(Vec3(0.1, 0.06, 0.05));
  auto s = tip_settings(10, "underwater", 5);
  s.fingertips.normal_sigma_deg = 5.0;
  const TactileLog log = test::simulate_and_write(m, "plate", s, 1, dir.path() / "a.h5");
  test::simulate_and_write(m, "plate", s, 2, dir.path() / "b.h5");
  CHECK(test::read_bytes(dir.path() / "a.h5") == test::read_bytes(dir.path() / "b.h5"));
  const TactileLog back = io::read_log(dir.path() / "a.h5");
  CHECK(back.sensing == Sensing::fingertips);
  CHECK(back.fingertip_normals);
  REQUIRE(back.grasps.size() == 10);
  for (std::size_t g = 0; g < 10; ++g) {
    CHECK(back.grasps[g].fingertip_touched == log.grasps[g].fingertip_touched);
    CHECK(back.grasps[g].joints == log.grasps[g].joints);
    for (std::size_t f = 0; f < log.grasps[g].fingertip_points.size(); ++f) {
      CHECK(back.grasps[g].fingertip_points[f] == log.grasps[g].fingertip_points[f]);
      CHECK(back.grasps[g].fingertip_normals[f] == log.grasps[g].fingertip_normals[f]);
    }
    CHECK(back.truth->joints[g] == log.truth->joints[g]);
  }
  {
    const auto f = io::h5::File::open(dir.path() / "a.h5", io::h5::File::Access::read);
    CHECK(f.root().int_attribute("format_version") == 3);
    CHECK(f.root().string_attribute("sensing") == "fingertips");
  }
  {
    io::LogWriter w = io::LogWriter::append_to(dir.path() / "a.h5");
    w.append(log.grasps[0], &log.truth->arm_poses[0], &log.truth->joints[0]);
    w.close();
  }
  CHECK(io::read_log(dir.path() / "a.h5").grasps.size() == 11);
  // A grasp that does not give one entry per finger, a touched point that is not finite, a
  // normal in a log without normals: each named, nothing written.
  TactileLog bad = log;
  bad.grasps[3].fingertip_touched.pop_back();
  const std::string want = "expected one entry per finger of the gripper (3), got 2 (" +
                           (dir.path() / "c.h5").string() + ", /grasps/fingertip_touched[3])";
  CHECK_THROWS_WITH_AS(io::write_log(dir.path() / "c.h5", bad), doctest::Contains(want.c_str()), Error);
  CHECK_FALSE(std::filesystem::exists(dir.path() / "c.h5"));
  bad = log;
  bad.grasps[2].fingertip_touched[1] = 1;
  bad.grasps[2].fingertip_points[1] = Vec3(0, std::nan(""), 0);
  CHECK_THROWS_WITH_AS(io::write_log(dir.path() / "c.h5", bad), doctest::Contains("/grasps/fingertip_point[2][1]"), Error);
  bad = log;
  bad.fingertip_normals = false;
  CHECK_THROWS_WITH_AS(io::write_log(dir.path() / "c.h5", bad), doctest::Contains("/grasps/fingertip_normal[0]"), Error);
  CHECK_FALSE(std::filesystem::exists(dir.path() / "c.h5"));
  // A pad log may not carry fingertip points.
  TactileLog pads;
  pads.pads = {pads.gripper.single_pad()};
  pads.gains.assign(pads.sensels(), 1.0f);
  GraspRecord r;
  r.joints.assign(static_cast<std::size_t>(pads.gripper.joint_count()), 0.0);
  r.tactile.assign(pads.sensels(), 0.0f);
  r.fingertip_touched = {1, 0, 0};
  r.fingertip_points.assign(3, Vec3::Zero());
  pads.grasps.push_back(r);
  CHECK_THROWS_WITH_AS(validate(pads, "pads.h5"), doctest::Contains("only a fingertip log"), Error);
}

TEST_CASE("fingertip settings errors") {
  const Mesh m = test::box_mesh(Vec3(0.1, 0.1, 0.1));
  auto s = tip_settings(3, "ideal", 1);
  s.fingertips.quantization = -0.001;
  CHECK_THROWS_AS(datasets::Simulator(m, "cube", Gripper(), s), Error);
  s = tip_settings(3, "ideal", 1);
  s.fingertips.normal_sigma_deg = 95.0;
  CHECK_THROWS_AS(datasets::Simulator(m, "cube", Gripper(), s), Error);
  CHECK(parse_sensing("fingertips") == Sensing::fingertips);
  CHECK(std::string(to_string(Sensing::fingertips)) == "fingertips");
}
