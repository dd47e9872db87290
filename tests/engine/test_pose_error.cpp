#include "engine/detail.hpp"
#include "engine/geometry/kabsch.hpp"
#include "engine/geometry/pose_error.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <numbers>

using namespace ts;

namespace {

using ts::detail::kRadPerDeg;

Mat3 rot(const Vec3& axis, double deg) {
  return Eigen::AngleAxisd(deg * kRadPerDeg, axis.normalized()).toRotationMatrix();
}

Pose pose(const Mat3& R, const Vec3& t) {
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

/// Brute-force oracle for an axial group: min over a fine grid of phi.
double axial_oracle(const Pose& est, const Pose& truth, const SymmetryGroup& g) {
  double best = 1e9;
  for (const Mat3& D : g.rotations)
    for (int i = 0; i < 36000; ++i) {
      const Mat3 G = rot(g.axis, i * 0.01) * D;
      best = std::min(best, rotation_angle((truth.linear() * G).transpose() * est.linear()));
    }
  return best / kRadPerDeg;
}

}  // namespace

TEST_CASE("Plain errors: position distance and Eq. 10 angle") {
  const Pose truth = pose(rot(Vec3(1, 1, 0), 40), Vec3(1, 2, 3));
  CHECK(pose_error(truth, truth).position_m == 0.0);
  CHECK(pose_error(truth, truth).orientation_deg == doctest::Approx(0.0));
  const Pose est = pose(truth.linear() * rot(Vec3(0, 0, 1), 30), Vec3(1, 2.01, 3));
  const PoseError e = pose_error(est, truth);
  CHECK(e.position_m == doctest::Approx(0.01));
  CHECK(e.orientation_deg == doctest::Approx(30.0));
  CHECK(e.symmetric_orientation_deg == doctest::Approx(30.0));
  CHECK(rotation_angle_eq10(truth.linear().transpose() * est.linear()) ==
        doctest::Approx(30.0 * kRadPerDeg));
}

TEST_CASE("Discrete symmetry: a right pose up to symmetry is not counted wrong") {
  // 4-fold about z through a centre off the origin (e.g. an object whose box centre is not its
  // centroid).
  SymmetryGroup g;
  g.centre = Vec3(0.01, -0.02, 0.005);
  g.rotations = {Mat3::Identity(), rot(Vec3::UnitZ(), 90), rot(Vec3::UnitZ(), 180),
                 rot(Vec3::UnitZ(), 270)};
  Rng rng(3);
  for (int i = 0; i < 20; ++i) {
    const Pose truth = pose(rng.rotation().toRotationMatrix(), Vec3(rng.uniform(), rng.uniform(), 5));
    const int k = 1 + i % 3;
    const Pose est = truth * g.transform(g.rotations[k]) * pose(rot(Vec3(1, 0, 0), 2.0), Vec3::Zero());
    const PoseError e = pose_error(est, truth, &g);
    CHECK(e.orientation_deg > 80.0);
    CHECK(e.symmetric_orientation_deg == doctest::Approx(2.0).epsilon(1e-6));
    // Position error of the origin: plain one sees the off-centre rotation, the symmetric not.
    CHECK(e.position_m == doctest::Approx((g.transform(g.rotations[k]).translation()).norm()).epsilon(1e-9));
    CHECK(e.symmetric_position_m < 1e-12);
  }
}

TEST_CASE("Axial symmetry: error is the tilt of the axis, matching a brute-force oracle") {
  SymmetryGroup g;
  g.kind = SymmetryGroup::Kind::axial;
  g.axis = Vec3(0.3, -0.2, 1.0).normalized();
  g.centre = Vec3(0.0, 0.0, 0.01);
  SUBCASE("cone-like (no flip)") { g.rotations = {Mat3::Identity()}; }
  SUBCASE("cylinder-like (with a half-turn)") {
    g.rotations = {Mat3::Identity(), rot(g.axis.unitOrthogonal(), 180)};
  }
  Rng rng(4);
  for (int i = 0; i < 4; ++i) {
    const Pose truth = pose(rng.rotation().toRotationMatrix(), Vec3(0.1, 0.2, 0.3));
    const Pose est = pose(truth.linear() * rot(rng.unit_vector(), rng.uniform(0, 180)),
                          Vec3(0.1, 0.2, 0.3));
    const double e = pose_error(est, truth, &g).symmetric_orientation_deg;
    const double oracle = axial_oracle(est, truth, g);
    CHECK(e <= oracle + 1e-9);
    CHECK(e > oracle - 0.01);
  }
  // Any rotation about the axis: zero; with the flip too when present.
  const Pose truth = pose(rot(Vec3(1, 0, 0), 33), Vec3(1, 1, 1));
  const Pose est = truth * g.transform(rot(g.axis, 77.7) * g.rotations.back());
  const PoseError e = pose_error(est, truth, &g);
  CHECK(e.symmetric_orientation_deg < 1e-5);
  CHECK(e.symmetric_position_m < 1e-9);
}

TEST_CASE("Spherical symmetry: any orientation is right") {
  SymmetryGroup g;
  g.kind = SymmetryGroup::Kind::spherical;
  g.centre = Vec3(0.02, 0, 0);
  Rng rng(5);
  const Pose truth = pose(rng.rotation().toRotationMatrix(), Vec3(3, 2, 1));
  const Pose est = truth * g.transform(rng.rotation().toRotationMatrix());
  const PoseError e = pose_error(est, truth, &g);
  CHECK(e.symmetric_orientation_deg < 1e-6);
  CHECK(e.symmetric_position_m < 1e-9);
}

TEST_CASE("Non-finite poses give the worst errors, not NaN") {
  Pose bad = Pose::Identity();
  bad.translation().x() = std::nan("");
  const PoseError e = pose_error(bad, Pose::Identity());
  CHECK(std::isinf(e.position_m));
  CHECK(e.orientation_deg == 180.0);
  CHECK(e.symmetric_orientation_deg == 180.0);
}
