#include "engine/recognition/scene.hpp"

#include "engine/geometry/cloud.hpp"
#include "engine/geometry/eigen_solvers.hpp"


#include <algorithm>
#include <cmath>
#include <numeric>

namespace ts {
inline namespace recognition {

namespace {

constexpr std::uint64_t kTagOrder = 0x0de7;
constexpr std::uint64_t kTagFreeOrder = 0xf7ee;

/// Largest pairwise distance: exact up to a few thousand points, else a lower bound from the
/// extreme points along 13 directions (enough for the size filter, which needs a lower bound).
double diameter_of(const std::vector<Vec3>& p) {
  const std::size_t n = p.size();
  if (n < 2) return 0.0;
  std::vector<std::size_t> idx;
  if (n <= 3000) {
    idx.resize(n);
    std::iota(idx.begin(), idx.end(), std::size_t{0});
  } else {
    static const std::array<Vec3, 13> dirs = {
        Vec3(1, 0, 0),  Vec3(0, 1, 0),  Vec3(0, 0, 1),  Vec3(1, 1, 0),  Vec3(1, -1, 0),
        Vec3(1, 0, 1),  Vec3(1, 0, -1), Vec3(0, 1, 1),  Vec3(0, 1, -1), Vec3(1, 1, 1),
        Vec3(1, 1, -1), Vec3(1, -1, 1), Vec3(-1, 1, 1)};
    for (const Vec3& d : dirs) {
      std::size_t lo = 0, hi = 0;
      for (std::size_t i = 1; i < n; ++i) {
        if (p[i].dot(d) < p[lo].dot(d)) lo = i;
        if (p[i].dot(d) > p[hi].dot(d)) hi = i;
      }
      idx.push_back(lo);
      idx.push_back(hi);
    }
  }
  double best = 0.0;
  for (std::size_t a = 0; a < idx.size(); ++a)
    for (std::size_t b = a + 1; b < idx.size(); ++b)
      best = std::max(best, (p[idx[a]] - p[idx[b]]).squaredNorm());
  return std::sqrt(best);
}

}  // namespace

Pose Scene::to_world(const Pose& T_scene_object) const {
  Pose T = T_scene_object;
  T.translation() += origin;
  return T;
}

Pose Scene::to_scene(const Pose& T_world_object) const {
  Pose T = T_world_object;
  T.translation() -= origin;
  return T;
}

int unobservable_dof(const std::vector<Vec3>& points, const std::vector<Vec3>& normals,
                     double eps) {
  std::size_t n = 0;
  Vec3 c = Vec3::Zero();
  for (std::size_t i = 0; i < points.size(); ++i)
    if (normals[i].squaredNorm() > 0.5) { c += points[i]; ++n; }
  if (n < 3) return 6;
  c /= static_cast<double>(n);
  double r2 = 0.0;
  for (std::size_t i = 0; i < points.size(); ++i)
    if (normals[i].squaredNorm() > 0.5) r2 += (points[i] - c).squaredNorm();
  const double L = std::sqrt(r2 / static_cast<double>(n));
  if (!(L > 0.0)) return 6;
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (normals[i].squaredNorm() <= 0.5) continue;
    Eigen::Matrix<double, 6, 1> J;
    J.head<3>() = normals[i];
    J.tail<3>() = ((points[i] - c) / L).cross(normals[i]);
    H.noalias() += J * J.transpose();
  }
  const Eigen::Matrix<double, 6, 1> ev = symmetric_eigenvalues(H);
  const double top = ev[5];
  if (!(top > 0.0)) return 6;
  int k = 0;
  for (int i = 0; i < 6; ++i)
    if (ev[i] < eps * top) ++k;
  return k;
}

namespace {

/// 1. Finite points only (in `in`, with their normals if the cloud has them); the origin is
///    their centroid, accumulated relative to the first point so that coordinates far from the
///    world origin keep their precision; the free space in a fixed pseudo-random order, so that
///    every prefix is a representative subset.
PointCloud local_points(Scene& sc, const PointCloud& contacts_world, const std::vector<Vec3>& free_world,
                        std::uint64_t seed, std::uint64_t step) {
  PointCloud in;
  const bool with_normals = contacts_world.has_normals();
  for (std::size_t i = 0; i < contacts_world.size(); ++i) {
    const Vec3& p = contacts_world.points[i];
    if (!finite(p) || (with_normals && !finite(contacts_world.normals[i]))) {
      ++sc.dropped_non_finite;
      continue;
    }
    in.points.push_back(p);
    if (with_normals) in.normals.push_back(contacts_world.normals[i]);
  }
  if (!in.empty()) {
    const Vec3 ref = in.points[0];
    Vec3 acc = Vec3::Zero();
    for (const Vec3& p : in.points) acc += p - ref;
    sc.origin = ref + acc / static_cast<double>(in.size());
  } else if (!free_world.empty()) {
    sc.origin = free_world[0];
  }
  for (Vec3& p : in.points) p -= sc.origin;
  for (const Vec3& q : free_world)
    if (finite(q)) sc.free_space.push_back(q - sc.origin);
  Rng rng(seed, step, kTagFreeOrder);
  for (std::size_t i = sc.free_space.size(); i > 1; --i)
    std::swap(sc.free_space[i - 1], sc.free_space[rng.index(i)]);
  return in;
}

/// The contacts, their evaluation order, tree, diameter and RMS radius; free points closer to
/// a contact than the clearance dropped.
void set_contacts(Scene& sc, const PointCloud& in, const SceneSettings& s, std::uint64_t seed, std::uint64_t step) {
  const std::size_t n = in.size();
  sc.contacts.points = in.points;
  sc.contacts.normals.assign(n, Vec3::Zero());
  sc.features = FeatureRows(descriptor_dim(s.descriptor), n);
  sc.feature_valid.assign(n, 0);
  sc.interior.assign(n, 0);
  sc.order.resize(n);
  std::iota(sc.order.begin(), sc.order.end(), std::uint32_t{0});
  Rng rng(seed, step, kTagOrder);
  for (std::size_t i = n; i > 1; --i) std::swap(sc.order[i - 1], sc.order[rng.index(i)]);
  sc.ordered.reserve(n);
  for (std::uint32_t i : sc.order) sc.ordered.push_back(sc.contacts.points[i]);
  if (n == 0) return;
  sc.tree = KdTree3(sc.contacts.points);
  sc.diameter = diameter_of(sc.contacts.points);
  if (s.free_clearance > 0.0 && !sc.free_space.empty()) {
    const double c2 = s.free_clearance * s.free_clearance;
    std::vector<Vec3> kept;
    kept.reserve(sc.free_space.size());
    for (const Vec3& q : sc.free_space)
      if (sc.tree.nearest(q).sq_distance >= c2) kept.push_back(q);
    sc.dropped_free = sc.free_space.size() - kept.size();
    sc.free_space = std::move(kept);
  }
  double r2 = 0.0;
  for (const Vec3& p : sc.contacts.points) r2 += p.squaredNorm();  // centroid is the origin
  sc.rms_radius = std::sqrt(r2 / static_cast<double>(n));
}

/// 2. PCA normals (Section 4.3.1: normal radius of the database), oriented like the input's
///    normals when it has them, else away from the contacts' centroid; the observability.
void set_normals(Scene& sc, const PointCloud& in, const FpfhSettings& fpfh, const SceneSettings& s) {
  NormalSettings ns;
  ns.radius = fpfh.normal_radius;
  const std::vector<Vec3> normals = estimate_normals(sc.contacts.points, ns);
  const bool with_normals = in.has_normals();
  for (std::size_t i = 0; i < sc.contacts.size(); ++i) {
    Vec3 nv = normals[i];
    if (!finite(nv) || nv.squaredNorm() < 0.5) continue;
    nv.normalize();
    const Vec3 ref = with_normals ? in.normals[i] : Vec3(sc.contacts.points[i]);
    if (nv.dot(ref) < 0.0) nv = -nv;
    sc.contacts.normals[i] = nv;
  }
  sc.unobservable_dof = unobservable_dof(sc.contacts.points, sc.contacts.normals, s.observability_eps);
}

/// 3. The descriptor (FPFH by default) on the points with normals (neighbourhoods from those
///    points only).
void set_descriptors(Scene& sc, const FpfhSettings& fpfh, const SceneSettings& s) {
  std::vector<std::uint32_t> with;
  for (std::size_t i = 0; i < sc.contacts.size(); ++i)
    if (sc.contacts.normals[i].squaredNorm() > 0.5) with.push_back(static_cast<std::uint32_t>(i));
  if (with.size() < 3) return;
  PointCloud surf;
  surf.points.reserve(with.size());
  surf.normals.reserve(with.size());
  for (std::uint32_t i : with) {
    surf.points.push_back(sc.contacts.points[i]);
    surf.normals.push_back(sc.contacts.normals[i]);
  }
  const KdTree3 surf_tree(surf.points);
  DescriptorSettings ds;
  ds.feature_radius = fpfh.feature_radius;
  const Descriptors fr = compute_descriptors(s.descriptor, surf.points, surf.normals, surf, surf_tree, ds);
  for (std::size_t k = 0; k < with.size(); ++k) {
    bool ok = fr.valid[k];
    for (float v : fr.row(k)) ok = ok && std::isfinite(v);
    if (!ok) continue;
    std::copy(fr.row(k).begin(), fr.row(k).end(), sc.features.row(with[k]));
    sc.feature_valid[with[k]] = 1;
  }
}

/// 4. Interior points: a full neighbourhood within the feature radius, i.e. the neighbours'
///    centroid does not shift tangentially (a patch boundary shifts it by ~0.4 radius).
void set_interior(Scene& sc, const FpfhSettings& fpfh, const SceneSettings& s) {
  const double r = fpfh.feature_radius;
  for (std::size_t i = 0; i < sc.contacts.size(); ++i) {
    if (!sc.feature_valid[i]) continue;
    const auto nb = sc.tree.radius(sc.contacts.points[i], r);
    if (static_cast<int>(nb.size()) < s.min_neighbours) continue;
    Vec3 c = Vec3::Zero();
    for (const Neighbour& b : nb) c += sc.contacts.points[b.index];
    c /= static_cast<double>(nb.size());
    Vec3 shift = c - sc.contacts.points[i];
    const Vec3& nv = sc.contacts.normals[i];
    shift -= shift.dot(nv) * nv;
    if (shift.norm() <= s.boundary_shift * r) sc.interior[i] = 1;
  }
}

}  // namespace

Scene prepare_scene(const PointCloud& contacts_world, const std::vector<Vec3>& free_world,
                    const FpfhSettings& fpfh, const SceneSettings& s, std::uint64_t seed,
                    std::uint64_t step) {
  Scene sc;
  sc.feature_radius = fpfh.feature_radius;
  PointCloud in = local_points(sc, contacts_world, free_world, seed, step);
  if (s.query_voxel > 0.0 && !in.empty()) in = voxel_filter(in, s.query_voxel);
  set_contacts(sc, in, s, seed, step);
  if (in.size() < 3 || !(sc.diameter > 0.0)) return sc;
  set_normals(sc, in, fpfh, s);
  set_descriptors(sc, fpfh, s);
  set_interior(sc, fpfh, s);
  return sc;
}

void set_grasps(Scene& scene, const GraspGroups& in) {
  scene.grasps = GraspGroups{};
  std::vector<Vec3> g, f;
  const bool has_free = in.free_first.size() == in.first.size();
  for (std::size_t k = 0; k < in.grasps(); ++k) {
    g.clear();
    f.clear();
    for (std::uint32_t i = in.first[k]; i < in.first[k + 1] && i < in.points.size(); ++i)
      if (finite(in.points[i])) g.push_back(in.points[i] - scene.origin);
    if (has_free)
      for (std::uint32_t i = in.free_first[k]; i < in.free_first[k + 1] && i < in.free.size(); ++i)
        if (finite(in.free[i])) f.push_back(in.free[i] - scene.origin);
    std::optional<Vec3> pivot;
    if (in.pivots.size() == in.grasps() && finite(in.pivots[k])) pivot = in.pivots[k] - scene.origin;
    if (!g.empty()) scene.grasps.add(g, f, pivot);
  }
}

}  // namespace recognition
}  // namespace ts
