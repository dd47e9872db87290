#include "datasets/scene.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

namespace ts::datasets {

namespace {
constexpr std::uint64_t kStreamScene = 0x7363656eULL;   // "scen"
constexpr std::uint64_t kStreamNeighbours = 0x6e626f72ULL;   // "nbor"
constexpr double kDeg = std::numbers::pi / 180.0;
constexpr int kMaxCells = 300;                          // per side: at most 90 601 vertices

void require(bool ok, const std::string& key, const std::string& what) {
  if (!ok) throw Error(key + " " + what, {}, key);
}
}  // namespace

const char* to_string(SceneKind kind) {
  switch (kind) {
    case SceneKind::seabed: return "seabed";
    case SceneKind::panel: return "panel";
    case SceneKind::pipe: return "pipe";
    case SceneKind::cluttered: return "cluttered";
    case SceneKind::none: break;
  }
  return "none";
}

SceneKind parse_scene_kind(const std::string& word, const std::string& file, const std::string& field) {
  if (word == "none") return SceneKind::none;
  if (word == "seabed") return SceneKind::seabed;
  if (word == "panel") return SceneKind::panel;
  if (word == "pipe") return SceneKind::pipe;
  if (word == "cluttered") return SceneKind::cluttered;
  throw Error("unknown scene '" + word + "' (none, seabed, panel, pipe, cluttered)", file, field);
}

void validate(const SceneSettings& s) {
  auto in = [](double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; };
  require(in(s.slope_deg, 0, 60), "scene.slope_deg", "must lie in [0, 60] degrees");
  require(in(s.relief_m, 0, 0.2), "scene.relief_m", "must lie in [0, 0.2] m");
  require(in(s.relief_wavelength_m, 0.01, 10), "scene.relief_wavelength_m", "must lie in [0.01, 10] m");
  require(!(s.gap_m < 0), "scene.gap_m",
          "must be >= 0: a negative gap would make the support intersect the object");
  require(in(s.gap_m, 0, 1), "scene.gap_m", "must lie in [0, 1] m");
  require(std::isfinite(s.off_target) && s.off_target >= 0 && s.off_target < 1, "scene.off_target",
          "must lie in [0, 1)");
  require(in(s.off_target_radius_m, 0, 10), "scene.off_target_radius_m", "must lie in [0, 10] m");
  require(in(s.extent_m, 0, 100), "scene.extent_m", "must lie in [0, 100] m");
  require(in(s.pipe_radius_m, 0, 5), "scene.pipe_radius_m", "must lie in [0, 5] m");
  if (s.kind == SceneKind::panel) {
    require(s.slope_deg == 0, "scene.slope_deg", "must be 0 for a panel (it is vertical)");
    require(s.relief_m == 0, "scene.relief_m", "must be 0 for a panel (it is flat)");
  }
  if (s.kind == SceneKind::pipe) {
    require(s.slope_deg == 0, "scene.slope_deg", "must be 0 for a pipe (it is horizontal)");
    require(s.relief_m == 0, "scene.relief_m", "must be 0 for a pipe (it is smooth)");
  } else if (s.kind != SceneKind::none) {   // (scene none ignores every scene.* key)
    require(s.pipe_radius_m == 0, "scene.pipe_radius_m", "is only for scene = pipe");
  }
  if (s.kind == SceneKind::cluttered) {
    require(s.neighbours >= 1 && s.neighbours <= 8, "scene.neighbours", "must lie in [1, 8]");
    require(in(s.neighbour_distance_m, 0.005, 1), "scene.neighbour_distance_m",
            "must lie in [0.005, 1] m (a neighbour at a smaller distance would touch or cut the object)");
    require(in(s.neighbour_share, 0, 1), "scene.neighbour_share", "must lie in [0, 1]");
  }
}

std::vector<std::size_t> neighbour_choice(std::size_t size, std::size_t target, int count, std::uint64_t seed) {
  require(count >= 0, "scene.neighbours", "must be >= 0");
  const std::size_t others = size - (target < size ? 1 : 0);
  if (static_cast<std::size_t>(count) > others)
    throw Error("scene.neighbours: " + std::to_string(count) + " neighbours asked for, the database holds " +
                    std::to_string(others) + " other objects",
                {}, "scene.neighbours");
  // A partial Fisher-Yates shuffle of the other objects' indices (the target's slot skipped).
  std::vector<std::size_t> pool;
  pool.reserve(others);
  for (std::size_t i = 0; i < size; ++i)
    if (i != target) pool.push_back(i);
  Rng rng(seed, kStreamNeighbours);
  for (std::size_t k = 0; k < static_cast<std::size_t>(count); ++k)
    std::swap(pool[k], pool[k + rng.index(pool.size() - k)]);
  pool.resize(static_cast<std::size_t>(count));
  return pool;
}

std::vector<SceneObject> scene_neighbours(const SceneSettings& s, std::size_t size, std::size_t target,
                                          std::uint64_t seed, const std::function<SceneObject(std::size_t)>& load) {
  std::vector<SceneObject> out;
  if (s.kind != SceneKind::cluttered) return out;
  for (std::size_t i : neighbour_choice(size, target, s.neighbours, seed)) out.push_back(load(i));
  return out;
}

double cluttered_extent(double object_radius, double neighbour_radius, const SceneSettings& s, double reach) {
  return object_radius + s.neighbour_distance_m + 2.0 * neighbour_radius + reach + 0.05;
}

namespace {

/// At most `limit` of a mesh's vertices, evenly strided.
std::vector<Vec3> sampled_vertices(const Mesh& m, std::size_t limit) {
  const std::size_t stride = std::max<std::size_t>(1, (m.vertices.size() + limit - 1) / limit);
  std::vector<Vec3> out;
  for (std::size_t i = 0; i < m.vertices.size(); i += stride) out.push_back(m.vertices[i]);
  return out;
}

/// Whether every point lies at least `d` from `index`'s surface and, `outside`, outside it (a
/// closed surface). Without the inside test the points must have come from outside in steps
/// shorter than 2 d (a point that crossed the surface was then nearer than d to it).
bool clear_of(const MeshIndex& index, const std::vector<Vec3>& points, const Vec3& shift, double d, bool outside) {
  for (const Vec3& p : points) {
    const Vec3 x = p + shift;
    if (index.closest_within(x, d) || (outside && index.inside(x))) return false;
  }
  return true;
}

}  // namespace

std::vector<PlacedObject> place_neighbours(const Mesh& object_world, const Support& seabed,
                                           const std::vector<SceneObject>& objects, const SceneSettings& s,
                                           std::uint64_t seed) {
  validate(s);
  if (s.kind != SceneKind::cluttered) throw Error("neighbours need scene = cluttered", {}, "scene");
  if (objects.size() != static_cast<std::size_t>(s.neighbours))
    throw Error("scene.neighbours: " + std::to_string(s.neighbours) + " neighbours asked for, " +
                    std::to_string(objects.size()) + " meshes given",
                {}, "scene.neighbours");
  constexpr std::size_t kSamples = 2000;
  const double d = s.neighbour_distance_m;
  const Vec3 up = seabed.up(), e1 = seabed.axis(), e2 = up.cross(e1);
  const auto box = mesh_bounds(object_world);
  const Vec3 centre = box.center();
  double r_object = 0.0;
  for (const Vec3& v : object_world.vertices) r_object = std::max(r_object, (v - centre).norm());
  const MeshIndex object_index(object_world);
  const std::vector<Vec3> object_samples = sampled_vertices(object_world, kSamples);

  Rng rng(seed, kStreamNeighbours, 1);
  const double phase = rng.uniform(0.0, 2.0 * std::numbers::pi);
  const double n = static_cast<double>(objects.size());
  std::vector<PlacedObject> placed;
  std::vector<MeshIndex> placed_index;
  for (std::size_t k = 0; k < objects.size(); ++k) {
    const SceneObject& o = objects[k];
    if (o.mesh.vertices.empty() || o.mesh.faces.empty())
      throw Error("neighbour '" + o.name + "' has an empty mesh", {}, "scene.neighbours");
    // Turned at random about its own bounding-box centre.
    const Eigen::Quaterniond q = rng.rotation();
    const double azimuth = phase + 2.0 * std::numbers::pi * (static_cast<double>(k) + rng.uniform(-0.25, 0.25)) / n;
    const Vec3 dir = std::cos(azimuth) * e1 + std::sin(azimuth) * e2;
    const Vec3 c_local = mesh_bounds(o.mesh).center();
    Mesh turned = o.mesh;
    double r = 0.0;
    for (Vec3& v : turned.vertices) {
      v = q * (v - c_local);
      r = std::max(r, v.norm());
    }
    // Where it rests at distance `along` from the object's centre in the seabed's plane: lowered
    // along `up` until its lowest vertex lies on the seabed.
    auto rest = [&](double along) {
      const Vec3 c = centre + along * dir;
      double lift = std::numeric_limits<double>::infinity();
      for (const Vec3& v : turned.vertices) lift = std::min(lift, seabed.above(c + v));
      return Vec3(c - lift * up);
    };
    const MeshIndex turned_index(turned);   // the neighbour about its centre
    const std::vector<Vec3> samples = sampled_vertices(turned, kSamples);
    auto apart = [&](const Vec3& c) {
      // (The object: approached from beyond the bounding spheres in steps of d / 4 or outward.)
      if (!clear_of(object_index, samples, c, d, false) || !clear_of(turned_index, object_samples, -c, d, false))
        return false;
      for (std::size_t j = 0; j < placed.size(); ++j)
        if (!clear_of(placed_index[j], samples, c, d, true)) return false;
      return true;
    };
    // Out from the bounding spheres' distance while another neighbour is in the way, then in.
    double along = r_object + r + d;
    int out = 0;
    while (!apart(rest(along))) {
      if (++out > 64)
        throw Error("scene.neighbours: neighbour '" + o.name + "' could not be placed apart from the others", {},
                    "scene.neighbours");
      along += d;
    }
    while (along - d / 4 > 0 && apart(rest(along - d / 4))) along -= d / 4;
    const Vec3 c = rest(along);
    PlacedObject p;
    p.name = o.name;
    p.T_world_object.linear() = q.toRotationMatrix();
    p.T_world_object.translation() = c - q * c_local;
    p.world = o.mesh;
    for (Vec3& v : p.world.vertices) v = p.T_world_object * v;
    Mesh shifted = turned;
    for (Vec3& v : shifted.vertices) v += c;
    placed_index.emplace_back(std::move(shifted));
    placed.push_back(std::move(p));
  }
  return placed;
}

Support::Support(const Mesh& object_mesh, const Pose& T_world_object, const SceneSettings& s, double reach,
                 std::uint64_t seed) {
  validate(s);
  if (s.kind == SceneKind::none) throw Error("scene none has no support", {}, "scene");
  if (object_mesh.vertices.empty()) throw Error("the object has no vertices", {}, "scene");
  Mesh world = object_mesh;
  for (Vec3& v : world.vertices) v = T_world_object * v;
  const auto box = mesh_bounds(world);
  const Vec3 centre = box.center();
  double r = 0.0;
  for (const Vec3& v : world.vertices) r = std::max(r, (v - centre).norm());

  // The plane: +z tilted by the slope (a panel: 90 degrees) about a seeded horizontal axis a;
  // e1 = a, e2 = n x e1.
  Rng rng(seed, kStreamScene);
  const double phi = rng.uniform(0.0, 2.0 * std::numbers::pi);
  const Vec3 a(std::cos(phi), std::sin(phi), 0.0);
  const double tilt = s.kind == SceneKind::panel ? 90.0 : s.slope_deg;
  n_ = Eigen::AngleAxisd(tilt * kDeg, a) * Vec3::UnitZ();
  e1_ = a;
  e2_ = n_.cross(e1_);
  origin_ = centre;
  half_ = s.extent_m > 0 ? s.extent_m : r + reach + 0.05;
  radius_ = std::min(s.off_target_radius_m > 0 ? s.off_target_radius_m : 1.5 * r, 0.9 * half_);
  if (s.kind == SceneKind::pipe) {
    n_ = Vec3::UnitZ();
    e2_ = n_.cross(e1_);
    place_pipe(world, centre, r, s);
    return;
  }

  // Heights on the grid: the relief (three seeded sinusoids), 0 when flat.
  cells_ = 1;
  if (s.relief_m > 0)
    cells_ = std::clamp(static_cast<int>(std::ceil(2.0 * half_ / std::max(0.003, s.relief_wavelength_m / 8))), 1,
                        kMaxCells);
  spacing_ = 2.0 * half_ / cells_;
  std::array<std::array<double, 4>, 3> waves{};   // kx, ky, phase, (unused)
  for (auto& w : waves) {
    const double psi = rng.uniform(0.0, 2.0 * std::numbers::pi);
    const double k = 2.0 * std::numbers::pi / (s.relief_wavelength_m * rng.uniform(0.7, 1.3));
    w = {k * std::cos(psi), k * std::sin(psi), rng.uniform(0.0, 2.0 * std::numbers::pi), 0.0};
  }
  const int N = cells_ + 1;
  h_.assign(static_cast<std::size_t>(N) * N, 0.0);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      const double u = -half_ + i * spacing_, v = -half_ + j * spacing_;
      double h = 0.0;
      if (s.relief_m > 0)
        for (const auto& w : waves) h += s.relief_m / 3.0 * std::sin(w[0] * u + w[1] * v + w[2]);
      h_[static_cast<std::size_t>(i) * N + j] = h;
    }

  const double lift = clearance(world, r, s.relief_m > 0) - s.gap_m;
  for (double& h : h_) h += lift;
  triangulate();
}

double Support::clearance(const Mesh& world, double r, bool relief) const {
  // Lowered until nothing of the object lies below it: at the object's vertices (the support
  // interpolated there) and, with relief, along its edges (every quarter grid spacing) and at the
  // grid's vertices under the object (the object's lowest surface point above each, by a ray cast
  // up along n): where two piecewise-linear surfaces come nearest.
  const int N = cells_ + 1;
  double lift = std::numeric_limits<double>::infinity();
  for (const Vec3& x : world.vertices) {
    const Vec3 d = x - origin_;
    lift = std::min(lift, d.dot(n_) - height(d.dot(e1_), d.dot(e2_)));
  }
  if (relief) {
    // Along the object's edges too (where an edge crosses a ridge of the grid between vertices).
    const double step = spacing_ / 4;
    for (const auto& f : world.faces)
      for (int e = 0; e < 3; ++e) {
        const Vec3 &a = world.vertices[f[e]], &b = world.vertices[f[(e + 1) % 3]];
        const int n = std::min(64, static_cast<int>(std::ceil((b - a).norm() / step)));
        for (int k = 1; k < n; ++k) {
          const Vec3 d = a + (b - a) * (static_cast<double>(k) / n) - origin_;
          lift = std::min(lift, d.dot(n_) - height(d.dot(e1_), d.dot(e2_)));
        }
      }
    const MeshIndex index(world);
    for (int i = 0; i < N; ++i)
      for (int j = 0; j < N; ++j) {
        const double u = -half_ + i * spacing_, v = -half_ + j * spacing_;
        if (u * u + v * v > r * r) continue;
        const Vec3 start = origin_ + u * e1_ + v * e2_ - (2.0 * r + 1.0) * n_;
        if (const auto hit = index.raycast(start, n_, 4.0 * r + 2.0))
          lift = std::min(lift, hit->t - (2.0 * r + 1.0) - h_[static_cast<std::size_t>(i) * N + j]);
      }
  }
  return lift;
}

void Support::place_pipe(const Mesh& world, const Vec3& centre, double r, const SceneSettings& s) {
  const double R = s.pipe_radius_m > 0 ? s.pipe_radius_m : std::max(0.05, r);
  pipe_radius_ = R;
  // The axis' height below the centre (along n): the highest at which no point of the object lies
  // inside the cylinder. A point d (from the centre) across the axis by |d.e2| < R must lie at
  // least sqrt(R^2 - (d.e2)^2) above it; one beside the pipe constrains nothing (a straddling
  // object). Checked at the vertices and along the edges (every 1 mm or R / 20).
  // With a gap, the same for a cylinder of radius R + gap: the pipe's clearance is then the gap.
  const double Rg = R + s.gap_m;
  double axis = std::numeric_limits<double>::infinity();
  auto constrain = [&](const Vec3& x) {
    const Vec3 d = x - centre;
    const double w = d.dot(e2_);
    if (std::abs(w) < Rg) axis = std::min(axis, d.dot(n_) - std::sqrt(Rg * Rg - w * w));
  };
  for (const Vec3& x : world.vertices) constrain(x);
  const double step = std::min(0.001, Rg / 20);
  for (const auto& f : world.faces)
    for (int e = 0; e < 3; ++e) {
      const Vec3 &a = world.vertices[f[e]], &b = world.vertices[f[(e + 1) % 3]];
      const int n = std::min(1 << 16, static_cast<int>(std::ceil((b - a).norm() / step)));
      for (int k = 1; k < n; ++k) constrain(a + (b - a) * (static_cast<double>(k) / n));
    }
  if (!std::isfinite(axis)) axis = -r - Rg;   // nothing above the pipe's width: under the object
  origin_ = centre + axis * n_;
  // The cylinder: rings of `sides` vertices at both ends (chords at most 0.2 mm inside the
  // circle), faces wound outward.
  const int sides = std::clamp(static_cast<int>(std::ceil(std::numbers::pi / std::acos(1.0 - std::min(0.0002 / R, 1.0)))),
                               16, 512);
  for (int end = 0; end < 2; ++end)
    for (int k = 0; k < sides; ++k) {
      const double t = 2.0 * std::numbers::pi * k / sides;
      mesh_.vertices.push_back(origin_ + (end == 0 ? -half_ : half_) * e1_ + R * (std::cos(t) * e2_ + std::sin(t) * n_));
    }
  for (int k = 0; k < sides; ++k) {
    const int a = k, b = (k + 1) % sides, c = sides + (k + 1) % sides, d = sides + k;
    // (b - a) runs along the circle (increasing t), (d - a) along e1: (b - a) x (c - a) points
    // outward (at t = 0 the tangent is n, and n x e1 = e2, the outward normal there).
    mesh_.faces.emplace_back(a, b, c);
    mesh_.faces.emplace_back(a, c, d);
  }
}

void Support::triangulate() {
  const int N = cells_ + 1;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      const double u = -half_ + i * spacing_, v = -half_ + j * spacing_;
      mesh_.vertices.push_back(origin_ + u * e1_ + v * e2_ + h_[static_cast<std::size_t>(i) * N + j] * n_);
    }
  for (int i = 0; i < cells_; ++i)
    for (int j = 0; j < cells_; ++j) {
      const int A = i * N + j, B = (i + 1) * N + j, C = (i + 1) * N + j + 1, D = i * N + j + 1;
      mesh_.faces.emplace_back(A, B, C);   // (B - A) x (C - A) along e1 x e2 = n: up
      mesh_.faces.emplace_back(A, C, D);
    }
}

Support::Cell Support::cell(double u, double v) const {
  const int N = cells_ + 1;
  const double gu = (u + half_) / spacing_, gv = (v + half_) / spacing_;
  const int i = std::clamp(static_cast<int>(std::floor(gu)), 0, cells_ - 1);
  const int j = std::clamp(static_cast<int>(std::floor(gv)), 0, cells_ - 1);
  auto at = [&](int a, int b) { return h_[static_cast<std::size_t>(a) * N + b]; };
  return {at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1), gu - i, gv - j};
}

double Support::height(double u, double v) const {
  const Cell c = cell(u, v);
  // The cell's two faces, split along its (i, j) - (i + 1, j + 1) diagonal.
  return c.fu >= c.fv ? c.a + c.fu * (c.b - c.a) + c.fv * (c.c - c.b) : c.a + c.fv * (c.d - c.a) + c.fu * (c.c - c.d);
}

Vec3 Support::face_normal(double u, double v) const {
  const Cell c = cell(u, v);
  const bool lower = c.fu >= c.fv;
  const double du = (lower ? c.b - c.a : c.c - c.d) / spacing_, dv = (lower ? c.c - c.b : c.d - c.a) / spacing_;
  return (n_ - du * e1_ - dv * e2_).normalized();
}

Vec3 Support::point(double u, double v) const {
  if (pipe_radius_ > 0)   // the pipe's top: its height over the axis at v across it (0 beside it)
    return origin_ + u * e1_ + v * e2_ + std::sqrt(std::max(0.0, pipe_radius_ * pipe_radius_ - v * v)) * n_;
  return origin_ + u * e1_ + v * e2_ + height(u, v) * n_;
}

double Support::above(const Vec3& x) const {
  const Vec3 d = x - origin_;
  if (pipe_radius_ > 0) return (d - d.dot(e1_) * e1_).norm() - pipe_radius_;
  return d.dot(n_) - height(d.dot(e1_), d.dot(e2_));
}

std::pair<Vec3, Vec3> Support::aim(Rng& rng) const {
  if (pipe_radius_ > 0) {   // the upper half, within radius_ of the object along the axis and
                            // around the top (the whole upper half of a pipe narrower than that)
    const double u = rng.uniform(-radius_, radius_);
    const double arc = std::min(std::numbers::pi / 2, radius_ / pipe_radius_);
    const double t = rng.uniform(std::numbers::pi / 2 - arc, std::numbers::pi / 2 + arc);
    const Vec3 normal = std::cos(t) * e2_ + std::sin(t) * n_;
    return {origin_ + u * e1_ + pipe_radius_ * normal, normal};
  }
  const double rho = radius_ * std::sqrt(rng.uniform());
  const double theta = rng.uniform(0.0, 2.0 * std::numbers::pi);
  const double u = rho * std::cos(theta), v = rho * std::sin(theta);
  return {point(u, v), face_normal(u, v)};
}

}  // namespace ts::datasets
