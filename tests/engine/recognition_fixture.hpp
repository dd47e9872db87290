// Synthetic recognition scenes for the engine tests: a small database of analytic shapes
// (sampled surfaces with exact normals, FPFH computed like the database builder does, no
// scanner), and tactile-like contact clouds (round patches of 4 mm taxels, per-patch offsets)
// taken from an object placed at a known pose.
#pragma once

#include "engine/database/database.hpp"
#include "engine/features/fpfh.hpp"
#include "engine/geometry/search.hpp"
#include "engine/recognition/recognizer.hpp"

#include <cmath>
#include <functional>
#include <map>
#include <mutex>
#include <unordered_set>
#include <memory>
#include <numbers>
#include <tuple>

namespace ts::test {

constexpr double kPi = std::numbers::pi;

inline Mesh box_mesh(const Vec3& size) {
  Mesh m;
  const Vec3 h = size / 2;
  for (int i = 0; i < 8; ++i)
    m.vertices.emplace_back((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? h.z() : -h.z());
  const int q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (auto& f : q) {
    m.faces.emplace_back(f[0], f[1], f[2]);
    m.faces.emplace_back(f[0], f[2], f[3]);
  }
  return m;
}

/// Regular n-gon prism (z axis), circumradius r, height h, optionally with each top vertex
/// raised by `twist` * i (breaks the symmetry), recentred on its bounding box.
inline Mesh prism_mesh(int n, double r, double h, double skew = 0.0) {
  Mesh m;
  for (int z = 0; z < 2; ++z)
    for (int i = 0; i < n; ++i) {
      const double rr = r * (1.0 + skew * (i == 0 ? 1.0 : 0.0));
      m.vertices.emplace_back(rr * std::cos(2 * kPi * i / n), rr * std::sin(2 * kPi * i / n),
                              z ? h / 2 + skew * h * i / n : -h / 2);
    }
  m.vertices.emplace_back(0, 0, -h / 2);
  m.vertices.emplace_back(0, 0, h / 2 + skew * h / 2);
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

/// UV sphere (closed, outward), recentred.
inline Mesh sphere_mesh(double r, int rings = 24, int segs = 48) {
  Mesh m;
  m.vertices.emplace_back(0, 0, r);
  for (int i = 1; i < rings; ++i) {
    const double th = kPi * i / rings;
    for (int j = 0; j < segs; ++j) {
      const double ph = 2 * kPi * j / segs;
      m.vertices.emplace_back(r * std::sin(th) * std::cos(ph), r * std::sin(th) * std::sin(ph), r * std::cos(th));
    }
  }
  m.vertices.emplace_back(0, 0, -r);
  const int south = static_cast<int>(m.vertices.size()) - 1;
  for (int j = 0; j < segs; ++j) m.faces.emplace_back(0, 1 + j, 1 + (j + 1) % segs);
  for (int i = 0; i < rings - 2; ++i)
    for (int j = 0; j < segs; ++j) {
      const int a = 1 + i * segs + j, b = 1 + i * segs + (j + 1) % segs;
      const int c = a + segs, d = b + segs;
      m.faces.emplace_back(a, c, d);
      m.faces.emplace_back(a, d, b);
    }
  const int last = 1 + (rings - 2) * segs;
  for (int j = 0; j < segs; ++j) m.faces.emplace_back(south, last + (j + 1) % segs, last + j);
  return m;
}

inline Mesh scaled(Mesh m, double f) {
  for (Vec3& v : m.vertices) v *= f;
  return m;
}

inline std::uint64_t voxel_key(const Vec3& p, double voxel) {
  const auto c = [&](double x) { return static_cast<std::uint64_t>(std::llround(std::floor(x / voxel)) & 0x1fffff); };
  return c(p.x()) | (c(p.y()) << 21) | (c(p.z()) << 42);
}

/// Area-uniform surface samples with face normals, thinned to one per `voxel`.
inline PointCloud sample_surface(const Mesh& m, double voxel, std::uint64_t seed) {
  std::vector<double> cum;
  double total = 0.0;
  for (const auto& f : m.faces) {
    const Vec3 &a = m.vertices[f[0]], &b = m.vertices[f[1]], &c = m.vertices[f[2]];
    total += 0.5 * (b - a).cross(c - a).norm();
    cum.push_back(total);
  }
  const std::size_t n = static_cast<std::size_t>(4.0 * total / (voxel * voxel)) + 100;
  Rng rng(seed);
  std::unordered_set<std::uint64_t> seen;
  seen.reserve(n);
  PointCloud out;
  for (std::size_t i = 0; i < n; ++i) {
    const double u = rng.uniform() * total;
    const std::size_t k = std::min<std::size_t>(std::lower_bound(cum.begin(), cum.end(), u) - cum.begin(), m.faces.size() - 1);
    const auto& f = m.faces[k];
    double r1 = rng.uniform(), r2 = rng.uniform();
    if (r1 + r2 > 1.0) { r1 = 1.0 - r1; r2 = 1.0 - r2; }
    const Vec3 &a = m.vertices[f[0]], &b = m.vertices[f[1]], &c = m.vertices[f[2]];
    const Vec3 p = a + r1 * (b - a) + r2 * (c - a);
    if (!seen.insert(voxel_key(p, voxel)).second) continue;
    out.points.push_back(p);
    out.normals.push_back((b - a).cross(c - a).normalized());
  }
  return out;
}

/// An object source over hand-built objects, with signed distance fields (use_fields = false:
/// none, the evaluation then uses the fine cloud's k-d tree as in the paper).
class TestSource final : public ObjectSource {
 public:
  std::vector<ObjectInfo> infos;
  std::vector<ObjectFeatures> feats;
  std::vector<PointCloud> fines;
  std::vector<Mesh> meshes;
  DatabaseSettings db_settings;
  std::vector<SparseGrid> field_fine, field_coarse;   ///< distance fields (empty: none)
  bool use_fields = true;

  std::size_t size() const override { return infos.size(); }
  const ObjectInfo& info(std::size_t i) const override { return infos.at(i); }
  const DatabaseSettings& settings() const override { return db_settings; }
  ObjectFeatures load_features(std::size_t i) const override { return feats.at(i); }
  PointCloud load_fine(std::size_t i) const override { return fines.at(i); }
  DistanceField load_field(std::size_t i) const override {
    if (!use_fields || field_fine.size() <= i) return DistanceField();
    return DistanceField::from_sparse(field_fine[i], field_coarse[i], true, db_settings.field.coarse_margin);
  }

  void add(const std::string& name, const Mesh& mesh, std::uint64_t seed) {
    const double s = scale_;
    ObjectInfo info;
    info.name = name;
    PointCloud fine = sample_surface(mesh, 0.002 * s, seed);
    PointCloud coarse = sample_surface(mesh, 0.005 * s, seed + 1000);
    Eigen::AlignedBox3d box;
    for (const Vec3& v : mesh.vertices) box.extend(v);
    info.extent = box.sizes();
    info.fine_points = fine.size();
    info.coarse_points = coarse.size();
    info.closed = true;
    const KdTree3 tree(fine.points);
    const FpfhResult fr = compute_fpfh(coarse.points, coarse.normals, fine, tree, db_settings.fpfh);
    ObjectFeatures of;
    of.coarse = coarse;
    of.features = FeatureRows(fr.features);
    const DistanceField field = DistanceField::build(mesh, true, db_settings.field);
    field_fine.push_back(field.fine_sparse());
    field_coarse.push_back(field.coarse_sparse());
    infos.push_back(info);
    feats.push_back(std::move(of));
    fines.push_back(std::move(fine));
    meshes.push_back(mesh);
  }

  explicit TestSource(double scale = 1.0) : scale_(scale) {
    db_settings.fpfh.normal_radius = 0.007 * scale;
    db_settings.fpfh.feature_radius = 0.012 * scale;
    db_settings.max_extent = 0.2 * scale;
    db_settings.field.fine_voxel = 0.002 * scale;
    db_settings.field.coarse_voxel = 0.01 * scale;
    db_settings.field.coarse_margin = 0.2 * scale;
  }

 private:
  double scale_;
};

/// Six shapes of about 10-15 cm (scaled by `scale`).
inline std::shared_ptr<TestSource> build_source(double scale) {
  auto src = std::make_shared<TestSource>(scale);
  src->add("box", scaled(box_mesh(Vec3(0.12, 0.08, 0.05)), scale), 1);
  src->add("nut", scaled(prism_mesh(5, 0.06, 0.04), scale), 2);
  src->add("ball", scaled(sphere_mesh(0.05), scale), 3);
  src->add("hexbar", scaled(prism_mesh(6, 0.03, 0.14), scale), 4);
  src->add("wedge", scaled(prism_mesh(3, 0.07, 0.05, 0.25), scale), 5);
  src->add("cube", scaled(box_mesh(Vec3(0.07, 0.07, 0.07)), scale), 6);
  return src;
}

/// The same, built once per scale per test process (sources are immutable once built).
inline std::shared_ptr<TestSource> make_source(double scale = 1.0) {
  static std::mutex m;
  static std::map<double, std::shared_ptr<TestSource>> cache;
  std::lock_guard<std::mutex> lock(m);
  auto& s = cache[scale];
  if (!s) s = build_source(scale);
  return s;
}

/// Tactile-like contacts: `patches` round patches (radius 12 mm, taxels every 4 mm, scaled),
/// each shifted by a per-patch offset (sigma `offset`) and per-point noise (sigma `noise`), of
/// the object's fine cloud placed at T_world_object.
inline PointCloud touch(const PointCloud& fine, const Pose& T_world_object, int patches,
                        std::uint64_t seed, double offset = 0.0, double noise = 0.0,
                        double scale = 1.0) {
  Rng rng(seed);
  PointCloud out;
  std::unordered_set<std::uint64_t> seen;
  const double radius = 0.012 * scale, taxel = 0.004 * scale;
  for (int k = 0; k < patches; ++k) {
    const std::size_t c = rng.index(fine.size());
    const Vec3 centre = fine.points[c];
    const Vec3 shift = offset * Vec3(rng.normal(), rng.normal(), rng.normal());
    for (std::size_t i = 0; i < fine.size(); ++i) {
      const Vec3& p = fine.points[i];
      if ((p - centre).norm() > radius || fine.normals[i].dot(fine.normals[c]) < 0.3) continue;
      const Vec3 w = T_world_object * p;
      if (!seen.insert(voxel_key(w, taxel)).second) continue;
      out.points.push_back(w + shift + noise * Vec3(rng.normal(), rng.normal(), rng.normal()));
    }
  }
  return out;
}

inline Pose random_pose(std::uint64_t seed, const Vec3& where) {
  Rng rng(seed);
  Pose T = Pose::Identity();
  T.linear() = rng.rotation().toRotationMatrix();
  T.translation() = where;
  return T;
}

/// The paper's structure with smaller numbers (unit tests must be fast).
inline RecognizerSettings fast_settings(Method m = Method::bricpsf) {
  RecognizerSettings s;
  s.method = m;
  s.n_p = 40;
  s.ransac.triplets = 10;
  s.ransac.registrations = 100;
  s.ransac.prune_w = 1500;
  s.ransac.normal_tolerance_deg = 15.0;
  s.index.exact = true;
  s.icp.max_points = 96;
  return s;
}

}  // namespace ts::test
