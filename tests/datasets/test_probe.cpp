// The simulator's probe (sensing = probe): contacts on the true surface within the ball-centre
// offset, free space outside the object, arm noise and 1 mm quantization in what is recorded,
// the log written and read back (format_version 2), identical logs for 1 and 2 threads.
#include "datasets/simulator.hpp"
#include "engine/recognition_fixture.hpp"
#include "engine/touch/fusion.hpp"
#include "io/h5.hpp"
#include "io/log_store.hpp"
#include "simulated_log.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>

using namespace ts;

namespace {

// Axis-aligned box of half-sizes h (outward winding).
Mesh box_mesh(const Vec3& h) { return test::box_mesh(2.0 * h); }

datasets::SimulatorSettings probe_settings(std::size_t touches, const std::string& noise, std::uint64_t seed) {
  datasets::SimulatorSettings s;
  s.grasps = touches;
  s.noise = datasets::noise_profile(noise);
  s.seed = seed;
  s.sensing = Sensing::probe;
  return s;
}

}  // namespace

TEST_CASE("probe, ideal noise: one contact per touch on the surface, the path free") {
  const Vec3 h(0.06, 0.04, 0.025);
  const datasets::Simulator sim(box_mesh(h), "box", Gripper(), probe_settings(40, "ideal", 3));
  const auto res = sim.run();
  const TactileLog& log = res.log;
  REQUIRE(log.sensing == Sensing::probe);
  REQUIRE(log.grasps.size() == 40);
  CHECK(log.pads.empty());
  CHECK(res.grasps_with_contact == 40);   // a convex box: every touch lands
  const Pose T_object_world = sim.object_pose().inverse();
  const double r = log.probe.ball_radius;
  const double max_tilt = sim.settings().probe.max_tilt_deg * std::numbers::pi / 180.0;
  auto box_distance = [&](const Vec3& p_world) {   // signed distance to the box
    const Vec3 q = (T_object_world * p_world).cwiseAbs() - h;
    return q.maxCoeff() > 0 ? q.cwiseMax(0.0).norm() : q.maxCoeff();
  };
  for (std::size_t g = 0; g < log.grasps.size(); ++g) {
    const GraspContacts c = grasp_contacts(log, g);
    REQUIRE(c.points.size() == 1);
    // The ball centre stopped one radius from the surface; the contact straight ahead of it is
    // off the surface by at most r (1 - cos tilt) on a face (the box's edges: at most r).
    CHECK(std::abs(box_distance(log.grasps[g].arm_pose.translation()) - r) < 2e-6);
    CHECK(std::abs(box_distance(c.points[0])) <= r + 1e-6);
    CHECK(log.grasps[g].probe_travel > 0.05);
    // Every ball centre along the path was at least r away from the box.
    for (double z = 0.0; z <= log.grasps[g].probe_travel; z += 0.005)
      CHECK(box_distance(log.grasps[g].arm_pose * Vec3(0, 0, -z)) >= r - 2e-6);
  }
  // On a face (not near an edge), the offset error stays below r (1 - cos tilt).
  int on_face = 0;
  for (std::size_t g = 0; g < log.grasps.size(); ++g) {
    const Vec3 q = (T_object_world * grasp_contacts(log, g).points[0]).cwiseAbs();
    const int inside = (q.array() < h.array() - 0.004).count();
    if (inside < 2) continue;
    ++on_face;
    CHECK(std::abs(box_distance(grasp_contacts(log, g).points[0])) <= r * (1.0 - std::cos(max_tilt)) + 1e-6);
  }
  CHECK(on_face > 20);
  // The exploration: contacts with normals (minus the approach), free points outside the box.
  Exploration ex(log);
  ex.advance_to(log.grasps.size());
  const PointCloud contacts = ex.contact_cloud();
  REQUIRE(contacts.has_normals());
  CHECK(contacts.size() <= 40);   // two touches may share a 2 mm voxel
  CHECK(contacts.size() >= 36);
  const PointCloud free = ex.free_cloud();
  CHECK(free.size() > 100);
  for (const Vec3& p : free.points) CHECK(box_distance(p) > 0.0);
}

TEST_CASE("probe noise: arm error and 1 mm quantization in the record, the truth unchanged") {
  const Mesh m = box_mesh(Vec3(0.05, 0.05, 0.05));
  auto s = probe_settings(30, "underwater", 8);
  s.probe.quantization = 0.001;
  const auto noisy = datasets::Simulator(m, "cube", Gripper(), s).run().log;
  const auto ideal = datasets::Simulator(m, "cube", Gripper(), probe_settings(30, "ideal", 8)).run().log;
  double sum2 = 0.0;
  for (std::size_t g = 0; g < 30; ++g) {
    // The same true touches whatever the noise.
    CHECK((noisy.truth->arm_poses[g].matrix() - ideal.truth->arm_poses[g].matrix()).norm() < 1e-12);
    const Vec3 t = noisy.grasps[g].arm_pose.translation();
    for (int k = 0; k < 3; ++k) CHECK(std::abs(t[k] * 1000.0 - std::round(t[k] * 1000.0)) < 1e-6);
    sum2 += (t - noisy.truth->arm_poses[g].translation()).squaredNorm();
  }
  const double rms_axis = std::sqrt(sum2 / (3.0 * 30));
  CHECK(rms_axis > 0.002);   // the underwater profile: 3 mm per axis
  CHECK(rms_axis < 0.0045);
}

TEST_CASE("probe logs: written and read back (format_version 2), same bytes for 1 and 2 threads") {
  test::TempDir dir;
  const Mesh m = box_mesh(Vec3(0.05, 0.03, 0.02));
  const TactileLog log = test::simulate_and_write(m, "plate", probe_settings(12, "underwater", 5), 1, dir.path() / "a.h5");
  test::simulate_and_write(m, "plate", probe_settings(12, "underwater", 5), 2, dir.path() / "b.h5");
  CHECK(test::read_bytes(dir.path() / "a.h5") == test::read_bytes(dir.path() / "b.h5"));
  const TactileLog back = io::read_log(dir.path() / "a.h5");
  CHECK(back.sensing == Sensing::probe);
  CHECK(back.probe.ball_radius == log.probe.ball_radius);
  REQUIRE(back.grasps.size() == 12);
  for (std::size_t g = 0; g < 12; ++g) {
    CHECK(back.grasps[g].probe_touched == log.grasps[g].probe_touched);
    CHECK(back.grasps[g].probe_travel == log.grasps[g].probe_travel);
    CHECK((back.grasps[g].arm_pose.matrix() - log.grasps[g].arm_pose.matrix()).norm() < 1e-12);
    CHECK((back.truth->arm_poses[g].matrix() - log.truth->arm_poses[g].matrix()).norm() < 1e-12);
  }
  {
    const auto f = io::h5::File::open(dir.path() / "a.h5", io::h5::File::Access::read);
    CHECK(f.root().int_attribute("format_version") == 2);
    CHECK(f.root().string_attribute("sensing") == "probe");
  }
  // Appending touches to a probe log.
  {
    io::LogWriter w = io::LogWriter::append_to(dir.path() / "a.h5");
    w.append(log.grasps[0], &log.truth->arm_poses[0]);
    w.close();
  }
  CHECK(io::read_log(dir.path() / "a.h5").grasps.size() == 13);
  // A bad value names the dataset.
  TactileLog bad = log;
  bad.grasps[3].probe_travel = -1.0;
  CHECK_THROWS_WITH_AS(io::write_log(dir.path() / "c.h5", bad), doctest::Contains("/grasps/probe_travel[3]"), Error);
  CHECK_FALSE(std::filesystem::exists(dir.path() / "c.h5"));
  bad = log;
  bad.probe.shaft_radius = 2.0 * bad.probe.ball_radius;
  CHECK_THROWS_WITH_AS(io::write_log(dir.path() / "c.h5", bad), doctest::Contains("/probe/shaft_radius"), Error);
}

TEST_CASE("probe settings errors") {
  const Mesh m = box_mesh(Vec3(0.05, 0.05, 0.05));
  auto s = probe_settings(3, "ideal", 1);
  s.probe.spec.ball_radius = 0.0;
  CHECK_THROWS_AS(datasets::Simulator(m, "cube", Gripper(), s), Error);
  s = probe_settings(3, "ideal", 1);
  s.probe.max_tilt_deg = 95.0;
  CHECK_THROWS_AS(datasets::Simulator(m, "cube", Gripper(), s), Error);
  CHECK_THROWS_WITH_AS(parse_sensing("taxels", "exp.toml", "sensing"), doctest::Contains("exp.toml"), Error);
}
