// Scenes of the simulator (issue 58): what lies around the explored object besides water.
//
// `seabed`: the object rests on a support surface, the seabed, which the hand touches as it
// touches the object. World frame, gravity along -z. The support is a height field over a square
// patch about the object's footprint: a plane whose upward normal is tilted `slope_deg` from +z
// about a seeded horizontal axis, plus sediment relief (a seeded sum of three sinusoids of
// wavelength about `relief_wavelength_m`, peak amplitude `relief_m`), triangulated on a grid. It is
// lowered along its normal until no vertex of the object lies below it, then raised by `gap_m`:
// with gap 0 the object's lowest point rests on it. A negative gap (the object sunk into the
// sediment) would make the support intersect the object and is refused.
//
// A share `off_target` of the grasps aim at the support instead of the object: a point of the
// support within `off_target_radius_m` of the object's footprint (area-uniform), approached from
// above along its normal, as an ROV pilot feels for the seabed beside the target. The other aims
// are the object's surface points as without a scene; an aim on the object's underside is
// blocked by the support and redrawn (the simulator's operator), so the hand comes from the open
// side.
//
// `panel`: the object is mounted against a fixture, a flat vertical plate (a subsea panel, a
// structure's side). The support is the same patch with its normal horizontal (a seeded
// azimuth), no relief, moved along its normal until it touches the object's farthest point on
// that side. The off-target grasps aim at the panel beside the object, approached along its
// normal; an aim on the object's face against the panel is blocked by it and redrawn.
//
// `pipe`: the object rests on a pipe, a horizontal cylinder of radius `pipe_radius_m` (0: the
// object's bounding radius, at least 5 cm) along a seeded azimuth, under the object's centre,
// raised until it touches the object's lowest point above it (vertices and edges; with `gap_m`,
// until the object's nearest point is that far from it). The object may straddle it (a clamp, a
// bracelet). The off-target grasps aim at the pipe's upper half within `off_target_radius_m` of
// the object along its axis and of its top around it, approached along the surface normal; the
// pipe is triangulated with chords at most 0.2 mm inside the circle. above() treats the pipe as
// unbounded along its axis (its mesh is `extent_m` each side of the object).
//
// `cluttered`: a seabed (as `seabed`, every seabed key applies) with `neighbours` other objects
// of the database lying on it around the object, as a dropped tool lies among others. Neighbour k
// (its mesh given by the caller, datasets::neighbour_choice draws which) is turned to a seeded
// random orientation and put in the seabed's plane at a seeded azimuth (evenly spread, jittered),
// far enough that their bounding spheres are `neighbour_distance_m` apart; it is then lowered
// onto the seabed (its lowest vertex on it) and slid towards the object, in steps of a quarter of
// the distance, while its sampled vertices stay at least the distance from the object's surface
// and outside it, the object's from its own, and it keeps that distance from the neighbours
// placed before it. So the nearest vertices are between the distance and 1.25 times it from the
// other surface, unless a neighbour placed before stopped it farther (sampled at up to 2 000
// vertices of each: a face or an edge between samples may come a little closer).
// The patch reaches past the neighbours by the hand's reach. A share `neighbour_share` of the
// off-target grasps aim at a neighbour (one drawn uniformly, a point area-uniform on its surface,
// approached along its outward normal; an aim blocked by the seabed is redrawn), the rest at the
// seabed.
//
// The support (and a cluttered scene's neighbours, their names and poses) are recorded in the
// log's ground truth (meshes in the world frame), so a study can tell which contacts touched the
// target, the seabed or a neighbour. The recognizer does not see them.
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/mesh.hpp"

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace ts::datasets {

enum class SceneKind { none, seabed, panel, pipe, cluttered };

const char* to_string(SceneKind kind);   ///< "none" / "seabed" / "panel" / "pipe" / "cluttered"
/// Throws ts::Error naming `file` and `field` for another word.
SceneKind parse_scene_kind(const std::string& word, const std::string& file = {}, const std::string& field = "scene");

struct SceneSettings {
  SceneKind kind = SceneKind::none;
  double slope_deg = 0.0;             ///< deg, the support's tilt from horizontal, in [0, 60]
                                      ///< (a panel: 0, it is vertical)
  double relief_m = 0.0;              ///< m, peak amplitude of the sediment relief (0: flat; a
                                      ///< panel: 0)
  double relief_wavelength_m = 0.12;  ///< m, wavelength of the relief's components
  double gap_m = 0.0;                 ///< m, the object's lowest point above the support (>= 0)
  double off_target = 0.0;            ///< share of grasps aimed at the support, in [0, 1)
  double off_target_radius_m = 0.0;   ///< m, those aims lie within this of the object's
                                      ///< footprint centre (0: 1.5 x the object's radius)
  double extent_m = 0.0;              ///< m, half-size of the support patch about the object
                                      ///< (0: the object's radius + `reach` + 5 cm, so the hand
                                      ///< meets the support wherever it goes down); a pipe: its
                                      ///< half-length
  double pipe_radius_m = 0.0;         ///< m, a pipe's radius (0: the object's bounding radius,
                                      ///< at least 5 cm); only for a pipe
  int neighbours = 2;                 ///< cluttered: other database objects beside the object,
                                      ///< in [1, 8]
  double neighbour_distance_m = 0.05; ///< m, cluttered: their surfaces' distance from the
                                      ///< object's (and each other's), in [0.005, 1]
  double neighbour_share = 0.5;       ///< cluttered: share of the off-target grasps aimed at a
                                      ///< neighbour (the rest at the seabed), in [0, 1]
};

/// A scene's object as the caller gives it: its name and object-frame mesh (the database's).
struct SceneObject {
  std::string name;
  Mesh mesh;
};

/// The `count` neighbours of a cluttered scene around database object `target`: distinct indices
/// of a database of `size` objects, none the target, drawn from `seed` (the same draw for the same
/// arguments). Throws ts::Error naming scene.neighbours when the database has too few others.
std::vector<std::size_t> neighbour_choice(std::size_t size, std::size_t target, int count, std::uint64_t seed);

/// The neighbours of the simulator's settings for a scene `s` (none unless s.kind is cluttered):
/// neighbour_choice(size, target, s.neighbours, seed), each object as `load` gives it.
std::vector<SceneObject> scene_neighbours(const SceneSettings& s, std::size_t size, std::size_t target,
                                          std::uint64_t seed, const std::function<SceneObject(std::size_t)>& load);

/// Throws ts::Error naming the key ("scene.slope_deg", ...) of a setting out of range.
void validate(const SceneSettings& s);

/// The support of a `seabed` scene under `object_mesh` (object frame) placed at `T_world_object`.
/// `reach`: the hand's reach (m), for the default extent. Deterministic in `seed`. Throws
/// ts::Error naming the key when s.kind is none or a setting is out of range.
class Support {
 public:
  Support(const Mesh& object_mesh, const Pose& T_world_object, const SceneSettings& s, double reach,
          std::uint64_t seed);

  /// World frame; faces wound so that their normals point up (away from the sediment).
  const Mesh& mesh() const { return mesh_; }
  /// Unit upward normal of the support's plane (before relief), world frame; a pipe: +z, the
  /// side the object rests on.
  const Vec3& up() const { return n_; }
  /// A pipe's axis (unit, horizontal) and radius; the axis passes through axis_point().
  const Vec3& axis() const { return e1_; }
  const Vec3& axis_point() const { return origin_; }
  double pipe_radius() const { return pipe_radius_; }
  /// The support's point above the plane point origin + u e1 + v e2 (on its triangulated surface;
  /// a pipe: on its top, u along the axis and v across it, on the axis' level beside it).
  Vec3 point(double u, double v) const;
  /// How far world point x lies above the support, along up() (negative: below it); a pipe:
  /// its distance from the pipe's surface (negative: inside it).
  double above(const Vec3& x) const;
  /// An aim of an off-target grasp: a point of the support within off_target_radius of the
  /// object's footprint centre (uniform over the disc) and the upward normal of the face under it;
  /// a pipe: a point of its upper half within off_target_radius along its axis, and its normal.
  std::pair<Vec3, Vec3> aim(Rng& rng) const;

 private:
  /// The grid cell holding (u, v): its corner heights (i, j), (i + 1, j), (i + 1, j + 1),
  /// (i, j + 1) and where (u, v) lies in it (fractions, clamped to the patch's cells).
  struct Cell {
    double a, b, c, d, fu, fv;
  };
  Cell cell(double u, double v) const;
  double height(double u, double v) const;   ///< above the plane, on the triangulated grid
  /// How far the support (heights so far) may rise before it meets the object (world frame,
  /// bounding radius r about origin_); with relief, also along edges and at grid vertices.
  double clearance(const Mesh& world, double r, bool relief) const;
  void triangulate();                        ///< mesh_ from the grid
  /// A pipe: origin_ on its axis under the object's centre, raised until the object (`world`,
  /// bounding radius r about `centre`) is the gap from it; mesh_ its cylinder.
  void place_pipe(const Mesh& world, const Vec3& centre, double r, const SceneSettings& s);
  Vec3 face_normal(double u, double v) const;

  Vec3 origin_, e1_, e2_, n_;
  double half_ = 0.0, spacing_ = 0.0, radius_ = 0.0, pipe_radius_ = 0.0;
  int cells_ = 1;
  std::vector<double> h_;                     ///< (cells + 1)^2 heights, row-major in (i: u, j: v)
  Mesh mesh_;
};

/// A neighbour as placed: its name, pose and world-frame mesh.
struct PlacedObject {
  std::string name;
  Pose T_world_object = Pose::Identity();
  Mesh world;
};

/// The half-size of a cluttered scene's seabed patch that reaches past neighbours of bounding
/// radii up to `neighbour_radius` (see above): the object's radius, the distance, twice that
/// radius, the hand's reach and 5 cm.
double cluttered_extent(double object_radius, double neighbour_radius, const SceneSettings& s, double reach);

/// The neighbours of a cluttered scene (see above) around `object_world` (world frame) on
/// `seabed`, one per entry of `objects` (s.neighbours of them). Deterministic in `seed`. Throws
/// ts::Error naming the key when a neighbour cannot be placed apart from the others.
std::vector<PlacedObject> place_neighbours(const Mesh& object_world, const Support& seabed,
                                           const std::vector<SceneObject>& objects, const SceneSettings& s,
                                           std::uint64_t seed);

}  // namespace ts::datasets
