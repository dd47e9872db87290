// Gripper description and forward kinematics (Eq. 2): P^W = T_EEF(Θarm) T_sensor(Θfinger) P^L.
//
// Frames. EEF (end effector): origin at the centre of the palm's front face, z the approach
// direction (out of the palm, toward the object). Each finger has a base frame F fixed to the
// palm (T_eef_base). A finger is a serial chain of links; link k turns about its joint axis
// (unit, in its parent frame: F for the first link, the previous link's frame otherwise) located
// at `joint_origin` in the parent frame:
//     T_parent_link(θ) = Trans(joint_origin) · Rot(joint_axis, θ)
// A link is a box in its own frame: x ∈ [-thickness/2, thickness/2], y ∈ [-width/2, width/2],
// z ∈ [0, length]. Its pad (tactile array, see engine/touch/tactile.hpp) is mounted by the fixed
// transform T_link_pad; the pad's z axis points out of the link toward the object. So
//     T_eef_pad(Θfinger) = T_eef_base · Π_k T_parent_link_k(θ_k) · T_link_pad   (T_sensor of Eq. 2)
//
// Joint angles are radians in memory (degrees only in the JSON file, see io/gripper_io.hpp).
// Joints are numbered finger-major: joint (f, k) is index joint_index(f, k); pads likewise.
//
// Closing model (shared by the simulator and the free-space sweep): from the `open` angles,
// every finger first turns its first joint to its final angle while the later joints stay
// open, then its second joint, and so on ("proximal first"). The swept volume of a grasp is
// the union of link boxes along that path.
#pragma once

#include "engine/core.hpp"
#include "engine/touch/tactile.hpp"

#include <string>
#include <vector>

namespace ts {
inline namespace touch {

struct LinkSpec {
  std::string name;
  double length = 0.07;                 ///< m, along link z
  double width = 0.035;                 ///< m, along link y
  double thickness = 0.02;              ///< m, along link x
  Vec3 joint_origin = Vec3::Zero();     ///< m, joint position in the parent frame
  Vec3 joint_axis = Vec3(0, -1, 0);     ///< unit axis in the parent frame; +θ closes
  double open = 0.0;                    ///< rad, angle of the open hand
  double min = -0.5;                    ///< rad, joint limit
  double max = 1.7;                     ///< rad, joint limit
  bool has_pad = true;                  ///< a tactile pad is mounted on this link
  Pose T_link_pad = Pose::Identity();   ///< pad frame in the link frame
};

struct FingerSpec {
  std::string name;
  Pose T_eef_base = Pose::Identity();   ///< finger base in the EEF frame
  std::vector<LinkSpec> links;
};

/// Palm: a disc of `radius` behind the EEF origin, z ∈ [-thickness, 0].
struct PalmSpec {
  double radius = 0.06;      ///< m
  double thickness = 0.03;   ///< m
};

struct GripperSpec {
  std::string name = "touchstone-3f";
  PalmSpec palm;
  std::vector<FingerSpec> fingers;
  SensorSettings sensor;
  std::string single_pad = "middle.distal";  ///< the pad logged by `--sensors 1` ("finger.link")
};

/// A pad's identity: finger and link indices and its name "finger.link".
struct PadRef {
  int finger = 0;
  int link = 0;
  int joint = 0;        ///< joint index of its link
  std::string name;
};

/// Validated gripper with index tables. Immutable; thread-safe.
class Gripper {
 public:
  Gripper();  ///< the default gripper (default_gripper_spec())
  /// Validates (throws ts::Error naming `file` and the field on a bad description).
  explicit Gripper(GripperSpec spec, const std::string& file = {});

  const GripperSpec& spec() const { return spec_; }
  const SensorSettings& sensor() const { return spec_.sensor; }
  int finger_count() const { return static_cast<int>(spec_.fingers.size()); }
  int joint_count() const { return static_cast<int>(joint_of_.size()); }
  int joint_index(int finger, int link) const;
  const LinkSpec& link(int joint) const;
  int finger_of_joint(int joint) const { return joint_of_[joint].first; }
  int link_of_joint(int joint) const { return joint_of_[joint].second; }

  const std::vector<PadRef>& pads() const { return pads_; }
  int pad_index(const std::string& name) const;   ///< -1 when absent
  int single_pad() const;                          ///< index of spec().single_pad

  std::vector<double> open_angles() const;
  /// Link frames in the EEF frame for all joints (size joint_count()).
  std::vector<Pose> link_poses(const std::vector<double>& joints) const;
  /// T_sensor of Eq. 2 for pad `pad` (index into pads()).
  Pose pad_pose(const std::vector<double>& joints, int pad) const;
  /// Link frames of one finger in the EEF frame, for that finger's joint angles only.
  void finger_link_poses(int finger, const double* finger_joints, Pose* out) const;

  /// Joint-space waypoints of the closing path from open to `joints` (proximal first), in
  /// order: open, after the first joints, ..., final. Consecutive waypoints differ in one joint
  /// per finger.
  std::vector<std::vector<double>> closing_waypoints(const std::vector<double>& joints) const;

  /// Largest distance of any point of the hand (palm, links, foam) from the EEF origin over the
  /// joint range: a bound for broad-phase tests.
  double reach() const { return reach_; }
  /// Largest distance of any point of the links moved by `joint` (its link and the ones after
  /// it) from that joint's axis origin: a point moves at most lever * |dθ|.
  double lever(int joint) const { return lever_[joint]; }

 private:
  GripperSpec spec_;
  std::vector<std::pair<int, int>> joint_of_;
  std::vector<int> first_joint_;
  std::vector<PadRef> pads_;
  double reach_ = 0.0;
  std::vector<double> lever_;
};

/// The compiled-in default: a three-finger gripper like the paper's SeeGrip (three fingers at
/// 120°, two links per finger, a 6 x 3 cm pad of 12 x 6 sensels on each link's inner face).
/// datasets/grippers/touchstone-3f.json holds the same description (a test keeps them equal).
GripperSpec default_gripper_spec();

/// A frame (rotation only) whose z axis is the unit vector `z`, its x axis turned by `roll` rad
/// about z from a fixed perpendicular of z: how an aimed pad is oriented (the simulator's
/// operator, the next-grasp planner).
Pose rolled_frame(const Vec3& z, double roll);

/// Rotation of `angle` rad about unit `axis` (joint rotations).
Pose joint_rotation(const Vec3& axis, double angle);

}  // namespace touch
}  // namespace ts
