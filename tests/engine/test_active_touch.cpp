// The next-grasp planner (engine/touch/active_touch.hpp) against a known truth: two hypotheses whose
// objects coincide except on one side (a 4 cm cube and a 7 cm x 4 cm x 4 cm box sharing the
// cube's -x face). Only a grasp on the +x side can tell them apart, and only there does the
// longer box fill the space the hand would sweep when aiming at the cube's +x face.
#include "engine/recognition_fixture.hpp"
#include "engine/touch/active_touch.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <cmath>

using namespace ts;

namespace {

/// Points on a box's faces every `step` with outward normals (object frame, centred).
PointCloud box_surface(const Vec3& size, double step) {
  PointCloud c;
  const Vec3 h = size / 2;
  for (int axis = 0; axis < 3; ++axis)
    for (double sign : {-1.0, 1.0}) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      const int nu = static_cast<int>(std::round(size[u] / step)), nv = static_cast<int>(std::round(size[v] / step));
      for (int i = 0; i <= nu; ++i)
        for (int j = 0; j <= nv; ++j) {
          Vec3 p;
          p[axis] = sign * h[axis];
          p[u] = -h[u] + size[u] * i / nu;
          p[v] = -h[v] + size[v] * j / nv;
          Vec3 n = Vec3::Zero();
          n[axis] = sign;
          c.points.push_back(p);
          c.normals.push_back(n);
        }
    }
  return c;
}

struct TwoBoxes {
  Vec3 size_a{0.04, 0.04, 0.04}, size_b{0.07, 0.04, 0.04};
  DistanceField field_a, field_b;
  PointCloud surf_a, surf_b;
  std::vector<Hypothesis> hyps;
  Pose world = Pose::Identity();   ///< where the scene sits (rotated and far off the origin)

  TwoBoxes() {
    DistanceFieldSettings s;
    field_a = DistanceField::build(test::box_mesh(size_a), true, s);
    field_b = DistanceField::build(test::box_mesh(size_b), true, s);
    surf_a = box_surface(size_a, 0.005);
    surf_b = box_surface(size_b, 0.005);
    world.linear() = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
    world.translation() = Vec3(3.0, -2.0, 40.0);
    Hypothesis a, b;
    a.object = 0;
    a.pose = world;
    a.log_weight = -10.0;
    b.object = 1;
    b.pose = world * Pose(Eigen::Translation3d(0.015, 0.0, 0.0));   // shares the cube's -x face
    b.log_weight = -10.0;
    hyps = {a, b};
  }
  PlanObjects objects() const {
    return [this](std::uint32_t o) {
      PlanObject p;
      p.field = o == 0 ? &field_a : &field_b;
      p.surface = o == 0 ? &surf_a : &surf_b;
      p.radius = 0.5 * (o == 0 ? size_a : size_b).norm();
      return p;
    };
  }
  /// A world point in the cube's frame.
  Vec3 local(const Vec3& w) const { return world.inverse() * w; }
};

}  // namespace

TEST_CASE("active touch: the planner picks a grasp on the side where the hypotheses differ") {
  TwoBoxes scene;
  ActiveSettings s;
  s.candidates = 240;
  const GraspPlanner planner(Gripper(), s);
  const auto all = planner.plan(scene.hyps, scene.objects(), 7, s.candidates);
  REQUIRE(all.size() == s.candidates);
  // Ranked by score.
  for (std::size_t i = 1; i < all.size(); ++i) CHECK(all[i - 1].score >= all[i].score);
  const PlannedGrasp& best = all.front();
  const Vec3 target = scene.local(best.command.target);
  INFO("best target (cube frame) " << target.transpose() << ", information " << best.information
                                   << ", blocked " << best.blocked_weight);
  // The best grasp touches the +x side (the cube's +x face or the longer box's extra part).
  CHECK(target.x() > 0.015);
  CHECK(scene.local(best.command.target + best.command.approach).x() < target.x());  // comes in from +x
  // Two equally weighted hypotheses: at most ln 2 nats, and a telling grasp gets most of it.
  CHECK(best.information <= std::log(2.0) + 1e-9);
  CHECK(best.information > 0.5);
  CHECK(best.blocked_weight == 0.0);
  int far_side = 0;
  for (const PlannedGrasp& g : all) {
    const Vec3 t = scene.local(g.command.target);
    // On the shared -x face both hypotheses predict the same: no information.
    if (t.x() < -0.019 && std::abs(t.y()) < 0.01 && std::abs(t.z()) < 0.01) {
      ++far_side;
      CHECK(g.information < 0.05);
    }
  }
  CHECK(far_side > 0);
}

TEST_CASE("active touch: the collision penalty is the weight of the hypotheses the swept hand runs into") {
  TwoBoxes scene;
  ActiveSettings s;
  s.candidates = 120;
  s.collision_weight = 2.0;
  const GraspPlanner planner(Gripper(), s);
  const auto best = planner.plan(scene.hyps, scene.objects(), 7, 1);
  REQUIRE(best.size() == 1);
  const GraspCommand& c = best[0].command;
  // A third hypothesis: the cube on the hand's path, 6 cm behind the hand at the aim (the palm
  // passes through it); a fourth far off the path. All four equally likely.
  auto hyps = scene.hyps;
  Hypothesis on_path = hyps[0], off_path = hyps[0];
  on_path.pose.translation() = c.T_world_eef.translation() - 0.06 * c.approach;
  off_path.pose.translation() = c.T_world_eef.translation() + Vec3(1.0, 1.0, 1.0);
  hyps.push_back(on_path);
  hyps.push_back(off_path);
  const auto scored = planner.evaluate({c}, hyps, scene.objects());
  CHECK(scored[0].blocked_weight == doctest::Approx(0.25).scale(0).epsilon(1e-12));
  CHECK(scored[0].score == doctest::Approx(scored[0].information - 2.0 * 0.25).scale(0).epsilon(1e-12));
  // With the blocking hypothesis far more likely, the grasp's score drops by about the weight.
  hyps[2].log_weight += 20.0;
  const auto heavy = planner.evaluate({c}, hyps, scene.objects());
  CHECK(heavy[0].blocked_weight > 0.99);
  CHECK(heavy[0].score < -1.9);
  // ... and the planner then prefers grasps that avoid that space.
  const auto replanned = planner.plan(hyps, scene.objects(), 7, 1);
  CHECK(replanned[0].blocked_weight < 0.5);
}

TEST_CASE("active touch: weights, temperature and the collision weight act as documented") {
  TwoBoxes scene;
  ActiveSettings s;
  s.candidates = 120;
  // One hypothesis far more likely: little to learn.
  auto skewed = scene.hyps;
  skewed[1].log_weight = skewed[0].log_weight - 30.0;
  const GraspPlanner planner(Gripper(), s);
  const auto best_skewed = planner.plan(skewed, scene.objects(), 3, 1);
  REQUIRE(best_skewed.size() == 1);
  CHECK(best_skewed[0].information < 1e-6);
  // Tempered (ln wt / 100): the gap of 30 becomes 0.3 and the telling grasps count again.
  ActiveSettings warm = s;
  warm.temperature = 100.0;
  const auto best_warm = GraspPlanner(Gripper(), warm).plan(skewed, scene.objects(), 3, 1);
  CHECK(best_warm[0].information > 0.3);
  // The planner's own evaluation of a chosen command gives the same score.
  const auto again = planner.evaluate({best_warm[0].command}, scene.hyps, scene.objects());
  const auto plain = planner.plan(scene.hyps, scene.objects(), 3, s.candidates);
  bool found = false;
  for (const auto& g : plain)
    if (g.candidate == best_warm[0].candidate) {
      found = true;
      CHECK(again[0].score == doctest::Approx(g.score).scale(0).epsilon(1e-12));
    }
  CHECK(found);
}

TEST_CASE("active touch: the information about the object is the part that tells objects apart") {
  TwoBoxes scene;
  ActiveSettings s;
  s.candidates = 120;
  // One hypothesis per object: everything the outcome tells is about the object.
  const GraspPlanner planner(Gripper(), s);
  for (const PlannedGrasp& g : planner.plan(scene.hyps, scene.objects(), 5, s.candidates))
    CHECK(std::abs(g.object_information - g.information) <= 1e-12);
  // The cube at two poses 3 cm apart, one object: nothing about the object, and with the pose
  // weight 0 only the collision penalty is left in the score.
  auto same = scene.hyps;
  same[1] = same[0];
  same[1].pose = scene.world * Pose(Eigen::Translation3d(0.03, 0.0, 0.0));
  const auto poses = planner.plan(same, scene.objects(), 5, s.candidates);
  CHECK(poses.front().information > 0.5);
  for (const PlannedGrasp& g : poses) CHECK(g.object_information == 0.0);
  ActiveSettings object_only = s;
  object_only.pose_weight = 0.0;
  for (const PlannedGrasp& g : GraspPlanner(Gripper(), object_only).plan(same, scene.objects(), 5, 8))
    CHECK(std::abs(g.score + g.blocked_weight) <= 1e-12);
  // Both: the cube at two poses and the long box. The score is the object's information plus the
  // weighted rest; the best grasp under the object-only score tells the objects apart.
  auto both = scene.hyps;
  both.push_back(same[1]);
  ActiveSettings mixed = s;
  mixed.pose_weight = 0.3;
  for (const PlannedGrasp& g : GraspPlanner(Gripper(), mixed).plan(both, scene.objects(), 5, s.candidates)) {
    CHECK(g.object_information >= 0.0);
    CHECK(g.object_information <= g.information + 1e-12);
    CHECK(std::abs(g.score - (g.object_information + 0.3 * (g.information - g.object_information) -
                              g.blocked_weight)) <= 1e-12);
  }
  const auto best = GraspPlanner(Gripper(), object_only).plan(both, scene.objects(), 5, 1);
  // Two objects, the cube carrying 2/3 of the weight: at most H(O) = ln 3 - (2/3) ln 2 nats.
  CHECK(best[0].object_information <= std::log(3.0) - 2.0 / 3.0 * std::log(2.0) + 1e-9);
  CHECK(best[0].object_information > 0.3);
}

TEST_CASE("active touch: weights that underflow at a low temperature leave finite scores") {
  TwoBoxes scene;
  auto skewed = scene.hyps;
  skewed[1].log_weight = skewed[0].log_weight - 30.0;   // exp(-30 / 1e-6) == 0
  ActiveSettings s;
  s.candidates = 40;
  s.temperature = 1e-6;
  s.pose_weight = 0.0;
  const auto all = GraspPlanner(Gripper(), s).plan(skewed, scene.objects(), 3, s.candidates);
  REQUIRE(all.size() == s.candidates);
  for (const PlannedGrasp& g : all) {
    CHECK(std::isfinite(g.score));
    CHECK(g.information == 0.0);          // one hypothesis holds all the weight
    CHECK(g.object_information == 0.0);
  }
}

TEST_CASE("active touch: the coverage term rewards aims away from the contacts so far") {
  TwoBoxes scene;
  ActiveSettings s;
  s.candidates = 60;
  s.coverage_weight = 0.7;
  s.coverage_radius = 0.04;
  const GraspPlanner planner(Gripper(), s);
  const auto planned = planner.plan(scene.hyps, scene.objects(), 9, 3);
  REQUIRE(planned.size() == 3);
  // Contacts 1 cm, 2 cm and 10 cm from the first command's target (and none nearer).
  const GraspCommand c = planned[0].command;
  const Vec3 u = c.approach.unitOrthogonal();
  for (const auto& [d, expected] : std::vector<std::pair<double, double>>{{0.01, 0.25}, {0.02, 0.5}, {0.1, 1.0}}) {
    const std::vector<Vec3> contacts = {c.target + d * u, c.target + (d + 0.05) * u};
    const auto g = planner.evaluate({c}, scene.hyps, scene.objects(), contacts);
    CHECK(std::abs(g[0].coverage - expected) <= 1e-12);
    CHECK(std::abs(g[0].score - (g[0].information - g[0].blocked_weight + 0.7 * expected)) <= 1e-12);
  }
  // Without contacts every aim is new ground.
  CHECK(planner.evaluate({c}, scene.hyps, scene.objects())[0].coverage == 1.0);
  // Off by default: the score is the information term alone.
  const auto plain = GraspPlanner(Gripper(), ActiveSettings{}).evaluate({c}, scene.hyps, scene.objects(),
                                                                        {c.target + 0.01 * u});
  CHECK(std::abs(plain[0].score - (plain[0].information - plain[0].blocked_weight)) <= 1e-12);
}

TEST_CASE("active touch: deterministic for any thread count") {
  TwoBoxes scene;
  ActiveSettings s;
  s.candidates = 64;
  const GraspPlanner planner(Gripper(), s);
  std::vector<PlannedGrasp> a, b;
  tbb::task_arena(1).execute([&] { a = planner.plan(scene.hyps, scene.objects(), 11, 64); });
  tbb::task_arena(2).execute([&] { b = planner.plan(scene.hyps, scene.objects(), 11, 64); });
  REQUIRE(a.size() == b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].candidate == b[i].candidate);
    CHECK(a[i].score == b[i].score);
    CHECK(a[i].command.T_world_eef.matrix() == b[i].command.T_world_eef.matrix());
  }
  // Another seed, other candidates.
  const auto c = planner.plan(scene.hyps, scene.objects(), 12, 64);
  CHECK(c.front().command.T_world_eef.matrix() != a.front().command.T_world_eef.matrix());
}

TEST_CASE("active touch: bad input is one clear error") {
  TwoBoxes scene;
  ActiveSettings s;
  s.candidates = 0;
  CHECK_THROWS_WITH_AS(GraspPlanner(Gripper(), s), doctest::Contains("active.candidates"), Error);
  s = ActiveSettings{};
  s.temperature = 0.0;
  CHECK_THROWS_WITH_AS(GraspPlanner(Gripper(), s), doctest::Contains("active.temperature"), Error);
  s = ActiveSettings{};
  s.pose_weight = -1.0;
  CHECK_THROWS_WITH_AS(GraspPlanner(Gripper(), s), doctest::Contains("active.pose_weight"), Error);
  s = ActiveSettings{};
  s.coverage_radius = 0.0;
  CHECK_THROWS_WITH_AS(GraspPlanner(Gripper(), s), doctest::Contains("active.coverage_radius_m"), Error);
  const GraspPlanner planner(Gripper(), ActiveSettings{});
  CHECK_THROWS_WITH_AS(planner.plan({}, scene.objects(), 1, 3), doctest::Contains("no contact yet"), Error);
  auto no_field = [&](std::uint32_t) { return PlanObject{}; };
  CHECK_THROWS_WITH_AS(planner.plan(scene.hyps, no_field, 1, 3), doctest::Contains("distance field"), Error);
}

TEST_CASE("active touch: with_leader puts a hypothesis first with the share asked for") {
  TwoBoxes scene;
  auto hyps = scene.hyps;
  hyps[1].log_weight = hyps[0].log_weight - 2.0;   // unequal, so the share is not a ratio of counts
  for (double temperature : {1.0, 3.0})
    for (double share : {0.2, 0.5, 0.9}) {
      CAPTURE(temperature);
      CAPTURE(share);
      const Pose truth = scene.world * Pose(Eigen::Translation3d(0.0, 0.001, 0.0));
      const auto with = with_leader(hyps, 1, truth, share, temperature);
      REQUIRE(with.size() == 3);
      CHECK(with[0].object == 1);
      CHECK(with[0].pose.isApprox(truth, 0.0));
      CHECK(with[1].log_weight == hyps[0].log_weight);   // the others unchanged, in order
      CHECK(with[2].log_weight == hyps[1].log_weight);
      double top = with[0].log_weight, sum = 0.0;
      for (const auto& h : with) top = std::max(top, h.log_weight);
      for (const auto& h : with) sum += std::exp((h.log_weight - top) / temperature);
      CHECK(std::exp((with[0].log_weight - top) / temperature) / sum == doctest::Approx(share).scale(0).epsilon(1e-12));
    }
  // A belief nearly sure of one box leaves little to learn; an even one between the two boxes
  // (the leader the cube, half the weight) keeps the telling grasps.
  ActiveSettings s;
  s.candidates = 120;
  const GraspPlanner planner(Gripper(), s);
  const auto sure = planner.plan(with_leader(scene.hyps, 0, scene.world, 0.99, 1.0), scene.objects(), 3, 1);
  const auto even = planner.plan(with_leader({scene.hyps[1]}, 0, scene.world, 0.5, 1.0), scene.objects(), 3, 1);
  REQUIRE(sure.size() == 1);
  REQUIRE(even.size() == 1);
  // The information about the object is at most the entropy of the object's belief: the cube
  // holds 0.99 + 0.005 (the leader and the cube's own hypothesis), the box 0.005.
  const double h_sure = -(0.995 * std::log(0.995) + 0.005 * std::log(0.005));
  CHECK(sure[0].object_information <= h_sure + 1e-9);
  CHECK(even[0].object_information > 0.5);
  CHECK_THROWS_WITH_AS(with_leader(scene.hyps, 0, scene.world, 1.0, 1.0), doctest::Contains("share"), Error);
  CHECK_THROWS_WITH_AS(with_leader(scene.hyps, 0, scene.world, 0.5, 0.0), doctest::Contains("temperature"), Error);
}

TEST_CASE("active touch: with the arm's offset marginalized, a constant difference tells nothing and a patch's shape still does") {
  // A 4 x 20 x 20 cm slab and one 2 mm thicker sharing its -x face: a pad (5.5 x 2.5 cm) on the
  // middle of the +x face predicts the same patch 2 mm apart under the two, a difference the
  // arm's per-grasp error (3 mm) could make alone; a pad reaching over the +x edges sees the
  // thicker slab's extra strip change the patch's shape, which no common offset makes.
  TwoBoxes scene;
  scene.size_a = Vec3(0.04, 0.2, 0.2);
  scene.size_b = Vec3(0.042, 0.2, 0.2);
  scene.field_a = DistanceField::build(test::box_mesh(scene.size_a), true, DistanceFieldSettings{});
  scene.field_b = DistanceField::build(test::box_mesh(scene.size_b), true, DistanceFieldSettings{});
  scene.surf_a = box_surface(scene.size_a, 0.005);
  scene.surf_b = box_surface(scene.size_b, 0.005);
  scene.hyps[1].pose = scene.world * Pose(Eigen::Translation3d(0.001, 0.0, 0.0));
  ActiveSettings plain;
  plain.candidates = 400;
  plain.sigma = 0.001;
  plain.aim_radius = 0.0;   // aims anywhere on the models
  ActiveSettings marginal = plain;
  marginal.offset_sigma = 0.003;
  const GraspPlanner p(Gripper(), plain), m(Gripper(), marginal);
  std::vector<GraspCommand> commands;
  for (const auto& g : p.plan(scene.hyps, scene.objects(), 3, plain.candidates)) commands.push_back(g.command);
  const auto a = p.evaluate(commands, scene.hyps, scene.objects(), {});
  const auto b = m.evaluate(commands, scene.hyps, scene.objects(), {});
  REQUIRE(a.size() == b.size());
  int face = 0;
  double best_marginal = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const Vec3 t = scene.local(a[i].command.target);
    CHECK(b[i].information <= a[i].information + 1e-12);   // marginalizing never adds information
    best_marginal = std::max(best_marginal, b[i].information);
    // Aimed at the +x face (either slab's), the pad (reaching 2.75 cm from the aim) well within it,
    // the hand blocked under both hypotheses or neither (the flag tells nothing).
    const bool same_flag = a[i].blocked_weight == 0.0 || a[i].blocked_weight == 1.0;
    if (t.x() > 0.019 && std::max(std::abs(t.y()), std::abs(t.z())) < 0.06 && same_flag) {
      ++face;
      INFO("target " << t.transpose() << ": " << a[i].information << " nats plain, " << b[i].information << " marginal");
      CHECK(a[i].information > 0.5);    // 2 mm at 1 mm noise: told apart
      CHECK(b[i].information < 0.05);   // but a 3 mm offset explains it
    }
  }
  CHECK(face > 0);
  CHECK(best_marginal > 0.3);   // some grasp's patch shape still tells them apart
  ActiveSettings bad = marginal;
  bad.offset_sigma = -0.001;
  CHECK_THROWS_AS(GraspPlanner(Gripper(), bad), Error);
}
