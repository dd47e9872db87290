// Congruent objects: two database objects whose surfaces coincide within a tolerance after a
// rigid motion (rotation and translation; no scaling) are congruent, and no touch can tell them
// apart. Two that coincide only after a reflection are mirror images (a left and a right part):
// flagged separately, since their surfaces do differ.
//
// How a pair is decided (compare_shapes):
//  1. Signature prefilter (may_be_congruent): each surface has a rigid-motion- and
//     reflection-invariant signature, its size (twice the largest distance of a vertex from the
//     area-weighted surface centroid) and its three principal spreads (square roots of the
//     eigenvalues of the area-weighted surface covariance). Surfaces within eps of each other have
//     spreads within about eps and sizes within about 2 eps, so pairs whose sizes differ by more
//     than 2.5 eps or a spread by more than 1.5 eps are not compared (eps = tolerance x the
//     larger size).
//  2. Alignment: centroids onto each other; rotations from the principal axes (every sign choice:
//     proper ones for congruence, improper ones for mirror images); when two spreads are alike
//     (a flange, a nut: one axis defined), the defined axes onto each other and every turn about
//     them in 3 degree steps (and reflected); when all three are (a cube, a regular octahedron),
//     from registering two extreme vertices of one object onto every pair of the other's with the
//     same radii and angle, against the other object and against its reflection. Candidates are
//     ranked by the distances of a few surface points.
//  3. Refinement: point-to-point ICP of a surface sample onto the exact closest points of the
//     other mesh.
//  4. Check: the largest distance, both ways, of each surface sample to the other mesh (exact
//     point-to-triangle distances, a bounding-volume hierarchy). Congruent when it is at most the
//     tolerance for a proper motion; mirror images when an improper one achieves it and no
//     proper one comes within twice the tolerance.
// Everything is deterministic (fixed-seed samples, fixed candidate order, per-pair slots).
#pragma once

#include "engine/core.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <vector>

namespace ts {
inline namespace geometry {

struct CongruenceSettings {
  /// Largest surface distance allowed, as a fraction of the larger object's size (the size: twice
  /// the largest distance of its surface from its surface centroid). 0.01: 2 mm for 200 mm objects.
  double tolerance = 0.01;
  std::size_t samples = 2000;   ///< surface points per object for the refinement and the check
  std::uint64_t seed = 1;       ///< surface sampling
};

/// Rigid-motion- and reflection-invariant summary of a mesh surface (metres).
struct ShapeSignature {
  double size = 0.0;                  ///< 2 x largest distance of a vertex from the surface centroid
  std::array<double, 3> spread{};     ///< sqrt of the surface covariance's eigenvalues, ascending
};

ShapeSignature surface_signature(const Mesh& mesh);

/// Necessary condition for two surfaces to be congruent or mirror images within `tolerance`
/// (relative, as CongruenceSettings::tolerance): sizes within 2.5 eps, spreads within 1.5 eps.
bool may_be_congruent(const ShapeSignature& a, const ShapeSignature& b, double tolerance);

enum class Congruence : std::uint8_t { none = 0, congruent = 1, mirror = 2 };
const char* to_string(Congruence c);

/// A mesh prepared for comparisons: surface sample, centroid, principal axes, distance queries.
class CongruenceShape {
 public:
  CongruenceShape(const Mesh& mesh, const CongruenceSettings& settings);
  ~CongruenceShape();
  CongruenceShape(CongruenceShape&&) noexcept;
  CongruenceShape& operator=(CongruenceShape&&) noexcept;

  const ShapeSignature& signature() const;
  const Vec3& centroid() const;
  const Mat3& axes() const;                  ///< principal axes (columns), ascending spread
  const std::vector<Vec3>& sample() const;   ///< area-uniform surface sample
  const std::vector<Vec3>& vertices() const; ///< mesh vertices relative to the centroid
  /// Distance from p to the surface (exact).
  double distance(const Vec3& p) const;
  /// Closest surface point to p.
  Vec3 closest(const Vec3& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The outcome of comparing a with b.
struct CongruenceMatch {
  Congruence kind = Congruence::none;
  /// Largest surface distance, both ways, at the best proper alignment / the best improper one,
  /// relative to the larger size (infinity: not tried; above 3 x the tolerance the check stops
  /// early, so the value is then only a lower bound).
  double proper_distance = std::numeric_limits<double>::infinity();
  double mirror_distance = std::numeric_limits<double>::infinity();
  /// The accepted motion x_b = linear * x_a + translation (det linear = -1 for a mirror image);
  /// for `none`, the best proper one.
  Mat3 linear = Mat3::Identity();
  Vec3 translation = Vec3::Zero();
  /// The distance of the accepted kind (proper_distance for none).
  double distance() const { return kind == Congruence::mirror ? mirror_distance : proper_distance; }
};

CongruenceMatch compare_shapes(const CongruenceShape& a, const CongruenceShape& b,
                               const CongruenceSettings& settings = {});
/// Convenience: prepares both meshes, then compare_shapes.
CongruenceMatch compare_meshes(const Mesh& a, const Mesh& b, const CongruenceSettings& settings = {});

/// A congruent or mirror pair of objects (a < b, indices into the caller's object list).
struct CongruentPair {
  std::uint32_t a = 0, b = 0;
  Congruence kind = Congruence::congruent;
  double distance = 0.0;   ///< relative, as CongruenceMatch::distance()
  /// The motion found, x_b = linear * x_a + translation (object frames): a pose of b carries
  /// over to a as T_world_a = T_world_b * motion.
  Mat3 linear = Mat3::Identity();
  Vec3 translation = Vec3::Zero();
};

struct CongruenceSearchStats {
  std::size_t candidates = 0;   ///< pairs that passed the signature prefilter
  std::size_t prepared = 0;     ///< shapes prepared (an object may be prepared in several batches)
  std::size_t found = 0;        ///< congruent and mirror pairs
  double seconds = 0.0;
};

/// Every congruent or mirror pair (i, j), i < j, among `signatures.size()` objects with
/// j >= first_new (0: all pairs; n - 1: those of the last object, as `db add` needs). Candidate
/// pairs come from the signature prefilter; `mesh_of(i)` gives object i's mesh (called from
/// several threads, possibly more than once per object: shapes are prepared in batches of at
/// most `batch_objects` objects, which bounds memory). Sorted by (a, b). Uses TBB.
std::vector<CongruentPair> find_congruent_pairs(const std::vector<ShapeSignature>& signatures,
                                                const std::function<Mesh(std::size_t)>& mesh_of,
                                                std::size_t first_new, const CongruenceSettings& settings,
                                                CongruenceSearchStats* stats = nullptr,
                                                std::size_t batch_objects = 64);

/// Classes of congruent objects from congruent pairs (union-find; mirror pairs ignored): each
/// class with at least two members, members ascending, classes ordered by their first member.
std::vector<std::vector<std::size_t>> congruence_classes(std::size_t n, const std::vector<CongruentPair>& pairs);

}  // namespace geometry
}  // namespace ts
