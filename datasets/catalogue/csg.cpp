#include "datasets/catalogue/csg.hpp"
#include "engine/detail.hpp"

#include "engine/geometry/eigen_solvers.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <unordered_map>

namespace ts::catalogue {

namespace {

using Grid = openvdb::FloatGrid;

using detail::init_openvdb;

std::shared_ptr<Shape::Node> make_node(Shape::Op op, const Shape& a, const Shape& b) {
  auto n = std::make_shared<Shape::Node>();
  n->op = op;
  n->kids = {a, b};
  return n;
}

/// Level set of a subtree under the accumulated transform T.
Grid::Ptr level_set(const Shape& s, const Pose& T, const openvdb::math::Transform& xform, float half_width) {
  const auto* n = s.node();
  const Pose TT = T * n->T;
  if (n->op == Shape::Op::Leaf) {
    std::vector<openvdb::Vec3s> points;
    points.reserve(n->mesh.vertices.size());
    for (const auto& v : n->mesh.vertices) {
      const Vec3 p = TT * v;
      points.emplace_back(float(p.x()), float(p.y()), float(p.z()));
    }
    std::vector<openvdb::Vec3I> tris;
    tris.reserve(n->mesh.faces.size());
    for (const auto& f : n->mesh.faces) tris.emplace_back(unsigned(f[0]), unsigned(f[1]), unsigned(f[2]));
    return openvdb::tools::meshToLevelSet<Grid>(xform, points, tris, half_width);
  }
  auto a = level_set(n->kids[0], TT, xform, half_width);
  auto b = level_set(n->kids[1], TT, xform, half_width);
  switch (n->op) {
    case Shape::Op::Union: openvdb::tools::csgUnion(*a, *b); break;
    case Shape::Op::Difference: openvdb::tools::csgDifference(*a, *b); break;
    case Shape::Op::Intersection: openvdb::tools::csgIntersection(*a, *b); break;
    default: break;
  }
  return a;
}

Mesh ring_lathe_closed(std::vector<Vec2> profile, int segments, double phase) {
  // Vertices: one pole per on-axis profile vertex, a ring per off-axis one.
  Mesh m;
  const std::size_t n = profile.size();
  std::vector<int> first(n);
  std::vector<bool> pole(n);
  for (std::size_t i = 0; i < n; ++i) {
    pole[i] = profile[i].x() <= 0.0;
    first[i] = static_cast<int>(m.vertices.size());
    if (pole[i]) {
      m.vertices.emplace_back(0.0, 0.0, profile[i].y());
    } else {
      for (int k = 0; k < segments; ++k) {
        const double a = phase + 2.0 * std::numbers::pi * k / segments;
        m.vertices.emplace_back(profile[i].x() * std::cos(a), profile[i].x() * std::sin(a), profile[i].y());
      }
    }
  }
  auto vid = [&](std::size_t i, int k) { return pole[i] ? first[i] : first[i] + (k % segments); };
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t j = (i + 1) % n;
    if (pole[i] && pole[j]) continue;
    for (int k = 0; k < segments; ++k) {
      const int a = vid(i, k), b = vid(i, k + 1), c = vid(j, k + 1), d = vid(j, k);
      if (!pole[i] && !pole[j]) {
        m.faces.emplace_back(a, b, c);
        m.faces.emplace_back(a, c, d);
      } else if (pole[i]) {
        m.faces.emplace_back(a, c, d);
      } else {
        m.faces.emplace_back(a, b, c);
      }
    }
  }
  return m;
}

}  // namespace

// --- Shape -----------------------------------------------------------------------------------
Shape Shape::leaf(Mesh mesh) {
  auto n = std::make_shared<Node>();
  n->mesh = std::move(mesh);
  Shape s;
  s.node_ = std::move(n);
  return s;
}

Shape Shape::moved(const Pose& T) const {
  auto n = std::make_shared<Node>(*node_);
  n->T = T * node_->T;
  Shape s;
  s.node_ = std::move(n);
  return s;
}

Shape operator|(const Shape& a, const Shape& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  Shape s;
  s.node_ = make_node(Shape::Op::Union, a, b);
  return s;
}
Shape operator-(const Shape& a, const Shape& b) {
  if (b.empty()) return a;
  Shape s;
  s.node_ = make_node(Shape::Op::Difference, a, b);
  return s;
}
Shape operator&(const Shape& a, const Shape& b) {
  Shape s;
  s.node_ = make_node(Shape::Op::Intersection, a, b);
  return s;
}

Shape unite(const std::vector<Shape>& shapes) {
  Shape s;
  for (const auto& x : shapes) s = s | x;
  return s;
}

// --- meshing ---------------------------------------------------------------------------------
MeshedShape mesh_shape(const Shape& shape, double voxel, double half_width) {
  if (shape.empty()) throw Error("empty shape");
  init_openvdb();
  const auto xform = openvdb::math::Transform::createLinearTransform(voxel);
  auto grid = level_set(shape, Pose::Identity(), *xform, static_cast<float>(half_width));
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> tris;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(*grid, points, tris, quads, 0.0, 0.0);

  MeshedShape out;
  Mesh& m = out.mesh;
  m.vertices.reserve(points.size());
  for (const auto& p : points) m.vertices.emplace_back(p.x(), p.y(), p.z());
  m.faces.reserve(tris.size() + 2 * quads.size());
  for (const auto& t : tris) m.faces.emplace_back(int(t[0]), int(t[1]), int(t[2]));
  out.quads = quads.size();
  auto area2 = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    return (m.vertices[b] - m.vertices[a]).cross(m.vertices[c] - m.vertices[a]).squaredNorm();
  };
  for (const auto& q : quads) {
    // Split along the shorter diagonal (better-shaped triangles), unless that makes a
    // zero-area triangle (a quad with two coincident corners) and the other split does not.
    const double ac = (m.vertices[q[0]] - m.vertices[q[2]]).squaredNorm();
    const double bd = (m.vertices[q[1]] - m.vertices[q[3]]).squaredNorm();
    const double min_ac = std::min(area2(q[0], q[1], q[2]), area2(q[0], q[2], q[3]));
    const double min_bd = std::min(area2(q[0], q[1], q[3]), area2(q[1], q[2], q[3]));
    const double tiny = 1e-6 * voxel * voxel * voxel * voxel;  // (area)^2 of 1e-3 voxel^2
    bool use_ac = ac <= bd;
    if (use_ac && min_ac <= tiny && min_bd > tiny) use_ac = false;
    if (!use_ac && min_bd <= tiny && min_ac > tiny) use_ac = true;
    if (use_ac) {
      m.faces.emplace_back(int(q[0]), int(q[1]), int(q[2]));
      m.faces.emplace_back(int(q[0]), int(q[2]), int(q[3]));
    } else {
      m.faces.emplace_back(int(q[0]), int(q[1]), int(q[3]));
      m.faces.emplace_back(int(q[1]), int(q[2]), int(q[3]));
    }
  }
  // Wind outward: volumeToMesh's convention, checked rather than assumed.
  double six_v = 0.0;
  for (const auto& f : m.faces)
    six_v += m.vertices[f[0]].dot(m.vertices[f[1]].cross(m.vertices[f[2]]));
  if (six_v < 0.0) {
    for (auto& f : m.faces) std::swap(f[1], f[2]);
    out.flipped = true;
  }
  return out;
}

std::string MeshCheck::describe() const {
  std::string s;
  auto add = [&](std::size_t n, const char* what) {
    if (!n) return;
    if (!s.empty()) s += ", ";
    s += std::to_string(n) + " " + what;
  };
  add(boundary_edges, "boundary edges");
  add(nonmanifold_edges, "non-manifold edges");
  add(misoriented_edges, "inconsistently wound edges");
  add(degenerate_faces, "degenerate faces");
  if (!finite) s += std::string(s.empty() ? "" : ", ") + "non-finite coordinates";
  if (volume <= 0.0) s += std::string(s.empty() ? "" : ", ") + "non-positive volume";
  return s.empty() ? "valid" : s;
}

MeshCheck check_mesh(const Mesh& m) {
  MeshCheck c;
  Eigen::AlignedBox3d box;
  for (const auto& v : m.vertices) {
    if (!v.allFinite()) c.finite = false;
    box.extend(v);
  }
  if (!c.finite || m.faces.empty()) {
    c.volume = 0.0;
    return c;
  }
  const double min_area = 1e-12 * box.sizes().squaredNorm();
  // Directed edge (a -> b) -> count; an undirected edge must appear once each way.
  std::unordered_map<std::uint64_t, std::uint32_t> directed;
  directed.reserve(m.faces.size() * 3);
  const Vec3 centre = box.center();
  double six_v = 0.0;
  for (const auto& f : m.faces) {
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) {
      ++c.degenerate_faces;
      continue;
    }
    const Vec3 a = m.vertices[f[0]] - centre, b = m.vertices[f[1]] - centre, d = m.vertices[f[2]] - centre;
    if (0.5 * (b - a).cross(d - a).norm() <= min_area) ++c.degenerate_faces;
    six_v += a.dot(b.cross(d));
    for (int e = 0; e < 3; ++e)
      ++directed[(std::uint64_t(std::uint32_t(f[e])) << 32) | std::uint32_t(f[(e + 1) % 3])];
  }
  c.volume = six_v / 6.0;
  for (const auto& [key, n] : directed) {
    const std::uint64_t a = key >> 32, b = key & 0xffffffffu;
    const auto it = directed.find((b << 32) | a);
    const std::uint32_t back = it == directed.end() ? 0 : it->second;
    if (a > b && it != directed.end()) continue;  // count each undirected edge once (from a < b)
    const std::uint32_t total = n + back;
    if (total == 1) ++c.boundary_edges;
    else if (total > 2) ++c.nonmanifold_edges;
    else if (n != 1 || back != 1) ++c.misoriented_edges;
  }
  return c;
}

// --- primitives ------------------------------------------------------------------------------
namespace prim {

int segments(double r, double voxel) {
  // Chord error r (1 - cos(pi / n)) ~ r pi^2 / (2 n^2) <= voxel / 8.
  const double n = std::numbers::pi * std::sqrt(4.0 * r / std::max(voxel, 1e-9));
  return std::clamp(static_cast<int>(std::ceil(n)), 16, 256);
}

Mesh lathe(const std::vector<Vec2>& profile, int segments, double phase) {
  return ring_lathe_closed(profile, segments, phase);
}

Mesh prism(const std::vector<Vec2>& poly, double z0, double z1) {
  Mesh m;
  const int n = static_cast<int>(poly.size());
  for (const auto& p : poly) m.vertices.emplace_back(p.x(), p.y(), z0);
  for (const auto& p : poly) m.vertices.emplace_back(p.x(), p.y(), z1);
  for (int i = 1; i + 1 < n; ++i) {
    m.faces.emplace_back(0, i + 1, i);
    m.faces.emplace_back(n, n + i, n + i + 1);
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    m.faces.emplace_back(i, j, n + j);
    m.faces.emplace_back(i, n + j, n + i);
  }
  return m;
}

Mesh box(const Vec3& lo, const Vec3& hi) {
  return prism({{lo.x(), lo.y()}, {hi.x(), lo.y()}, {hi.x(), hi.y()}, {lo.x(), hi.y()}}, lo.z(), hi.z());
}

Mesh cylinder(double r, double z0, double z1, int seg) { return lathe({{0, z0}, {r, z0}, {r, z1}, {0, z1}}, seg); }

Mesh tube(double ri, double ro, double z0, double z1, int seg) {
  return lathe({{ri, z0}, {ro, z0}, {ro, z1}, {ri, z1}}, seg);
}

Mesh cone(double r0, double r1, double z0, double z1, int seg) {
  return lathe({{0, z0}, {r0, z0}, {r1, z1}, {0, z1}}, seg);
}

Mesh torus(double major, double minor, int seg_major, int seg_minor) {
  std::vector<Vec2> circle;
  for (int k = 0; k < seg_minor; ++k) {
    const double a = 2.0 * std::numbers::pi * k / seg_minor;
    circle.emplace_back(major + minor * std::cos(a), minor * std::sin(a));
  }
  return lathe(circle, seg_major);
}

Mesh sphere(double r, int seg) {
  std::vector<Vec2> arc;
  const int n = std::max(8, seg / 2);
  for (int k = 0; k <= n; ++k) {
    const double a = -std::numbers::pi / 2 + std::numbers::pi * k / n;
    arc.emplace_back(k == 0 || k == n ? 0.0 : r * std::cos(a), r * std::sin(a));
  }
  return lathe(arc, seg);
}

Mesh hex_prism(double s, double z0, double z1) {
  std::vector<Vec2> hex;
  const double R = s / std::sqrt(3.0);  // circumradius
  for (int k = 0; k < 6; ++k) {
    const double a = std::numbers::pi / 6 + std::numbers::pi / 3 * k;
    hex.emplace_back(R * std::cos(a), R * std::sin(a));
  }
  return prism(hex, z0, z1);
}

Mesh sector(double r, double angle, double z0, double z1) {
  std::vector<Vec2> poly{{0.0, 0.0}};
  const int n = std::max(2, static_cast<int>(std::ceil(angle / (std::numbers::pi / 16))));
  const double R = r / std::cos(angle / n / 2);  // chords outside radius r
  for (int k = 0; k <= n; ++k) {
    const double a = angle * k / n;
    const double rr = (k == 0 || k == n) ? R : R;
    poly.emplace_back(rr * std::cos(a), rr * std::sin(a));
  }
  return prism(poly, z0, z1);
}

}  // namespace prim

Pose frame(const Vec3& origin, const Vec3& axis) {
  Pose T = Pose::Identity();
  T.linear() = quaternion_from_two_vectors(Vec3::UnitZ(), axis.normalized()).toRotationMatrix();
  T.translation() = origin;
  return T;
}

}  // namespace ts::catalogue
