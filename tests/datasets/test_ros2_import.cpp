// datasets/ros2_import.hpp: a simulated log played out as a ROS 2 recording (MCAP, CDR
// messages at their own rates) and imported back gives the same grasps; the map file's and the
// recording's mistakes give one error naming the file and the key or the message.
#include "datasets/ros2_import.hpp"
#include "datasets/simulator.hpp"
#include "engine/recognition_fixture.hpp"
#include "io/mcap.hpp"
#include "io/ros2_messages.hpp"
#include "ros2_recording.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <fstream>

using namespace ts;
namespace ros2 = ts::io::ros2;

namespace {

TactileLog simulated() {
  datasets::SimulatorSettings s;
  s.grasps = 6;
  s.noise = datasets::noise_profile("underwater");
  s.seed = 4;
  return datasets::Simulator(test::box_mesh(Vec3(0.12, 0.08, 0.05)), "box", Gripper(), s).run().log;
}

std::filesystem::path write_map(const test::TempDir& dir, const std::string& text) {
  const auto p = dir / "map.toml";
  std::ofstream(p) << text;
  return p;
}

const char* kMap = R"(object = "box"
max_skew_s = 0.05
[arm]
topic = "/arm/eef_pose"
[joints]
topic = "/hand/joint_states"
[tactile]
topic = "/hand/tactile"
)";

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("ROS 2 import: a log played out as a recording comes back grasp for grasp") {
  test::TempDir dir("ros2");
  const TactileLog log = simulated();
  REQUIRE(log.grasps.size() == 6);
  TactileLog unhinted = log;
  for (GraspRecord& g : unhinted.grasps) g.past_peak.clear();
  std::fill(unhinted.gains.begin(), unhinted.gains.end(), 1.0f);   // nor a per-sensel calibration
  for (const bool tf : {false, true}) {
    INFO("arm on " << (tf ? "/tf" : "PoseStamped"));
    test::Ros2Recording r;
    r.tf = tf;
    r.reversed_joints = tf;   // the joints matched by name, whatever their order
    test::record_ros2(log, dir / "rec.mcap", r);
    std::string map = kMap;
    if (tf) map.replace(map.find("topic = \"/arm/eef_pose\""), 23, "topic = \"/tf\"\nparent = \"world\"\nchild = \"eef\"");
    const datasets::Ros2Map m = datasets::read_ros2_map(write_map(dir, map));
    datasets::Ros2ImportReport rep;
    const TactileLog back = datasets::import_ros2(dir / "rec.mcap", m, "map.toml", &rep);
    CHECK(back.object == "box");
    CHECK(back.pads == log.pads);
    REQUIRE(back.grasps.size() == log.grasps.size());
    CHECK(rep.grasps == 6);
    CHECK(rep.arm_messages == 30);
    CHECK(std::abs(rep.largest_skew_s - 0.03) < 1e-9);   // the joints' 30 ms
    for (std::size_t g = 0; g < log.grasps.size(); ++g) {
      CHECK((back.grasps[g].arm_pose.matrix() - log.grasps[g].arm_pose.matrix()).cwiseAbs().maxCoeff() < 1e-12);
      CHECK(back.grasps[g].joints == log.grasps[g].joints);
      CHECK(back.grasps[g].tactile == log.grasps[g].tactile);
      CHECK(std::abs(back.grasps[g].time - (10.0 + 60.0 * static_cast<double>(g))) < 1e-6);
      // The contacts the recognizer sees are the simulated log's (without the simulator's fold
      // hints and calibration gains, which no recording carries).
      const auto a = grasp_contacts(unhinted, g), b = grasp_contacts(back, g);
      REQUIRE(a.points.size() == b.points.size());
      for (std::size_t i = 0; i < a.points.size(); ++i) CHECK((a.points[i] - b.points[i]).norm() < 1e-12);
    }
  }
}

TEST_CASE("ROS 2 import: the map's and the recording's mistakes name the file and the key or message") {
  test::TempDir dir("ros2bad");
  const TactileLog log = simulated();
  test::record_ros2(log, dir / "rec.mcap", {});
  const auto rec = dir / "rec.mcap";
  auto import = [&](const std::string& map) {
    return datasets::import_ros2(rec, datasets::read_ros2_map(write_map(dir, map)), "map.toml");
  };
  // The map file.
  CHECK(error_of([&] { import("[arm]\ntopic = \"/arm/eef_pose\"\n[tactile]\ntopic = \"/hand/tactile\"\n"); })
            .find("joints.topic") != std::string::npos);
  CHECK(error_of([&] { import(std::string(kMap) + "colour = \"red\"\n"); }).find("unknown key") != std::string::npos);
  CHECK(error_of([&] { import("pads = [\"no.such\"]\n" + std::string(kMap)); }).find("no pad 'no.such'") != std::string::npos);
  CHECK(error_of([&] { import(std::string("max_skew_s = -1\n") + (kMap + 33)); }).find("max_skew_s") != std::string::npos);
  // Topics: absent, or carrying another type.
  std::string absent = kMap;
  absent.replace(absent.find("/hand/tactile"), 13, "/hand/touch");
  CHECK(error_of([&] { import(absent); }).find("no topic /hand/touch") != std::string::npos);
  std::string wrong = kMap;
  wrong.replace(wrong.find("/hand/tactile"), 13, "/chatter");
  CHECK(error_of([&] { import(wrong); }).find("carries std_msgs/msg/String") != std::string::npos);
  // The arm samples 160-240 ms from the images: beyond max_skew_s, named by grasp.
  test::Ros2Recording late;
  late.arm_lag_s = 0.2;
  test::record_ros2(log, rec, late);
  const std::string skew = error_of([&] { import(kMap); });
  CHECK(skew.find("grasp 1") != std::string::npos);
  CHECK(skew.find("/arm/eef_pose") != std::string::npos);
  CHECK(skew.find("rec.mcap") != std::string::npos);
  // A joint missing from the JointState messages.
  test::Ros2Recording missing;
  missing.drop_joint = 2;
  test::record_ros2(log, rec, missing);
  CHECK(error_of([&] { import(kMap); }).find("no joint") != std::string::npos);
}

TEST_CASE("ROS 2 import: the sample map file reads") {
  const auto m = datasets::read_ros2_map(TS_SOURCE_DIR "/datasets/ros2/map.toml");
  CHECK(m.arm_topic == "/arm/eef_pose");
  CHECK(m.arm_parent.empty());
  CHECK(m.joints_topic == "/hand/joint_states");
  CHECK(m.tactile_topic == "/hand/tactile");
  CHECK(m.pads == std::vector<std::string>{"middle.distal"});
  CHECK(m.max_skew_s == 0.05);
  CHECK(m.gripper.empty());
}
