// Near-twin verification (Touchstone extension for large databases): the last word between the
// leading objects when they look alike.
//
// Large databases hold families of near-identical objects (sizes of one part, stretched or
// perturbed variants). Eq. 4-6 with a 20 cm outlier distance rank hypotheses by differences of
// 1e-4 in ln wt, and the per-grasp offsets absorb a few millimetres of shape difference grasp by
// grasp for free, so a variant scores like the original. The verification weighs the same
// evidence as a likelihood with a noise model: each grasp's contacts may shift by t_g (the arm's
// pose error, a Gaussian prior of offset_sigma per axis), each shifted contact's distance d to
// the surface is Gaussian (contact_sigma), clamped at three sigmas (outliers):
//     V = sum_g |t_g|^2 / offset_sigma^2 + sum_i min(d_i^2, (3 contact_sigma)^2) / contact_sigma^2
// (-2 ln likelihood up to a constant; lower is better). With `free_sigma`, V also weighs what
// each grasp's hand held free at its end (its links' faces, shifted by the same t_g): a sample
// at depth x inside the object adds min(x, 3 free_sigma)^2 / free_sigma^2. The fingers closed
// onto the true object and stopped at its surface, so a larger look-alike, whose offsets put
// the contacts on its surface, has them inside it. A variant must pay for its shape
// difference either in larger offsets or in residuals, the original does not. The best
// hypothesis of each of the `rivals` leading objects (by weight) whose ln wt is within
// `max_gap` of the best is scored, and the one with the lowest V is the answer of the step.
// Only near-ties are re-decided: V ignores free space, which Eq. 6 weighs, so an object that
// Eq. 6 already rejects clearly (free-space violations cost lambda = 0.02 each) keeps its rank.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/evaluate.hpp"
#include "engine/recognition/scene.hpp"

#include <vector>

namespace ts {
inline namespace recognition {

struct TwinSettings {
  std::size_t rivals = 0;           ///< leading objects compared (0: off; needs grasp groups)
  double max_gap = 0.005;           ///< only objects within this of the best ln wt compete
  double contact_sigma = 0.001;     ///< m, contact noise of the likelihood
  double offset_sigma = 0.003;      ///< m, per-grasp arm offset prior (per axis)
  /// Free-space term (0: off): each grasp's hand surfaces (GraspGroups::free), shifted by the
  /// grasp's offset, must lie outside the object; a sample at depth x inside costs
  /// min(x, 3 free_sigma)^2 / free_sigma^2. Needs a signed field (closed objects).
  double free_sigma = 0.0;          ///< m
  /// Rotations in the offsets (0: translations only): each grasp's arm error also turns its
  /// contacts and hand samples about its pivot (the measured end effector, GraspGroups::pivots),
  /// with a Gaussian prior of this many degrees per axis. A pad or a finger a hand's length
  /// from the wrist moves by millimetres under a 1 degree error, which no translation takes out.
  double rotation_sigma = 0.0;      ///< deg
  std::size_t fit_points = 64;      ///< contacts per grasp in the offset fit
  int iterations = 5;               ///< Gauss-Newton iterations of the offset fit
  /// Pose refinement under V: alternate a Gauss-Newton step of the pose on the shifted
  /// contacts with a new offset fit, at most this many times, while V falls (0: V at the
  /// hypothesis's own pose, which ICP fitted without the offsets).
  int refine = 0;
  /// Pose transfer: each step the leading hypothesis's pose is also tried on the `transfer`
  /// other objects whose keypoints fit the contacts best at that pose (the shortlist's
  /// screening), refined by ICP and evaluated like new hypotheses, so that a look-alike of the
  /// leader is judged at the right pose even when RANSAC found it nowhere (0: off).
  std::size_t transfer = 0;
  std::size_t transfer_min_database = 0;   ///< transfer acts only on databases of more objects
  /// With the shape prior active, only the prior's this-many best objects of the step are
  /// screened for the transfer (0: every allowed object). A look-alike of the leader fits the
  /// contacts' pair statistics about as well as the leader, so it ranks near it; screening the
  /// rest of a large database each step costs time for objects that cannot win.
  std::size_t transfer_pool = 0;
};

/// V of one hypothesis (see above), or +inf when the scene has no grasp groups or the object
/// no distance field.
double twin_score(const Scene& scene, const ObjectGeometry& geometry, const Pose& T_scene_object,
                  const TwinSettings& settings);

}  // namespace recognition
}  // namespace ts
