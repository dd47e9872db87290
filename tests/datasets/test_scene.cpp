// Scenes of the simulator (issue 58): the seabed under the object (flat, sloped, with relief)
// touches the object without intersecting it; a share of the grasps aim at it and touch it; the
// support travels in the log's ground truth (format_version 4) and back; the same log for 1 and 2
// threads; bad settings refused naming the key.
#include "datasets/scene.hpp"
#include "datasets/simulator.hpp"
#include "engine/recognition_fixture.hpp"
#include "engine/touch/fusion.hpp"
#include "io/log_store.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <tbb/task_arena.h>

#include <cmath>
#include <optional>
#include <utility>

using namespace ts;

namespace {

/// `edit` applied to settings of `kind` makes a Support refuse them, naming `key`.
template <class Edit>
void refused(const Mesh& mesh, const Pose& T, datasets::SceneKind kind, Edit edit, const std::string& key) {
  datasets::SceneSettings bad;
  bad.kind = kind;
  edit(bad);
  try {
    datasets::Support(mesh, T, bad, 0.15, 3);
    FAIL("accepted a bad " << key);
  } catch (const Error& e) {
    CHECK(e.field() == key);
  }
}

Pose tilted_pose() {
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(0.7, Vec3(1, 2, 0.5).normalized())).toRotationMatrix();
  T.translation() = Vec3(0.1, -0.05, 0.3);
  return T;
}

/// A box of half-size h explored in a scene of `kind` (40 ideal grasps, 40 % aimed off the target).
struct BoxInScene {
  Vec3 h{0.05, 0.035, 0.03};
  datasets::SimulatorSettings settings;
  std::optional<datasets::Simulator> sim;
  datasets::SimulationResult res;
  explicit BoxInScene(datasets::SceneKind kind) {
    settings.grasps = 40;
    settings.noise = datasets::noise_profile("ideal");
    settings.seed = 7;
    settings.scene.kind = kind;
    settings.scene.off_target = 0.4;
    sim.emplace(test::box_mesh(2.0 * h), "box", Gripper(), settings);
    res = sim->run();
  }
  /// Every contact lies within 1.5 mm of the box or the support (signed distance `to_support`,
  /// never below -1.5 mm: nothing sensed behind or inside it); counts of those nearer each.
  template <class Distance>
  std::pair<std::size_t, std::size_t> contacts_on_object_and_support(Distance to_support) const {
    const Pose T_object_world = sim->object_pose().inverse();
    std::size_t on_object = 0, on_support = 0;
    for (std::size_t g = 0; g < res.log.grasps.size(); ++g)
      for (const Vec3& p : grasp_contacts(res.log, g).points) {
        const Vec3 q = (T_object_world * p).cwiseAbs() - h;
        const double d_object = q.maxCoeff() > 0 ? q.cwiseMax(0.0).norm() : -q.maxCoeff();
        const double d_support = to_support(p);
        CHECK(d_support > -0.0015);
        CHECK(std::min(d_object, std::abs(d_support)) < 0.0015);
        on_object += d_object < std::abs(d_support);
        on_support += std::abs(d_support) <= d_object;
      }
    return {on_object, on_support};
  }
};

}  // namespace

TEST_CASE("seabed: a flat support touches the object's lowest point, faces up, bad settings named") {
  const Mesh box = test::box_mesh(Vec3(0.1, 0.07, 0.06));
  const Pose T = tilted_pose();
  datasets::SceneSettings s;
  s.kind = datasets::SceneKind::seabed;
  const datasets::Support flat(box, T, s, 0.15, 3);
  CHECK(flat.up().isApprox(Vec3::UnitZ(), 1e-12));
  double lowest = 1e9;
  for (const Vec3& v : box.vertices) lowest = std::min(lowest, (T * v).z());
  REQUIRE(flat.mesh().faces.size() == 2);
  for (const Vec3& v : flat.mesh().vertices) CHECK(std::abs(v.z() - lowest) < 1e-12);
  for (const auto& f : flat.mesh().faces) {
    const auto& V = flat.mesh().vertices;
    CHECK((V[f[1]] - V[f[0]]).cross(V[f[2]] - V[f[0]]).dot(flat.up()) > 0);   // wound up
  }
  // The patch reaches past the hand: half-size = radius + reach + 5 cm.
  double r = 0.0;
  for (const Vec3& v : box.vertices) r = std::max(r, v.norm());
  CHECK((flat.mesh().vertices[0] - flat.mesh().vertices[3]).norm() ==
        doctest::Approx(2.0 * std::sqrt(2.0) * (r + 0.2)).epsilon(1e-9));

  s.gap_m = 0.01;
  const datasets::Support lifted(box, T, s, 0.15, 3);
  for (const Vec3& v : lifted.mesh().vertices) CHECK(std::abs(v.z() - (lowest - 0.01)) < 1e-12);
  CHECK(lifted.mesh().vertices[0].z() < lowest);

  const auto seabed = datasets::SceneKind::seabed;
  refused(box, T, seabed, [](auto& b) { b.gap_m = -0.001; }, "scene.gap_m");
  refused(box, T, seabed, [](auto& b) { b.slope_deg = 61; }, "scene.slope_deg");
  refused(box, T, seabed, [](auto& b) { b.off_target = 1.0; }, "scene.off_target");
  refused(box, T, seabed, [](auto& b) { b.relief_m = std::nan(""); }, "scene.relief_m");
  refused(box, T, seabed, [](auto& b) { b.kind = datasets::SceneKind::none; }, "scene");
  CHECK_THROWS_AS(datasets::parse_scene_kind("reef"), Error);
}

TEST_CASE("seabed with slope and relief: nothing of the object below it, and it touches") {
  const Mesh box = test::box_mesh(Vec3(0.12, 0.08, 0.05));   // a flat face larger than the relief's bumps
  for (const double slope : {0.0, 25.0}) {
    CAPTURE(slope);
    const Pose T = slope > 0 ? tilted_pose() : Pose::Identity();
    datasets::SceneSettings s;
    s.kind = datasets::SceneKind::seabed;
    s.slope_deg = slope;
    s.relief_m = 0.01;
    s.relief_wavelength_m = 0.06;
    const datasets::Support sup(box, T, s, 0.15, 11);
    CHECK(std::abs(std::acos(std::clamp(sup.up().z(), -1.0, 1.0)) * 180 / 3.14159265358979 - slope) < 1e-6);
    CHECK(sup.mesh().faces.size() > 1000);   // a grid fine enough for the relief
    // The object's surface, densely sampled (vertices and points of its faces), against the
    // support's triangulated surface, measured along the support's normal through a ray cast.
    Mesh world = box;
    for (Vec3& v : world.vertices) v = T * v;
    const MeshIndex support(sup.mesh());
    double lowest_gap = 1e9;
    Rng rng(5);
    for (const auto& f : world.faces)
      for (int k = 0; k < 400; ++k) {
        double a = rng.uniform(), b = rng.uniform();
        if (a + b > 1) a = 1 - a, b = 1 - b;
        const Vec3 x = world.vertices[f[0]] + a * (world.vertices[f[1]] - world.vertices[f[0]]) +
                       b * (world.vertices[f[2]] - world.vertices[f[0]]);
        // Down along -n from x to the support: a hit at t >= 0 means x is above it.
        const auto down = support.raycast(x, -sup.up(), 10.0);
        const auto up = support.raycast(x, sup.up(), 10.0);
        if (up && !down) CHECK(up->t < 1e-5);   // never below the support (on it, within 10 um)
        if (down) lowest_gap = std::min(lowest_gap, down->t);
      }
    CHECK(lowest_gap >= 0.0);
    CHECK(lowest_gap < 0.003);   // it rests on it (sampled points come within 3 mm of the contact)
    // The relief's heights above their plane span at most twice the amplitude.
    double lo = 1e9, hi = -1e9;
    for (const Vec3& v : sup.mesh().vertices) lo = std::min(lo, v.dot(sup.up())), hi = std::max(hi, v.dot(sup.up()));
    CHECK(hi - lo <= 2 * 0.01 + 1e-9);
    CHECK(hi - lo >= 0.005);   // and it is not flat
  }
}

TEST_CASE("simulator in a seabed scene: grasps touch the seabed and the object, identical for 1 and 2 threads") {
  const Vec3 h(0.05, 0.035, 0.03);
  datasets::SimulatorSettings s;
  s.grasps = 40;
  s.noise = datasets::noise_profile("ideal");
  s.seed = 7;
  s.scene.kind = datasets::SceneKind::seabed;
  s.scene.off_target = 0.4;
  const datasets::Simulator sim(test::box_mesh(2.0 * h), "box", Gripper(), s);
  auto run_with = [&](int threads) {
    tbb::task_arena arena(threads);
    return arena.execute([&] { return sim.run(); });
  };
  const auto res = run_with(2);
  const auto one = run_with(1);
  REQUIRE(res.log.truth);
  CHECK(res.log.truth->scene == "seabed");
  const Mesh& seabed = res.log.truth->support;
  REQUIRE(seabed.faces.size() == 2);
  const double z0 = seabed.vertices[0].z();
  const Pose T_object_world = sim.object_pose().inverse();
  std::size_t on_object = 0, on_seabed = 0, contacts = 0;
  for (std::size_t g = 0; g < res.log.grasps.size(); ++g) {
    CHECK(res.log.grasps[g].tactile == one.log.grasps[g].tactile);
    CHECK(res.log.grasps[g].arm_pose.isApprox(one.log.grasps[g].arm_pose, 0));
    const GraspContacts c = grasp_contacts(res.log, g);
    for (const Vec3& p : c.points) {
      ++contacts;
      const Vec3 q = (T_object_world * p).cwiseAbs() - h;
      const double d_object = q.maxCoeff() > 0 ? q.cwiseMax(0.0).norm() : -q.maxCoeff();
      const double d_seabed = std::abs(p.z() - z0);
      CHECK(p.z() > z0 - 0.0015);               // nothing sensed below the seabed
      CHECK(std::min(d_object, d_seabed) < 0.0015);   // every contact on one of the two surfaces
      on_object += d_object < d_seabed;
      on_seabed += d_seabed <= d_object;
    }
  }
  CHECK(contacts > 100);
  CHECK(on_seabed > contacts / 10);   // the off-target grasps (and some others) touched the seabed
  CHECK(on_object > contacts / 4);    // and the object is still touched
  // The hand came from the open side: no grasp's hand is below the seabed, and the free space
  // its sweeps mark lies above it (a free voxel's centre within half the 4 cm resolution).
  for (const Pose& T : res.log.truth->arm_poses) CHECK(T.translation().z() > z0);
  Exploration ex(res.log);
  ex.advance_to(res.log.grasps.size());
  const PointCloud free = ex.free_cloud();
  CHECK(free.size() > 20);
  for (const Vec3& q : free.points) CHECK(q.z() > z0 - 0.02 - 1e-9);

  // The ground truth round trip: format_version 4, the support back bit for bit.
  test::TempDir dir;
  const auto path = dir.path() / "seabed.h5";
  io::LogHeader header = io::header_of(res.log);
  io::LogWriter w = io::LogWriter::create(path, header);
  for (std::size_t g = 0; g < res.log.grasps.size(); ++g)
    w.append(res.log.grasps[g], &res.log.truth->arm_poses[g], &res.log.truth->joints[g]);
  w.close();
  const TactileLog back = io::read_log(path);
  REQUIRE(back.truth);
  CHECK(back.truth->scene == "seabed");
  REQUIRE(back.truth->support.vertices.size() == seabed.vertices.size());
  for (std::size_t i = 0; i < seabed.vertices.size(); ++i) CHECK(back.truth->support.vertices[i] == seabed.vertices[i]);
  CHECK(back.truth->support.faces == seabed.faces);

  // Without a scene the log says so and carries no support; a probe refuses a scene.
  datasets::SimulatorSettings plain = s;
  plain.scene = {};
  const auto none = datasets::Simulator(test::box_mesh(2.0 * h), "box", Gripper(), plain).run();
  CHECK(none.log.truth->scene == "none");
  CHECK(none.log.truth->support.faces.empty());
  datasets::SimulatorSettings probe = s;
  probe.sensing = Sensing::probe;
  try {
    datasets::Simulator(test::box_mesh(2.0 * h), "box", Gripper(), probe);
    FAIL("a probe accepted a scene");
  } catch (const Error& e) {
    CHECK(e.field() == "scene");
  }
}

TEST_CASE("fingertips in a seabed scene: every contact on the object or the seabed") {
  const Vec3 h(0.05, 0.035, 0.03);
  datasets::SimulatorSettings s;
  s.grasps = 24;
  s.noise = datasets::noise_profile("ideal");
  s.seed = 9;
  s.sensing = Sensing::fingertips;
  s.scene.kind = datasets::SceneKind::seabed;
  s.scene.off_target = 0.5;
  s.scene.slope_deg = 10;
  const datasets::Simulator sim(test::box_mesh(2.0 * h), "box", Gripper(), s);
  const auto res = sim.run();
  const MeshIndex seabed(res.log.truth->support);
  const Pose T_object_world = sim.object_pose().inverse();
  std::size_t on_seabed = 0, contacts = 0;
  for (std::size_t g = 0; g < res.log.grasps.size(); ++g)
    for (const Vec3& p : grasp_contacts(res.log, g).points) {
      ++contacts;
      const Vec3 q = (T_object_world * p).cwiseAbs() - h;
      const double d_object = q.maxCoeff() > 0 ? q.cwiseMax(0.0).norm() : -q.maxCoeff();
      const double d_seabed = seabed.closest(p).distance;
      CHECK(std::min(d_object, d_seabed) < 1e-9);   // noise-free: exactly on a surface
      on_seabed += d_seabed < d_object;
    }
  CHECK(contacts > 20);
  CHECK(on_seabed > 0);
  CHECK(on_seabed < contacts);
}

TEST_CASE("panel: a vertical plate the object is mounted against; grasps touch it from the open side") {
  // The support's geometry: vertical (its normal horizontal), flat, touching the object's
  // farthest point on its side; slope and relief refused naming their keys.
  const Mesh box = test::box_mesh(Vec3(0.1, 0.07, 0.06));
  const Pose T = tilted_pose();
  datasets::SceneSettings ps;
  ps.kind = datasets::SceneKind::panel;
  const datasets::Support panel(box, T, ps, 0.15, 3);
  CHECK(std::abs(panel.up().z()) < 1e-12);
  CHECK(panel.up().norm() == doctest::Approx(1.0).scale(0).epsilon(1e-12));
  REQUIRE(panel.mesh().faces.size() == 2);
  double nearest = 1e9;
  for (const Vec3& v : box.vertices) nearest = std::min(nearest, panel.above(T * v));
  CHECK(std::abs(nearest) < 1e-12);   // it touches, nothing of the object behind it
  for (const Vec3& v : panel.mesh().vertices) CHECK(std::abs(panel.above(v)) < 1e-12);
  CHECK(std::string(datasets::to_string(datasets::SceneKind::panel)) == "panel");
  CHECK(datasets::parse_scene_kind("panel") == datasets::SceneKind::panel);
  refused(box, T, ps.kind, [](auto& b) { b.slope_deg = 0.01; }, "scene.slope_deg");
  refused(box, T, ps.kind, [](auto& b) { b.relief_m = 0.01; }, "scene.relief_m");

  // The simulator: some contacts on the panel, the others on the object, none behind the panel;
  // the hands and their free space in front of it.
  const BoxInScene b(datasets::SceneKind::panel);
  const auto& res = b.res;
  REQUIRE(res.log.truth);
  CHECK(res.log.truth->scene == "panel");
  const Mesh& plate = res.log.truth->support;
  REQUIRE(plate.faces.size() == 2);
  const Vec3& V0 = plate.vertices[0];
  const Vec3 n = (plate.vertices[plate.faces[0][1]] - V0).cross(plate.vertices[plate.faces[0][2]] - V0).normalized();
  CHECK(std::abs(n.z()) < 1e-9);   // vertical
  const auto [on_object, on_panel] = b.contacts_on_object_and_support([&](const Vec3& p) { return n.dot(p - V0); });
  const std::size_t contacts = on_object + on_panel;
  CHECK(contacts > 100);
  CHECK(on_panel > contacts / 10);
  CHECK(on_object > contacts / 4);
  for (const Pose& A : res.log.truth->arm_poses) CHECK(n.dot(A.translation() - V0) > 0);
  Exploration ex(res.log);
  ex.advance_to(res.log.grasps.size());
  for (const Vec3& q : ex.free_cloud().points) CHECK(n.dot(q - V0) > -0.02 - 1e-9);
}

TEST_CASE("pipe: a horizontal cylinder the object rests on; grasps touch it and the object, none inside it") {
  // The support's geometry: a horizontal axis under the object, the object's lowest point over the
  // pipe touching it (vertices and edges), the gap above that, the mesh on the circle.
  const Mesh box = test::box_mesh(Vec3(0.1, 0.07, 0.06));
  const Pose T = tilted_pose();
  datasets::SceneSettings ps;
  ps.kind = datasets::SceneKind::pipe;
  auto nearest_of = [&](const datasets::Support& p) {   // over vertices and edges every 0.1 mm
    double nearest = 1e9;
    for (const auto& f : box.faces)
      for (int e = 0; e < 3; ++e) {
        const Vec3 a = T * box.vertices[f[e]], b = T * box.vertices[f[(e + 1) % 3]];
        const int n = static_cast<int>(std::ceil((b - a).norm() / 1e-4));
        for (int k = 0; k <= n; ++k) nearest = std::min(nearest, p.above(a + (b - a) * (double(k) / n)));
      }
    return nearest;
  };
  const datasets::Support pipe(box, T, ps, 0.15, 3);
  const double r = std::sqrt(0.05 * 0.05 + 0.035 * 0.035 + 0.03 * 0.03);   // the box's bounding radius
  CHECK(pipe.pipe_radius() == doctest::Approx(r).scale(0).epsilon(1e-9));
  CHECK(std::abs(pipe.axis().z()) < 1e-12);
  {  // Aims: on the pipe's upper half, near the object along the axis and (a wide pipe) its top.
    Rng rng(5);
    for (int k = 0; k < 200; ++k) {
      const auto [x, normal] = pipe.aim(rng);
      CHECK(std::abs(pipe.above(x)) < 1e-12);
      CHECK(normal.z() >= -1e-12);
      CHECK(std::abs(normal.dot(pipe.axis())) < 1e-12);
      CHECK(std::abs((x - pipe.axis_point()).dot(pipe.axis())) <= 1.5 * r + 1e-12);
    }
    datasets::SceneSettings wide = ps;
    wide.pipe_radius_m = 2.0;
    const datasets::Support big(box, T, wide, 0.15, 3);
    for (int k = 0; k < 200; ++k) {
      const auto [x, normal] = big.aim(rng);
      CHECK(std::abs(big.above(x)) < 1e-9);
      CHECK(std::acos(std::min(1.0, normal.z())) <= 1.5 * r / 2.0 + 1e-9);   // within 1.5 r of the top
    }
  }
  CHECK(std::abs(nearest_of(pipe)) < 1e-5);   // it touches; nothing of the object inside it
  CHECK((pipe.axis_point() - T.translation()).dot(Vec3::UnitZ()) < -r);   // under the object
  for (const Vec3& v : pipe.mesh().vertices) CHECK(std::abs(pipe.above(v)) < 1e-12);
  {  // outward faces: each face's normal points away from the axis
    const Mesh& m = pipe.mesh();
    for (const auto& f : m.faces) {
      const Vec3 c = (m.vertices[f[0]] + m.vertices[f[1]] + m.vertices[f[2]]) / 3.0;
      const Vec3 n = (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]);
      const Vec3 d = c - pipe.axis_point();
      CHECK(n.dot(d - d.dot(pipe.axis()) * pipe.axis()) > 0);
    }
  }
  ps.gap_m = 0.01;
  ps.pipe_radius_m = 0.2;
  const datasets::Support raised(box, T, ps, 0.15, 3);
  CHECK(raised.pipe_radius() == 0.2);
  CHECK(nearest_of(raised) == doctest::Approx(0.01).scale(0).epsilon(1e-5));
  CHECK(std::string(datasets::to_string(datasets::SceneKind::pipe)) == "pipe");
  CHECK(datasets::parse_scene_kind("pipe") == datasets::SceneKind::pipe);
  refused(box, T, ps.kind, [](auto& b) { b.slope_deg = 5; }, "scene.slope_deg");
  refused(box, T, ps.kind, [](auto& b) { b.relief_m = 0.01; }, "scene.relief_m");
  refused(box, T, ps.kind, [](auto& b) { b.pipe_radius_m = 6; }, "scene.pipe_radius_m");
  refused(box, T, datasets::SceneKind::seabed, [](auto& b) { b.pipe_radius_m = 0.1; }, "scene.pipe_radius_m");
  refused(box, T, datasets::SceneKind::panel, [](auto& b) { b.pipe_radius_m = 0.1; }, "scene.pipe_radius_m");

  // The simulator: the log's support is this pipe; contacts on the pipe or the object, none
  // inside the pipe; the hands outside it.
  const BoxInScene b(datasets::SceneKind::pipe);
  const auto& res = b.res;
  REQUIRE(res.log.truth);
  CHECK(res.log.truth->scene == "pipe");
  const datasets::Support same(test::box_mesh(2.0 * b.h), b.sim->object_pose(), b.settings.scene, Gripper().reach(),
                               b.settings.seed);
  REQUIRE(res.log.truth->support.vertices.size() == same.mesh().vertices.size());
  for (std::size_t i = 0; i < same.mesh().vertices.size(); ++i)
    CHECK((res.log.truth->support.vertices[i] - same.mesh().vertices[i]).norm() < 1e-12);
  const auto [on_object, on_pipe] = b.contacts_on_object_and_support([&](const Vec3& p) { return same.above(p); });
  const std::size_t contacts = on_object + on_pipe;
  CHECK(contacts > 100);
  CHECK(on_pipe > contacts / 10);
  CHECK(on_object > contacts / 4);
  for (const Pose& A : res.log.truth->arm_poses) CHECK(same.above(A.translation()) > 0);
}

TEST_CASE("cluttered: neighbours from the database lie on the seabed at the distance, apart, and are touched") {
  // The draw: distinct objects, never the target, the same for the same seed; too many refused.
  const auto a = datasets::neighbour_choice(10, 4, 3, 11);
  CHECK(a == datasets::neighbour_choice(10, 4, 3, 11));
  REQUIRE(a.size() == 3);
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i] < 10);
    CHECK(a[i] != 4);
    for (std::size_t j = 0; j < i; ++j) CHECK(a[i] != a[j]);
  }
  CHECK(datasets::neighbour_choice(10, 4, 9, 11).size() == 9);
  try {
    datasets::neighbour_choice(10, 4, 10, 11);
    FAIL("drew more neighbours than the database's other objects");
  } catch (const Error& e) {
    CHECK(e.field() == "scene.neighbours");
  }

  // The placement on a flat seabed around a tilted box: each neighbour rests on the seabed (its
  // lowest vertex on it), its vertices between the distance and 1.25 times it from the object's
  // surface (the object's from its own likewise at least the distance), and the neighbours at
  // least the distance apart; the same placement for the same seed.
  const Mesh box = test::box_mesh(Vec3(0.1, 0.07, 0.06));
  const Pose T = tilted_pose();
  Mesh world = box;
  for (Vec3& v : world.vertices) v = T * v;
  datasets::SceneSettings cs;
  cs.kind = datasets::SceneKind::cluttered;
  cs.neighbours = 3;
  cs.neighbour_distance_m = 0.04;
  cs.extent_m = 0.6;
  const datasets::Support seabed(box, T, cs, 0.15, 3);
  const std::vector<datasets::SceneObject> objects{{"ball", test::sphere_mesh(0.05)},
                                                   {"bar", test::box_mesh(Vec3(0.3, 0.04, 0.04))},
                                                   {"cube", test::box_mesh(Vec3(0.07, 0.07, 0.07))}};
  const auto placed = datasets::place_neighbours(world, seabed, objects, cs, 5);
  REQUIRE(placed.size() == 3);
  const MeshIndex object_index(world);
  auto nearest = [](const MeshIndex& index, const Mesh& m) {
    double d = 1e9;
    for (const Vec3& v : m.vertices) d = std::min(d, index.closest(v).distance);
    return d;
  };
  for (std::size_t k = 0; k < placed.size(); ++k) {
    const datasets::PlacedObject& p = placed[k];
    CHECK(p.name == objects[k].name);
    REQUIRE(p.world.vertices.size() == objects[k].mesh.vertices.size());
    for (std::size_t i = 0; i < p.world.vertices.size(); ++i)
      CHECK((p.world.vertices[i] - p.T_world_object * objects[k].mesh.vertices[i]).norm() < 1e-12);
    double lowest = 1e9;
    for (const Vec3& v : p.world.vertices) lowest = std::min(lowest, seabed.above(v));
    CHECK(std::abs(lowest) < 1e-9);
    const MeshIndex own(p.world);
    const double d = std::min(nearest(object_index, p.world), nearest(own, world));
    CHECK(d >= 0.04 - 1e-9);
    CHECK(d <= 1.25 * 0.04 + 1e-9);
    for (std::size_t j = 0; j < k; ++j) CHECK(nearest(MeshIndex(placed[j].world), p.world) >= 0.04 - 1e-9);
  }
  const auto again = datasets::place_neighbours(world, seabed, objects, cs, 5);
  for (std::size_t k = 0; k < placed.size(); ++k) CHECK(again[k].T_world_object.isApprox(placed[k].T_world_object, 0));

  // Bad settings named: a count out of [1, 8], a distance that would touch, a share outside
  // [0, 1], meshes that do not match the count.
  refused(box, T, cs.kind, [](auto& b) { b.neighbours = 0; }, "scene.neighbours");
  refused(box, T, cs.kind, [](auto& b) { b.neighbours = 9; }, "scene.neighbours");
  refused(box, T, cs.kind, [](auto& b) { b.neighbour_distance_m = 0.001; }, "scene.neighbour_distance_m");
  refused(box, T, cs.kind, [](auto& b) { b.neighbour_share = 1.5; }, "scene.neighbour_share");
  try {
    datasets::place_neighbours(world, seabed, {objects[0]}, cs, 5);
    FAIL("placed one mesh as three neighbours");
  } catch (const Error& e) {
    CHECK(e.field() == "scene.neighbours");
  }
  CHECK(datasets::parse_scene_kind("cluttered") == datasets::SceneKind::cluttered);
  CHECK(std::string(datasets::to_string(datasets::SceneKind::cluttered)) == "cluttered");

  // The simulator: 40 % of the grasps off the target, half of those at the two neighbours. The
  // contacts lie on the object, the seabed or a neighbour (within 1.5 mm), each kind touched;
  // the log's truth holds the neighbours as placed, and it round-trips (format_version 5).
  const Vec3 h(0.05, 0.035, 0.03);
  datasets::SimulatorSettings s;
  s.grasps = 60;
  s.noise = datasets::noise_profile("ideal");
  s.seed = 7;
  s.scene.kind = datasets::SceneKind::cluttered;
  s.scene.off_target = 0.4;
  s.scene.neighbours = 2;
  s.scene.neighbour_distance_m = 0.03;
  s.neighbours = {objects[0], objects[2]};
  const datasets::Simulator sim(test::box_mesh(2.0 * h), "box", Gripper(), s);
  auto run_with = [&](int threads) {
    tbb::task_arena arena(threads);
    return arena.execute([&] { return sim.run(); });
  };
  const auto res = run_with(2);
  const auto one = run_with(1);
  REQUIRE(res.log.truth);
  CHECK(res.log.truth->scene == "cluttered");
  REQUIRE(res.log.truth->neighbours.size() == 2);
  CHECK(res.log.truth->neighbours[0].name == "ball");
  CHECK(res.log.truth->neighbours[1].name == "cube");
  std::vector<MeshIndex> neighbour_index;
  for (const auto& n : res.log.truth->neighbours) neighbour_index.emplace_back(n.mesh);
  const MeshIndex seabed_index(res.log.truth->support);
  const Pose T_object_world = sim.object_pose().inverse();
  std::size_t on_object = 0, on_seabed = 0, on_neighbour = 0;
  for (std::size_t g = 0; g < res.log.grasps.size(); ++g) {
    CHECK(res.log.grasps[g].tactile == one.log.grasps[g].tactile);
    for (const Vec3& p : grasp_contacts(res.log, g).points) {
      const Vec3 q = (T_object_world * p).cwiseAbs() - h;
      const double d_object = q.maxCoeff() > 0 ? q.cwiseMax(0.0).norm() : -q.maxCoeff();
      const double d_seabed = seabed_index.closest(p).distance;
      double d_neighbour = 1e9;
      for (const MeshIndex& n : neighbour_index) d_neighbour = std::min(d_neighbour, n.closest(p).distance);
      CHECK(std::min({d_object, d_seabed, d_neighbour}) < 0.0015);
      if (d_object <= std::min(d_seabed, d_neighbour)) ++on_object;
      else if (d_neighbour < d_seabed) ++on_neighbour;
      else ++on_seabed;
    }
  }
  const std::size_t contacts = on_object + on_seabed + on_neighbour;
  CHECK(contacts > 150);
  CHECK(on_object > contacts / 4);
  CHECK(on_neighbour > contacts / 20);
  CHECK(on_seabed > contacts / 50);

  test::TempDir dir;
  const auto path = dir.path() / "cluttered.h5";
  io::LogWriter w = io::LogWriter::create(path, io::header_of(res.log));
  for (std::size_t g = 0; g < res.log.grasps.size(); ++g)
    w.append(res.log.grasps[g], &res.log.truth->arm_poses[g], &res.log.truth->joints[g]);
  w.close();
  const TactileLog back = io::read_log(path);
  REQUIRE(back.truth);
  REQUIRE(back.truth->neighbours.size() == 2);
  for (std::size_t k = 0; k < 2; ++k) {
    const auto& x = res.log.truth->neighbours[k];
    const auto& y = back.truth->neighbours[k];
    CHECK(y.name == x.name);
    CHECK(y.pose.isApprox(x.pose, 1e-12));
    CHECK(y.mesh.vertices == x.mesh.vertices);
    CHECK(y.mesh.faces == x.mesh.faces);
  }

  // The simulator wants the count's meshes, and meshes only in a cluttered scene.
  datasets::SimulatorSettings missing = s;
  missing.neighbours.pop_back();
  datasets::SimulatorSettings seabed_only = s;
  seabed_only.scene.kind = datasets::SceneKind::seabed;
  for (const auto* bad : {&missing, &seabed_only}) {
    try {
      datasets::Simulator(test::box_mesh(2.0 * h), "box", Gripper(), *bad);
      FAIL("accepted neighbours that do not match the scene");
    } catch (const Error& e) {
      CHECK(e.field() == "scene.neighbours");
    }
  }
}
