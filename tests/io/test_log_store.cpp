// Tactile logs in HDF5: write -> read round trip, appending without rewriting, byte-identical
// output, a log written by hand from FORMAT_LOG.md, and bad files (missing groups, mismatched
// image sizes, NaN poses, negative or over-range signals, bad gripper descriptions).
#include "io/gripper_io.hpp"
#include "io/h5.hpp"
#include "io/log_store.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <limits>

using namespace ts;

namespace {
TactileLog sample_log(std::size_t grasps, bool truth, std::size_t pads = 2) {
  TactileLog log;
  log.object = "cube";
  log.noise = "underwater";
  log.seed = 0xfedcba9876543210ULL;  // above 2^63: stored bit-exact
  log.pads = pads == 1 ? std::vector<int>{1} : std::vector<int>{1, 4};
  const std::size_t n = log.sensels();
  Rng rng(3);
  for (std::size_t i = 0; i < log.pads.size() * n; ++i) log.gains.push_back(static_cast<float>(rng.uniform(0.8, 1.2)));
  if (truth) log.truth = LogGroundTruth{};
  if (truth) {
    log.truth->object_pose.linear() = rng.rotation().toRotationMatrix();
    log.truth->object_pose.translation() = Vec3(1e5, -2e4, -3000.0);  // a dive far from the origin
  }
  for (std::size_t k = 0; k < grasps; ++k) {
    GraspRecord r;
    r.time = 60.0 * k;
    r.arm_pose.linear() = rng.rotation().toRotationMatrix();
    r.arm_pose.translation() = Vec3(1e5 + rng.uniform(), -2e4, -3000.0);
    for (int j = 0; j < 6; ++j) r.joints.push_back(rng.uniform(-0.4, 1.5));
    for (std::size_t i = 0; i < log.pads.size() * n; ++i) {
      r.tactile.push_back(i % 5 == 0 ? static_cast<float>(rng.uniform(0.0, 255.0)) : 0.0f);
      r.past_peak.push_back(static_cast<std::uint8_t>(i % 5 == 0 ? 1 + rng.index(2) : 1));
    }
    if (truth) {
      Pose T = r.arm_pose;
      T.translation() += Vec3(0.003, -0.002, 0.001);
      log.truth->arm_poses.push_back(T);
      log.truth->joints.push_back(r.joints);
    }
    log.grasps.push_back(r);
  }
  return log;
}

void check_equal(const TactileLog& a, const TactileLog& b) {
  CHECK(a.object == b.object);
  CHECK(a.noise == b.noise);
  CHECK(a.seed == b.seed);
  CHECK(a.pads == b.pads);
  CHECK(a.gains == b.gains);
  CHECK(io::gripper_to_json(a.gripper.spec()) == io::gripper_to_json(b.gripper.spec()));
  REQUIRE(a.grasps.size() == b.grasps.size());
  for (std::size_t k = 0; k < a.grasps.size(); ++k) {
    const auto& x = a.grasps[k];
    const auto& y = b.grasps[k];
    CHECK(x.time == y.time);
    CHECK(x.joints == y.joints);
    CHECK(x.tactile == y.tactile);
    CHECK(x.past_peak == y.past_peak);
    CHECK((x.arm_pose.translation() - y.arm_pose.translation()).norm() < 1e-9);
    CHECK((x.arm_pose.linear() - y.arm_pose.linear()).norm() < 1e-12);
  }
  REQUIRE(a.truth.has_value() == b.truth.has_value());
  if (a.truth) {
    CHECK(a.truth->object_pose.isApprox(b.truth->object_pose, 1e-12));
    REQUIRE(a.truth->arm_poses.size() == b.truth->arm_poses.size());
    for (std::size_t k = 0; k < a.truth->arm_poses.size(); ++k)
      CHECK(a.truth->arm_poses[k].isApprox(b.truth->arm_poses[k], 1e-12));
    CHECK(a.truth->joints == b.truth->joints);
  }
}

void expect_error(const std::filesystem::path& p, const std::string& field) {
  try {
    io::read_log(p);
    FAIL("no error; expected one naming " << field);
  } catch (const Error& e) {
    INFO(e.what());
    CHECK(e.file() == p.string());
    CHECK(e.field().find(field) != std::string::npos);
  }
}

// A log written with the plain HDF5 wrapper, the way a user converts a robot's recording:
// exactly the layout of io/FORMAT_LOG.md. `defect` breaks one thing.
void write_by_hand(const std::filesystem::path& path, const std::string& defect = {}) {
  namespace h5 = io::h5;
  const Gripper g;
  const std::size_t G = 3, P = 1, R = 12, C = 6;
  h5::File f = h5::File::create(path);
  h5::Group root = f.root();
  root.set_attribute("format", "touchstone-tactile-log");
  root.set_attribute("format_version", std::int64_t{1});
  root.set_attribute("object", "unknown");
  if (defect != "no gripper")
    root.create_group("gripper").write_strings(
        "description", {defect == "bad gripper" ? std::string("{\"name\": 1}") : io::gripper_to_json(g.spec())});
  h5::Group s = root.create_group("sensors");
  s.write("pad_index", std::vector<std::int32_t>{defect == "bad pad" ? 9 : 1});
  std::vector<float> gain(P * R * C, 1.0f);
  s.write("gain", gain.data(), {P, R, C});
  if (defect == "no grasps") return;
  h5::Group gr = root.create_group("grasps");
  std::vector<double> time = {0.0, 61.5, 118.0};
  gr.write("time", time);
  std::vector<double> pose;
  for (std::size_t k = 0; k < G; ++k) {
    for (double v : {412345.0 + k, 5.8e6, -2500.0, 1.0, 0.0, 0.0, 0.0}) pose.push_back(v);
  }
  if (defect == "nan pose") pose[7 + 1] = std::numeric_limits<double>::quiet_NaN();
  if (defect == "bad quaternion") pose[7 + 3] = 2.0;
  gr.write("arm_pose", pose.data(), {G, 7});
  std::vector<double> joints(G * 6, 0.3);
  gr.write("joints", joints.data(), {G, 6});
  const std::size_t cols = defect == "image size" ? 5 : C;
  std::vector<float> tactile(G * P * R * cols, 0.0f);
  tactile[10] = 150.0f;
  if (defect == "negative") tactile[20] = -3.0f;
  if (defect == "over range") tactile[20] = 300.0f;
  if (defect == "nan signal") tactile[20] = std::numeric_limits<float>::quiet_NaN();
  gr.write("tactile", tactile.data(), {G, P, R, cols});
  // no past_peak dataset: it is optional
  f.close();
}
}  // namespace

TEST_CASE("log write -> read round trip, with and without ground truth") {
  test::TempDir dir("log");
  for (bool truth : {true, false}) {
    const TactileLog log = sample_log(5, truth);
    const auto p = dir / (truth ? "a.h5" : "b.h5");
    io::write_log(p, log);
    check_equal(log, io::read_log(p));
  }
  // a log without grasps is valid too
  const TactileLog empty = sample_log(0, true, 1);
  io::write_log(dir / "e.h5", empty);
  check_equal(empty, io::read_log(dir / "e.h5"));
}

TEST_CASE("a scene's support in the ground truth: format_version 4, read back; bad ones named") {
  test::TempDir dir("log");
  TactileLog log = sample_log(3, true);
  log.truth->scene = "seabed";
  log.truth->support.vertices = {Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(1, 1, 0.25), Vec3(-1, 1, 0)};
  log.truth->support.faces = {Eigen::Vector3i(0, 1, 2), Eigen::Vector3i(0, 2, 3)};
  const auto good = dir / "scene.h5";
  io::write_log(good, log);
  {
    const h5::File f = h5::File::open(good);
    CHECK(f.root().int_attribute("format_version") == 4);
  }
  const TactileLog back = io::read_log(good);
  REQUIRE(back.truth);
  CHECK(back.truth->scene == "seabed");
  CHECK(back.truth->support.vertices == log.truth->support.vertices);
  CHECK(back.truth->support.faces == log.truth->support.faces);
  // Without ground truth a support cannot be written; nor a support without its scene's name.
  TactileLog orphan = log;
  orphan.truth->scene = "none";
  CHECK_THROWS_AS(io::write_log(dir / "orphan.h5", orphan), Error);
  CHECK_FALSE(std::filesystem::exists(dir / "orphan.h5"));

  // Hand-made defects, each named: the group in an older version, an index out of range, a
  // vertex not finite, no scene name, a shape outside the bounds (checked before reading).
  auto defect = [&](const std::string& name, auto edit, const std::string& field) {
    INFO(name);
    const auto p = dir / (name + ".h5");
    io::write_log(p, sample_log(2, true));   // version 1, no support
    {
      h5::File f = h5::File::open(p, h5::File::Access::read_write);
      h5::Group g = f.root().open_group("ground_truth").create_group("support");
      f.root().set_attribute("format_version", std::int64_t{4});
      edit(f, g);
    }
    expect_error(p, field);
  };
  const std::vector<double> tri = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  defect("old version", [&](h5::File& f, h5::Group& g) {
    f.root().set_attribute("format_version", std::int64_t{1});
    g.set_attribute("scene", std::string("seabed"));
    g.write("vertices", tri.data(), {3, 3});
    g.write("faces", std::vector<std::int32_t>{0, 1, 2}.data(), {1, 3});
  }, "/format_version");
  defect("index", [&](h5::File&, h5::Group& g) {
    g.set_attribute("scene", std::string("seabed"));
    g.write("vertices", tri.data(), {3, 3});
    g.write("faces", std::vector<std::int32_t>{0, 1, 2, 0, 3, 1}.data(), {2, 3});
  }, "/ground_truth/support/faces[1]");
  defect("nan", [&](h5::File&, h5::Group& g) {
    g.set_attribute("scene", std::string("seabed"));
    std::vector<double> v = tri;
    v[4] = std::nan("");
    g.write("vertices", v.data(), {3, 3});
    g.write("faces", std::vector<std::int32_t>{0, 1, 2}.data(), {1, 3});
  }, "/ground_truth/support/vertices[1]");
  defect("no scene", [&](h5::File&, h5::Group& g) {
    g.write("vertices", tri.data(), {3, 3});
    g.write("faces", std::vector<std::int32_t>{0, 1, 2}.data(), {1, 3});
  }, "/ground_truth/support/scene");
  defect("empty", [&](h5::File&, h5::Group& g) {
    g.set_attribute("scene", std::string("seabed"));
    g.create_extendible<double>("vertices", {3});   // [0, 3]: too few rows
    g.write("faces", std::vector<std::int32_t>{0, 1, 2}.data(), {1, 3});
  }, "/ground_truth/support/vertices");
}

TEST_CASE("grasps append without rewriting; same content gives the same bytes") {
  test::TempDir dir("log");
  const TactileLog log = sample_log(6, true);
  io::write_log(dir / "whole.h5", log);
  // Write 2 grasps, close, reopen twice and append the rest.
  {
    TactileLog first = log;
    first.grasps.resize(2);
    first.truth->arm_poses.resize(2);
    first.truth->joints.resize(2);
    io::write_log(dir / "grown.h5", first);
  }
  for (std::size_t from : {2, 4}) {
    io::LogWriter w = io::LogWriter::append_to(dir / "grown.h5");
    CHECK(w.grasps() == from);
    for (std::size_t k = from; k < from + 2; ++k)
      w.append(log.grasps[k], &log.truth->arm_poses[k], &log.truth->joints[k]);
    w.close();
  }
  check_equal(log, io::read_log(dir / "grown.h5"));
  // Identical content written twice: identical bytes.
  io::write_log(dir / "again.h5", log);
  CHECK(test::read_bytes(dir / "whole.h5") == test::read_bytes(dir / "again.h5"));
}

TEST_CASE("appending refuses bad grasps and writes nothing") {
  test::TempDir dir("log");
  const TactileLog log = sample_log(1, false);
  io::write_log(dir / "l.h5", log);
  io::LogWriter w = io::LogWriter::append_to(dir / "l.h5");
  GraspRecord bad = log.grasps[0];
  bad.tactile.pop_back();
  CHECK_THROWS_AS(w.append(bad), Error);
  bad = log.grasps[0];
  bad.arm_pose.translation().x() = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_AS(w.append(bad), Error);
  Pose truth = Pose::Identity();
  CHECK_THROWS_AS(w.append(log.grasps[0], &truth), Error);  // this log has no ground truth
  w.append(log.grasps[0]);
  w.close();
  CHECK(io::read_log(dir / "l.h5").grasps.size() == 2);
}

TEST_CASE("an atomic log that is not closed leaves no file") {
  test::TempDir dir("log");
  const TactileLog log = sample_log(2, false);
  {
    io::LogWriter w = io::LogWriter::create(dir / "x.h5", io::header_of(log));
    w.append(log.grasps[0]);
  }  // abandoned (as when the simulator throws)
  CHECK_FALSE(std::filesystem::exists(dir / "x.h5"));
  CHECK(std::distance(std::filesystem::directory_iterator(dir.path()), {}) == 0);
}

TEST_CASE("a log written by hand after FORMAT_LOG.md reads back") {
  test::TempDir dir("log");
  write_by_hand(dir / "robot.h5");
  const TactileLog log = io::read_log(dir / "robot.h5");
  CHECK(log.grasps.size() == 3);
  CHECK(log.object == "unknown");
  CHECK(log.noise == "real");
  CHECK_FALSE(log.truth.has_value());
  CHECK(log.grasps[1].arm_pose.translation().x() == 412346.0);
  CHECK(log.grasps[0].tactile[10] == 150.0f);
  CHECK(log.grasps[0].past_peak.empty());  // no past_peak dataset: fold side unknown
}

TEST_CASE("bad logs: one clear error naming the file and the field") {
  test::TempDir dir("log");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"no gripper", "gripper"},
      {"bad gripper", "/gripper/description"},
      {"bad pad", "/sensors/pad_index[0]"},
      {"no grasps", "grasps"},
      {"nan pose", "/grasps/arm_pose[1]"},
      {"bad quaternion", "/grasps/arm_pose[1]"},
      {"image size", "/grasps/tactile"},
      {"negative", "/grasps/tactile[0][0][20]"},
      {"over range", "/grasps/tactile[0][0][20]"},
      {"nan signal", "/grasps/tactile[0][0][20]"},
  };
  for (const auto& c : cases) {
    const std::string& defect = c.first;   // (not a structured binding: clang 14 cannot capture one in INFO)
    const std::string& field = c.second;
    INFO(defect);
    const auto p = dir / "bad.h5";
    write_by_hand(p, defect);
    expect_error(p, field);
  }
  // Not a tactile log at all.
  {
    io::h5::File f = io::h5::File::create(dir / "db.h5");
    f.root().set_attribute("format", "touchstone-db");
    f.close();
    expect_error(dir / "db.h5", "/format");
  }
  test::write_text(dir / "text.h5", "hello");
  CHECK_THROWS_AS(io::read_log(dir / "text.h5"), Error);
  CHECK_THROWS_AS(io::read_log(dir / "missing.h5"), Error);
}

namespace {
// A fingertip log (format_version 3) written by hand after FORMAT_LOG.md, as a recording's
// contact points would be converted. `defect` breaks one thing.
void write_fingertips_by_hand(const std::filesystem::path& path, const std::string& defect = {}) {
  namespace h5 = io::h5;
  const Gripper g;
  const std::uint64_t G = 2, F = defect == "finger count" ? 2 : 3, J = 6;
  h5::File f = h5::File::create(path);
  h5::Group root = f.root();
  root.set_attribute("format", "touchstone-tactile-log");
  root.set_attribute("format_version", std::int64_t{defect == "version 2" ? 2 : 3});
  root.set_attribute("sensing", "fingertips");
  root.create_group("gripper").write_strings("description", {io::gripper_to_json(g.spec())});
  if (defect != "no fingertips group")
    root.create_group("fingertips").set_attribute("normals", std::int64_t{0});
  h5::Group gr = root.create_group("grasps");
  gr.write("time", std::vector<double>{0.0, 30.0});
  std::vector<double> pose;
  for (std::uint64_t k = 0; k < G; ++k)
    for (double v : {1.0 + 0.01 * static_cast<double>(k), 2.0, -30.0, 1.0, 0.0, 0.0, 0.0}) pose.push_back(v);
  gr.write("arm_pose", pose.data(), {G, 7});
  std::vector<double> joints(G * J, 0.4);
  gr.write("joints", joints.data(), {G, J});
  std::vector<std::uint8_t> touched{1, 1, 0, 0, 1, 1};
  if (defect == "touched 2") touched[4] = 2;
  touched.resize(G * F);
  gr.write("fingertip_touched", touched.data(), {G, F});
  std::vector<double> points(G * F * 3, std::numeric_limits<double>::quiet_NaN());   // untouched: unread
  const double xyz[6][3] = {{1.05, 2.0, -29.9}, {1.03, 2.02, -29.9}, {0, 0, 0},
                            {0, 0, 0}, {1.06, 1.99, -29.91}, {1.04, 2.01, -29.92}};
  for (std::uint64_t i = 0; i < G * F; ++i)
    if (touched[i])
      for (int c = 0; c < 3; ++c) points[3 * i + c] = xyz[i][c];
  if (defect == "nan point") points[3 * 4 + 1] = std::numeric_limits<double>::quiet_NaN();
  gr.write("fingertip_point", points.data(), {G, F, 3});
  f.close();
}
}  // namespace

TEST_CASE("a fingertip log written by hand after FORMAT_LOG.md reads back; bad ones are named") {
  test::TempDir dir("log");
  write_fingertips_by_hand(dir / "hand.h5");
  const TactileLog log = io::read_log(dir / "hand.h5");
  REQUIRE(log.sensing == Sensing::fingertips);
  CHECK_FALSE(log.fingertip_normals);
  REQUIRE(log.grasps.size() == 2);
  const GraspContacts c0 = grasp_contacts(log, 0), c1 = grasp_contacts(log, 1);
  REQUIRE(c0.points.size() == 2);
  REQUIRE(c1.points.size() == 2);
  CHECK(c0.points[1] == Vec3(1.03, 2.02, -29.9));
  CHECK(c1.pad_slot == std::vector<int>{1, 2});   // the fingers that touched
  CHECK(c1.points[0] == Vec3(1.06, 1.99, -29.91));
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"finger count", "/grasps/fingertip_touched"},
      {"version 2", "/format_version"},
      {"no fingertips group", "fingertips"},
      {"touched 2", "/grasps/fingertip_touched[1][1]"},
      {"nan point", "/grasps/fingertip_point[1][1]"}};
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const auto& [defect, field] = cases[i];
    CAPTURE(defect);
    const auto path = dir / ("bad-" + std::to_string(i) + ".h5");
    write_fingertips_by_hand(path, defect);
    try {
      (void)io::read_log(path);
      FAIL("no error");
    } catch (const Error& e) {
      CHECK(e.file() == path.string());
      CHECK_MESSAGE(e.field().find(field) != std::string::npos, e.field());
    }
  }
}
