#include "engine/touch/fusion.hpp"
#include "engine/detail.hpp"

#include "engine/geometry/cloud.hpp"

#include <cmath>
#include <set>

namespace ts {
inline namespace touch {

namespace {
using detail::require;

bool rigid_pose(const Pose& T) {
  if (!T.matrix().allFinite()) return false;
  const Mat3 R = T.linear();
  return (R.transpose() * R - Mat3::Identity()).norm() < 1e-5 && R.determinant() > 0.0 &&
         T.matrix().row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1));
}
}  // namespace

const char* to_string(Sensing s) {
  switch (s) {
    case Sensing::probe: return "probe";
    case Sensing::fingertips: return "fingertips";
    case Sensing::pads: break;
  }
  return "pads";
}

Sensing parse_sensing(const std::string& word, const std::string& file, const std::string& field) {
  if (word == "pads") return Sensing::pads;
  if (word == "probe") return Sensing::probe;
  if (word == "fingertips") return Sensing::fingertips;
  throw Error("unknown sensing '" + word + "' (pads, probe, fingertips)", file, field);
}

void validate_grasp(const TactileLog& log, const GraspRecord& r, std::size_t k, const std::string& file) {
  const Gripper& g = log.gripper;
  const std::size_t n = log.sensels();
  const double full_scale = g.sensor().signal_full_scale;
  const std::size_t image = log.pads.size() * n;
  std::string at = "[";
  at += std::to_string(k);
  at += ']';
  require(std::isfinite(r.time), "timestamp is not finite", file, "/grasps/time" + at);
  require(rigid_pose(r.arm_pose), "arm pose is not a finite rigid transform", file, "/grasps/arm_pose" + at);
  if (log.sensing == Sensing::probe) {
    require(std::isfinite(r.probe_travel) && r.probe_travel >= 0.0,
            "probe travel must be finite and >= 0", file, "/grasps/probe_travel" + at);
    require(r.joints.empty() && r.tactile.empty() && r.past_peak.empty(),
            "a probe touch has no joint angles or tactile images", file, "/grasps" + at);
    return;
  }
  require(r.joints.size() == static_cast<std::size_t>(g.joint_count()),
          "expected " + std::to_string(g.joint_count()) + " joint angles, got " +
              std::to_string(r.joints.size()),
          file, "/grasps/joints" + at);
  for (double q : r.joints) require(std::isfinite(q), "joint angle is not finite", file, "/grasps/joints" + at);
  if (log.sensing == Sensing::fingertips) {
    const auto F = static_cast<std::size_t>(g.finger_count());
    require(r.tactile.empty() && r.past_peak.empty(), "a fingertip grasp has no tactile images", file,
            "/grasps/tactile" + at);
    require(r.fingertip_touched.size() == F,
            "expected one entry per finger of the gripper (" + std::to_string(F) + "), got " +
                std::to_string(r.fingertip_touched.size()),
            file, "/grasps/fingertip_touched" + at);
    require(r.fingertip_points.size() == F,
            "expected one point per finger of the gripper (" + std::to_string(F) + "), got " +
                std::to_string(r.fingertip_points.size()),
            file, "/grasps/fingertip_point" + at);
    require(r.fingertip_normals.size() == (log.fingertip_normals ? F : 0),
            log.fingertip_normals ? "expected one normal per finger of the gripper (" + std::to_string(F) + ")"
                                  : std::string("this log records no fingertip normals"),
            file, "/grasps/fingertip_normal" + at);
    for (std::size_t f = 0; f < F; ++f) {
      const std::string where = at + "[" + std::to_string(f) + "]";
      require(r.fingertip_touched[f] <= 1, "fingertip_touched must be 0 or 1", file, "/grasps/fingertip_touched" + where);
      if (!r.fingertip_touched[f]) continue;
      require(r.fingertip_points[f].allFinite(), "fingertip point is not finite", file, "/grasps/fingertip_point" + where);
      if (log.fingertip_normals)
        require(r.fingertip_normals[f].allFinite() && std::abs(r.fingertip_normals[f].norm() - 1.0) < 1e-3,
                "fingertip normal is not a unit vector", file, "/grasps/fingertip_normal" + where);
    }
    return;
  }
  require(r.fingertip_touched.empty() && r.fingertip_points.empty() && r.fingertip_normals.empty(),
          "only a fingertip log records fingertip contacts", file, "/grasps/fingertip_point" + at);
  require(r.tactile.size() == image,
          "tactile image size " + std::to_string(r.tactile.size()) + " does not match " +
              std::to_string(log.pads.size()) + " pads x " + std::to_string(n) + " sensels",
          file, "/grasps/tactile" + at);
  for (std::size_t i = 0; i < r.tactile.size(); ++i) {
    const float e = r.tactile[i];
    if (std::isfinite(e) && e >= 0.0f && e <= full_scale) continue;
    const std::string where = "/grasps/tactile" + at + "[" + std::to_string(i / n) + "][" + std::to_string(i % n) + "]";
    require(std::isfinite(e), "tactile signal is not finite", file, where);
    require(e >= 0.0f, "tactile signal " + std::to_string(e) + " is negative", file, where);
    require(false, "tactile signal " + std::to_string(e) + " exceeds the full scale " + std::to_string(full_scale),
            file, where);
  }
  require(r.past_peak.empty() || r.past_peak.size() == image,
          "past-peak flags do not match the tactile image size", file, "/grasps/past_peak" + at);
  for (auto h : r.past_peak)
    require(h <= 2, "past-peak flag must be 0, 1 or 2", file, "/grasps/past_peak" + at);
}

void validate(const TactileLog& log, const std::string& file) {
  const Gripper& g = log.gripper;
  const std::size_t n = log.sensels();
  if (log.sensing == Sensing::probe) {
    const ProbeSpec& p = log.probe;
    require(std::isfinite(p.ball_radius) && p.ball_radius >= 0.0 && p.ball_radius < 0.1,
            "probe ball radius must be in [0, 0.1) m", file, "/probe/ball_radius");
    require(std::isfinite(p.shaft_radius) && p.shaft_radius >= 0.0 && p.shaft_radius <= p.ball_radius,
            "probe shaft radius must be in [0, ball_radius] m", file, "/probe/shaft_radius");
    require(log.pads.empty() && log.gains.empty(), "a probe log records no tactile pad", file,
            "/sensors");
  } else if (log.sensing == Sensing::fingertips) {
    require(log.pads.empty() && log.gains.empty(), "a fingertip log records no tactile pad", file, "/sensors");
    require(log.gripper.finger_count() > 0, "a fingertip log needs a gripper with fingers", file,
            "/gripper/description");
  } else {
    require(!log.pads.empty(), "log records no tactile pad", file, "/sensors/pad_index");
  }
  std::set<int> seen;
  for (std::size_t i = 0; i < log.pads.size(); ++i) {
    const int p = log.pads[i];
    require(p >= 0 && p < static_cast<int>(g.pads().size()),
            "pad index " + std::to_string(p) + " is not a pad of the gripper", file,
            "/sensors/pad_index[" + std::to_string(i) + "]");
    require(seen.insert(p).second, "pad index " + std::to_string(p) + " listed twice", file,
            "/sensors/pad_index[" + std::to_string(i) + "]");
  }
  require(log.gains.size() == log.pads.size() * n,
          "calibration gains: expected " + std::to_string(log.pads.size() * n) + " values, got " +
              std::to_string(log.gains.size()),
          file, "/sensors/gain");
  for (std::size_t i = 0; i < log.gains.size(); ++i)
    require(std::isfinite(log.gains[i]) && log.gains[i] > 0.0f,
            "calibration gain must be positive and finite", file,
            "/sensors/gain[" + std::to_string(i / n) + "][" + std::to_string(i % n) + "]");
  for (std::size_t k = 0; k < log.grasps.size(); ++k) validate_grasp(log, log.grasps[k], k, file);
  if (log.truth) {
    require(log.truth->arm_poses.size() == log.grasps.size(),
            "ground truth has " + std::to_string(log.truth->arm_poses.size()) + " arm poses for " +
                std::to_string(log.grasps.size()) + " grasps",
            file, "/ground_truth/arm_pose");
    require(log.truth->joints.empty() || log.truth->joints.size() == log.grasps.size(),
            "ground truth joint rows do not match the grasps", file, "/ground_truth/joints");
    require(rigid_pose(log.truth->object_pose), "ground-truth object pose is not a finite rigid transform",
            file, "/ground_truth/object_pose");
    for (std::size_t k = 0; k < log.truth->arm_poses.size(); ++k)
      require(rigid_pose(log.truth->arm_poses[k]), "ground-truth arm pose is not a finite rigid transform",
              file, "/ground_truth/arm_pose[" + std::to_string(k) + "]");
  }
}

GraspContacts grasp_contacts(const TactileLog& log, std::size_t g, const ContactSettings& s) {
  GraspContacts out;
  const GraspRecord& r = log.grasps.at(g);
  if (log.sensing == Sensing::probe) {
    if (r.probe_touched) {
      out.points.push_back(r.arm_pose * Vec3(0.0, 0.0, log.probe.ball_radius));
      out.pad_slot.push_back(0);
    }
    return out;
  }
  if (log.sensing == Sensing::fingertips) {
    for (std::size_t f = 0; f < r.fingertip_touched.size(); ++f)
      if (r.fingertip_touched[f]) {
        out.points.push_back(r.fingertip_points[f]);
        out.pad_slot.push_back(static_cast<int>(f));
      }
    return out;
  }
  const SensorSettings& sensor = log.gripper.sensor();
  const std::size_t n = log.sensels();
  for (std::size_t slot = 0; slot < log.pads.size(); ++slot) {
    // Eq. 2: P^W = T_EEF(Θarm) T_sensor(Θfinger) P^L
    const Pose T_world_pad = r.arm_pose * log.gripper.pad_pose(r.joints, log.pads[slot]);
    for (std::size_t j = 0; j < n; ++j) {
      const std::size_t i = slot * n + j;
      const FoldHint hint = r.past_peak.empty() ? FoldHint::unknown : static_cast<FoldHint>(r.past_peak[i]);
      const SenselReading reading = invert_sensel(sensor, log.gain(slot, j), r.tactile[i], hint);  // Eq. 1
      if (!reading.contact) continue;
      out.ambiguous += (reading.flags & kSenselAmbiguous) != 0;
      out.at_peak += (reading.flags & kSenselAtPeak) != 0;
      out.clamped += (reading.flags & kSenselClamped) != 0;
      if ((reading.flags & kSenselAmbiguous) && !s.keep_ambiguous) continue;
      out.points.push_back(T_world_pad * sensel_contact(sensor, static_cast<int>(j), reading));
      out.pad_slot.push_back(static_cast<int>(slot));
    }
  }
  return out;
}

Exploration::Exploration(const TactileLog& log, const ExplorationSettings& settings)
    : log_(log),
      settings_(settings),
      origin_(log.grasps.empty() ? Vec3(Vec3::Zero()) : Vec3(log.grasps.front().arm_pose.translation())),
      grid_(settings.free.voxel, origin_) {}

void Exploration::advance_to(std::size_t k) {
  k = std::min(k, log_.grasps.size());
  for (; steps_ < k; ++steps_) {
    const GraspRecord& r = log_.grasps[steps_];
    const GraspContacts c = grasp_contacts(log_, steps_, settings_.contact);
    // Swept links first, contacts after: a voxel holding a contact is occupied either way
    // (occupied wins), so the order does not change the result.
    if (log_.sensing == Sensing::probe) {
      // The ball swept a cylinder of its radius from the start of the approach to where it
      // stopped (the shaft, no wider, follows inside it); its centres sampled as free points.
      const double travel = r.probe_travel;
      grid_.mark_free_cylinder(r.arm_pose, log_.probe.ball_radius, -travel, 0.0);
      const double step = settings_.probe_free_spacing;
      if (step > 0.0)
        for (double z = settings_.probe_free_start; z <= travel + 1e-12; z += step)
          probe_free_.push_back(r.arm_pose * Vec3(0, 0, -z));
      for (std::size_t i = 0; i < c.points.size(); ++i) raw_normals_.push_back(-r.arm_pose.linear().col(2));
    } else {
      mark_swept_volume(grid_, log_.gripper, r.arm_pose, r.joints, settings_.free);
      if (log_.sensing == Sensing::fingertips && log_.fingertip_normals)
        for (int f : c.pad_slot) raw_normals_.push_back(r.fingertip_normals[static_cast<std::size_t>(f)]);
    }
    for (const Vec3& p : c.points) grid_.mark_occupied(p);
    raw_.insert(raw_.end(), c.points.begin(), c.points.end());
    per_grasp_.push_back(c.points.size());
    // A grasp's contacts never change: filtered once. Its hand's final surfaces ride along.
    if (log_.sensing == Sensing::probe)
      groups_.add(voxel_filtered(c.points));
    else
      groups_.add(voxel_filtered(c.points),
                  settings_.hand_free_spacing > 0.0
                      ? hand_surface_samples(log_.gripper, r.arm_pose, r.joints, settings_.hand_free_spacing, settings_.free)
                      : std::vector<Vec3>{},
                  Vec3(r.arm_pose.translation()));
  }
}

std::vector<Vec3> Exploration::voxel_filtered(const std::vector<Vec3>& world) const {
  // Voxel filter in the local frame, then back to world coordinates.
  if (world.empty()) return {};
  PointCloud local;
  local.points.reserve(world.size());
  for (const Vec3& p : world) local.points.push_back(p - origin_);
  std::vector<Vec3> out = voxel_filter(local, settings_.contact_voxel).points;
  for (Vec3& p : out) p += origin_;
  return out;
}

PointCloud Exploration::contact_cloud() const {
  PointCloud out;
  if (raw_normals_.size() != raw_.size() || raw_.empty()) {
    out.points = voxel_filtered(raw_);
    return out;
  }
  // Contacts with their normals (a probe's: minus the approach), voxel-filtered together.
  PointCloud local;
  for (std::size_t i = 0; i < raw_.size(); ++i) {
    local.points.push_back(raw_[i] - origin_);
    local.normals.push_back(raw_normals_[i]);
  }
  if (local.empty()) return out;
  out = voxel_filter(local, settings_.contact_voxel);
  for (Vec3& p : out.points) p += origin_;
  return out;
}

PointCloud Exploration::free_cloud() const {
  PointCloud out;
  const Eigen::AlignedBox3d box = free_space_box(raw_, settings_.free.s_obj_max);
  out.points = grid_.full_free_cloud(box, settings_.free.res_free);
  for (const Vec3& p : probe_free_)
    if (box.contains(p)) out.points.push_back(p);
  return out;
}

ExplorationClouds exploration_clouds(const TactileLog& log, std::size_t k,
                                     const ExplorationSettings& settings) {
  Exploration ex(log, settings);
  ex.advance_to(k);
  ExplorationClouds out;
  out.contacts = ex.contact_cloud();
  out.free = ex.free_cloud();
  out.raw_contacts = ex.raw_contacts().size();
  out.contacts_per_grasp = ex.contacts_per_grasp();
  out.grasps = ex.grasp_groups();
  return out;
}

}  // namespace touch
}  // namespace ts
