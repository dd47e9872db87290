// Stiff and extreme cases: each must give a flagged or correct answer, never NaN or a crash.
#include "engine/database/symmetry_cache.hpp"
#include "engine/geometry/kabsch.hpp"
#include "engine/geometry/pose_error.hpp"
#include "engine/geometry/symmetry.hpp"
#include "engine/recognition/recognizer.hpp"
#include "recognition_fixture.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <limits>

using namespace ts;

namespace {

using test::fast_settings;

void check_step_finite(const StepResult& r) {
  CHECK(r.best.pose.matrix().allFinite());
  for (const Hypothesis& h : r.hypotheses) {
    CHECK(h.pose.matrix().allFinite());
    CHECK_FALSE(std::isnan(h.log_weight));
  }
  for (double p : r.posteriors) CHECK(std::isfinite(p));
}

}  // namespace

TEST_CASE("A single flat patch gives a flagged answer (rotation about the normal unobservable)") {
  auto src = test::make_source();
  Database db(src);
  Recognizer rec(db, fast_settings());
  // A 4 mm taxel grid on the big face of the box (z = +0.025), 3 x 2 cm, slightly noisy.
  const Pose T = test::random_pose(21, Vec3(0.3, 0.3, 0.3));
  PointCloud c;
  Rng rng(1);
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 6; ++j)
      c.points.push_back(T * Vec3(-0.015 + 0.004 * i, -0.01 + 0.004 * j, 0.025 + 0.0002 * rng.normal()));
  const StepResult r = rec.step(c, {});
  check_step_finite(r);
  CHECK(r.unobservable_dof >= 3);
  CHECK(r.pose_ambiguous);
  // Patches all over the object remove the ambiguity.
  Recognizer rec2(db, fast_settings());
  const StepResult r2 = rec2.step(test::touch(src->fines[4], T, 10, 3), {});
  CHECK(r2.unobservable_dof == 0);
  CHECK_FALSE(r2.pose_ambiguous);
}

TEST_CASE("Contacts 100 km from the origin give the same answer as at the origin") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(22, Vec3(0.05, -0.02, 0.01));
  const Vec3 far(1.0e5, -0.6e5, -2.5e3);
  // The prepared query is the same up to the rounding of the input coordinates.
  PointCloud c = test::touch(src->fines[4], T, 6, 31, 0.0005, 0.0002);
  PointCloud cf = c;
  for (Vec3& p : cf.points) p += far;
  const Scene a = prepare_scene(c, {}, db.settings().fpfh, {}, 1, 1);
  const Scene b = prepare_scene(cf, {}, db.settings().fpfh, {}, 1, 1);
  REQUIRE(a.contacts.size() == b.contacts.size());
  CHECK((a.origin + far - b.origin).norm() < 1e-9);
  // (FPFH histograms are not compared: their bins are discontinuous, and on flat faces a
  // 1e-12 m change moves some values across bin edges, at the origin as much as far away.)
  for (std::size_t i = 0; i < a.contacts.size(); ++i) {
    CHECK((a.contacts.points[i] - b.contacts.points[i]).norm() < 1e-9);
    CHECK((a.contacts.normals[i] - b.contacts.normals[i]).norm() < 1e-6);
  }
  // Recognition: both right, and the same answer (up to the tiny input rounding, which can
  // flip a near-tie somewhere in RANSAC, so not necessarily bit for bit).
  Recognizer near_rec(db, fast_settings()), far_rec(db, fast_settings());
  StepResult rn, rf;
  for (int k = 1; k <= 6; ++k) {
    PointCloud ck = test::touch(src->fines[4], T, k, 31, 0.0005, 0.0002), cfk = ck;
    for (Vec3& p : cfk.points) p += far;
    std::vector<Vec3> free{T * Vec3(0, 0, 0.2), T * Vec3(0.2, 0, 0)}, freef = free;
    for (Vec3& p : freef) p += far;
    rn = near_rec.step(ck, free);
    rf = far_rec.step(cfk, freef);
    check_step_finite(rf);
  }
  Pose shifted = T;
  shifted.translation() += far;
  for (const auto& [r, truth] : {std::pair(rn, T), std::pair(rf, shifted)}) {
    REQUIRE(r.valid);
    CHECK(r.best.object == 4u);
    const PoseError e = pose_error(r.best.pose, truth);
    CHECK(e.position_m < 0.002);
    CHECK(e.orientation_deg < 2.0);
  }
  Pose back = rf.best.pose;
  back.translation() -= far;
  CHECK((back.translation() - rn.best.pose.translation()).norm() < 0.001);
  CHECK(rotation_angle(back.linear().transpose() * rn.best.pose.linear()) < 0.02);
}

TEST_CASE("Objects of 1 cm and 2 m with scaled parameters are recognized alike") {
  for (double scale : {0.08, 15.0}) {  // the 10-15 cm shapes become about 1 cm and 2 m
    auto src = test::make_source(scale);
    Database db(src);
    Recognizer rec(db, fast_settings().scaled(scale));
    const std::size_t obj = 4;
    const Pose T = test::random_pose(23, Vec3(1.0, 2.0, 3.0) * scale);
    StepResult r;
    for (int k = 1; k <= 6; ++k)
      r = rec.step(test::touch(src->fines[obj], T, k, 17, 0.0, 0.0, scale), {});
    INFO("scale " << scale);
    check_step_finite(r);
    REQUIRE(r.valid);
    CHECK(r.best.object == obj);
    const PoseError e = pose_error(r.best.pose, T);
    CHECK(e.position_m < 0.01 * scale);
    CHECK(e.orientation_deg < 2.0);
  }
}

TEST_CASE("All contacts identical, an empty cloud, non-finite points: flagged, never NaN") {
  auto src = test::make_source();
  Database db(src);
  Recognizer rec(db, fast_settings());
  SUBCASE("identical") {
    PointCloud same;
    same.points.assign(50, Vec3(10, 20, 30));
    const StepResult r = rec.step(same, {Vec3(10, 20, 30.1)});
    check_step_finite(r);
    CHECK_FALSE(r.valid);
    CHECK(r.unobservable_dof == 6);
  }
  SUBCASE("empty, then data") {
    const StepResult r = rec.step({}, {});
    check_step_finite(r);
    CHECK_FALSE(r.valid);
    CHECK(r.contacts == 0);
    const Pose T = test::random_pose(24, Vec3(0, 0, 0));
    const StepResult r2 = rec.step(test::touch(src->fines[4], T, 6, 5), {});
    CHECK(r2.valid);
    check_step_finite(r2);
  }
  SUBCASE("non-finite points are dropped") {
    const Pose T = test::random_pose(25, Vec3(0, 0, 0));
    PointCloud c = test::touch(src->fines[4], T, 5, 6);
    const std::size_t n = c.size();
    c.points.emplace_back(std::numeric_limits<double>::quiet_NaN(), 0, 0);
    c.points.emplace_back(0, std::numeric_limits<double>::infinity(), 0);
    const StepResult r = rec.step(c, {Vec3(std::nan(""), 0, 0)});
    check_step_finite(r);
    CHECK(r.valid);
    CHECK(r.contacts == n);
  }
  SUBCASE("two points, three collinear points") {
    PointCloud two;
    two.points = {Vec3(0, 0, 0), Vec3(0.01, 0, 0)};
    check_step_finite(rec.step(two, {}));
    PointCloud line;
    for (int i = 0; i < 30; ++i) line.points.emplace_back(0.002 * i, 0.0, 0.0);
    const StepResult r = rec.step(line, {});
    check_step_finite(r);
    CHECK_FALSE(r.valid);
  }
}

TEST_CASE("Symmetric objects are not counted wrong when the pose is right up to symmetry") {
  auto src = test::make_source();
  Database db(src);
  std::shared_ptr<const FeatureIndex> index;  // the shared FeatureTable is used
  SymmetryCache symmetries;
  for (std::size_t obj : {1u, 2u, 5u}) {  // nut (D5), ball (sphere), cube (octahedral)
    Recognizer rec(db, index, fast_settings());
    const Pose T = test::random_pose(60 + obj, Vec3(0.2, 0.2, 0.2));
    StepResult r;
    for (int k = 1; k <= 10; ++k) r = rec.step(test::touch(src->fines[obj], T, k, 70 + obj), {});
    INFO("object " << db.info(obj).name);
    REQUIRE(r.valid);
    CHECK(r.best.object == obj);
    const SymmetryGroup& g = symmetries.get(db, obj);
    CHECK_FALSE(g.trivial());
    const PoseError e = pose_error(r.best.pose, T, &g);
    CHECK(e.symmetric_orientation_deg < 3.0);
    CHECK(e.symmetric_position_m < 0.003);
    CHECK(e.symmetric_orientation_deg <= e.orientation_deg);
  }
}
