// A ROS 2 recording (MCAP) made into a tactile log (`touchstone log import REC.mcap --map MAP.toml
// --out LOG.h5`). The map file says which topics hold what:
//
//   object = "valve_0006"        # the explored object, when known ("" : unknown)
//   gripper = "hand.json"        # gripper description (default: the built-in touchstone-3f);
//                                # relative to the map file
//   pads = ["middle.distal"]     # logged pads, in the tactile array's order (default: the
//                                # gripper's single pad)
//   max_skew_s = 0.05            # a grasp's arm pose and joints lie within this of its images
//
//   [arm]
//   topic = "/arm/eef_pose"      # geometry_msgs/msg/PoseStamped: T_world_eef, or
//                                # tf2_msgs/msg/TFMessage with:
//   parent = "world"             #   the transform parent -> child that is T_world_eef
//   child = "eef"
//
//   [joints]
//   topic = "/hand/joint_states" # sensor_msgs/msg/JointState
//   names = ["thumb.proximal", ...]  # the gripper's joints in its order (default: the gripper's
//                                    # "<finger>.<link>" names)
//   unit = "rad"                 # or "deg"
//
//   [tactile]
//   topic = "/hand/tactile"      # std_msgs/msg/Float32MultiArray: pads x sensels signals; each
//                                # message is one grasp
//
// Each tactile message becomes a grasp at its log time, with the arm pose and the joints whose
// log times are nearest to it (an error when the nearest is farther than max_skew_s). Gains
// are 1 (the calibration is not in the recording).
#pragma once

#include "engine/touch/fusion.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace ts::datasets {

struct Ros2Map {
  std::string object;
  std::filesystem::path gripper;          ///< empty: the built-in gripper
  std::vector<std::string> pads;          ///< pad names; empty: the gripper's single pad
  double max_skew_s = 0.05;
  std::string arm_topic, arm_parent, arm_child;
  std::string joints_topic;
  std::vector<std::string> joint_names;   ///< empty: the gripper's "<finger>.<link>"
  bool joints_in_degrees = false;
  std::string tactile_topic;
};

/// Read a map file (TOML). Throws ts::Error naming the file and the key.
Ros2Map read_ros2_map(const std::filesystem::path& file);

struct Ros2ImportReport {
  std::size_t grasps = 0;
  std::size_t arm_messages = 0, joint_messages = 0;
  double largest_skew_s = 0.0;            ///< over the grasps, arm and joints
};

/// The tactile log of a recording under `map` (`map_file` names the map in errors). Throws
/// ts::Error naming the recording and the message, or the map file and the key.
TactileLog import_ros2(const std::filesystem::path& recording, const Ros2Map& map, const std::string& map_file,
                       Ros2ImportReport* report = nullptr);

}  // namespace ts::datasets
