#include "datasets/shapes.hpp"

#include <cmath>
#include <numbers>

namespace ts::datasets {

Mesh ring_prism(const std::vector<Vec3>& bottom, const std::vector<Vec3>& top,
                const Vec3& bottom_centre, const Vec3& top_centre) {
  const int n = static_cast<int>(bottom.size());
  Mesh m;
  m.vertices = bottom;
  m.vertices.insert(m.vertices.end(), top.begin(), top.end());
  m.vertices.push_back(bottom_centre);
  m.vertices.push_back(top_centre);
  const int cb = 2 * n, ct = 2 * n + 1;
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    m.faces.emplace_back(cb, j, i);
    m.faces.emplace_back(ct, n + i, n + j);
    m.faces.emplace_back(i, j, n + j);
    m.faces.emplace_back(i, n + j, n + i);
  }
  Eigen::AlignedBox3d box;
  for (const Vec3& v : m.vertices) box.extend(v);
  for (Vec3& v : m.vertices) v -= box.center();
  return m;
}

Mesh slanted_prism(const std::vector<double>& radii, double h, double slant_x, double slant_y) {
  constexpr double pi = std::numbers::pi;
  const int n = static_cast<int>(radii.size());
  std::vector<Vec3> bottom, top;
  for (int i = 0; i < n; ++i) {
    const double x = radii[i] * std::cos(2 * pi * i / n), y = radii[i] * std::sin(2 * pi * i / n);
    bottom.emplace_back(x, y, -h / 2);
    top.emplace_back(x, y, h / 2 + slant_x * x + slant_y * y);
  }
  return ring_prism(bottom, top, Vec3(0, 0, -h / 2), Vec3(0, 0, h / 2));
}

}  // namespace ts::datasets
