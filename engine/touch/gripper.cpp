#include "engine/touch/gripper.hpp"
#include "engine/detail.hpp"

#include <cmath>
#include <numbers>

namespace ts {
inline namespace touch {

namespace {
using detail::require;
using detail::kRadPerDeg;


bool finite_pose(const Pose& T) { return T.matrix().allFinite(); }

bool rigid(const Pose& T) {
  const Mat3 R = T.linear();
  return (R.transpose() * R - Mat3::Identity()).norm() < 1e-6 && R.determinant() > 0.0;
}

Pose rpy(double roll, double pitch, double yaw, const Vec3& t) {
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(yaw, Vec3::UnitZ()) * Eigen::AngleAxisd(pitch, Vec3::UnitY()) *
                Eigen::AngleAxisd(roll, Vec3::UnitX()))
                   .toRotationMatrix();
  T.translation() = t;
  return T;
}
}  // namespace

Pose joint_rotation(const Vec3& axis, double angle) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
  return T;
}

GripperSpec default_gripper_spec() {
  GripperSpec g;
  g.name = "touchstone-3f";
  g.palm = {0.06, 0.03};
  g.single_pad = "middle.distal";
  const char* names[3] = {"middle", "left", "right"};
  for (int f = 0; f < 3; ++f) {
    FingerSpec finger;
    finger.name = names[f];
    const double azimuth = f * 120.0 * kRadPerDeg;
    finger.T_eef_base = rpy(0, 0, azimuth, Vec3(0.05 * std::cos(azimuth), 0.05 * std::sin(azimuth), 0));
    LinkSpec proximal;
    proximal.name = "proximal";
    proximal.length = 0.075;
    proximal.joint_origin = Vec3::Zero();
    proximal.open = -40.0 * kRadPerDeg;
    proximal.min = -45.0 * kRadPerDeg;
    proximal.max = 100.0 * kRadPerDeg;
    LinkSpec distal;
    distal.name = "distal";
    distal.length = 0.064;  // the 60 mm pad covers it nearly to the tip
    distal.joint_origin = Vec3(0, 0, proximal.length);
    distal.open = 0.0;
    distal.min = -10.0 * kRadPerDeg;
    distal.max = 100.0 * kRadPerDeg;
    for (LinkSpec* l : {&proximal, &distal}) {
      l->width = 0.035;
      l->thickness = 0.02;
      l->joint_axis = Vec3(0, -1, 0);
      l->has_pad = true;
      // Pad on the inner face (link -x), centred along the link: pad x = link z, pad z = -link x.
      l->T_link_pad = rpy(0, -90.0 * kRadPerDeg, 0, Vec3(-0.5 * l->thickness, 0, 0.5 * l->length));
    }
    finger.links = {proximal, distal};
    g.fingers.push_back(finger);
  }
  return g;
}

Gripper::Gripper() : Gripper(default_gripper_spec()) {}

Gripper::Gripper(GripperSpec spec, const std::string& file) : spec_(std::move(spec)) {
  validate(spec_.sensor, file);
  require(spec_.palm.radius >= 0 && spec_.palm.thickness >= 0 && std::isfinite(spec_.palm.radius) &&
              std::isfinite(spec_.palm.thickness),
          "palm size must be non-negative", file, "palm");
  require(!spec_.fingers.empty(), "a gripper needs at least one finger", file, "fingers");
  reach_ = std::hypot(spec_.palm.radius, spec_.palm.thickness);
  for (int f = 0; f < finger_count(); ++f) {
    const FingerSpec& finger = spec_.fingers[f];
    const std::string where = "fingers[" + std::to_string(f) + "]";
    require(!finger.name.empty() && finger.name.find('.') == std::string::npos,
            "finger needs a name without '.'", file, where + ".name");
    for (int g = 0; g < f; ++g)
      require(spec_.fingers[g].name != finger.name, "duplicate finger name '" + finger.name + "'",
              file, where + ".name");
    require(finite_pose(finger.T_eef_base) && rigid(finger.T_eef_base),
            "finger base must be a finite rigid transform", file, where + ".base");
    require(!finger.links.empty(), "a finger needs at least one link", file, where + ".links");
    first_joint_.push_back(static_cast<int>(joint_of_.size()));
    std::vector<double> radius;
    double chain = finger.T_eef_base.translation().norm();
    for (int k = 0; k < static_cast<int>(finger.links.size()); ++k) {
      const LinkSpec& l = finger.links[k];
      const std::string lw = where + ".links[" + std::to_string(k) + "]";
      require(!l.name.empty() && l.name.find('.') == std::string::npos,
              "link needs a name without '.'", file, lw + ".name");
      require(l.length > 0 && l.width > 0 && l.thickness > 0 && std::isfinite(l.length) &&
                  std::isfinite(l.width) && std::isfinite(l.thickness),
              "link dimensions must be positive", file, lw);
      require(l.joint_origin.allFinite(), "joint origin must be finite", file, lw + ".joint.origin_m");
      require(l.joint_axis.allFinite() && std::abs(l.joint_axis.norm() - 1.0) < 1e-6,
              "joint axis must be a unit vector", file, lw + ".joint.axis");
      require(std::isfinite(l.min) && std::isfinite(l.max) && l.min <= l.open && l.open <= l.max,
              "joint limits must satisfy min <= open <= max", file, lw + ".joint");
      require(finite_pose(l.T_link_pad) && rigid(l.T_link_pad),
              "pad mount must be a finite rigid transform", file, lw + ".pad");
      const int joint = static_cast<int>(joint_of_.size());
      joint_of_.emplace_back(f, k);
      if (l.has_pad) pads_.push_back({f, k, joint, finger.name + "." + l.name});
      chain += l.joint_origin.norm();
      const double fat = 0.5 * l.thickness + spec_.sensor.foam_thickness;
      const double pad_r = l.T_link_pad.translation().norm() +
                           std::hypot(0.5 * spec_.sensor.size_x, 0.5 * spec_.sensor.size_y,
                                      spec_.sensor.foam_thickness);
      const double link_r = std::max(std::hypot(fat, 0.5 * l.width, l.length), pad_r);
      reach_ = std::max(reach_, chain + link_r);
      radius.push_back(link_r);
    }
    // lever of joint k: offsets of the later joints plus the largest link radius from k on
    const int n = static_cast<int>(finger.links.size());
    for (int k = 0; k < n; ++k) {
      double lever = 0.0, r = 0.0;
      for (int m = k; m < n; ++m) {
        if (m > k) lever += finger.links[m].joint_origin.norm();
        r = std::max(r, radius[m]);
      }
      lever_.push_back(lever + r);
    }
  }
  require(single_pad() >= 0, "single_pad '" + spec_.single_pad + "' names no pad", file,
          "single_pad");
}

int Gripper::joint_index(int finger, int link) const { return first_joint_[finger] + link; }

const LinkSpec& Gripper::link(int joint) const {
  return spec_.fingers[joint_of_[joint].first].links[joint_of_[joint].second];
}

int Gripper::pad_index(const std::string& name) const {
  for (std::size_t i = 0; i < pads_.size(); ++i)
    if (pads_[i].name == name) return static_cast<int>(i);
  return -1;
}

int Gripper::single_pad() const { return pad_index(spec_.single_pad); }

std::vector<double> Gripper::open_angles() const {
  std::vector<double> q(joint_of_.size());
  for (std::size_t j = 0; j < q.size(); ++j) q[j] = link(static_cast<int>(j)).open;
  return q;
}

void Gripper::finger_link_poses(int finger, const double* finger_joints, Pose* out) const {
  const FingerSpec& f = spec_.fingers[finger];
  Pose T = f.T_eef_base;
  for (std::size_t k = 0; k < f.links.size(); ++k) {
    const LinkSpec& l = f.links[k];
    Pose step = joint_rotation(l.joint_axis, finger_joints[k]);
    step.translation() = l.joint_origin;
    T = T * step;
    out[k] = T;
  }
}

std::vector<Pose> Gripper::link_poses(const std::vector<double>& joints) const {
  if (static_cast<int>(joints.size()) != joint_count())
    throw Error("expected " + std::to_string(joint_count()) + " joint angles, got " +
                    std::to_string(joints.size()),
                {}, "joints");
  std::vector<Pose> out(joints.size());
  for (int f = 0; f < finger_count(); ++f)
    finger_link_poses(f, joints.data() + first_joint_[f], out.data() + first_joint_[f]);
  return out;
}

Pose Gripper::pad_pose(const std::vector<double>& joints, int pad) const {
  const PadRef& p = pads_.at(pad);
  const auto& f = spec_.fingers[p.finger];
  std::vector<Pose> links(f.links.size());
  if (static_cast<int>(joints.size()) != joint_count())
    throw Error("expected " + std::to_string(joint_count()) + " joint angles", {}, "joints");
  finger_link_poses(p.finger, joints.data() + first_joint_[p.finger], links.data());
  return links[p.link] * f.links[p.link].T_link_pad;
}

std::vector<std::vector<double>> Gripper::closing_waypoints(const std::vector<double>& joints) const {
  std::vector<std::vector<double>> out;
  std::vector<double> q = open_angles();
  out.push_back(q);
  std::size_t max_links = 0;
  for (const auto& f : spec_.fingers) max_links = std::max(max_links, f.links.size());
  for (std::size_t k = 0; k < max_links; ++k) {
    for (int f = 0; f < finger_count(); ++f)
      if (k < spec_.fingers[f].links.size()) {
        const int j = first_joint_[f] + static_cast<int>(k);
        q[j] = joints[j];
      }
    out.push_back(q);
  }
  return out;
}

Pose rolled_frame(const Vec3& z, double roll) {
  const Vec3 helper = std::abs(z.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  const Vec3 f1 = z.cross(helper).normalized(), f2 = z.cross(f1);
  const Vec3 x = std::cos(roll) * f1 + std::sin(roll) * f2;
  Pose T = Pose::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = z.cross(x);
  T.linear().col(2) = z;
  return T;
}

}  // namespace touch
}  // namespace ts
