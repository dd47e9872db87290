// A tactile log played out as a ROS 2 recording (MCAP with CDR messages), for the tests of
// `log import` (datasets/ros2_import.hpp).
#pragma once

#include "engine/touch/fusion.hpp"
#include "io/mcap.hpp"
#include "io/ros2_messages.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

namespace ts::test {

namespace ros2 = ts::io::ros2;

inline std::vector<std::string> joint_names(const Gripper& G) {
  std::vector<std::string> names;
  for (int j = 0; j < G.joint_count(); ++j)
    names.push_back(G.spec().fingers[static_cast<std::size_t>(G.finger_of_joint(j))].name + "." + G.link(j).name);
  return names;
}

struct Ros2Recording {
  bool tf = false;              ///< the arm on /tf (with another transform beside it)
  double arm_lag_s = 0.004;     ///< the arm sample nearest each grasp lies this far before it
  bool reversed_joints = false; ///< JointState lists the joints in reverse order
  std::size_t drop_joint = 0;   ///< 1-based: leave this joint out of the JointState messages
};

/// The log's grasps as a recording: tactile images once per grasp (at 10 s + 60 s per grasp),
/// the arm at 50 Hz around each grasp (its true sample `arm_lag_s` before the images, the
/// others 20 ms apart, offset by 1 m so that a wrong match shows), the joints at 10 Hz.
inline void record_ros2(const TactileLog& log, const std::filesystem::path& path, const Ros2Recording& r = {}) {
  std::vector<io::McapSchema> schemas = {
      {1, r.tf ? "tf2_msgs/msg/TFMessage" : "geometry_msgs/msg/PoseStamped", "ros2msg", {}},
      {2, "sensor_msgs/msg/JointState", "ros2msg", {}},
      {3, "std_msgs/msg/Float32MultiArray", "ros2msg", {}},
      {4, "std_msgs/msg/String", "ros2msg", {}}};
  std::vector<io::McapChannel> channels = {{1, 1, r.tf ? "/tf" : "/arm/eef_pose", "cdr", {}},
                                           {2, 2, "/hand/joint_states", "cdr", {}},
                                           {3, 3, "/hand/tactile", "cdr", {}},
                                           {4, 4, "/chatter", "cdr", {}}};
  std::vector<io::McapOutMessage> out;
  auto at = [](double s) { return static_cast<std::uint64_t>(std::llround(s * 1e9)); };
  const auto names = joint_names(log.gripper);
  std::uint32_t seq = 0;
  for (std::size_t g = 0; g < log.grasps.size(); ++g) {
    const GraspRecord& rec = log.grasps[g];
    const double t = 10.0 + 60.0 * static_cast<double>(g);
    for (int k = -2; k <= 2; ++k) {   // the arm: the grasp's pose at t - lag, others moved by 1 m
      Pose T = rec.arm_pose;
      if (k != 0) T.translation() += Vec3(1.0, 0, 0);
      const double ts_ = t - r.arm_lag_s + 0.02 * k;
      std::vector<std::uint8_t> data;
      if (r.tf) {
        ros2::TransformStamped a{{0, 0}, "world", "eef", T}, b{{0, 0}, "world", "camera", Pose::Identity()};
        data = ros2::encode_tf_message({b, a});
      } else {
        data = ros2::encode_pose_stamped({{0, 0}, "world", T});
      }
      out.push_back({1, seq++, at(ts_), at(ts_), std::move(data)});
    }
    ros2::JointState js;
    js.name = names;
    js.position = rec.joints;
    if (r.reversed_joints) {
      std::reverse(js.name.begin(), js.name.end());
      std::reverse(js.position.begin(), js.position.end());
    }
    if (r.drop_joint) {
      js.name.erase(js.name.begin() + static_cast<std::ptrdiff_t>(r.drop_joint - 1));
      js.position.erase(js.position.begin() + static_cast<std::ptrdiff_t>(r.drop_joint - 1));
    }
    out.push_back({2, seq++, at(t - 0.03), at(t - 0.03), ros2::encode_joint_state(js)});
    out.push_back({4, seq++, at(t), at(t), {0, 1, 0, 0, 3, 0, 0, 0, 'h', 'i', 0}});
    ros2::Float32MultiArray a;
    a.dim = {{"pads", 1, static_cast<std::uint32_t>(rec.tactile.size())},
             {"sensels", static_cast<std::uint32_t>(rec.tactile.size()), static_cast<std::uint32_t>(rec.tactile.size())}};
    a.data = rec.tactile;
    out.push_back({3, seq++, at(t), at(t), ros2::encode_float32_multi_array(a)});
  }
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.log_time < b.log_time; });
  io::write_mcap(path, {"ros2", "touchstone test"}, schemas, channels, out);
}

}  // namespace ts::test
