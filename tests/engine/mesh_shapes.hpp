// Generated closed test meshes with known geometry (outward winding, shared vertices).
#pragma once

#include "engine/core.hpp"

#include <cmath>
#include <map>
#include <numbers>
#include <utility>

namespace ts::test {

/// Icosphere: an icosahedron subdivided `levels` times, projected to the sphere of `radius`.
inline Mesh make_sphere(double radius, int levels, const Vec3& centre = Vec3::Zero()) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3> v = {{-1, t, 0}, {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (auto& p : v) p.normalize();
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      const int id = static_cast<int>(v.size()) - 1;
      mid.emplace(key, id);
      return id;
    };
    std::vector<Eigen::Vector3i> g;
    for (const auto& tri : f) {
      const int a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]), c = midpoint(tri[2], tri[0]);
      g.emplace_back(tri[0], a, c);
      g.emplace_back(tri[1], b, a);
      g.emplace_back(tri[2], c, b);
      g.emplace_back(a, b, c);
    }
    f = std::move(g);
  }
  Mesh m;
  for (const auto& p : v) m.vertices.push_back(centre + radius * p);
  m.faces = std::move(f);
  return m;
}

/// Axis-aligned box [-h, h] (h = half sizes) with each face split into n x n quads (2 triangles).
inline Mesh make_box(const Vec3& half, int n, const Vec3& centre = Vec3::Zero()) {
  Mesh m;
  std::map<std::array<int, 3>, int> ids;  // lattice coordinates in [0, n]^3 -> vertex
  auto vertex = [&](std::array<int, 3> g) {
    auto it = ids.find(g);
    if (it != ids.end()) return it->second;
    Vec3 p;
    for (int k = 0; k < 3; ++k) p[k] = centre[k] + half[k] * (2.0 * g[k] / n - 1.0);
    m.vertices.push_back(p);
    const int id = static_cast<int>(m.vertices.size()) - 1;
    ids.emplace(g, id);
    return id;
  };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, w = (axis + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          auto at = [&](int di, int dj) {
            std::array<int, 3> g{};
            g[axis] = side * n;
            g[u] = i + di;
            g[w] = j + dj;
            return vertex(g);
          };
          const int a = at(0, 0), b = at(1, 0), c = at(1, 1), d = at(0, 1);
          // (u, w, axis) is right-handed, so (a, b, c) faces +axis; flip on the low side.
          if (side == 1) {
            m.faces.emplace_back(a, b, c);
            m.faces.emplace_back(a, c, d);
          } else {
            m.faces.emplace_back(a, c, b);
            m.faces.emplace_back(a, d, c);
          }
        }
      }
    }
  }
  return m;
}

/// Torus around the z axis: major radius R, minor radius r, nu x nv quads.
inline Mesh make_torus(double R, double r, int nu, int nv) {
  Mesh m;
  for (int i = 0; i < nu; ++i) {
    const double a = 2.0 * std::numbers::pi * i / nu;
    for (int j = 0; j < nv; ++j) {
      const double b = 2.0 * std::numbers::pi * j / nv;
      m.vertices.emplace_back((R + r * std::cos(b)) * std::cos(a), (R + r * std::cos(b)) * std::sin(a),
                              r * std::sin(b));
    }
  }
  auto id = [&](int i, int j) { return (i % nu) * nv + (j % nv); };
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const int a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
      m.faces.emplace_back(a, b, c);
      m.faces.emplace_back(a, c, d);
    }
  return m;
}

/// The same mesh with every face's winding reversed.
inline Mesh flipped(Mesh m) {
  for (auto& f : m.faces) std::swap(f[1], f[2]);
  return m;
}

}  // namespace ts::test
