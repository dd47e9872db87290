// The support under the object (issue 58): a seabed, a deck or a bench the hand touches as often
// as the object, whose contacts belong to no database object; or the pipe it sits on. Estimated
// per step from the contacts and free space as a plane (support.mode = plane) or a cylinder
// (support.mode = cylinder), and its contacts set aside before recognition.
//
// Plane:
// Candidates: the plane of each grasp's patch (its contacts' PCA, when flat within the tolerance),
// or, without grasp groups (a points-only cloud), planes through seeded triplets of contacts;
// each refitted to the contacts within twice `tolerance` of it (a pad that met the seabed with
// its edge leaves a strip whose plane is a few degrees off), then twice to those within
// `tolerance`. Up is the free side: where the hands that touched it were (their free points), or
// the free space near it. The contacts it explains lie within `tolerance` above it or up to
// SupportSurface::kBelow tolerances below it (the arm's error moves a grasp's contacts on it
// together, mostly into it).
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
// Cylinder (a pipe): candidate axes from pairs of grasp patches whose planes meet at more than
// 15 degrees (the axis along their normals' cross product, through the point where their normal
// lines meet, the radius their mean distance from it; the two radii within twice the tolerance
// of each other), or (without grasp groups, or no such pair) from seeded pairs of contacts with
// normals. Each is
// refitted to the contacts within the tolerance (axis: the direction least along their
// patches' normals; then the circle of their projections, Gauss-Newton) and judged as the plane
// is, with "above" read as outside: the free side is outside it, the other contacts lie
// outside it, and no free space lies inside it along the stretch its contacts span. The 16
// candidates with the most contacts on them are judged; the radius must lie within
// [max(min_radius, 2 x tolerance), 10 m] (a finger, a bar or a bone's shaft is no pipe); the
// one chosen has the most grasps on it, then the most contacts. A contact with a normal, or a grasp's patch, counts as on it only when
// its normal lies within 25 degrees of the cylinder's there (a face it merely grazes does not).
//
// Deterministic: candidates in grasp order, triplets and pairs from Rng(seed, step).
#pragma once

#include "engine/core.hpp"

#include <cstdint>
#include <vector>

namespace ts {
inline namespace recognition {

enum class SupportMode : int { off = 0, plane = 1, cylinder = 2 };   ///< support.mode, in its order

struct SupportSettings {
  SupportMode mode = SupportMode::off;   ///< support.mode: off | plane | cylinder
  bool enabled() const { return mode != SupportMode::off; }
  double tolerance = 0.006;          ///< m, a contact nearer the plane than this is the support's
  std::size_t min_contacts = 12;     ///< contacts on the plane, and off it, needed to decide
  std::size_t min_grasps = 2;        ///< grasps whose patch lies on it (with grasp groups)
  double above_share = 0.9;          ///< of the contacts off the plane, the share above it
  double free_margin = -1.0;         ///< m, free space deeper than this below it refutes it
                                     ///< (< 0: the stage "support" takes the tolerance plus d_thresh
                                     ///< of Eq. 8, half the free-space resolution, as a free
                                     ///< voxel's centre may lie that far from the volume the hand
                                     ///< swept; estimate_support alone, the tolerance)
  std::size_t triplets = 256;        ///< candidates without grasp groups (triplets, or pairs of
                                     ///< contacts for a cylinder)
  double min_radius = 0.04;          ///< m, the thinnest cylinder taken for a pipe
  double attribution = 0.01;         ///< m, a contact this near the answer's surface is the
                                     ///< object's (stage "attribution")
  double sink = 0.02;                ///< m, a plane found: a hypothesis that puts the object
                                     ///< deeper than this below it loses ln wt (Scene::Floor;
                                     ///< 0: off)
  double sink_cost = 1.0;            ///< ln wt it loses at twice `sink` deep and deeper (1: as
                                     ///< much as every contact beyond d_outlier)
};

/// Why no support was found: the test at which the candidate with the most contacts on it failed
/// (the one most likely the support), in the order the tests run (a later one: it passed every
/// test before it).
enum class SupportVerdict : int {
  not_looked = 0,      ///< support.mode off
  no_candidate,        ///< no flat patch (no triplet, no pair of patches for a cylinder)
  few_contacts,        ///< fewer than support.min_contacts contacts on any candidate (or no fit)
  few_grasps,          ///< fewer than min_grasps grasps' patches on it
  side_unclear,        ///< the hands' free points do not tell its free side (4 to 1)
  rest_not_above,      ///< too few contacts off it, or too few of those on its free side
  free_behind,         ///< free space below it (inside a cylinder) where it was touched
  found,               ///< a support was found
};
/// "found", "few_grasps", ...: the name the answer's JSON and the run store's report use.
const char* to_string(SupportVerdict v);

/// The support a step found: a plane or a cylinder, world frame.
struct SupportSurface {
  enum class Shape { plane, cylinder };
  bool found = false;
  Shape shape = Shape::plane;
  Vec3 normal = Vec3::UnitZ();       ///< plane: unit, up (the free side)
  double offset = 0.0;               ///< plane: normal . x = offset
  Vec3 axis = Vec3::UnitX();         ///< cylinder: unit, along its axis
  Vec3 point = Vec3::Zero();         ///< cylinder: the point of its axis nearest its contacts' centroid
  double radius = 0.0;               ///< cylinder: m
  std::size_t contacts_on = 0;       ///< input contacts within the tolerance (found = false: of the
                                     ///< largest candidate, when it got that far)
  std::size_t contacts_above = 0;    ///< input contacts above it (outside a cylinder) beyond the tolerance
  std::size_t grasps_on = 0;         ///< grasps whose patch lies on it
  std::size_t candidates = 0;        ///< candidates examined
  SupportVerdict verdict = SupportVerdict::not_looked;   ///< found, or why not

  /// Positive on the free side: above the plane, outside the cylinder.
  double signed_distance(const Vec3& x) const {
    if (shape == Shape::plane) return normal.dot(x) - offset;
    const Vec3 d = x - point;
    return (d - axis.dot(d) * axis).norm() - radius;
  }
  /// Whether it explains a contact at x: within `tolerance` of it, or below it (inside a
  /// cylinder) by up to kBelow tolerances. Nothing of the object lies below its support, while
  /// the arm's error moves a grasp's contacts on the support together, by more than the
  /// tolerance (underwater: 3 mm per axis and 1 degree per grasp), and mostly into it as the hand
  /// pressed there.
  static constexpr double kBelow = 3.0;
  bool explains(const Vec3& x, double tolerance) const {
    const double d = signed_distance(x);
    return d < tolerance && d > -kBelow * tolerance;
  }
  /// The unit normal towards the free side at the surface point nearest x (on a cylinder's axis:
  /// any direction across it).
  Vec3 normal_at(const Vec3& x) const {
    if (shape == Shape::plane) return normal;
    const Vec3 d = x - point;
    const Vec3 r = d - axis.dot(d) * axis;
    if (r.norm() > 0.0) return r.normalized();
    return (std::abs(axis.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(axis).normalized();
  }
};

/// The support of one step's contacts (world frame), of settings.mode's shape, or found = false
/// (also with mode off). Throws ts::Error naming
/// the field ("support.tolerance", ...) on settings out of range.
SupportSurface estimate_support(const PointCloud& contacts, const GraspGroups& grasps, const std::vector<Vec3>& free,
                              const SupportSettings& settings, std::uint64_t seed, std::uint64_t step);

/// `contacts` without the points the support explains (SupportSurface::explains); `grasps` likewise
/// (their free points and pivots kept, grasps left empty kept empty).
PointCloud without_support(const PointCloud& contacts, const SupportSurface& support, double tolerance);
GraspGroups without_support(const GraspGroups& grasps, const SupportSurface& support, double tolerance);

}  // namespace recognition
}  // namespace ts
