// The ROS 2 messages a tactile recording carries, decoded from their CDR serialization (the
// "cdr" message encoding of rosbag2's MCAP files: a 4-byte encapsulation header, little- or
// big-endian, every primitive aligned to its size from the end of that header, strings with
// their terminating NUL counted, sequences prefixed by a uint32 count).
//
//   geometry_msgs/msg/PoseStamped     the arm's end-effector pose (T_world_eef)
//   tf2_msgs/msg/TFMessage            the same from /tf (a parent -> child transform)
//   sensor_msgs/msg/JointState        the finger joints
//   std_msgs/msg/Float32MultiArray    the tactile images (pads x sensels)
//
// Every count is checked against the bytes left before anything is allocated; a malformed
// message is one ts::Error naming `file` and `what` (e.g. "message 12 on /tf") and the field.
#pragma once

#include "engine/core.hpp"

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace ts::io::ros2 {

struct Stamp {
  std::int32_t sec = 0;
  std::uint32_t nanosec = 0;
  double seconds() const { return static_cast<double>(sec) + 1e-9 * static_cast<double>(nanosec); }
};

struct PoseStamped {
  Stamp stamp;
  std::string frame_id;
  Pose pose = Pose::Identity();   ///< the quaternion normalized (refused when far from unit)
};

struct TransformStamped {
  Stamp stamp;
  std::string frame_id;           ///< parent
  std::string child_frame_id;
  Pose transform = Pose::Identity();  ///< T_parent_child
};

struct JointState {
  Stamp stamp;
  std::vector<std::string> name;
  std::vector<double> position, velocity, effort;
};

struct MultiArrayDimension {
  std::string label;
  std::uint32_t size = 0, stride = 0;
};

struct Float32MultiArray {
  std::vector<MultiArrayDimension> dim;
  std::uint32_t data_offset = 0;
  std::vector<float> data;
};

/// The decoders; `file` and `what` name the message in errors.
PoseStamped decode_pose_stamped(std::span<const std::uint8_t> cdr, const std::string& file, const std::string& what);
std::vector<TransformStamped> decode_tf_message(std::span<const std::uint8_t> cdr, const std::string& file,
                                                const std::string& what);
JointState decode_joint_state(std::span<const std::uint8_t> cdr, const std::string& file, const std::string& what);
Float32MultiArray decode_float32_multi_array(std::span<const std::uint8_t> cdr, const std::string& file,
                                             const std::string& what);

/// A CDR writer for the same messages (tests and tools that make recordings): little-endian.
std::vector<std::uint8_t> encode_pose_stamped(const PoseStamped& m);
std::vector<std::uint8_t> encode_tf_message(const std::vector<TransformStamped>& m);
std::vector<std::uint8_t> encode_joint_state(const JointState& m);
std::vector<std::uint8_t> encode_float32_multi_array(const Float32MultiArray& m);

}  // namespace ts::io::ros2
