// Constructive solid geometry for the parametric catalogue: solids are trees of closed
// triangle-mesh primitives (tessellated here) combined by union, difference and intersection.
// mesh_shape() turns each primitive into a narrow-band OpenVDB level set
// (tools::meshToLevelSet), combines them with tools::csgUnion / csgDifference /
// csgIntersection and meshes the result with tools::volumeToMesh (quads split into triangles,
// faces wound outward). OpenVDB stays inside csg.cpp.
#pragma once

#include "engine/core.hpp"

#include <memory>
#include <vector>

namespace ts::catalogue {

using Vec2 = Eigen::Vector2d;

/// A solid under construction (an immutable CSG tree; copies share nodes).
class Shape {
 public:
  enum class Op { Leaf, Union, Difference, Intersection };
  Shape() = default;
  /// A closed triangle mesh (winding does not matter: sign comes from OpenVDB's flood fill).
  static Shape leaf(Mesh mesh);
  /// The same solid moved by T (p' = T p).
  Shape moved(const Pose& T) const;

  friend Shape operator|(const Shape& a, const Shape& b);  ///< union
  friend Shape operator-(const Shape& a, const Shape& b);  ///< difference a \ b
  friend Shape operator&(const Shape& a, const Shape& b);  ///< intersection

  bool empty() const { return !node_; }

  struct Node {
    Op op = Op::Leaf;
    Mesh mesh;                 ///< leaf only
    std::vector<Shape> kids;   ///< two for an operation
    Pose T = Pose::Identity(); ///< applied to the whole subtree
  };
  const Node* node() const { return node_.get(); }

 private:
  std::shared_ptr<const Node> node_;
};

/// Union of many shapes (empty shapes skipped).
Shape unite(const std::vector<Shape>& shapes);

/// Result of meshing a solid.
struct MeshedShape {
  Mesh mesh;                  ///< closed when valid, faces wound outward
  std::size_t quads = 0;      ///< quads split by volumeToMesh's output
  bool flipped = false;       ///< volumeToMesh's winding was inward and has been flipped
};

/// Level sets of voxel `voxel` (m) and half-width `half_width` voxels, combined and meshed at
/// the zero iso-surface (adaptivity 0). Throws ts::Error on an empty shape.
MeshedShape mesh_shape(const Shape& shape, double voxel, double half_width = 3.0);

/// Mesh validity as the catalogue requires it.
struct MeshCheck {
  std::size_t boundary_edges = 0;     ///< edges used by one face
  std::size_t nonmanifold_edges = 0;  ///< edges used by more than two faces
  std::size_t misoriented_edges = 0;  ///< edges whose two faces run it the same way
  std::size_t degenerate_faces = 0;   ///< repeated vertex or area below 1e-12 of the bbox diagonal^2
  bool finite = true;                 ///< every coordinate finite
  double volume = 0.0;                ///< signed, m^3 (> 0 when wound outward)
  bool valid() const {
    return boundary_edges == 0 && nonmanifold_edges == 0 && misoriented_edges == 0 &&
           degenerate_faces == 0 && finite && volume > 0.0;
  }
  std::string describe() const;       ///< "3 boundary edges, 1 degenerate face"
};
MeshCheck check_mesh(const Mesh& mesh);

// --- primitives (closed triangle meshes) -----------------------------------------------------
namespace prim {

/// Segments of a circle of radius r so that the chord error stays below voxel / 8 (16..256).
int segments(double r, double voxel);
/// Solid of revolution about z of a simple closed profile polygon of (r, z) points, r >= 0;
/// vertices with r == 0 lie on the axis (poles). `phase`: angle of the first segment, rad.
Mesh lathe(const std::vector<Vec2>& profile, int segments, double phase = 0.0);
/// Convex polygon (x, y), counter-clockwise, extruded over z in [z0, z1].
Mesh prism(const std::vector<Vec2>& polygon, double z0, double z1);
Mesh box(const Vec3& lo, const Vec3& hi);
Mesh cylinder(double r, double z0, double z1, int segments);            ///< axis z
Mesh tube(double r_in, double r_out, double z0, double z1, int segments); ///< axis z
Mesh cone(double r0, double r1, double z0, double z1, int segments);    ///< frustum, axis z
Mesh torus(double major, double minor, int segments_major, int segments_minor);  ///< axis z
Mesh sphere(double r, int segments);
/// Regular hexagonal prism, across-flats `s`, axis z, flats parallel to x.
Mesh hex_prism(double s, double z0, double z1);
/// Circular sector of radius r from angle 0 to `angle` (rad, <= pi) extruded over [z0, z1].
Mesh sector(double r, double angle, double z0, double z1);

}  // namespace prim

/// Rotation taking +z to `axis` (unit), as a pose with translation `origin`.
Pose frame(const Vec3& origin, const Vec3& axis);

}  // namespace ts::catalogue
