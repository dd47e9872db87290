// The exploration simulator: random grasps on a database object (Section 5.1), written as the
// tactile log a robot would record.
//
// The object (its object-frame mesh from the database) is placed at a seeded random 6-DOF pose.
// Each grasp imitates an operator steering the hand (Section 5.1): a random point p on the
// surface (area-uniform) with outward normal n is aimed at with the single pad (the middle
// finger's distal pad): at random nominal joint angles of its finger, that pad's foam would
// rest on p facing it (within `max_tilt_deg` of -n, random roll, p at a random spot of the pad).
// The open hand comes in along -n from outside the object until it would touch it; an aim the
// hand cannot reach (e.g. the middle of a face larger than the hand) is redrawn, up to
// `max_attempts`, and the aim that came closest is used. Then every finger closes (proximal joint first, then distal:
// Gripper's closing model) until a link touches. A link whose foam touches keeps
// pressing until its deepest sensel is compressed by a random press depth (some beyond the
// response peak); a link whose rigid body touches stops there. All collisions are ray casts
// against the true mesh (MeshIndex): swept arcs of sample points of the links, and each
// sensel's foam column, so the sensed compression is the exact distance to the real surface.
//
// Noise is applied to what is recorded only: the measured arm pose (per grasp, per axis),
// finger joint readings, sensel signals (multiplicative), the force-resolution noise of
// contacted sensels, and a lateral offset of where each sensel samples the surface (Q of
// Section 5.6). The log's ground-truth group keeps the object pose and the true arm poses
// and joints.
//
// Determinism: grasp g draws its geometry from Rng(seed, 1, g) and its noise from
// Rng(seed, 2, g); grasps run in parallel (TBB, in the caller's arena) into pre-sized slots.
// Same seed => identical log for any thread count; the same seed with another noise profile
// gives the same true grasps.
#pragma once

#include "engine/geometry/mesh.hpp"
#include "engine/touch/active_touch.hpp"
#include "engine/touch/fusion.hpp"
#include "datasets/scene.hpp"

#include <memory>
#include <string>

namespace ts::datasets {

struct NoiseSettings {
  std::string name = "ideal";          ///< profile name recorded in the log
  double arm_position_sigma = 0.0;     ///< m, per axis, per grasp (measured EEF position error)
  double arm_rotation_sigma_deg = 0.0; ///< deg, per axis of a small rotation, per grasp
  double joint_sigma_deg = 0.0;        ///< deg, finger joint encoder noise
  double signal_noise = 0.0;           ///< relative σ of every sensel signal (multiplicative)
  double force_noise = 0.0;            ///< relative σ of contacted sensels (force resolution)
  double lateral_sigma = 0.0;          ///< m, σ of where a sensel samples the surface, per axis
  /// Relative drop below the peak needed for the preprocessor to flag a sensel "past peak";
  /// negative: 2 x signal_noise.
  double fold_detect = -1.0;
};

/// "ideal" (no noise), "underwater" (3 mm / 1° arm pose error, 5 % signal noise), "deepsea"
/// (underwater + 50 % force-resolution noise and 2 mm lateral sampling error, so contacts
/// scatter with about Q = diag(2 mm)). Throws ts::Error for another name.
NoiseSettings noise_profile(const std::string& name);

struct GraspSettings {
  double max_tilt_deg = 5.0;         ///< aimed pad's normal within this cone about -n
  double aim_min_deg = 0.0;          ///< nominal joint angles of the aiming finger, range
  double aim_max_deg = 60.0;         ///< deg
  int max_attempts = 24;             ///< aims redrawn while the object blocks the approach
  double approach_tolerance = 0.002; ///< m, an approach blocked earlier than this is redrawn
  double press_min = 0.0008;         ///< m, compression of the deepest sensel when a pad stops
  double press_max = 0.0038;         ///< m (above 0.8 x 4 mm: beyond the response peak)
  double clearance = 0.0003;         ///< m, stop this far before a rigid collision
  double angle_step_deg = 2.0;       ///< chord of swept arcs in collision tests
  double inner_spacing = 0.0025;     ///< m, collision samples on a link's inner face
  double other_spacing = 0.004;      ///< m, collision samples on the palm and link tips
};

/// The probe of `sensing = probe`: each touch aims the ball at a random surface point p
/// (area-uniform) from a direction within `max_tilt_deg` of -n, starting outside the object's
/// bounding sphere, and moves straight in until the ball first touches the surface (exact: sphere
/// tracing on the mesh's distance). A start inside the object is redrawn. The log records the
/// tool pose at the stop (ball centre; with the arm noise of the profile, `contact_sigma` more
/// per axis, and the position rounded to `quantization`) and the travel.
struct ProbeSettings {
  ProbeSpec spec;                    ///< ball and shaft radii
  double max_tilt_deg = 20.0;        ///< approach direction within this cone about -n
  double contact_sigma = 0.0;        ///< m per axis, measurement noise of the ball centre
                                     ///< beyond the arm's (e.g. a probe's own noise)
  double quantization = 0.0;         ///< m, recorded positions rounded to this grid (0: none)
  int max_attempts = 24;             ///< aims redrawn when the start lies inside the object
};

/// The hand of `sensing = fingertips`: grasps as for the pads (the same aim, approach and
/// closing), but the robot reports one contact point per finger whose distal link (its
/// fingertip) touched the object: the surface point nearest that link at the final joint
/// angles, placed as the robot places it (its measured arm pose and joint readings, so the
/// point carries the arm's error) and rounded to `quantization`. A normal is reported only when
/// `normal_sigma_deg` >= 0: the true outward normal seen through the same kinematics, tilted by
/// that much more per axis.
struct FingertipSettings {
  double quantization = 0.0;         ///< m, reported coordinates rounded to this grid (0: none)
  double normal_sigma_deg = -1.0;    ///< deg, normal noise per axis; < 0: no normals
};

struct SimulatorSettings {
  std::size_t grasps = 40;           ///< grasps, or probe touches
  Sensing sensing = Sensing::pads;   ///< pads: the gripper's tactile arrays; probe: ProbeSettings;
                                     ///< fingertips: FingertipSettings
  ProbeSettings probe;
  FingertipSettings fingertips;
  SceneSettings scene;               ///< what lies around the object (none: water alone)
  /// A cluttered scene's neighbours (scene.neighbours of them, object-frame meshes from the
  /// database; neighbour_choice draws which), placed by the simulator (place_neighbours).
  std::vector<SceneObject> neighbours;
  int sensors = 1;                   ///< 1: the gripper's single_pad; 6 (or all): every pad
  NoiseSettings noise;
  GraspSettings grasp;
  double gain_min = 0.85;            ///< per-sensel calibration gain range
  double gain_max = 1.15;
  Vec3 world_offset = Vec3::Zero();  ///< m, the object sits within `placement` of this point
  double placement = 0.25;           ///< m, half-size of the box of object positions
  double grasp_interval = 60.0;      ///< s between grasps (timestamps)
  std::uint64_t seed = 1;
};

/// Diagnostics of one grasp (true values, not in the log's measured part).
struct GraspDiagnostics {
  double approach_travel = 0.0;      ///< m moved in from the start
  int attempts = 0;                  ///< aims drawn (1: the first was reachable)
  int touching_links = 0;            ///< links that stopped on the object (any part)
  int contact_sensels = 0;           ///< logged sensels above threshold (true compression);
                                     ///< probe and fingertips: contacts reported
  int past_peak_sensels = 0;         ///< logged sensels compressed beyond the peak
  double max_compression = 0.0;      ///< m, over logged sensels
};

struct SimulationResult {
  TactileLog log;
  std::vector<GraspDiagnostics> diagnostics;
  std::size_t grasps_with_contact = 0;   ///< grasps where a logged pad sensed contact
};

class Simulator {
 public:
  /// `object_mesh` is in the object frame (as the database stores it). Throws ts::Error for an
  /// empty mesh or bad settings.
  Simulator(Mesh object_mesh, std::string object_name, Gripper gripper, SimulatorSettings settings);
  ~Simulator();
  Simulator(Simulator&&) noexcept;
  Simulator& operator=(Simulator&&) noexcept;

  const Pose& object_pose() const;      ///< T_world_object
  const MeshIndex& mesh() const;        ///< object frame
  const SimulatorSettings& settings() const;
  /// Pads recorded in the log (indices into gripper.pads()).
  const std::vector<int>& logged_pads() const;

  /// All grasps (parallel over grasps inside the caller's task arena).
  SimulationResult run() const;
  /// Grasp g alone: measured record, true arm pose and joints, diagnostics.
  struct Grasp {
    GraspRecord measured;
    Pose true_arm_pose;
    std::vector<double> true_joints;
    GraspDiagnostics diagnostics;
  };
  Grasp grasp(std::size_t g) const;   ///< a probe touch under sensing = probe
  /// The operator's aim of grasp g (what grasp(g) executes), as a command: the hand pose where
  /// the approach stopped (world), the approach direction, the aimed finger's nominal joint
  /// angles (the others open), the aimed surface point. No finger closes, nothing is recorded.
  GraspCommand aim(std::size_t g) const;

 private:
  Grasp grasp_or_aim(std::size_t g, GraspCommand* aim_only) const;
  /// Closing the fingers at T_obj_eef and recording (grasp g's noise stream).
  Grasp finish(const Pose& T_obj_eef, double travel, int attempts, std::size_t g, Rng& rng) const;
  /// The fingertip contacts of a grasp closed at true joints `q` (`tip`: per finger, its distal
  /// link touched), after `out.measured` has its arm pose and joint readings.
  void record_fingertips(const Pose& T_obj_eef, const std::vector<double>& q, const std::vector<char>& tip,
                         Rng& noise, Grasp& out) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ts::datasets
