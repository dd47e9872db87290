// Forward kinematics (Eq. 2) of the default gripper against poses computed by hand.
#include "engine/detail.hpp"
#include "engine/touch/gripper.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <numbers>

using namespace ts;

namespace {
using ts::detail::kRadPerDeg;

void check_vec(const Vec3& a, const Vec3& b, double tol = 1e-12) {
  INFO("got " << a.transpose() << " expected " << b.transpose());
  CHECK((a - b).norm() < tol);
}

std::vector<double> joints_of(const Gripper& g, double middle1, double middle2) {
  std::vector<double> q(g.joint_count(), 0.0);
  q[g.joint_index(0, 0)] = middle1;
  q[g.joint_index(0, 1)] = middle2;
  return q;
}
}  // namespace

TEST_CASE("default gripper: three fingers, two links each, six pads") {
  Gripper g;
  CHECK(g.finger_count() == 3);
  CHECK(g.joint_count() == 6);
  REQUIRE(g.pads().size() == 6);
  CHECK(g.pads()[1].name == "middle.distal");
  CHECK(g.single_pad() == 1);
  CHECK(g.pad_index("left.proximal") == 2);
  CHECK(g.pad_index("nope") == -1);
  CHECK(g.sensor().sensels() == 72);
  // reach bounds every pad corner at any joint angles
  const auto& s = g.sensor();
  for (double a : {-0.4, 0.0, 0.7, 1.5})
    for (std::size_t p = 0; p < g.pads().size(); ++p) {
      const Pose T = g.pad_pose(std::vector<double>(6, a), static_cast<int>(p));
      for (int c = 0; c < 4; ++c) {
        const Vec3 corner((c & 1 ? 0.5 : -0.5) * s.size_x, (c & 2 ? 0.5 : -0.5) * s.size_y,
                          s.foam_thickness);
        CHECK((T * corner).norm() <= g.reach());
      }
    }
}

TEST_CASE("forward kinematics: straight fingers") {
  Gripper g;
  const std::vector<double> q(6, 0.0);
  // Middle finger at azimuth 0: base (0.05, 0, 0). Distal pad: link 2 origin at z = 0.075, pad
  // on the inner face (x = -0.01) at mid-length 0.032; the pad faces -x (the palm axis).
  const Pose T = g.pad_pose(q, g.pad_index("middle.distal"));
  check_vec(T.translation(), Vec3(0.04, 0.0, 0.107));
  check_vec(T.linear().col(2), Vec3(-1, 0, 0));   // pad normal
  check_vec(T.linear().col(0), Vec3(0, 0, 1));    // pad length along the finger
  check_vec(T.linear().col(1), Vec3(0, 1, 0));
  // Left finger at azimuth 120°: base 0.05 (cos 120°, sin 120°, 0), same offsets rotated.
  const double c = std::cos(120 * kRadPerDeg), s = std::sin(120 * kRadPerDeg);
  const Pose L = g.pad_pose(q, g.pad_index("left.distal"));
  check_vec(L.translation(), Vec3(0.05 * c - 0.01 * c, 0.05 * s - 0.01 * s, 0.107));
  check_vec(L.linear().col(2), Vec3(-c, -s, 0));
  const Pose P = g.pad_pose(q, g.pad_index("right.proximal"));
  const double c3 = std::cos(240 * kRadPerDeg), s3 = std::sin(240 * kRadPerDeg);
  check_vec(P.translation(), Vec3(0.04 * c3, 0.04 * s3, 0.0375));
}

TEST_CASE("forward kinematics: bent middle finger, computed by hand") {
  Gripper g;
  // θ1 = 90°: the proximal link lies across the palm, the distal pad faces the palm (-z).
  {
    const Pose T = g.pad_pose(joints_of(g, 90 * kRadPerDeg, 0.0), 1);
    // pad origin = base + Ry(-90°) (-0.01, 0, 0.107) = (0.05, 0, 0) + (-0.107, 0, -0.01)
    check_vec(T.translation(), Vec3(-0.057, 0.0, -0.01), 1e-12);
    check_vec(T.linear().col(2), Vec3(0, 0, -1), 1e-12);
  }
  // θ1 = 30°, θ2 = 45°: with Ry(φ) = [[cos φ, 0, sin φ], [0, 1, 0], [-sin φ, 0, cos φ]] and
  // closing = rotation by -θ about y:
  //   v  = Ry(-45°) (-0.01, 0, 0.032) + (0, 0, 0.075)
  //   p  = (0.05, 0, 0) + Ry(-30°) v
  {
    const double a1 = 30 * kRadPerDeg, a2 = 45 * kRadPerDeg;
    const double vx = std::cos(a2) * -0.01 - std::sin(a2) * 0.032;
    const double vz = std::sin(a2) * -0.01 + std::cos(a2) * 0.032 + 0.075;
    const double px = 0.05 + std::cos(a1) * vx - std::sin(a1) * vz;
    const double pz = std::sin(a1) * vx + std::cos(a1) * vz;
    const Pose T = g.pad_pose(joints_of(g, a1, a2), 1);
    check_vec(T.translation(), Vec3(px, 0.0, pz), 1e-12);
    check_vec(T.translation(), Vec3(-0.020997, 0.0, 0.063575), 1e-6);  // the same, by calculator
    // the pad normal turned by 75° from -x toward -z
    check_vec(T.linear().col(2), Vec3(-std::cos(75 * kRadPerDeg), 0, -std::sin(75 * kRadPerDeg)), 1e-12);
  }
}

TEST_CASE("Eq. 2: world contact = T_EEF * T_sensor * P^L") {
  Gripper g;
  Pose T_eef = Pose::Identity();
  T_eef.linear() = Eigen::AngleAxisd(90 * kRadPerDeg, Vec3::UnitZ()).toRotationMatrix();
  T_eef.translation() = Vec3(1.0, 2.0, 3.0);
  const std::vector<double> q(6, 0.0);
  // Sensel 0 of the middle distal pad, contact 1 mm above the base: P^L = (-0.0275, -0.0125, 0.001).
  const Vec3 PL(-0.0275, -0.0125, 0.001);
  const Vec3 PW = T_eef * g.pad_pose(q, 1) * PL;
  // In the EEF frame: pad origin (0.04, 0, 0.107) + x_L*(0,0,1) + y_L*(0,1,0) + z_L*(-1,0,0)
  const Vec3 P_eef(0.04 - 0.001, -0.0125, 0.107 - 0.0275);
  // Rz(90°): (x, y, z) -> (-y, x, z)
  check_vec(PW, Vec3(1.0 + 0.0125, 2.0 + P_eef.x(), 3.0 + P_eef.z()), 1e-12);
}

TEST_CASE("closing path: proximal joints first, then distal") {
  Gripper g;
  std::vector<double> q = {0.5, 0.3, 0.6, 0.2, 0.7, 0.1};
  const auto w = g.closing_waypoints(q);
  REQUIRE(w.size() == 3);
  CHECK(w[0] == g.open_angles());
  CHECK(w[1] == std::vector<double>{0.5, 0.0, 0.6, 0.0, 0.7, 0.0});
  CHECK(w[2] == q);
}

TEST_CASE("gripper validation names the field") {
  auto expect = [](GripperSpec spec, const std::string& field) {
    try {
      Gripper g(spec, "g.json");
      FAIL("no error");
    } catch (const Error& e) {
      CHECK(e.file() == "g.json");
      CHECK(e.field().find(field) != std::string::npos);
    }
  };
  GripperSpec s = default_gripper_spec();
  s.fingers[1].links[0].joint_axis = Vec3(0, 2, 0);
  expect(s, "fingers[1].links[0].joint.axis");
  s = default_gripper_spec();
  s.fingers[2].name = "middle";
  expect(s, "fingers[2].name");
  s = default_gripper_spec();
  s.single_pad = "middle.tip";
  expect(s, "single_pad");
  s = default_gripper_spec();
  s.fingers[0].links[1].open = 3.0;
  expect(s, "fingers[0].links[1].joint");
  s = default_gripper_spec();
  s.fingers.clear();
  expect(s, "fingers");
  s = default_gripper_spec();
  s.sensor.foam_thickness = -1;
  expect(s, "sensor.foam_thickness_m");
}
