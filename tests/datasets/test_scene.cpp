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
  const Vec3 h(0.05, 0.035, 0.03);
  datasets::SimulatorSettings s;
  s.grasps = 40;
  s.noise = datasets::noise_profile("ideal");
  s.seed = 7;
  s.scene.kind = datasets::SceneKind::panel;
  s.scene.off_target = 0.4;
  const datasets::Simulator sim(test::box_mesh(2.0 * h), "box", Gripper(), s);
  const auto res = sim.run();
  REQUIRE(res.log.truth);
  CHECK(res.log.truth->scene == "panel");
  const Mesh& plate = res.log.truth->support;
  REQUIRE(plate.faces.size() == 2);
  const Vec3& V0 = plate.vertices[0];
  const Vec3 n = (plate.vertices[plate.faces[0][1]] - V0).cross(plate.vertices[plate.faces[0][2]] - V0).normalized();
  CHECK(std::abs(n.z()) < 1e-9);   // vertical
  const Pose T_object_world = sim.object_pose().inverse();
  std::size_t on_object = 0, on_panel = 0, contacts = 0;
  for (std::size_t g = 0; g < res.log.grasps.size(); ++g)
    for (const Vec3& p : grasp_contacts(res.log, g).points) {
      ++contacts;
      const Vec3 q = (T_object_world * p).cwiseAbs() - h;
      const double d_object = q.maxCoeff() > 0 ? q.cwiseMax(0.0).norm() : -q.maxCoeff();
      const double d_panel = n.dot(p - V0);
      CHECK(d_panel > -0.0015);   // nothing sensed behind the panel
      CHECK(std::min(d_object, std::abs(d_panel)) < 0.0015);
      on_object += d_object < std::abs(d_panel);
      on_panel += std::abs(d_panel) <= d_object;
    }
  CHECK(contacts > 100);
  CHECK(on_panel > contacts / 10);
  CHECK(on_object > contacts / 4);
  for (const Pose& A : res.log.truth->arm_poses) CHECK(n.dot(A.translation() - V0) > 0);
  Exploration ex(res.log);
  ex.advance_to(res.log.grasps.size());
  for (const Vec3& q : ex.free_cloud().points) CHECK(n.dot(q - V0) > -0.02 - 1e-9);
}
