#include "engine/geometry/congruence.hpp"

#include "engine/geometry/eigen_solvers.hpp"
#include "engine/geometry/kabsch.hpp"
#include "engine/geometry/mesh.hpp"
#include "engine/geometry/symmetry.hpp"

#include <Eigen/Eigenvalues>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <numeric>

namespace ts {
inline namespace geometry {

namespace {

// Prefilter slacks, in units of eps (the largest surface distance allowed). Surfaces within eps
// of each other, point for point: each spread (a singular value of the centred points over the
// square root of their count) moves by at most the RMS displacement, so by eps (Weyl's inequality
// for singular values), and the size by up to 2 eps (both ends of a stretched bar move by eps).
// The margins cover unequal area measures (a remeshed surface): measured on the 450-object study
// database, accepted pairs reach 0.9 eps in a spread and 1.4 eps in the size.
constexpr double kSizeSlack = 2.5;
constexpr double kSpreadSlack = 1.5;

bool face_ok(const Mesh& m, const Eigen::Vector3i& f) {
  const auto n = static_cast<int>(m.vertices.size());
  return f[0] >= 0 && f[1] >= 0 && f[2] >= 0 && f[0] < n && f[1] < n && f[2] < n;
}

/// Area-weighted surface moments, exact over the triangles: for a triangle (a, b, c) of area w,
/// integral of x = w (a + b + c) / 3, integral of x x^T = w / 12 (a a^T + b b^T + c c^T + s s^T),
/// s = a + b + c (computed about the bounding-box centre, for precision).
struct SurfaceMoments {
  Vec3 centroid = Vec3::Zero();
  Mat3 axes = Mat3::Identity();
  ShapeSignature signature;
};

SurfaceMoments surface_moments(const Mesh& mesh) {
  SurfaceMoments out;
  if (mesh.vertices.empty()) return out;
  Eigen::AlignedBox3d box;
  for (const Vec3& v : mesh.vertices) box.extend(v);
  const Vec3 o = box.center();
  double area = 0.0;
  Vec3 m1 = Vec3::Zero();
  Mat3 m2 = Mat3::Zero();
  for (const auto& f : mesh.faces) {
    if (!face_ok(mesh, f)) continue;
    const Vec3 a = mesh.vertices[f[0]] - o, b = mesh.vertices[f[1]] - o, c = mesh.vertices[f[2]] - o;
    const double w = 0.5 * (b - a).cross(c - a).norm();
    const Vec3 s = a + b + c;
    area += w;
    m1 += w * s / 3.0;
    m2 += w / 12.0 * (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
  }
  if (!(area > 0.0)) return out;
  const Vec3 mean = m1 / area;
  const Mat3 cov = m2 / area - mean * mean.transpose();
  Eigen::SelfAdjointEigenSolver<Mat3> eig(cov);
  out.centroid = o + mean;
  out.axes = eig.eigenvectors();
  for (int k = 0; k < 3; ++k) out.signature.spread[static_cast<std::size_t>(k)] = std::sqrt(std::max(eig.eigenvalues()[k], 0.0));
  double r = 0.0;
  for (const Vec3& v : mesh.vertices) r = std::max(r, (v - out.centroid).norm());
  out.signature.size = 2.0 * r;
  return out;
}

/// Area-uniform sample of the surface, deterministic for a seed.
std::vector<Vec3> sample_surface(const Mesh& mesh, std::size_t n, std::uint64_t seed) {
  std::vector<double> cum;
  std::vector<std::size_t> face;
  double total = 0.0;
  for (std::size_t i = 0; i < mesh.faces.size(); ++i) {
    const auto& f = mesh.faces[i];
    if (!face_ok(mesh, f)) continue;
    const double w = 0.5 * (mesh.vertices[f[1]] - mesh.vertices[f[0]]).cross(mesh.vertices[f[2]] - mesh.vertices[f[0]]).norm();
    if (!(w > 0.0)) continue;
    total += w;
    cum.push_back(total);
    face.push_back(i);
  }
  std::vector<Vec3> out;
  if (cum.empty()) return out;
  Rng rng(seed, 0xc0e6u);
  out.reserve(n);
  for (std::size_t k = 0; k < n; ++k) {
    const double x = rng.uniform(0.0, total);
    const std::size_t j = std::min<std::size_t>(
        static_cast<std::size_t>(std::upper_bound(cum.begin(), cum.end(), x) - cum.begin()), cum.size() - 1);
    const auto& f = mesh.faces[face[j]];
    const double r1 = std::sqrt(rng.uniform()), r2 = rng.uniform();
    out.push_back((1.0 - r1) * mesh.vertices[f[0]] + r1 * (1.0 - r2) * mesh.vertices[f[1]] +
                  r1 * r2 * mesh.vertices[f[2]]);
  }
  return out;
}

}  // namespace

ShapeSignature surface_signature(const Mesh& mesh) { return surface_moments(mesh).signature; }

bool may_be_congruent(const ShapeSignature& a, const ShapeSignature& b, double tolerance) {
  const double eps = tolerance * std::max(a.size, b.size);
  if (std::abs(a.size - b.size) > kSizeSlack * eps) return false;
  for (std::size_t k = 0; k < 3; ++k)
    if (std::abs(a.spread[k] - b.spread[k]) > kSpreadSlack * eps) return false;
  return true;
}

const char* to_string(Congruence c) {
  switch (c) {
    case Congruence::congruent: return "congruent";
    case Congruence::mirror: return "mirror";
    default: return "none";
  }
}

// --- prepared shapes -------------------------------------------------------------------------
struct CongruenceShape::Impl {
  MeshIndex index;
  SurfaceMoments moments;
  std::vector<Vec3> sample;
  std::vector<Vec3> vertices;   ///< centred on the centroid (extreme points)
  explicit Impl(const Mesh& mesh) : index(mesh) {}
};

CongruenceShape::CongruenceShape(const Mesh& mesh, const CongruenceSettings& s) : impl_(std::make_unique<Impl>(mesh)) {
  impl_->moments = surface_moments(mesh);
  impl_->sample = sample_surface(mesh, std::max<std::size_t>(s.samples, 16), s.seed);
  impl_->vertices.reserve(mesh.vertices.size());
  for (const Vec3& v : mesh.vertices) impl_->vertices.push_back(v - impl_->moments.centroid);
}
CongruenceShape::~CongruenceShape() = default;
CongruenceShape::CongruenceShape(CongruenceShape&&) noexcept = default;
CongruenceShape& CongruenceShape::operator=(CongruenceShape&&) noexcept = default;

const ShapeSignature& CongruenceShape::signature() const { return impl_->moments.signature; }
const Vec3& CongruenceShape::centroid() const { return impl_->moments.centroid; }
const Mat3& CongruenceShape::axes() const { return impl_->moments.axes; }
const std::vector<Vec3>& CongruenceShape::sample() const { return impl_->sample; }
const std::vector<Vec3>& CongruenceShape::vertices() const { return impl_->vertices; }
double CongruenceShape::distance(const Vec3& p) const { return impl_->index.closest(p).distance; }
Vec3 CongruenceShape::closest(const Vec3& p) const { return impl_->index.closest(p).point; }

// --- comparison ------------------------------------------------------------------------------
namespace {

struct Motion {
  Mat3 L = Mat3::Identity();
  Vec3 t = Vec3::Zero();
};

/// m points spread over the sample (every (n/m)-th).
std::vector<Vec3> stride(const std::vector<Vec3>& v, std::size_t m) {
  std::vector<Vec3> out;
  const std::size_t n = v.size();
  m = std::min(m, n);
  for (std::size_t i = 0; i < m; ++i) out.push_back(v[(i * n) / m]);
  return out;
}

/// Sum of squared distances (each clamped at `cap`) of the points moved by m onto b.
double quick_cost(const std::vector<Vec3>& pts, const Motion& m, const CongruenceShape& b, double cap) {
  double s = 0.0;
  for (const Vec3& x : pts) s += std::min(b.distance(m.L * x + m.t), cap);
  return s;
}

/// Symmetric point-to-point ICP: a's points `pa` paired with their closest points on b, and b's
/// points `pb` with their closest points on a (moved along), fitted together, so that a part of
/// one surface that the other lacks pulls from both sides (a stretched copy stays centred instead
/// of sliding along its flat faces). Keeps det(L). `rms` receives the RMS pair distance of the
/// last iteration.
Motion icp(const CongruenceShape& a, const std::vector<Vec3>& pa, const CongruenceShape& b,
           const std::vector<Vec3>& pb, Motion m, double size, int iterations, double stop, double* rms) {
  std::vector<Vec3> x(pa.size() + pb.size()), y(x.size());
  for (int it = 0; it < iterations; ++it) {
    const Mat3 Li = m.L.transpose();
    for (std::size_t i = 0; i < pa.size(); ++i) {
      x[i] = m.L * pa[i] + m.t;
      y[i] = b.closest(x[i]);
    }
    for (std::size_t j = 0; j < pb.size(); ++j) {
      x[pa.size() + j] = m.L * a.closest(Li * (pb[j] - m.t)) + m.t;
      y[pa.size() + j] = pb[j];
    }
    const RigidFit fit = kabsch(x, y);
    if (!fit.valid) break;
    const Mat3 U = fit.T_target_source.linear();
    const Vec3 u = fit.T_target_source.translation();
    m.L = U * m.L;
    m.t = U * m.t + u;
    if (rms) *rms = fit.rms;
    if (rotation_angle(U) < stop && u.norm() < stop * size) break;
  }
  return m;
}

/// Largest distance, both ways, at motion m (x_b = L x_a + t), relative to `size`. Stops at the
/// first distance above `stop` (relative; the result is then a lower bound above it).
double two_way_distance(const CongruenceShape& a, const CongruenceShape& b, const Motion& m, double size,
                        double stop = std::numeric_limits<double>::infinity()) {
  const Mat3 Li = m.L.transpose();   // orthogonal
  const double limit = stop * size;
  double d = 0.0;
  for (const Vec3& x : a.sample())
    if ((d = std::max(d, b.distance(m.L * x + m.t))) > limit) return d / size;
  for (const Vec3& y : b.sample())
    if ((d = std::max(d, a.distance(Li * (y - m.t)))) > limit) return d / size;
  return d / size;
}

/// Candidate rotations (about the centroids) from the principal axes: every sign choice.
void axis_candidates(const CongruenceShape& a, const CongruenceShape& b, std::vector<Mat3>& out) {
  for (int s = 0; s < 8; ++s) {
    const Vec3 d((s & 1) ? -1.0 : 1.0, (s & 2) ? -1.0 : 1.0, (s & 4) ? -1.0 : 1.0);
    out.push_back(b.axes() * d.asDiagonal() * a.axes().transpose());
  }
}

/// Candidate rotations from extreme vertices (shapes whose principal axes are not defined), onto
/// b reflected by `reflect` first (identity or a mirror), composed with the reflection.
void extreme_candidates(const std::vector<Vec3>& va, const std::vector<Vec3>& vb, const Mat3& reflect, double eps,
                        std::vector<Mat3>& out) {
  std::vector<Vec3> target;
  target.reserve(vb.size());
  for (const Vec3& p : vb) target.push_back(reflect * p);
  for (const Mat3& R : extreme_pair_rotations(va, target, eps)) out.push_back(reflect * R);   // reflect^-1 = reflect
}

/// The best motion of one handedness (proper: det +1, improper: det -1) among the candidates:
/// the `keep` cheapest by quick cost, each refined by ICP, judged by the two-way distance.
std::pair<Motion, double> best_of(const CongruenceShape& a, const CongruenceShape& b, const std::vector<Mat3>& rotations,
                                  bool proper, double size, double eps, const std::vector<Vec3>& quick,
                                  const std::vector<Vec3>& fit_a, const std::vector<Vec3>& fit_b) {
  // Cheap first: 24 points for every candidate, 128 for the best 12, ICP for the best 3.
  const std::vector<Vec3> first(quick.begin(), quick.begin() + static_cast<std::ptrdiff_t>(std::min<std::size_t>(24, quick.size())));
  std::vector<std::pair<double, std::size_t>> cost;
  for (std::size_t i = 0; i < rotations.size(); ++i) {
    if ((rotations[i].determinant() > 0.0) != proper) continue;
    Motion m{rotations[i], b.centroid() - rotations[i] * a.centroid()};
    cost.emplace_back(quick_cost(first, m, b, 4.0 * eps), i);
  }
  std::sort(cost.begin(), cost.end());
  if (cost.size() > 12) cost.resize(12);
  for (auto& [c, i] : cost) c = quick_cost(quick, Motion{rotations[i], b.centroid() - rotations[i] * a.centroid()}, b, 4.0 * eps);
  std::sort(cost.begin(), cost.end());
  // Coarse ICP (100 + 100 points, at most 15 iterations) of the best 3 (only those whose quick
  // cost is within twice the best's); the best of them by RMS is refined (300 + 300 points)
  // unless even its RMS is 3 times the tolerance: the largest distance, at least the RMS, is then
  // far beyond it. The check stops at the first point 3 times beyond the tolerance (for a pair
  // that is not congruent only a lower bound is needed).
  const auto coarse_a = stride(fit_a, 100), coarse_b = stride(fit_b, 100);
  Motion coarse;
  double coarse_rms = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < cost.size() && k < 3; ++k) {
    if (k > 0 && cost[k].first > 2.0 * cost[0].first + 1e-12 * size) break;
    const Mat3& R = rotations[cost[k].second];
    double rms = std::numeric_limits<double>::infinity();
    const Motion m = icp(a, coarse_a, b, coarse_b, Motion{R, b.centroid() - R * a.centroid()}, size, 15, 1e-6, &rms);
    if (rms < coarse_rms) {
      coarse_rms = rms;
      coarse = m;
    }
  }
  const double stop = 3.0 * eps / size;
  if (!std::isfinite(coarse_rms)) return {Motion{}, std::numeric_limits<double>::infinity()};
  if (coarse_rms > 3.0 * eps) return {coarse, two_way_distance(a, b, coarse, size, stop)};
  const Motion fine = icp(a, fit_a, b, fit_b, coarse, size, 40, 1e-9, nullptr);
  return {fine, two_way_distance(a, b, fine, size, stop)};
}

/// Which principal axes a signature defines: all three (their spreads differ by more than 15 %),
/// only one (the other two alike: a disc, a nut, a bar of square section; returns its index),
/// or none (a cube, a regular octahedron, a sphere).
enum class Axes { three, one, none };
Axes defined_axes(const ShapeSignature& s, int* unique) {
  auto alike = [&](std::size_t i, std::size_t j) { return s.spread[j] - s.spread[i] <= 0.15 * s.spread[j]; };
  const bool a01 = alike(0, 1), a12 = alike(1, 2);
  if (a01 && a12) return Axes::none;
  if (!a01 && !a12) return Axes::three;
  *unique = a01 ? 2 : 0;
  return Axes::one;
}

/// Candidate rotations for shapes with one defined axis: a's axis onto b's (both signs), then
/// every turn about it in 3 degree steps; and the same after a reflection through a plane that
/// holds a's axis (the mirror-image candidates).
void sweep_candidates(const CongruenceShape& a, const CongruenceShape& b, int unique, std::vector<Mat3>& out) {
  const Vec3 ua = a.axes().col(unique).normalized(), ub = b.axes().col(unique).normalized();
  const Vec3 n = ua.unitOrthogonal();
  const Mat3 reflect = Mat3::Identity() - 2.0 * n * n.transpose();
  constexpr int kSteps = 120;
  for (double sign : {1.0, -1.0}) {
    // normalized(): for nearly opposite vectors (1 + cos small, but above Eigen's threshold
    // for its exact branch) FromTwoVectors' quaternion is off unit length by up to 1e-4.
    const Mat3 R0 = quaternion_from_two_vectors(ua, sign * ub).normalized().toRotationMatrix();
    for (int k = 0; k < kSteps; ++k) {
      const Mat3 R = Eigen::AngleAxisd(2.0 * std::numbers::pi * k / kSteps, ub).toRotationMatrix() * R0;
      out.push_back(R);
      out.push_back(R * reflect);
    }
  }
}

}  // namespace

CongruenceMatch compare_shapes(const CongruenceShape& a, const CongruenceShape& b, const CongruenceSettings& s) {
  CongruenceMatch out;
  const double size = std::max(a.signature().size, b.signature().size);
  if (!(size > 0.0) || a.sample().empty() || b.sample().empty()) return out;
  const double eps = s.tolerance * size;
  std::vector<Mat3> rotations;
  // Principal axes always; where either shape leaves them (partly) undefined, the candidates of
  // its kind too.
  axis_candidates(a, b, rotations);
  int unique_a = -1, unique_b = -1;
  const Axes axes_a = defined_axes(a.signature(), &unique_a), axes_b = defined_axes(b.signature(), &unique_b);
  if (axes_a == Axes::one || axes_b == Axes::one) sweep_candidates(a, b, axes_a == Axes::one ? unique_a : unique_b, rotations);
  if (axes_a == Axes::none || axes_b == Axes::none) {
    const Mat3 mirror = Vec3(-1.0, 1.0, 1.0).asDiagonal();
    extreme_candidates(a.vertices(), b.vertices(), Mat3::Identity(), eps, rotations);
    extreme_candidates(a.vertices(), b.vertices(), mirror, eps, rotations);
  }
  const auto quick = stride(a.sample(), 128);
  const auto fit_a = stride(a.sample(), 300), fit_b = stride(b.sample(), 300);
  const auto proper = best_of(a, b, rotations, true, size, eps, quick, fit_a, fit_b);
  out.proper_distance = proper.second;
  out.linear = proper.first.L;
  out.translation = proper.first.t;
  if (out.proper_distance <= s.tolerance) {
    out.kind = Congruence::congruent;
    return out;
  }
  // Mirror images: a reflection fits and no rotation comes near (a nearly symmetric pair just
  // beyond the tolerance either way is no left and right part).
  if (out.proper_distance <= 2.0 * s.tolerance) return out;
  const auto improper = best_of(a, b, rotations, false, size, eps, quick, fit_a, fit_b);
  out.mirror_distance = improper.second;
  if (out.mirror_distance <= s.tolerance) {
    out.kind = Congruence::mirror;
    out.linear = improper.first.L;
    out.translation = improper.first.t;
  }
  return out;
}

CongruenceMatch compare_meshes(const Mesh& a, const Mesh& b, const CongruenceSettings& s) {
  return compare_shapes(CongruenceShape(a, s), CongruenceShape(b, s), s);
}

// --- many objects ----------------------------------------------------------------------------
std::vector<CongruentPair> find_congruent_pairs(const std::vector<ShapeSignature>& sigs,
                                                const std::function<Mesh(std::size_t)>& mesh_of, std::size_t first_new,
                                                const CongruenceSettings& s, CongruenceSearchStats* stats,
                                                std::size_t batch_objects) {
  if (!(s.tolerance > 0.0) || !std::isfinite(s.tolerance))
    throw Error("the congruence tolerance must be a positive number, not " + std::to_string(s.tolerance), {},
                "tolerance");
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t n = sigs.size();
  // 1. Candidates: sorted by size, only neighbours within the size slack can pass.
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) {
    return sigs[x].size != sigs[y].size ? sigs[x].size < sigs[y].size : x < y;
  });
  std::vector<std::pair<std::uint32_t, std::uint32_t>> candidates;
  for (std::size_t oi = 0; oi < n; ++oi) {
    const std::size_t i = order[oi];
    for (std::size_t oj = oi + 1; oj < n; ++oj) {
      const std::size_t j = order[oj];
      if (sigs[j].size - sigs[i].size > kSizeSlack * s.tolerance * sigs[j].size) break;
      if (std::max(i, j) < first_new) continue;
      if (may_be_congruent(sigs[i], sigs[j], s.tolerance))
        candidates.emplace_back(static_cast<std::uint32_t>(std::min(i, j)), static_cast<std::uint32_t>(std::max(i, j)));
    }
  }
  // Grouped by connected component of the candidate graph (near-twins come in clusters), so that
  // a batch holds whole clusters and an object is prepared once unless its cluster is larger
  // than a batch; by (a, b) within a cluster.
  {
    std::vector<std::size_t> parent(n);
    std::iota(parent.begin(), parent.end(), std::size_t{0});
    auto root = [&](std::size_t x) {
      while (parent[x] != x) x = parent[x] = parent[parent[x]];
      return x;
    };
    for (const auto& [a, b] : candidates) {
      const std::size_t x = root(a), y = root(b);
      if (x != y) parent[std::max(x, y)] = std::min(x, y);
    }
    std::sort(candidates.begin(), candidates.end(), [&](const auto& p, const auto& q) {
      const std::size_t rp = root(p.first), rq = root(q.first);
      return rp != rq ? rp < rq : p < q;
    });
  }
  // 2. Batches of consecutive candidates over at most batch_objects objects: shapes prepared in
  //    parallel, pairs compared in parallel, each into its own slot.
  std::vector<CongruenceMatch> match(candidates.size());
  std::size_t prepared = 0;
  batch_objects = std::max<std::size_t>(batch_objects, 2);
  for (std::size_t begin = 0; begin < candidates.size();) {
    std::vector<std::uint32_t> objects;
    std::size_t end = begin;
    for (; end < candidates.size(); ++end) {
      std::vector<std::uint32_t> more = objects;
      for (std::uint32_t o : {candidates[end].first, candidates[end].second})
        if (std::find(more.begin(), more.end(), o) == more.end()) more.push_back(o);
      if (more.size() > batch_objects && end > begin) break;
      objects = std::move(more);
    }
    std::sort(objects.begin(), objects.end());
    std::vector<std::unique_ptr<CongruenceShape>> shapes(objects.size());
    tbb::parallel_for(std::size_t{0}, objects.size(), [&](std::size_t k) {
      shapes[k] = std::make_unique<CongruenceShape>(mesh_of(objects[k]), s);
    });
    prepared += objects.size();
    auto shape = [&](std::uint32_t o) -> const CongruenceShape& {
      return *shapes[static_cast<std::size_t>(std::lower_bound(objects.begin(), objects.end(), o) - objects.begin())];
    };
    tbb::parallel_for(begin, end, [&](std::size_t k) {
      match[k] = compare_shapes(shape(candidates[k].first), shape(candidates[k].second), s);
    });
    begin = end;
  }
  std::vector<CongruentPair> out;
  for (std::size_t k = 0; k < candidates.size(); ++k)
    if (match[k].kind != Congruence::none)
      out.push_back({candidates[k].first, candidates[k].second, match[k].kind, match[k].distance(), match[k].linear,
                     match[k].translation});
  std::sort(out.begin(), out.end(), [](const CongruentPair& x, const CongruentPair& y) {
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  });
  if (stats) {
    stats->candidates = candidates.size();
    stats->prepared = prepared;
    stats->found = out.size();
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  return out;
}

std::vector<std::vector<std::size_t>> congruence_classes(std::size_t n, const std::vector<CongruentPair>& pairs) {
  std::vector<std::size_t> parent(n);
  std::iota(parent.begin(), parent.end(), std::size_t{0});
  auto root = [&](std::size_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const auto& p : pairs) {
    if (p.kind != Congruence::congruent || p.a >= n || p.b >= n) continue;
    const std::size_t x = root(p.a), y = root(p.b);
    if (x != y) parent[std::max(x, y)] = std::min(x, y);
  }
  std::vector<std::vector<std::size_t>> by_root(n);
  for (std::size_t i = 0; i < n; ++i) by_root[root(i)].push_back(i);
  std::vector<std::vector<std::size_t>> out;
  for (auto& c : by_root)
    if (c.size() >= 2) out.push_back(std::move(c));
  return out;   // each root is its class's smallest member, so classes come by first member
}

}  // namespace geometry
}  // namespace ts
