// The support under the object (issue 58): a seabed, a deck or a bench the hand touches as often
// as the object, whose contacts belong to no database object. Estimated per step from the
// contacts and free space as a plane, and its contacts set aside before recognition.
//
// Candidates: the plane of each grasp's patch (its contacts' PCA, when flat within the tolerance),
// or, without grasp groups (a points-only cloud), planes through seeded triplets of contacts;
// each refitted to the contacts within `tolerance` of it. Up is the free side: where the hands
// that touched it were (their free points), or the free space near it.
//
// A plane is the support when, beside enough contacts on it (`min_contacts`, and with grasp
// groups `min_grasps` grasps whose patches lie on it):
//   - the other contacts lie above it (`above_share` of those off it): the object rests on its
//     support, while a face of the object has the rest of the object behind it (below), so a
//     box's face is never taken for a support;
//   - no free space lies below it where it was touched (within the disc its contacts span, more
//     than `free_margin` below, 2 % of the free points there at most): the hand never went under
//     the seabed, while it did go round the rim of a flange's face and behind it.
// The support chosen is the candidate with the most contacts on it (ties: the first). A concave
// object explored from one side only (an L-bracket's inner face) can pass both tests: that is why
// the support is looked for only when the user says the scene has one (support.mode = plane).
//
// Deterministic: candidates in grasp order, triplets from Rng(seed, step).
#pragma once

#include "engine/core.hpp"

#include <cstdint>
#include <vector>

namespace ts {
inline namespace recognition {

struct SupportSettings {
  bool enabled = false;              ///< support.mode: off | plane
  double tolerance = 0.006;          ///< m, a contact nearer the plane than this is the support's
  std::size_t min_contacts = 12;     ///< contacts on the plane, and off it, needed to decide
  std::size_t min_grasps = 2;        ///< grasps whose patch lies on it (with grasp groups)
  double above_share = 0.9;          ///< of the contacts off the plane, the share above it
  double free_margin = -1.0;         ///< m, free space deeper than this below it refutes it
                                     ///< (< 0: the stage "support" takes the tolerance plus d_thresh
                                     ///< of Eq. 8, half the free-space resolution, as a free
                                     ///< voxel's centre may lie that far from the volume the hand
                                     ///< swept; estimate_support alone, the tolerance)
  std::size_t triplets = 256;        ///< candidate planes without grasp groups
  double attribution = 0.01;         ///< m, a contact this near the answer's surface is the
                                     ///< object's (stage "attribution")
};

struct SupportPlane {
  bool found = false;
  Vec3 normal = Vec3::UnitZ();       ///< unit, up (the free side), world frame
  double offset = 0.0;               ///< the plane: normal . x = offset
  std::size_t contacts_on = 0;       ///< input contacts within the tolerance
  std::size_t contacts_above = 0;    ///< input contacts above it (beyond the tolerance)
  std::size_t grasps_on = 0;         ///< grasps whose patch lies on it
  std::size_t candidates = 0;        ///< planes examined

  double signed_distance(const Vec3& x) const { return normal.dot(x) - offset; }
};

/// The support of one step's contacts (world frame), or found = false. Throws ts::Error naming
/// the field ("support.tolerance", ...) on settings out of range.
SupportPlane estimate_support(const PointCloud& contacts, const GraspGroups& grasps, const std::vector<Vec3>& free,
                              const SupportSettings& settings, std::uint64_t seed, std::uint64_t step);

/// `contacts` without the points the support explains (within its tolerance); `grasps` likewise
/// (their free points and pivots kept, grasps left empty kept empty).
PointCloud without_support(const PointCloud& contacts, const SupportPlane& plane, double tolerance);
GraspGroups without_support(const GraspGroups& grasps, const SupportPlane& plane, double tolerance);

}  // namespace recognition
}  // namespace ts
