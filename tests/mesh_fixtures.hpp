// Small meshes for tests, and an OFF writer to put them on disk.
#pragma once

#include "engine/core.hpp"
#include "engine/mesh_shapes.hpp"  // flipped()

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <utility>

namespace ts::test {

/// Axis-aligned box, faces wound outward (counter-clockwise seen from outside).
inline Mesh box_mesh(const Vec3& lo, const Vec3& hi) {
  Mesh m;
  for (int i = 0; i < 8; ++i)
    m.vertices.emplace_back(i & 1 ? hi.x() : lo.x(), i & 2 ? hi.y() : lo.y(), i & 4 ? hi.z() : lo.z());
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.faces.emplace_back(q[0], q[1], q[2]);
    m.faces.emplace_back(q[0], q[2], q[3]);
  }
  return m;
}

/// A chiral solid (no rotation maps it onto its mirror image): a cube [-2, 2]^3 and three
/// separate bars of different lengths along +x (9), +y (6) and +z (3).
inline Mesh chiral_mesh() {
  Mesh m;
  for (const auto& [lo, hi] : {std::pair{Vec3(-2, -2, -2), Vec3(2, 2, 2)}, std::pair{Vec3(3, -1.5, -1.5), Vec3(12, 1.5, 1.5)},
                               std::pair{Vec3(-1.5, 3, -1.5), Vec3(1.5, 9, 1.5)}, std::pair{Vec3(-1.5, -1.5, 3), Vec3(1.5, 1.5, 6)}}) {
    const Mesh b = box_mesh(lo, hi);
    const int base = static_cast<int>(m.vertices.size());
    m.vertices.insert(m.vertices.end(), b.vertices.begin(), b.vertices.end());
    for (const auto& f : b.faces) m.faces.emplace_back(f + Eigen::Vector3i::Constant(base));
  }
  return m;
}

/// The mesh moved by x -> L x + t (L orthogonal); faces flipped when L is a reflection, so they
/// stay wound outward.
inline Mesh moved_mesh(Mesh m, const Mat3& L, const Vec3& t) {
  for (auto& v : m.vertices) v = L * v + t;
  if (L.determinant() < 0.0)
    for (auto& f : m.faces) std::swap(f[1], f[2]);
  return m;
}

/// Icosphere of `radius` around `centre`, `subdivisions` times refined; wound outward.
inline Mesh icosphere_mesh(double radius, int subdivisions, const Vec3& centre = Vec3::Zero()) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  Mesh m;
  for (const auto& v : {Vec3(-1, t, 0), Vec3(1, t, 0), Vec3(-1, -t, 0), Vec3(1, -t, 0), Vec3(0, -1, t),
                        Vec3(0, 1, t), Vec3(0, -1, -t), Vec3(0, 1, -t), Vec3(t, 0, -1), Vec3(t, 0, 1),
                        Vec3(-t, 0, -1), Vec3(-t, 0, 1)})
    m.vertices.push_back(v.normalized());
  const int f[20][3] = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                        {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                        {3, 8, 9},  {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (const auto& x : f) m.faces.emplace_back(x[0], x[1], x[2]);
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.vertices.push_back((m.vertices[a] + m.vertices[b]).normalized());
      return mid[key] = static_cast<int>(m.vertices.size()) - 1;
    };
    std::vector<Eigen::Vector3i> faces;
    for (const auto& x : m.faces) {
      const int a = midpoint(x[0], x[1]), b = midpoint(x[1], x[2]), c = midpoint(x[2], x[0]);
      faces.emplace_back(x[0], a, c);
      faces.emplace_back(x[1], b, a);
      faces.emplace_back(x[2], c, b);
      faces.emplace_back(a, b, c);
    }
    m.faces = std::move(faces);
  }
  for (auto& v : m.vertices) v = centre + radius * v;
  return m;
}

inline void write_off(const std::filesystem::path& path, const Mesh& m) {
  std::ofstream out(path);
  out.precision(17);
  out << "OFF\n" << m.vertices.size() << ' ' << m.faces.size() << " 0\n";
  for (const auto& v : m.vertices) out << v.x() << ' ' << v.y() << ' ' << v.z() << '\n';
  for (const auto& f : m.faces) out << "3 " << f[0] << ' ' << f[1] << ' ' << f[2] << '\n';
}

}  // namespace ts::test
