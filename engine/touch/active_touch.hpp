// Active touch (issue 13): choose the next grasp that tells the most about object and pose.
//
// Candidates. Each candidate imitates the simulator's operator on one of the leading hypotheses'
// models instead of the true object: a surface point p of the hypothesis' model (its keypoints,
// outward by the centroid rule) within `aim_radius` of a contact so far (the true surface surely
// continues there; a grasp that misses the object tells the recognizer little), the aimed pad (the gripper's single_pad) facing it, a seeded roll
// and seeded nominal joint angles of the aimed finger; the open hand comes in along -n. A command
// is that hand pose at the aim (T_world_eef, open fingers), the approach direction and the finger
// joint targets (the aimed finger's nominal angles, the others open). As the simulator's operator
// redraws an aim the open hand cannot reach, an aim blocked on the aimed hypothesis' own model is
// redrawn (`attempts`).
//
// Prediction. Under each of the top-K hypotheses (object, pose) the distance field of its object
// answers, without the true mesh:
//   - what the pad would feel: the signed distance of 3 x 3 points of the pad's foam (at the
//     aim, nominal angles) to that hypothesis' surface, clamped to +-`cap` (0: contact where the
//     aim expects it; larger: the surface is farther or absent; negative: nearer);
//   - whether the swept open hand would run into that hypothesis' object before reaching the aim
//     (each hand sample sphere-traced along the approach through the object's bounding sphere;
//     a distance below `clearance` blocks).
// Score. The expected information about which hypothesis is true is the mutual information
// between the hypothesis and the outcome y (the predicted pad distances and the blocked flag,
// observed with isotropic Gaussian noise `sigma`), estimated by the pairwise Bhattacharyya lower
// bound of Kolchinsky and Tracey (2017):
//     I >= - sum_i w_i ln sum_j w_j exp(-|y_i - y_j|^2 / (8 sigma^2))     (nats, <= H(w))
// With the arm's per-grasp offset marginalized (`offset_sigma` = s > 0), the P pad distances
// share an offset: covariance S = sigma^2 I + s^2 1 1^T, and |y_i - y_j|^2 / sigma^2 becomes the
// Mahalanobis form  (|D|^2 - s^2 (sum D)^2 / (sigma^2 + P s^2)) / sigma^2  over the pad part D
// (Sherman-Morrison); the blocked flag keeps its own term.
// Weights are the hypotheses' weights tempered by `temperature` and renormalized over the K.
// The same estimator splits I(H; Y) = I(O; Y) + I(H; Y | O) into what the outcome tells about
// the object O and what it tells about the pose among one object's hypotheses (the within-object
// bound, weighted by each object's share W_o, is I(H; Y | O), >= 0):
//     I(O; Y) ~ sum_i w_i ln( sum_{j: o_j = o_i} w_j k_ij / (W_{o_i} sum_j w_j k_ij) ),
//     k_ij = exp(-|y_i - y_j|^2 / (8 sigma^2))                          (clamped at 0; <= H(O))
// Recognition names the object first, so the pose part is weighted by `pose_weight`
// (1: the information about the hypothesis, object and pose alike).
// The collision penalty is `collision_weight` x (sum of the weights of the hypotheses under which
// the hand is blocked): a grasp that would run into the likely object ranks lower.
// A new-ground bonus: coverage = min(d, coverage_radius) / coverage_radius, d the distance of
// the aim from the nearest contact so far (all of them; 1 without contacts):
//     score = I(O; Y) + pose_weight * (I(H; Y) - I(O; Y)) - collision_weight * blocked_weight
//             + coverage_weight * coverage
// I(O; Y) is a difference of two pairwise bounds, an estimate rather than a bound itself.
// The K hypotheses: the best of each object first (up to K/2 objects), then the rest by weight,
// so hypotheses of competing objects are always compared.
//
// Determinism: candidate c draws from Rng(seed, c); candidates are scored in parallel (TBB, the
// caller's arena) into their own slots and ranked by (score, index): the same result for any
// thread count.
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/distance_field.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/touch/gripper.hpp"

#include <functional>
#include <vector>

namespace ts {
inline namespace touch {

struct ActiveSettings {
  std::size_t candidates = 48;      ///< candidate grasps scored per step
  std::size_t hypotheses = 16;      ///< K, hypotheses the outcomes are predicted under
  std::size_t leaders = 8;          ///< hypotheses whose models the candidates aim at
  double sigma = 0.004;             ///< m, noise of a predicted pad distance (arm pose, foam)
  /// m, the arm's per-grasp error along the pad's normal, common to the whole patch (0: off, the
  /// arm's error is left in `sigma`). When > 0 the outcomes' pad distances are compared with the
  /// offset marginalized: covariance sigma^2 I + offset_sigma^2 1 1^T, so two hypotheses whose
  /// predicted patches differ by a constant (parallel faces a few mm apart) are told apart only
  /// as far as the offset allows, and a patch spanning both surfaces of a distinguishing feature
  /// (a raised face and the flange face) measures their difference free of the offset.
  double offset_sigma = 0.0;
  double cap = 0.02;                ///< m, predicted distances clamped to +-cap
  double collision_weight = 1.0;    ///< nats per unit of blocked hypothesis weight
  double temperature = 1.0;         ///< ln wt divided by this before normalizing (> 0)
  double pose_weight = 1.0;         ///< weight of the information about the pose within an
                                    ///< object against that about the object (>= 0)
  double coverage_weight = 0.0;     ///< nats per unit of coverage: how far the aim lies from
                                    ///< the contacts so far, min(d, coverage_radius) /
                                    ///< coverage_radius (0: off)
  double coverage_radius = 0.05;    ///< m, the distance at which an aim counts as new ground
  double clearance = 0.002;         ///< m, a hand sample nearer than this to a surface blocks
  double aim_min_deg = 0.0;         ///< nominal angles of the aimed finger's joints, range
  double aim_max_deg = 60.0;        ///< (as the simulator's operator)
  double hand_spacing = 0.02;       ///< m, spacing of the hand samples swept along the approach
  double aim_radius = 0.05;         ///< m, aims only at model points within this of a contact
                                    ///< so far (where the true surface surely continues; 0 or no
                                    ///< contacts: anywhere on the model)
  std::size_t attempts = 8;         ///< aims per candidate: one the open hand cannot reach on
                                    ///< the aimed hypothesis' model is redrawn (as the simulator)
};

/// A grasp to execute: the open hand at the aim, reached along `approach`.
struct GraspCommand {
  Pose T_world_eef = Pose::Identity();  ///< hand pose at the aim (world; fingers open)
  Vec3 approach = Vec3::UnitZ();        ///< unit, world: direction the hand moves in
  std::vector<double> joints;           ///< rad, finger joint targets (the aimed finger's
                                        ///< nominal angles, the others open)
  Vec3 target = Vec3::Zero();           ///< world, the aimed surface point
};

struct PlannedGrasp {
  GraspCommand command;
  std::size_t candidate = 0;        ///< index among the step's candidates
  std::uint32_t aimed_object = 0;   ///< object of the hypothesis whose model was aimed at
  double information = 0.0;         ///< nats, expected information about the hypothesis
                                    ///< (object and pose; lower bound)
  double object_information = 0.0;  ///< nats, the part of it about the object (<= information)
  double blocked_weight = 0.0;      ///< share of the hypothesis weight that blocks the hand
  double coverage = 0.0;            ///< min(distance of the aim from the contacts so far,
                                    ///< coverage_radius) / coverage_radius (1 without contacts)
  double score = 0.0;               ///< object_information + pose_weight * (information -
                                    ///< object_information) - collision_weight * blocked_weight
                                    ///< + coverage_weight * coverage
};

/// `hypotheses` (best first) with one more put first: `object` at `pose`, weighted so that the
/// planner (ln wt tempered by `temperature`, normalized over the hypotheses it selects, a subset)
/// gives it at least the share `share` of the belief (0 < share < 1). Experiments use it with the
/// true object and pose (diagnostics.oracle_belief): how a planner would do with a belief that
/// holds the truth. Throws ts::Error on a share or temperature out of range.
std::vector<Hypothesis> with_leader(const std::vector<Hypothesis>& hypotheses, std::uint32_t object,
                                    const Pose& pose, double share, double temperature);

/// What the planner reads of one object (object frame): its distance field, points of its
/// surface with normals (aims), and the radius of a sphere about its origin that holds it.
struct PlanObject {
  const DistanceField* field = nullptr;
  const PointCloud* surface = nullptr;
  double radius = 0.0;
};
using PlanObjects = std::function<PlanObject(std::uint32_t object)>;

class GraspPlanner {
 public:
  /// Throws ts::Error naming the field on bad settings ("active.candidates" = 0, ...).
  GraspPlanner(Gripper gripper, ActiveSettings settings);

  /// The `n_best` best of `settings.candidates` candidates aimed at the leading hypotheses
  /// (`hypotheses`: a recognizer state, best first, world poses). Throws ts::Error when there
  /// is no hypothesis (nothing to plan from) or an object has no field or surface.
  /// `contacts`: the contacts so far (world), for `aim_radius`; empty: aims anywhere.
  std::vector<PlannedGrasp> plan(const std::vector<Hypothesis>& hypotheses, const PlanObjects& objects,
                                 std::uint64_t seed, std::size_t n_best,
                                 const std::vector<Vec3>& contacts = {}) const;
  /// Scores given commands (in their order) under the hypotheses; `contacts` (world): the
  /// contacts so far, for the coverage term.
  std::vector<PlannedGrasp> evaluate(const std::vector<GraspCommand>& commands,
                                     const std::vector<Hypothesis>& hypotheses,
                                     const PlanObjects& objects,
                                     const std::vector<Vec3>& contacts = {}) const;

  const ActiveSettings& settings() const { return s_; }
  const Gripper& gripper() const { return gripper_; }
  /// Hand samples of the open hand (EEF frame) swept in the collision test.
  const std::vector<Vec3>& hand_samples() const { return hand_; }

 private:
  struct Selected;
  Selected select(const std::vector<Hypothesis>& hypotheses, const PlanObjects& objects) const;
  PlannedGrasp score(const GraspCommand& c, const Selected& sel, const std::vector<Vec3>& contacts) const;
  bool hand_blocked(const std::vector<Vec3>& hand_world, const Vec3& d, std::size_t k, const Selected& sel) const;

  Gripper gripper_;
  ActiveSettings s_;
  int pad_ = 0;
  std::vector<Vec3> hand_;          ///< EEF frame, open hand
  std::vector<Vec3> pad_points_;    ///< pad frame: 3 x 3 points on the foam surface
};

/// The database's objects for the planner: each object's distance field, keypoints (coarse
/// cloud with normals) and half the diagonal of its bounding box. Loads what the hypotheses
/// need; the returned function keeps them alive.
PlanObjects database_plan_objects(const Database& db);

}  // namespace touch
}  // namespace ts
