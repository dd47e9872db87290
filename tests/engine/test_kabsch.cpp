#include "engine/geometry/kabsch.hpp"
#include "engine/geometry/pose_error.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <numbers>

using namespace ts;

namespace {

Pose random_pose(Rng& rng, double spread) {
  Pose T = Pose::Identity();
  T.linear() = rng.rotation().toRotationMatrix();
  T.translation() = Vec3(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)) * spread;
  return T;
}

std::vector<Vec3> random_points(Rng& rng, std::size_t n, double size) {
  std::vector<Vec3> p(n);
  for (auto& x : p) x = Vec3(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)) * size;
  return p;
}

/// T * p for every p, each moved by Gaussian noise of `sigma` per axis (none: 0).
std::vector<Vec3> moved(const Pose& T, const std::vector<Vec3>& src, Rng& rng, double sigma = 0.0) {
  std::vector<Vec3> dst;
  for (const Vec3& p : src) {
    Vec3 e = Vec3::Zero();
    if (sigma > 0.0) e = Vec3(rng.normal(), rng.normal(), rng.normal()) * sigma;
    dst.push_back(T * p + e);
  }
  return dst;
}

double angle_between(const Pose& a, const Pose& b) {
  return rotation_angle(a.linear().transpose() * b.linear());
}

}  // namespace

TEST_CASE("Kabsch recovers an exact rigid transform") {
  Rng rng(11);
  for (int trial = 0; trial < 50; ++trial) {
    const Pose T = random_pose(rng, 0.5);
    const auto src = random_points(rng, 3 + trial, 0.1);
    const RigidFit fit = kabsch(src, moved(T, src, rng));
    REQUIRE(fit.valid);
    CHECK(angle_between(fit.T_target_source, T) < 1e-9);
    CHECK((fit.T_target_source.translation() - T.translation()).norm() < 1e-9);
    CHECK(fit.rms < 1e-9);
    CHECK(fit.T_target_source.linear().determinant() == doctest::Approx(1.0));
  }
}

TEST_CASE("Kabsch agrees with Eigen's umeyama on noisy pairs; rotation_from_covariance gives the nearest rotation") {
  // Eigen::umeyama (no scaling) as the oracle of the unweighted fit: kabsch() keeps its own
  // for the weights, the centring relative to the first point (dive logs 100 km out) and the
  // degeneracy diagnostics umeyama does not give.
  Rng rng(17);
  for (int trial = 0; trial < 30; ++trial) {
    const Pose T = random_pose(rng, 0.5);
    const auto src = random_points(rng, 5 + trial, 0.1);
    const std::vector<Vec3> dst = moved(T, src, rng, 0.003);
    Eigen::Matrix3Xd a(3, src.size()), b(3, src.size());
    for (std::size_t i = 0; i < src.size(); ++i) a.col(static_cast<Eigen::Index>(i)) = src[i], b.col(static_cast<Eigen::Index>(i)) = dst[i];
    const Eigen::Matrix4d oracle = Eigen::umeyama(a, b, false);
    const RigidFit fit = kabsch(src, dst);
    REQUIRE(fit.valid);
    CHECK((fit.T_target_source.matrix() - oracle).cwiseAbs().maxCoeff() < 1e-10);
  }
  // The nearest rotation of a perturbed rotation M (H = M^T): the polar factor, M (M^T M)^-1/2.
  for (int trial = 0; trial < 20; ++trial) {
    const Mat3 R = rng.rotation().toRotationMatrix();
    Mat3 M = R;
    for (int i = 0; i < 9; ++i) M(i / 3, i % 3) += 0.01 * rng.normal();
    Eigen::SelfAdjointEigenSolver<Mat3> es(M.transpose() * M);
    const Mat3 polar = M * es.operatorInverseSqrt();
    const Mat3 near = rotation_from_covariance(M.transpose());
    CHECK((near - polar).cwiseAbs().maxCoeff() < 1e-12);
    CHECK(near.determinant() == doctest::Approx(1.0).scale(0).epsilon(1e-12));
  }
}

TEST_CASE("Kabsch with noise: residual near the noise, pose close") {
  Rng rng(12);
  const Pose T = random_pose(rng, 0.3);
  const auto src = random_points(rng, 2000, 0.1);
  std::vector<Vec3> dst;
  const double sigma = 0.001;
  for (const Vec3& p : src) dst.push_back(T * p + sigma * Vec3(rng.normal(), rng.normal(), rng.normal()));
  const RigidFit fit = kabsch(src, dst);
  REQUIRE(fit.valid);
  CHECK(fit.rms == doctest::Approx(sigma * std::sqrt(3.0)).epsilon(0.1).scale(0));   // within 10 %
  CHECK(angle_between(fit.T_target_source, T) < 1e-3);
}

TEST_CASE("Kabsch corrects reflections: a mirrored target gives a proper rotation") {
  Rng rng(13);
  const auto src = random_points(rng, 40, 0.1);
  std::vector<Vec3> dst;
  for (const Vec3& p : src) dst.emplace_back(-p.x(), p.y(), p.z());  // mirror image
  const RigidFit fit = kabsch(src, dst);
  REQUIRE(fit.valid);
  CHECK(fit.reflection_fixed);
  CHECK(fit.T_target_source.linear().determinant() == doctest::Approx(1.0));
  CHECK((fit.T_target_source.linear() * fit.T_target_source.linear().transpose() - Mat3::Identity())
            .norm() < 1e-12);
}

TEST_CASE("Kabsch on a planar triplet (the RANSAC case) is exact and proper") {
  Rng rng(14);
  for (int trial = 0; trial < 200; ++trial) {
    const Pose T = random_pose(rng, 1.0);
    const auto src = random_points(rng, 3, 0.05);
    if (!triangle_well_conditioned(src[0], src[1], src[2], 0.1)) continue;
    std::vector<Vec3> dst;
    for (const Vec3& p : src) dst.push_back(T * p);
    const RigidFit fit = kabsch(src, dst);
    REQUIRE(fit.valid);
    CHECK(angle_between(fit.T_target_source, T) < 1e-8);
    CHECK(fit.T_target_source.linear().determinant() == doctest::Approx(1.0));
  }
}

TEST_CASE("Degenerate inputs are rejected by geometry, never NaN") {
  const Vec3 a(0, 0, 0), b(0.01, 0, 0), c(0.02, 0, 0);
  SUBCASE("collinear") {
    const std::array<Vec3, 3> s{a, b, c};
    const RigidFit fit = kabsch(s, s);
    CHECK_FALSE(fit.valid);
    CHECK(fit.T_target_source.matrix().allFinite());
    CHECK_FALSE(triangle_well_conditioned(a, b, c, 0.01));
  }
  SUBCASE("near-collinear") {
    const Vec3 c2(0.02, 1e-9, 0);
    const std::array<Vec3, 3> s{a, b, c2};
    CHECK_FALSE(kabsch(s, s).valid);
    CHECK_FALSE(triangle_well_conditioned(a, b, c2, 0.01));
    // but the residual of this fit would be zero: rejection is by geometry
  }
  SUBCASE("coincident") {
    const std::array<Vec3, 3> s{a, a, a};
    CHECK_FALSE(kabsch(s, s).valid);
    CHECK_FALSE(triangle_well_conditioned(a, a, a, 0.01));
  }
  SUBCASE("two coincident of three") {
    CHECK_FALSE(triangle_well_conditioned(a, a, Vec3(0, 0.01, 0), 0.01));
  }
  SUBCASE("too few, mismatched, non-finite") {
    const std::array<Vec3, 2> two{a, b};
    CHECK_FALSE(kabsch(two, two).valid);
    const std::array<Vec3, 3> s{a, b, Vec3(0, 0.01, 0)};
    const std::array<Vec3, 3> t{a, b, Vec3(0, std::nan(""), 0)};
    CHECK_FALSE(kabsch(s, t).valid);
    const std::array<Vec3, 4> four{a, b, c, a};
    CHECK_FALSE(kabsch(s, four).valid);
    const std::array<double, 3> w{0, 0, 0};
    CHECK_FALSE(kabsch(s, s, w).valid);
  }
  SUBCASE("triangle test is scale invariant") {
    const double h = std::sqrt(3.0) / 2.0;
    for (double scale : {1e-6, 1e-2, 1.0, 1e3}) {
      CHECK(triangle_well_conditioned(Vec3(0, 0, 0), Vec3(scale, 0, 0), Vec3(scale / 2, scale * h, 0), 0.5));
    }
  }
}

TEST_CASE("Kabsch far from the origin (100 km) is as accurate as at the origin") {
  Rng rng(15);
  const Pose T = random_pose(rng, 0.1);
  const auto local = random_points(rng, 30, 0.05);
  const Vec3 far(1.0e5, -0.7e5, 3.2e3);
  std::vector<Vec3> src, dst;
  for (const Vec3& p : local) {
    src.push_back(p + far);
    dst.push_back(T * p + far);  // the same motion, both clouds 100 km out
  }
  const RigidFit fit = kabsch(src, dst);
  REQUIRE(fit.valid);
  CHECK(angle_between(fit.T_target_source, T) < 1e-9);
  for (std::size_t i = 0; i < src.size(); ++i)
    CHECK((fit.T_target_source * src[i] - dst[i]).norm() < 1e-7);
}

TEST_CASE("Weights: zero-weighted outliers do not move the fit") {
  Rng rng(16);
  const Pose T = random_pose(rng, 0.2);
  auto src = random_points(rng, 20, 0.1);
  std::vector<Vec3> dst;
  std::vector<double> w;
  for (std::size_t i = 0; i < src.size(); ++i) {
    dst.push_back(T * src[i]);
    w.push_back(1.0);
  }
  for (int i = 0; i < 5; ++i) {
    src.push_back(Vec3::Random());
    dst.push_back(Vec3::Random() * 10.0);
    w.push_back(0.0);
  }
  const RigidFit fit = kabsch(src, dst, w);
  REQUIRE(fit.valid);
  CHECK(angle_between(fit.T_target_source, T) < 1e-9);
}

TEST_CASE("rotation_angle agrees with Eq. 10 and stays accurate near 0 and pi") {
  Rng rng(17);
  for (int i = 0; i < 1000; ++i) {
    const Mat3 R = rng.rotation().toRotationMatrix();
    CHECK(rotation_angle(R) == doctest::Approx(rotation_angle_eq10(R)).epsilon(1e-6));
  }
  for (double a : {1e-9, 1e-6, 1e-3, 0.5, 3.0, std::numbers::pi - 1e-7}) {
    const Mat3 R = Eigen::AngleAxisd(a, Vec3(1, 2, 3).normalized()).toRotationMatrix();
    CHECK(rotation_angle(R) == doctest::Approx(a).epsilon(1e-6));
  }
  CHECK(rotation_angle(Mat3::Identity()) == 0.0);
}

TEST_CASE("A prepared target gives kabsch()'s fit bit for bit, its rejections included") {
  Rng rng(41);
  const auto same = [](const RigidFit& a, const RigidFit& b) {
    return a.valid == b.valid && a.reflection_fixed == b.reflection_fixed && a.rms == b.rms &&
           a.sv_ratio == b.sv_ratio && a.T_target_source.matrix() == b.T_target_source.matrix();
  };
  KabschSettings strict;
  strict.min_sv_ratio = 0.15;
  for (int trial = 0; trial < 200; ++trial) {
    const std::size_t n = trial % 3 == 0 ? 3 : 3 + static_cast<std::size_t>(trial % 7);
    const std::vector<Vec3> target = random_points(rng, n, 0.2);
    const KabschTarget prepared(target);
    for (int k = 0; k < 5; ++k) {
      std::vector<Vec3> src = moved(random_pose(rng, 0.5), target, rng, 0.01 * k);
      if (k == 4) src = random_points(rng, n, 0.2);   // unrelated: reflections, poor fits
      CAPTURE(trial);
      CAPTURE(k);
      CHECK(same(kabsch(src, prepared), kabsch(src, target)));
      CHECK(same(kabsch(src, prepared, strict), kabsch(src, target, {}, strict)));
    }
  }
  // What kabsch() rejects of the target or the pairing, the prepared target rejects alike.
  const std::vector<Vec3> src{Vec3(0, 0, 0), Vec3(0.1, 0, 0), Vec3(0, 0.1, 0)};
  const std::vector<Vec3> collinear{Vec3(0, 0, 0), Vec3(0.1, 0, 0), Vec3(0.2, 0, 0)};
  const std::vector<Vec3> coincident(3, Vec3(1, 2, 3));
  std::vector<Vec3> not_finite = src;
  not_finite[1].y() = std::numeric_limits<double>::quiet_NaN();
  const std::vector<Vec3> four{Vec3(0, 0, 0), Vec3(0.1, 0, 0), Vec3(0, 0.1, 0), Vec3(0, 0, 0.1)};
  const std::vector<Vec3>* targets[] = {&collinear, &coincident, &not_finite, &four};
  for (const std::vector<Vec3>* t : targets) {
    const RigidFit fit = kabsch(src, KabschTarget(*t));
    CHECK_FALSE(fit.valid);
    CHECK(fit.T_target_source.matrix() == Pose::Identity().matrix());
    CHECK(same(fit, kabsch(src, *t)));
  }
  CHECK_FALSE(kabsch(src, KabschTarget()).valid);
  // A source that is not finite, against a prepared target that is.
  const KabschTarget good(std::vector<Vec3>{Vec3(0, 0, 0), Vec3(0.1, 0, 0), Vec3(0, 0.1, 0)});
  CHECK_FALSE(kabsch(not_finite, good).valid);
  CHECK(same(kabsch(not_finite, good), kabsch(not_finite, good.points())));
  // A valid fit through the prepared path: the exact transform back.
  const Pose T = random_pose(rng, 1.0);
  const RigidFit fit = kabsch(src, KabschTarget(moved(T, src, rng)));
  REQUIRE(fit.valid);
  CHECK((fit.T_target_source.matrix() - T.matrix()).cwiseAbs().maxCoeff() < 1e-12);
}
