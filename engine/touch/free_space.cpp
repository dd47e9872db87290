#include "engine/touch/free_space.hpp"
#include "engine/detail.hpp"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <tuple>
#include <unordered_map>

namespace ts {

void detail::init_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

inline namespace touch {

namespace {
using detail::init_openvdb;
constexpr std::int32_t kFree = 1;
constexpr std::int32_t kOccupied = 2;


using Key = std::array<std::int64_t, 3>;
struct KeyHash {
  std::size_t operator()(const Key& k) const {
    std::uint64_t h = 1469598103934665603ULL;
    for (auto v : k) h = (h ^ static_cast<std::uint64_t>(v)) * 1099511628211ULL;
    return static_cast<std::size_t>(h);
  }
};
}  // namespace

struct OccupancyGrid::Impl {
  double voxel;
  Vec3 origin;
  openvdb::Int32Grid::Ptr grid;

  Impl(double v, const Vec3& o) : voxel(v), origin(o) {
    init_openvdb();
    grid = openvdb::Int32Grid::create(0);
  }
  Impl(const Impl& other)
      : voxel(other.voxel), origin(other.origin), grid(other.grid->deepCopy()), cube_res(other.cube_res),
        cubes(other.cubes) {}

  // Free voxels per cube of size cube_res (for free_cloud), kept up to date by every update
  // once free_cloud has been called with that size.
  double cube_res = 0.0;
  std::unordered_map<Key, std::int32_t, KeyHash> cubes;

  std::int64_t cube_voxels = 0;  ///< cube_res / voxel when an integer (exact keys), else 0

  static std::int64_t floor_div(std::int64_t a, std::int64_t b) {
    return a >= 0 ? a / b : -((-a + b - 1) / b);
  }
  Key cube_of(const openvdb::Coord& c) const {
    if (cube_voxels > 0)
      return {floor_div(c.x(), cube_voxels), floor_div(c.y(), cube_voxels), floor_div(c.z(), cube_voxels)};
    return {static_cast<std::int64_t>(std::floor(c.x() * voxel / cube_res + 1e-9)),
            static_cast<std::int64_t>(std::floor(c.y() * voxel / cube_res + 1e-9)),
            static_cast<std::int64_t>(std::floor(c.z() * voxel / cube_res + 1e-9))};
  }
  /// Per-cube free counts for cubes of size res, built once and then kept current.
  void ensure_cubes(double res) {
    if (cube_res == res) return;
    cube_res = res;
    const double ratio = res / voxel;
    const auto n = static_cast<std::int64_t>(std::lround(ratio));
    cube_voxels = n >= 1 && std::abs(ratio - static_cast<double>(n)) < 1e-6 ? n : 0;
    cubes.clear();
    for (auto it = grid->cbeginValueOn(); it; ++it)
      if (*it == kFree) ++cubes[cube_of(it.getCoord())];
  }
  void changed(const openvdb::Coord& c, std::int32_t before, std::int32_t after) {
    if (cube_res <= 0.0 || (before == kFree) == (after == kFree)) return;
    const Key k = cube_of(c);
    if (after == kFree) {
      ++cubes[k];
    } else if (--cubes[k] == 0) {
      cubes.erase(k);
    }
  }
  template <class Accessor>
  void set_free(Accessor& acc, const openvdb::Coord& c) {
    const std::int32_t before = acc.getValue(c);
    if (before == kOccupied || before == kFree) return;
    acc.setValue(c, kFree);
    changed(c, before, kFree);
  }

  Vec3 local(const Vec3& p_world) const { return (p_world - origin) / voxel; }
  openvdb::Coord coord_of(const Vec3& p_world) const {
    const Vec3 l = local(p_world);
    return openvdb::Coord(static_cast<int>(std::lround(l.x())), static_cast<int>(std::lround(l.y())),
                          static_cast<int>(std::lround(l.z())));
  }
  Vec3 centre(const openvdb::Coord& c) const {
    return origin + voxel * Vec3(c.x(), c.y(), c.z());
  }
};

OccupancyGrid::OccupancyGrid(double voxel, const Vec3& origin) {
  if (!(voxel > 0.0) || !std::isfinite(voxel)) throw Error("occupancy voxel must be positive", {}, "voxel");
  if (!origin.allFinite()) throw Error("occupancy origin must be finite", {}, "origin");
  impl_ = std::make_unique<Impl>(voxel, origin);
}
OccupancyGrid::~OccupancyGrid() = default;
OccupancyGrid::OccupancyGrid(OccupancyGrid&&) noexcept = default;
OccupancyGrid& OccupancyGrid::operator=(OccupancyGrid&&) noexcept = default;
OccupancyGrid::OccupancyGrid(const OccupancyGrid& o) : impl_(std::make_unique<Impl>(*o.impl_)) {}
OccupancyGrid& OccupancyGrid::operator=(const OccupancyGrid& o) {
  if (this != &o) impl_ = std::make_unique<Impl>(*o.impl_);
  return *this;
}

double OccupancyGrid::voxel() const { return impl_->voxel; }
const Vec3& OccupancyGrid::origin() const { return impl_->origin; }

void OccupancyGrid::mark_free_box(const Pose& T_world_box, const Vec3& lo, const Vec3& hi) {
  // Voxel-index bounds of the box's corners, then an exact centre-in-box test per voxel, done
  // in the box frame relative to the grid origin (no large coordinates).
  const double v = impl_->voxel;
  Pose T_local_box = T_world_box;
  T_local_box.translation() = T_world_box.translation() - impl_->origin;
  Eigen::AlignedBox3d aabb;
  for (int c = 0; c < 8; ++c) {
    const Vec3 corner((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(), (c & 4) ? hi.z() : lo.z());
    aabb.extend(T_local_box * corner);
  }
  const Eigen::Vector3i i0 = (aabb.min() / v).array().ceil().cast<int>();
  const Eigen::Vector3i i1 = (aabb.max() / v).array().floor().cast<int>();
  const Pose T_box_local = T_local_box.inverse();
  auto acc = impl_->grid->getAccessor();
  const double eps = 1e-12;
  for (int i = i0.x(); i <= i1.x(); ++i)
    for (int j = i0.y(); j <= i1.y(); ++j) {
      // Solve the z-range of the segment of this (i, j) column inside the box analytically.
      const Vec3 base = T_box_local * Vec3(i * v, j * v, 0.0);
      const Vec3 dir = T_box_local.linear().col(2) * v;  // box-frame step per k
      double kmin = i0.z(), kmax = i1.z();
      bool empty = false;
      for (int a = 0; a < 3 && !empty; ++a) {
        if (std::abs(dir[a]) < eps) {
          if (base[a] < lo[a] || base[a] > hi[a]) empty = true;
          continue;
        }
        double t0 = (lo[a] - base[a]) / dir[a], t1 = (hi[a] - base[a]) / dir[a];
        if (t0 > t1) std::swap(t0, t1);
        kmin = std::max(kmin, std::ceil(t0 - 1e-9));
        kmax = std::min(kmax, std::floor(t1 + 1e-9));
      }
      if (empty) continue;
      for (int k = static_cast<int>(kmin); k <= static_cast<int>(kmax); ++k) {
        const Vec3 pb = base + dir * k;
        if ((pb.array() < lo.array() - 1e-12).any() || (pb.array() > hi.array() + 1e-12).any()) continue;
        impl_->set_free(acc, openvdb::Coord(i, j, k));
      }
    }
}

void OccupancyGrid::mark_free_cylinder(const Pose& T_world_cyl, double radius, double z0, double z1) {
  const double v = impl_->voxel;
  Pose T_local_cyl = T_world_cyl;
  T_local_cyl.translation() = T_world_cyl.translation() - impl_->origin;
  Eigen::AlignedBox3d aabb;
  for (int c = 0; c < 8; ++c) {
    const Vec3 corner((c & 1) ? radius : -radius, (c & 2) ? radius : -radius, (c & 4) ? z1 : z0);
    aabb.extend(T_local_cyl * corner);
  }
  const Eigen::Vector3i i0 = (aabb.min() / v).array().ceil().cast<int>();
  const Eigen::Vector3i i1 = (aabb.max() / v).array().floor().cast<int>();
  const Pose T_cyl_local = T_local_cyl.inverse();
  auto acc = impl_->grid->getAccessor();
  for (int i = i0.x(); i <= i1.x(); ++i)
    for (int j = i0.y(); j <= i1.y(); ++j)
      for (int k = i0.z(); k <= i1.z(); ++k) {
        const Vec3 p = T_cyl_local * Vec3(i * v, j * v, k * v);
        if (p.z() < z0 || p.z() > z1 || p.x() * p.x() + p.y() * p.y() > radius * radius) continue;
        impl_->set_free(acc, openvdb::Coord(i, j, k));
      }
}

void OccupancyGrid::mark_occupied(const Vec3& p_world) {
  if (!p_world.allFinite()) return;
  const openvdb::Coord c = impl_->coord_of(p_world);
  const std::int32_t before = impl_->grid->tree().getValue(c);
  impl_->grid->tree().setValue(c, kOccupied);
  impl_->changed(c, before, kOccupied);
}

void OccupancyGrid::merge(const OccupancyGrid& other) {
  if (other.impl_->voxel != impl_->voxel || other.impl_->origin != impl_->origin)
    throw Error("cannot merge occupancy grids with different voxel size or origin");
  auto acc = impl_->grid->getAccessor();
  for (auto it = other.impl_->grid->cbeginValueOn(); it; ++it) {
    const openvdb::Coord c = it.getCoord();
    const std::int32_t before = acc.getValue(c);
    if (*it > before) {
      acc.setValue(c, *it);
      impl_->changed(c, before, *it);
    }
  }
}

Occupancy OccupancyGrid::state(const Vec3& p_world) const {
  const auto acc = impl_->grid->getConstAccessor();
  return static_cast<Occupancy>(acc.getValue(impl_->coord_of(p_world)));
}

std::size_t OccupancyGrid::free_count() const {
  std::size_t n = 0;
  for (auto it = impl_->grid->cbeginValueOn(); it; ++it) n += (*it == kFree);
  return n;
}

std::size_t OccupancyGrid::occupied_count() const {
  std::size_t n = 0;
  for (auto it = impl_->grid->cbeginValueOn(); it; ++it) n += (*it == kOccupied);
  return n;
}

namespace {
std::vector<openvdb::Coord> sorted_free(const openvdb::Int32Grid& grid) {
  std::vector<openvdb::Coord> out;
  for (auto it = grid.cbeginValueOn(); it; ++it)
    if (*it == kFree) out.push_back(it.getCoord());
  std::sort(out.begin(), out.end(), [](const openvdb::Coord& a, const openvdb::Coord& b) {
    return std::make_tuple(a.x(), a.y(), a.z()) < std::make_tuple(b.x(), b.y(), b.z());
  });
  return out;
}
}  // namespace

std::vector<Vec3> OccupancyGrid::free_centres() const {
  std::vector<Vec3> out;
  for (const auto& c : sorted_free(*impl_->grid)) out.push_back(impl_->centre(c));
  return out;
}

std::vector<Vec3> OccupancyGrid::free_cloud(const Eigen::AlignedBox3d& box, double res) const {
  if (box.isEmpty() || !(res > 0.0)) return {};
  Impl& m = *impl_;
  const double v = m.voxel;
  m.ensure_cubes(res);  // (re)build the per-cube counts once; updates keep them current
  std::vector<Key> keys;
  keys.reserve(m.cubes.size());
  for (const auto& [k, n] : m.cubes) keys.push_back(k);
  std::sort(keys.begin(), keys.end());
  const Eigen::AlignedBox3d local_box(box.min() - m.origin, box.max() - m.origin);
  const auto acc = m.grid->getConstAccessor();
  std::vector<Vec3> out;
  for (const Key& k : keys) {
    const Vec3 lo = res * Vec3(k[0], k[1], k[2]), hi = lo + Vec3::Constant(res);
    if (!local_box.intersects(Eigen::AlignedBox3d(lo, hi))) continue;
    const Vec3 centre = lo + Vec3::Constant(0.5 * res);
    auto usable = [&](const openvdb::Coord& c) {
      const Vec3 l = v * Vec3(c.x(), c.y(), c.z());
      return acc.getValue(c) == kFree && m.cube_of(c) == k && local_box.contains(l);
    };
    // The free voxel nearest to the cube's centre (ties: the smaller (i, j, k)): the centre
    // voxel itself when free, else a scan of the cube in increasing (i, j, k).
    const openvdb::Coord mid(static_cast<int>(std::lround(centre.x() / v)), static_cast<int>(std::lround(centre.y() / v)),
                             static_cast<int>(std::lround(centre.z() / v)));
    bool found = false;
    openvdb::Coord best;
    double best_d = 0.0;
    auto consider = [&](const openvdb::Coord& c) {
      if (!usable(c)) return;
      const double d = (v * Vec3(c.x(), c.y(), c.z()) - centre).squaredNorm();
      if (!found || d < best_d) found = true, best = c, best_d = d;
    };
    consider(mid);  // the voxel centre nearest to the cube's centre: taken when usable
    if (!found) {
      const Eigen::Vector3i i0 = (lo / v).array().floor().cast<int>() - 1;
      const Eigen::Vector3i i1 = (hi / v).array().ceil().cast<int>() + 1;
      for (int i = i0.x(); i <= i1.x(); ++i)
        for (int j = i0.y(); j <= i1.y(); ++j)
          for (int l = i0.z(); l <= i1.z(); ++l) consider(openvdb::Coord(i, j, l));
    }
    if (found) out.push_back(m.origin + v * Vec3(best.x(), best.y(), best.z()));
  }
  return out;
}

std::vector<Vec3> OccupancyGrid::full_free_cloud(const Eigen::AlignedBox3d& box, double res) const {
  std::vector<Vec3> out;
  if (box.isEmpty() || !(res > 0.0)) return out;
  Impl& m = *impl_;
  m.ensure_cubes(res);
  // A cube is full when it holds as many free voxel centres as it holds voxel centres.
  const auto per_axis = std::max<std::int64_t>(1, std::lround(res / m.voxel));
  const std::int64_t full = per_axis * per_axis * per_axis;
  std::vector<Key> keys;
  for (const auto& [k, n] : m.cubes)
    if (n >= full) keys.push_back(k);
  std::sort(keys.begin(), keys.end());
  for (const Key& k : keys) {
    const Vec3 centre = m.origin + res * Vec3(double(k[0]) + 0.5, double(k[1]) + 0.5, double(k[2]) + 0.5);
    if (box.contains(centre)) out.push_back(centre);
  }
  return out;
}

std::vector<Vec3> hand_surface_samples(const Gripper& gripper, const Pose& T_world_eef,
                                       const std::vector<double>& joints, double spacing,
                                       const FreeSpaceSettings& settings) {
  if (static_cast<int>(joints.size()) != gripper.joint_count())
    throw Error("joint count does not match the gripper", {}, "joints");
  if (!(spacing > 0.0)) throw Error("hand sample spacing must be positive", {}, "spacing");
  // Evenly spaced values from lo to hi inclusive, at most `spacing` apart.
  auto ticks = [spacing](double lo, double hi) {
    const int n = std::max(1, static_cast<int>(std::ceil((hi - lo) / spacing)));
    std::vector<double> v(static_cast<std::size_t>(n) + 1);
    for (int i = 0; i <= n; ++i) v[static_cast<std::size_t>(i)] = lo + (hi - lo) * i / n;
    return v;
  };
  std::vector<Vec3> out;
  const std::vector<Pose> links = gripper.link_poses(joints);
  for (int j = 0; j < gripper.joint_count(); ++j) {
    const LinkSpec& l = gripper.link(j);
    const Pose T = T_world_eef * links[static_cast<std::size_t>(j)];
    // The faces that lead the closing: the inner face (x = -thickness / 2, the side that closes
    // onto the object, under the pad) and the tip (z = length). They stop at the object; the
    // outer face moves away from it, and the sides move along it.
    for (double y : ticks(-0.5 * l.width, 0.5 * l.width))
      for (double z : ticks(0.0, l.length)) out.push_back(T * Vec3(-0.5 * l.thickness, y, z));
    for (double x : ticks(-0.5 * l.thickness, 0.5 * l.thickness))
      for (double y : ticks(-0.5 * l.width, 0.5 * l.width))
        if (x > -0.5 * l.thickness) out.push_back(T * Vec3(x, y, l.length));   // its inner edge is above
  }
  const auto& palm = gripper.spec().palm;
  if (settings.palm && palm.radius > 0 && palm.thickness > 0) {
    for (double x : ticks(-palm.radius, palm.radius))
      for (double y : ticks(-palm.radius, palm.radius))
        if (x * x + y * y <= palm.radius * palm.radius) out.push_back(T_world_eef * Vec3(x, y, 0.0));
  }
  return out;
}

void mark_swept_volume(OccupancyGrid& grid, const Gripper& gripper, const Pose& T_world_eef,
                       const std::vector<double>& joints, const FreeSpaceSettings& settings) {
  if (static_cast<int>(joints.size()) != gripper.joint_count())
    throw Error("joint count does not match the gripper", {}, "joints");
  const auto& spec = gripper.spec();
  if (settings.palm && spec.palm.radius > 0 && spec.palm.thickness > 0)
    grid.mark_free_cylinder(T_world_eef, spec.palm.radius, -spec.palm.thickness, 0.0);
  const auto waypoints = gripper.closing_waypoints(joints);
  const double max_step = 0.5 * grid.voxel();
  std::vector<Pose> links;
  for (std::size_t w = 0; w < waypoints.size(); ++w) {
    int steps = 1;
    if (w > 0) {
      // A point of finger f moves at most Σ_k lever(k) |dθ_k| over the segment.
      double move = 0.0;
      for (int f = 0; f < gripper.finger_count(); ++f) {
        double m = 0.0;
        for (std::size_t k = 0; k < gripper.spec().fingers[f].links.size(); ++k) {
          const int j = gripper.joint_index(f, static_cast<int>(k));
          m += gripper.lever(j) * std::abs(waypoints[w][j] - waypoints[w - 1][j]);
        }
        move = std::max(move, m);
      }
      steps = std::max(1, static_cast<int>(std::ceil(move / max_step)));
    }
    for (int s = (w == 0 ? 0 : 1); s <= (w == 0 ? 0 : steps); ++s) {
      std::vector<double> q = waypoints[w];
      if (w > 0) {
        const double t = static_cast<double>(s) / steps;
        for (std::size_t j = 0; j < q.size(); ++j)
          q[j] = waypoints[w - 1][j] + t * (waypoints[w][j] - waypoints[w - 1][j]);
      }
      links = gripper.link_poses(q);
      for (int j = 0; j < gripper.joint_count(); ++j) {
        const LinkSpec& l = gripper.link(j);
        const Vec3 lo(-0.5 * l.thickness, -0.5 * l.width, 0.0);
        const Vec3 hi(0.5 * l.thickness, 0.5 * l.width, l.length);
        // Skip links that did not move on this segment (marked at an earlier waypoint).
        if (w > 0) {
          bool moved = false;
          const int f = gripper.finger_of_joint(j);
          for (int k = 0; k <= gripper.link_of_joint(j); ++k) {
            const int jk = gripper.joint_index(f, k);
            moved |= waypoints[w][jk] != waypoints[w - 1][jk];
          }
          if (!moved) continue;
        }
        grid.mark_free_box(T_world_eef * links[j], lo, hi);
      }
    }
  }
}

Eigen::AlignedBox3d free_space_box(const std::vector<Vec3>& contacts, double s_obj_max) {
  Eigen::AlignedBox3d box;
  if (contacts.empty()) return box;
  Eigen::AlignedBox3d cont;
  Vec3 c = Vec3::Zero();
  // Centroid relative to the first point (numerically safe far from the origin).
  const Vec3 ref = contacts.front();
  for (const auto& p : contacts) {
    cont.extend(p);
    c += p - ref;
  }
  c = ref + c / static_cast<double>(contacts.size());
  const Vec3 half = 0.5 * cont.sizes() + Vec3::Constant(s_obj_max);
  return Eigen::AlignedBox3d(c - half, c + half);
}

}  // namespace touch
}  // namespace ts
