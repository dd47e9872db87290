// Synthetic recognition scenes for the engine tests: a small database of analytic shapes
// (sampled surfaces with exact normals, FPFH computed like the database builder does, no
// scanner), and tactile-like contact clouds (round patches of 4 mm taxels, per-patch offsets)
// taken from an object placed at a known pose.
#pragma once

#include "datasets/shapes.hpp"
#include "engine/database/database.hpp"
#include "engine/features/fpfh.hpp"
#include "engine/geometry/search.hpp"
#include "engine/recognition/recognizer.hpp"
#include "fixture_cache.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <unordered_set>
#include <memory>
#include <numbers>
#include <tuple>
#include <unistd.h>

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

/// Regular n-gon prism (z axis), circumradius r, height h, recentred on its bounding box;
/// `skew` breaks the symmetry: vertex 0 at (1 + skew) r and top vertex i raised by skew h i / n
/// (the top centre by skew h / 2).
inline Mesh prism_mesh(int n, double r, double h, double skew = 0.0) {
  std::vector<Vec3> bottom, top;
  for (int i = 0; i < n; ++i) {
    const double rr = r * (1.0 + skew * (i == 0 ? 1.0 : 0.0));
    const double x = rr * std::cos(2 * kPi * i / n), y = rr * std::sin(2 * kPi * i / n);
    bottom.emplace_back(x, y, -h / 2);
    top.emplace_back(x, y, h / 2 + skew * h * i / n);
  }
  return datasets::ring_prism(bottom, top, Vec3(0, 0, -h / 2), Vec3(0, 0, h / 2 + skew * h / 2));
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

/// A built source's objects as bytes (what TestSource::add computes), for the other processes of
/// this test binary (fixture_cache.hpp): a copy of every value, so a loaded source equals the
/// built one bit for bit.
namespace source_bytes {
// Vectors of plain values (numbers, Vec3, Eigen::Vector3i, std::array): their bytes as they are.
template <class T>
void put(std::ostream& o, const std::vector<T>& v) {
  const std::uint64_t n = v.size();
  o.write(reinterpret_cast<const char*>(&n), sizeof n);
  o.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T)));
}
template <class T>
bool get(std::istream& in, std::vector<T>& v) {
  std::uint64_t n = 0;
  if (!in.read(reinterpret_cast<char*>(&n), sizeof n) || n > (std::uint64_t{1} << 32)) return false;
  v.resize(n);
  return static_cast<bool>(in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T))));
}
template <class T>
void put_one(std::ostream& o, const T& x) { put(o, std::vector<T>{x}); }
template <class T>
bool get_one(std::istream& in, T& x) {
  std::vector<T> v;
  if (!get(in, v) || v.size() != 1) return false;
  x = v[0];
  return true;
}
constexpr std::uint64_t kMagic = 0x7453727543616368ULL;   // format of this file; change it with the layout

inline void save(const TestSource& s, const std::filesystem::path& path) {
  const auto part = path.string() + ".tmp-" + std::to_string(::getpid());
  {
    std::ofstream o(part, std::ios::binary);
    put_one(o, kMagic);
    put_one(o, static_cast<std::uint64_t>(s.infos.size()));
    for (std::size_t i = 0; i < s.infos.size(); ++i) {
      const ObjectInfo& info = s.infos[i];
      put(o, std::vector<char>(info.name.begin(), info.name.end()));
      put_one(o, info.extent);
      put_one(o, static_cast<std::uint64_t>(info.fine_points));
      put_one(o, static_cast<std::uint64_t>(info.coarse_points));
      put_one(o, static_cast<char>(info.closed));
      put(o, s.feats[i].coarse.points), put(o, s.feats[i].coarse.normals);
      put_one(o, s.feats[i].features.dim()), put(o, s.feats[i].features.values());
      put(o, s.fines[i].points), put(o, s.fines[i].normals);
      put(o, s.meshes[i].vertices), put(o, s.meshes[i].faces);
      for (const SparseGrid* g : {&s.field_fine[i], &s.field_coarse[i]}) put_one(o, g->voxel), put(o, g->ijk), put(o, g->value);
    }
    put_one(o, kMagic);
    if (!o) return;
  }
  std::error_code ec;   // whole or not at all: another process may be reading it
  std::filesystem::rename(part, path, ec);
  if (ec) std::filesystem::remove(part, ec);
}

/// Fills `s` (made with the source's scale) from `path`; false if the file is missing or not whole.
inline bool load(TestSource& s, const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::uint64_t magic = 0, n = 0;
  if (!in || !get_one(in, magic) || magic != kMagic || !get_one(in, n) || n > 1000) return false;
  for (std::uint64_t i = 0; i < n; ++i) {
    ObjectInfo info;
    std::vector<char> name;
    std::uint64_t fine_points = 0, coarse_points = 0;
    char closed = 0;
    ObjectFeatures of;
    int dim = 0;
    std::vector<float> values;
    PointCloud fine;
    Mesh mesh;
    SparseGrid fine_field, coarse_field;
    if (!get(in, name) || !get_one(in, info.extent) || !get_one(in, fine_points) ||
        !get_one(in, coarse_points) || !get_one(in, closed) || !get(in, of.coarse.points) ||
        !get(in, of.coarse.normals) || !get_one(in, dim) || dim <= 0 || !get(in, values) ||
        !get(in, fine.points) || !get(in, fine.normals) || !get(in, mesh.vertices) || !get(in, mesh.faces))
      return false;
    for (SparseGrid* g : {&fine_field, &coarse_field})
      if (!get_one(in, g->voxel) || !get(in, g->ijk) || !get(in, g->value)) return false;
    info.name.assign(name.begin(), name.end());
    info.fine_points = fine_points, info.coarse_points = coarse_points, info.closed = closed != 0;
    of.features = FeatureRows(dim);
    of.features.values() = std::move(values);
    s.infos.push_back(info), s.feats.push_back(std::move(of)), s.fines.push_back(std::move(fine));
    s.meshes.push_back(std::move(mesh));
    s.field_fine.push_back(std::move(fine_field)), s.field_coarse.push_back(std::move(coarse_field));
  }
  return get_one(in, magic) && magic == kMagic;
}
}  // namespace source_bytes

/// The same, built once per scale per test process (sources are immutable once built), and
/// once per test binary when the test cache can be written (fixture_cache.hpp).
inline std::shared_ptr<TestSource> make_source(double scale = 1.0) {
  static std::mutex m;
  static std::map<double, std::shared_ptr<TestSource>> cache;
  std::lock_guard<std::mutex> lock(m);
  auto& s = cache[scale];
  if (s) return s;
  char key[64];
  std::snprintf(key, sizeof key, "source-%a", scale);
  const auto path = fixture_cache(key, ".bin");
  auto loaded = std::make_shared<TestSource>(scale);
  if (!path.empty() && source_bytes::load(*loaded, path)) return s = loaded;
  s = build_source(scale);
  if (!path.empty()) source_bytes::save(*s, path);
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
