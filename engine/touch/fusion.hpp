// Data fusion (Section 4.1.2): tactile logs in memory, contact points from tactile images and
// kinematics (Eq. 1-2), the cumulative voxel-filtered contact cloud PC_cum^cont and the
// free-space cloud PC^free inside box B (Eq. 3).
//
// For the recognizer, the whole interface is:
//
//     ts::ExplorationClouds c = ts::exploration_clouds(log, k, settings);   // after k grasps
//     // c.contacts: PC_cum,k^cont (world frame)   c.free: PC_k^free (world frame)
//
// or, step by step without recomputing earlier grasps:
//
//     ts::Exploration ex(log, settings);
//     for (std::size_t k = 1; k <= log.grasps.size(); ++k) {
//       ex.advance_to(k);
//       use(ex.contact_cloud(), ex.free_cloud());
//     }
//
// Both give identical clouds for the same k. Coordinates are world coordinates in double;
// internally everything is computed relative to the first grasp's arm position (origin()), so
// logs far from the world origin lose no precision. Deterministic: no randomness, fixed order.
#pragma once

#include "engine/core.hpp"
#include "engine/touch/free_space.hpp"
#include "engine/touch/gripper.hpp"
#include "engine/touch/tactile.hpp"

#include <optional>

namespace ts {
inline namespace touch {

/// How a log senses touch: `pads`, the gripper's tactile arrays (the default, every log written
/// before the probe); `probe`, a rigid probe with a ball tip that records one contact per
/// touch (a touch probe on an ROV arm); or `fingertips`, a hand that reports one contact point
/// per fingertip that touched (iCub, Allegro or Shadow fingertip sensors, force-torque sensing in
/// an ROV gripper's jaws), usually without a normal.
enum class Sensing { pads, probe, fingertips };
const char* to_string(Sensing s);                              ///< "pads" / "probe" / "fingertips"
/// Throws ts::Error naming `file` and `field` on another word.
Sensing parse_sensing(const std::string& word, const std::string& file = {}, const std::string& field = {});

/// The probe of a `probe` log: a shaft ending in a ball. Its tool frame has its origin at the
/// ball centre and z along the shaft toward the object (the approach direction).
struct ProbeSpec {
  double ball_radius = 0.003;    ///< m
  double shaft_radius = 0.002;   ///< m, at most ball_radius (the ball's path covers the shaft's)
};

/// One grasp as a robot records it (a probe log: one probe touch; the pad fields stay empty).
struct GraspRecord {
  double time = 0.0;                    ///< s, when the tactile images were taken
  Pose arm_pose = Pose::Identity();     ///< T_world_eef as measured: T_EEF(Θarm) of Eq. 2
  std::vector<double> joints;           ///< rad, Θfinger, Gripper::joint_count() values
  std::vector<float> tactile;           ///< signals, pads x sensels (pad-major, j = row*cols+col)
  std::vector<std::uint8_t> past_peak;  ///< FoldHint per signal (same layout), or empty: unknown
  // Probe logs: arm_pose is T_world_tool when the probe stopped (the ball centre, z the
  // approach direction). The ball centre came in along z from arm_pose * (0, 0, -probe_travel).
  double probe_travel = 0.0;            ///< m the ball centre moved along z (probe logs)
  bool probe_touched = false;           ///< the probe stopped on contact (false: it went the
                                        ///< whole way free; the touch adds free space only)
  // Fingertip logs (joints as for pads, no tactile images): one slot per finger of the gripper.
  std::vector<std::uint8_t> fingertip_touched;  ///< 1: finger f's tip reported a contact
  std::vector<Vec3> fingertip_points;   ///< world frame, as the robot reports it (its arm pose
                                        ///< and kinematics, its rounding); unused where not touched
  std::vector<Vec3> fingertip_normals;  ///< outward surface normals (world) or empty: none
};

/// Evaluation-only truth (simulated logs): never used to compute contacts or free space.
struct LogGroundTruth {
  Pose object_pose = Pose::Identity();  ///< T_world_object
  std::vector<Pose> arm_poses;          ///< true T_world_eef per grasp
  std::vector<std::vector<double>> joints;  ///< true joint angles per grasp
  std::string scene = "none";           ///< the simulator's scene ("none": the object alone)
  Mesh support;                         ///< the scene's support surface, world frame (empty: none)
  /// Another object of the scene (a cluttered scene's neighbour): its name, pose and world mesh.
  struct Neighbour {
    std::string name;
    Pose pose = Pose::Identity();       ///< T_world_object
    Mesh mesh;                          ///< world frame
  };
  std::vector<Neighbour> neighbours;
};

struct TactileLog {
  std::string object;                   ///< explored object's name ("" when unknown)
  std::string noise = "real";           ///< noise profile of a simulated log; "real" otherwise
  std::uint64_t seed = 0;               ///< simulator seed (0 for real logs)
  Gripper gripper;                      ///< description incl. sensor model
  std::vector<int> pads;                ///< logged pads: indices into gripper.pads()
  std::vector<float> gains;             ///< calibration gain, pads.size() x sensels
  std::vector<GraspRecord> grasps;
  std::optional<LogGroundTruth> truth;
  Sensing sensing = Sensing::pads;      ///< probe, fingertips: pads and gains are empty
  ProbeSpec probe;                      ///< the probe of a probe log
  bool fingertip_normals = false;       ///< fingertip logs: every grasp carries normals

  std::size_t sensels() const { return static_cast<std::size_t>(gripper.sensor().sensels()); }
  float gain(std::size_t pad_slot, std::size_t sensel) const { return gains[pad_slot * sensels() + sensel]; }
};

/// Checks a log held in memory (sizes, finiteness, signal range, rigid poses, pads). Throws
/// ts::Error naming `file` and the offending field as its HDF5 path and indices
/// ("/grasps/tactile[3][0][17]": grasp 3, logged pad 0, sensel 17).
void validate(const TactileLog& log, const std::string& file = {});
/// The per-grasp part of validate() for grasp number `index` (used before appending).
void validate_grasp(const TactileLog& log, const GraspRecord& grasp, std::size_t index,
                    const std::string& file = {});

struct ContactSettings {
  bool keep_ambiguous = true;  ///< keep sensels whose side of the fold is unknown (rising value)
};

/// Contacts of one grasp, world frame, with diagnostics.
struct GraspContacts {
  std::vector<Vec3> points;    ///< P^W of Eq. 2, ordered by (logged pad, sensel)
  std::vector<int> pad_slot;   ///< index into log.pads for each point
  int ambiguous = 0;           ///< sensels with kSenselAmbiguous (kept or not)
  int at_peak = 0;             ///< sensels at or above their calibrated peak
  int clamped = 0;             ///< past-peak sensels with a signal below the end response
};

/// Eq. 1 then Eq. 2 for every sensel of every logged pad of grasp `g`. A probe log gives the
/// touch's one contact, the ball centre moved by the ball radius along the approach (the
/// contact assumed straight ahead of the ball), or none when the probe touched nothing. A
/// fingertip log gives the reported point of each finger that touched (pad_slot: the finger).
GraspContacts grasp_contacts(const TactileLog& log, std::size_t g, const ContactSettings& s = {});

struct ExplorationSettings {
  double contact_voxel = 0.002;  ///< m, voxel-grid filter of the cumulative contact cloud
  double probe_free_spacing = 0.01;  ///< m, probe logs: free points sampled along each touch's
                                     ///< ball-centre path (a thin path fills no res_free cube),
  double probe_free_start = 0.01;    ///< m, from this far behind the stopped ball centre: the
                                     ///< samples are free by the ball radius only, so the
                                     ///< evaluation should use d_thresh <= ball radius; the
                                     ///< last centimetre is left out against the arm noise
  double hand_free_spacing = 0.01;   ///< m, spacing of the hand's final surfaces kept per grasp
                                     ///< (GraspGroups::free; 0: none)
  ContactSettings contact;
  FreeSpaceSettings free;
};

struct ExplorationClouds {
  PointCloud contacts;           ///< PC_cum^cont after the voxel filter (no normals)
  PointCloud free;               ///< PC^free inside B (Eq. 3), sampled at res_free
  std::size_t raw_contacts = 0;  ///< contacts before the voxel filter
  std::vector<std::size_t> contacts_per_grasp;
  GraspGroups grasps;            ///< Exploration::grasp_groups()
};

/// Incremental exploration over a log (holds a reference: the log must outlive it).
class Exploration {
 public:
  Exploration(const TactileLog& log, const ExplorationSettings& settings = {});
  /// Fuse grasps [steps(), k) (k is clamped to the log's size).
  void advance_to(std::size_t k);
  std::size_t steps() const { return steps_; }
  const Vec3& origin() const { return origin_; }
  const std::vector<Vec3>& raw_contacts() const { return raw_; }
  const std::vector<std::size_t>& contacts_per_grasp() const { return per_grasp_; }
  const OccupancyGrid& grid() const { return grid_; }
  PointCloud contact_cloud() const;   ///< voxel-filtered PC_cum^cont; a probe log's contacts
                                      ///< carry normals (minus the approach directions), a
                                      ///< fingertip log's those it reports, if any
  PointCloud free_cloud() const;      ///< PC^free in B around the current contacts: centres of
                                      ///< the res_free cubes that are entirely free
                                      ///< (OccupancyGrid::full_free_cloud); a probe log adds
                                      ///< its paths' samples inside B
  /// The contacts grouped by grasp, each grasp voxel-filtered on its own (contact_voxel):
  /// what the evaluation needs to take out each grasp's arm pose error.
  const GraspGroups& grasp_groups() const { return groups_; }

 private:
  const TactileLog& log_;
  ExplorationSettings settings_;
  Vec3 origin_;
  OccupancyGrid grid_;
  std::size_t steps_ = 0;
  std::vector<Vec3> raw_;
  std::vector<Vec3> raw_normals_;      ///< per raw contact: probe logs minus the approach,
                                       ///< fingertip logs with normals the reported ones
  std::vector<Vec3> probe_free_;       ///< probe logs: samples of the ball-centre paths
  std::vector<std::size_t> per_grasp_;
  GraspGroups groups_;

  std::vector<Vec3> voxel_filtered(const std::vector<Vec3>& world) const;
};

/// Clouds after the first k grasps (the recognizer's entry point).
ExplorationClouds exploration_clouds(const TactileLog& log, std::size_t k,
                                     const ExplorationSettings& settings = {});

}  // namespace touch
}  // namespace ts
