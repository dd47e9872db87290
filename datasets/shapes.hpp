// Procedural meshes for studies and tests that need shapes of known form without a mesh file
// (the stress study's asymmetric prisms; the tests' prisms).
#pragma once

#include "engine/core.hpp"

#include <vector>

namespace ts::datasets {

/// The closed solid between two rings of n vertices (top[i] above bottom[i], both rings
/// counter-clockwise seen from +z) and the centres of its caps: each cap a fan about its centre,
/// each side two triangles, faces wound outward; recentred on its bounding box. Vertices: the
/// bottom ring, the top ring, the bottom centre, the top centre.
Mesh ring_prism(const std::vector<Vec3>& bottom, const std::vector<Vec3>& top,
                const Vec3& bottom_centre, const Vec3& top_centre);

/// A closed prism over a star-shaped polygon (vertex i at angle 2 pi i / n, radius radii[i],
/// n = radii.size() >= 3) of height h about z, its top raised by slant . (x, y) (the top is the
/// plane z = h / 2 + slant_x x + slant_y y): a ring_prism. With equal radii and no slant: the
/// regular n-gon prism of circumradius r.
Mesh slanted_prism(const std::vector<double>& radii, double h, double slant_x, double slant_y);

}  // namespace ts::datasets
