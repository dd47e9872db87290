// The exploration simulator: contacts on the true surface and free space outside the object
// with ideal noise, byte-identical logs for any thread count, noise profiles, bad settings.
#include "datasets/simulator.hpp"
#include "engine/touch/fusion.hpp"
#include "io/log_store.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <map>
#include <numbers>

using namespace ts;

namespace {
// Icosphere of radius r (outward winding).
Mesh icosphere(double r, int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  Mesh m;
  for (const Vec3& v : {Vec3(-1, t, 0), Vec3(1, t, 0), Vec3(-1, -t, 0), Vec3(1, -t, 0), Vec3(0, -1, t),
                        Vec3(0, 1, t), Vec3(0, -1, -t), Vec3(0, 1, -t), Vec3(t, 0, -1), Vec3(t, 0, 1),
                        Vec3(-t, 0, -1), Vec3(-t, 0, 1)})
    m.vertices.push_back(v.normalized());
  m.faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
             {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
             {3, 8, 9},  {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.vertices.push_back((m.vertices[a] + m.vertices[b]).normalized());
      return mid[key] = static_cast<int>(m.vertices.size()) - 1;
    };
    std::vector<Eigen::Vector3i> faces;
    for (const auto& f : m.faces) {
      const int a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]), c = midpoint(f[2], f[0]);
      faces.insert(faces.end(), {{f[0], a, c}, {f[1], b, a}, {f[2], c, b}, {a, b, c}});
    }
    m.faces = faces;
  }
  for (auto& v : m.vertices) v *= r;
  return m;
}

// Axis-aligned box of half-sizes h, each face split into n x n quads (outward winding).
Mesh box(const Vec3& h, int n) {
  Mesh m;
  for (int axis = 0; axis < 3; ++axis)
    for (int side : {-1, 1}) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      const int base = static_cast<int>(m.vertices.size());
      for (int i = 0; i <= n; ++i)
        for (int j = 0; j <= n; ++j) {
          Vec3 p;
          p[axis] = side * h[axis];
          p[u] = h[u] * (2.0 * i / n - 1.0);
          p[v] = h[v] * (2.0 * j / n - 1.0);
          m.vertices.push_back(p);
        }
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          const int a = base + i * (n + 1) + j, b = a + n + 1, c = b + 1, d = a + 1;
          if (side > 0) {
            m.faces.emplace_back(a, b, c);
            m.faces.emplace_back(a, c, d);
          } else {
            m.faces.emplace_back(a, c, b);
            m.faces.emplace_back(a, d, c);
          }
        }
    }
  return m;
}

datasets::SimulatorSettings settings(std::size_t grasps, const std::string& noise, int sensors, std::uint64_t seed) {
  datasets::SimulatorSettings s;
  s.grasps = grasps;
  s.noise = datasets::noise_profile(noise);
  s.sensors = sensors;
  s.seed = seed;
  return s;
}
}  // namespace

TEST_CASE("ideal noise: every contact within 0.5 mm of the true surface, free space outside") {
  struct Case {
    const char* name;
    Mesh mesh;
    Vec3 offset;
  };
  const std::vector<Case> cases = {{"sphere", icosphere(0.06, 3), Vec3::Zero()},
                                   {"box", box(Vec3(0.07, 0.045, 0.03), 6), Vec3(1e5, -4e4, -2500.0)}};
  for (const auto& c : cases) {
    INFO(c.name);
    auto s = settings(16, "ideal", 6, 11);
    s.world_offset = c.offset;
    const datasets::Simulator sim(c.mesh, c.name, Gripper(), s);
    const auto result = sim.run();
    const TactileLog& log = result.log;
    REQUIRE(log.truth);
    CHECK_NOTHROW(validate(log));
    const Pose T_object_world = log.truth->object_pose.inverse();
    std::size_t contacts = 0;
    double worst = 0.0;
    for (std::size_t g = 0; g < log.grasps.size(); ++g) {
      // The ideal log's measured arm pose is the true one.
      CHECK(log.grasps[g].arm_pose.isApprox(log.truth->arm_poses[g], 1e-12));
      for (const Vec3& p : grasp_contacts(log, g).points) {
        worst = std::max(worst, sim.mesh().closest(T_object_world * p).distance);
        ++contacts;
      }
    }
    INFO("contacts " << contacts << ", worst " << worst);
    CHECK(result.grasps_with_contact >= 8);  // non-vacuous: most grasps touch
    CHECK(contacts > 100);
    CHECK(worst < 0.5e-3);

    // Free space: no free voxel centre deeper inside the object than half a voxel.
    ExplorationSettings es;
    Exploration ex(log, es);
    ex.advance_to(log.grasps.size());
    const auto free = ex.grid().free_centres();
    CHECK(free.size() > 1000);
    std::size_t inside = 0;
    double deepest = 0.0;
    for (const Vec3& p : free) {
      const Vec3 q = T_object_world * p;
      if (!sim.mesh().inside(q)) continue;
      ++inside;
      deepest = std::max(deepest, sim.mesh().closest(q).distance);
    }
    INFO("free voxels " << free.size() << ", inside " << inside << ", deepest " << deepest);
    CHECK(deepest <= 0.5 * es.free.voxel);
    // and the sampled free-space cloud of Eq. 3 likewise
    for (const Vec3& p : ex.free_cloud().points) {
      const Vec3 q = T_object_world * p;
      if (sim.mesh().inside(q)) CHECK(sim.mesh().closest(q).distance <= 0.5 * es.free.voxel);
    }
  }
}

TEST_CASE("same seed => byte-identical log for 1 and 2 threads") {
  test::TempDir dir("sim");
  const Mesh mesh = box(Vec3(0.05, 0.04, 0.06), 4);
  auto s = settings(10, "deepsea", 6, 5);
  const datasets::Simulator sim(mesh, "box", Gripper(), s);
  for (int threads : {1, 2}) {
    tbb::task_arena arena(threads);
    const auto r = arena.execute([&] { return sim.run(); });
    io::write_log(dir / (threads == 1 ? "t1.h5" : "t2.h5"), r.log);
  }
  CHECK(test::read_bytes(dir / "t1.h5") == test::read_bytes(dir / "t2.h5"));
  // Another seed gives another log.
  s.seed = 6;
  io::write_log(dir / "s6.h5", datasets::Simulator(mesh, "box", Gripper(), s).run().log);
  CHECK(test::read_bytes(dir / "t1.h5") != test::read_bytes(dir / "s6.h5"));
}

TEST_CASE("noise profiles: measured values move, the true grasps stay") {
  const Mesh mesh = icosphere(0.05, 2);
  const auto ideal = datasets::Simulator(mesh, "s", Gripper(), settings(48, "ideal", 1, 3)).run();
  const auto under = datasets::Simulator(mesh, "s", Gripper(), settings(48, "underwater", 1, 3)).run();
  const auto deep = datasets::Simulator(mesh, "s", Gripper(), settings(48, "deepsea", 1, 3)).run();
  CHECK(under.log.noise == "underwater");
  CHECK(deep.log.noise == "deepsea");
  double sq = 0.0, rot = 0.0;
  for (std::size_t g = 0; g < 48; ++g) {
    // Same seed: the same true grasps whatever the noise.
    CHECK(ideal.log.truth->arm_poses[g].isApprox(under.log.truth->arm_poses[g], 1e-12));
    CHECK(ideal.log.truth->arm_poses[g].isApprox(deep.log.truth->arm_poses[g], 1e-12));
    CHECK(ideal.log.grasps[g].tactile.size() == 72);
    const Pose& measured = under.log.grasps[g].arm_pose;
    const Pose& truth = under.log.truth->arm_poses[g];
    sq += (measured.translation() - truth.translation()).squaredNorm();
    rot += Eigen::AngleAxisd(truth.linear().transpose() * measured.linear()).angle();
  }
  const double sigma = std::sqrt(sq / (3 * 48));
  CHECK(sigma > 0.002);
  CHECK(sigma < 0.0042);
  const double mean_angle_deg = rot / 48 * 180 / std::numbers::pi;
  // |N(0, I) 1°| has mean 1.6°
  CHECK(mean_angle_deg > 1.0);
  CHECK(mean_angle_deg < 2.2);
  // Deep-sea contacts scatter more about the surface than underwater ones, measured in the
  // true arm frame (arm errors aside).
  auto scatter = [&](const datasets::SimulationResult& r) {
    TactileLog log = r.log;
    for (std::size_t g = 0; g < log.grasps.size(); ++g) log.grasps[g].arm_pose = log.truth->arm_poses[g];
    const datasets::Simulator sim(mesh, "s", Gripper(), settings(1, "ideal", 1, 3));
    double s2 = 0;
    std::size_t n = 0;
    for (std::size_t g = 0; g < log.grasps.size(); ++g)
      for (const Vec3& p : grasp_contacts(log, g).points) {
        s2 += std::pow(sim.mesh().closest(log.truth->object_pose.inverse() * p).distance, 2);
        ++n;
      }
    REQUIRE(n > 50);
    return std::sqrt(s2 / n);
  };
  const double s_under = scatter(under), s_deep = scatter(deep);
  CHECK(s_under < 0.0015);
  CHECK(s_deep > s_under);
  CHECK(s_deep > 0.0005);
}

TEST_CASE("simulator input errors") {
  CHECK_THROWS_AS(datasets::noise_profile("murky"), Error);
  const Mesh mesh = icosphere(0.05, 1);
  CHECK_THROWS_AS(datasets::Simulator(Mesh{}, "empty", Gripper(), settings(2, "ideal", 1, 1)), Error);
  CHECK_THROWS_AS(datasets::Simulator(mesh, "s", Gripper(), settings(2, "ideal", 3, 1)), Error);
  auto s = settings(2, "ideal", 1, 1);
  s.noise.signal_noise = -0.1;
  CHECK_THROWS_AS(datasets::Simulator(mesh, "s", Gripper(), s), Error);
  s = settings(2, "ideal", 1, 1);
  s.grasp.press_max = 0.005;  // deeper than the foam
  CHECK_THROWS_AS(datasets::Simulator(mesh, "s", Gripper(), s), Error);
}

TEST_CASE("underwater contacts are unbiased: in the true arm frame they scatter about the surface, not off it") {
  // A bias along the normal (contacts outside or inside the surface) would make a larger or
  // smaller look-alike fit better than the true object; the arm's pose error is per grasp and
  // taken out here.
  for (double r : {0.03, 0.1}) {
    CAPTURE(r);
    const Mesh mesh = icosphere(r, 4);
    const datasets::Simulator sim(mesh, "s", Gripper(), settings(40, "underwater", 1, 5));
    TactileLog log = sim.run().log;
    for (std::size_t g = 0; g < log.grasps.size(); ++g) log.grasps[g].arm_pose = log.truth->arm_poses[g];
    double sum = 0, sq = 0;
    std::size_t n = 0;
    for (std::size_t g = 0; g < log.grasps.size(); ++g)
      for (const Vec3& p : grasp_contacts(log, g).points) {
        const Vec3 q = log.truth->object_pose.inverse() * p;
        const double d = sim.mesh().closest(q).distance * (sim.mesh().inside(q) ? -1.0 : 1.0);
        sum += d;
        sq += d * d;
        ++n;
      }
    REQUIRE(n > 300);
    const double mean = sum / double(n), rms = std::sqrt(sq / double(n));
    CAPTURE(mean);
    CAPTURE(rms);
    CHECK(std::abs(mean) < 0.1e-3);   // measured: -0.03 to -0.01 mm
    CHECK(rms > 0.05e-3);             // the signal noise is felt (0.13-0.18 mm)
    CHECK(rms < 0.4e-3);
  }
}
