// Simulated laser scanner (Section 4.2): the database's dense clouds come from scanning the
// object's mesh from viewpoints chosen by the widest-unexplored-cone strategy.
#include "engine/geometry/scanner.hpp"

#include "engine/geometry/cloud.hpp"
#include "engine/geometry/search.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <memory>
#include <optional>

namespace ts {
inline namespace geometry {

namespace {

// Stream ids of ts::Rng(seed, stream, ...): every random draw of the scanner has its own.
constexpr std::uint64_t kTrackingStream = 0x5ca1;   // surface samples that track coverage
constexpr std::uint64_t kRandomViewStream = 0x7a2d; // random view directions (per view index)
constexpr std::uint64_t kCoverageStream = 0xc0fe;   // surface samples of surface_coverage

constexpr double kMaxPixels = 1 << 26;  // rays per view: beyond, settings are a mistake
constexpr double kFailDecay = 0.5;  // weight kept by a sample a chosen view should have covered

struct SurfaceSamples {
  std::vector<Vec3> points, normals;  ///< normals: unit face normals as wound
};

/// Area-weighted uniform samples on the mesh surface.
SurfaceSamples sample_surface(const Mesh& mesh, int count, Rng& rng) {
  SurfaceSamples s;
  std::vector<double> cumulative;
  cumulative.reserve(mesh.faces.size());
  double total = 0.0;
  for (const auto& f : mesh.faces) {
    const Vec3& a = mesh.vertices[f[0]];
    total += 0.5 * (mesh.vertices[f[1]] - a).cross(mesh.vertices[f[2]] - a).norm();
    cumulative.push_back(total);
  }
  if (!(total > 0.0) || count <= 0) return s;
  s.points.reserve(count);
  s.normals.reserve(count);
  for (int i = 0; i < count; ++i) {
    const double x = rng.uniform() * total;
    auto it = std::upper_bound(cumulative.begin(), cumulative.end(), x);
    if (it == cumulative.end()) --it;
    const auto& f = mesh.faces[static_cast<std::size_t>(it - cumulative.begin())];
    const Vec3 &a = mesh.vertices[f[0]], &b = mesh.vertices[f[1]], &c = mesh.vertices[f[2]];
    const double r1 = std::sqrt(rng.uniform()), r2 = rng.uniform();
    s.points.push_back((1.0 - r1) * a + r1 * (1.0 - r2) * b + r1 * r2 * c);
    s.normals.push_back((b - a).cross(c - a).normalized());
  }
  return s;
}

/// One view: an orthographic raster of parallel rays along `d`, pixel (i, j) starting at
/// origin + i h u + j h v, with its first hit (t = +inf for a miss).
struct View {
  Vec3 d, u, v, origin;
  double h = 0.0;
  int nu = 0, nv = 0;
  std::vector<double> t;
  std::vector<int> face;

  Vec3 ray_origin(int i, int j) const { return origin + (i * h) * u + (j * h) * v; }
  Vec3 hit(int i, int j) const { return ray_origin(i, j) + t[std::size_t(j) * nu + i] * d; }
};

/// Cast one view's raster. Every pixel's ray is parallel to d, so its first hit is the
/// nearest triangle covering the pixel centre in the orthographic projection: the rays are
/// traced by scan conversion with a depth test (exactly what per-ray BVH casting returns, an
/// order of magnitude faster). Like MeshIndex::raycast, barycentric coordinates get a small
/// tolerance so that rays through shared edges never slip through, triangles seen edge-on
/// are skipped, and equal depths go to the smaller face index.
View cast_view(const Mesh& mesh, const Vec3& d, const Vec3& centre, double radius, double h) {
  View view;
  view.d = d;
  view.u = d.unitOrthogonal();
  view.v = d.cross(view.u);
  view.h = h;
  // Vertices in raster coordinates: (a, b) in pixels (pixel centres at integers), z = depth.
  const std::size_t nvert = mesh.vertices.size();
  std::vector<Vec3> q(nvert);
  double amin = std::numeric_limits<double>::infinity(), amax = -amin, bmin = amin, bmax = -amin;
  for (std::size_t k = 0; k < nvert; ++k) {
    const Vec3 rel = mesh.vertices[k] - centre;
    q[k] = Vec3(rel.dot(view.u), rel.dot(view.v), rel.dot(d));
    amin = std::min(amin, q[k].x()), amax = std::max(amax, q[k].x());
    bmin = std::min(bmin, q[k].y()), bmax = std::max(bmax, q[k].y());
  }
  view.nu = static_cast<int>(std::ceil((amax - amin) / h)) + 2;
  view.nv = static_cast<int>(std::ceil((bmax - bmin) / h)) + 2;
  const double a0 = amin - 0.5 * h, b0 = bmin - 0.5 * h, depth0 = radius + h;
  view.origin = centre - depth0 * d + a0 * view.u + b0 * view.v;
  for (auto& p : q) p = Vec3((p.x() - a0) / h, (p.y() - b0) / h, p.z() + depth0);
  const std::size_t pixels = std::size_t(view.nu) * view.nv;
  view.t.assign(pixels, std::numeric_limits<double>::infinity());
  view.face.assign(pixels, -1);

  // Bin triangles into bands of rows (in face order), then fill the bands in parallel: each
  // band owns its rows, and the depth test makes the result independent of visiting order.
  constexpr int kBandRows = 8;
  const int bands = (view.nv + kBandRows - 1) / kBandRows;
  std::vector<std::vector<int>> band_faces(bands);
  constexpr double kEdgeEps = 1e-9;  // barycentric tolerance, as in MeshIndex::raycast
  const int n_faces = static_cast<int>(mesh.faces.size());
  for (int f = 0; f < n_faces; ++f) {
    const auto& fc = mesh.faces[f];
    const double lo = std::min({q[fc[0]].y(), q[fc[1]].y(), q[fc[2]].y()});
    const double hi = std::max({q[fc[0]].y(), q[fc[1]].y(), q[fc[2]].y()});
    const int j0 = std::max(0, static_cast<int>(std::ceil(lo - 1e-6)));
    const int j1 = std::min(view.nv - 1, static_cast<int>(std::floor(hi + 1e-6)));
    for (int band = j0 / kBandRows; j0 <= j1 && band <= j1 / kBandRows; ++band) band_faces[band].push_back(f);
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, bands, 1), [&](const tbb::blocked_range<int>& r) {
    for (int band = r.begin(); band != r.end(); ++band) {
      const int row_lo = band * kBandRows, row_hi = std::min(view.nv - 1, row_lo + kBandRows - 1);
      for (const int f : band_faces[band]) {
        const auto& fc = mesh.faces[f];
        const Vec3 &A = q[fc[0]], &B = q[fc[1]], &C = q[fc[2]];
        const double area2 = (B.x() - A.x()) * (C.y() - A.y()) - (B.y() - A.y()) * (C.x() - A.x());
        // Edge-on (the rays' Möller–Trumbore determinant would vanish): never hit.
        const double e1 = (B - A).head<2>().norm(), e2 = (C - A).head<2>().norm();
        if (!(std::abs(area2) > 1e-12 * std::max(e1 * e2, 1e-300))) continue;
        const double inv = 1.0 / area2;
        const double slack = 1e-6;
        const int i0 = std::max(0, static_cast<int>(std::ceil(std::min({A.x(), B.x(), C.x()}) - slack)));
        const int i1 = std::min(view.nu - 1, static_cast<int>(std::floor(std::max({A.x(), B.x(), C.x()}) + slack)));
        const int j0 = std::max(row_lo, static_cast<int>(std::ceil(std::min({A.y(), B.y(), C.y()}) - slack)));
        const int j1 = std::min(row_hi, static_cast<int>(std::floor(std::max({A.y(), B.y(), C.y()}) + slack)));
        for (int j = j0; j <= j1; ++j) {
          for (int i = i0; i <= i1; ++i) {
            // Barycentric coordinates of the pixel centre (i, j).
            const double l1 = ((i - A.x()) * (C.y() - A.y()) - (j - A.y()) * (C.x() - A.x())) * inv;
            const double l2 = ((B.x() - A.x()) * (j - A.y()) - (B.y() - A.y()) * (i - A.x())) * inv;
            if (l1 < -kEdgeEps || l2 < -kEdgeEps || l1 + l2 > 1.0 + kEdgeEps) continue;
            const double t = A.z() + l1 * (B.z() - A.z()) + l2 * (C.z() - A.z());
            const std::size_t px = std::size_t(j) * view.nu + i;
            if (t < view.t[px] || (t == view.t[px] && f < view.face[px])) {
              view.t[px] = t;
              view.face[px] = f;
            }
          }
        }
      }
    }
  });
  return view;
}

/// Append the view's first hits in pixel order, with face normals turned toward the scanner.
void append_hits(const Mesh& mesh, const View& view, PointCloud& hits) {
  for (int j = 0; j < view.nv; ++j)
    for (int i = 0; i < view.nu; ++i) {
      const int f = view.face[std::size_t(j) * view.nu + i];
      if (f < 0) continue;
      const auto& fc = mesh.faces[f];
      Vec3 normal = (mesh.vertices[fc[1]] - mesh.vertices[fc[0]])
                        .cross(mesh.vertices[fc[2]] - mesh.vertices[fc[0]])
                        .normalized();
      if (normal.dot(view.d) > 0.0) normal = -normal;
      hits.points.push_back(view.hit(i, j));
      hits.normals.push_back(normal);
    }
}

/// Is p within `radius` of a hit of the view? Looks only at the pixels around p's projection.
bool covered_by(const View& view, const Vec3& p, double radius) {
  const Vec3 rel = p - view.origin;
  const double fi = rel.dot(view.u) / view.h, fj = rel.dot(view.v) / view.h;
  const double w = radius / view.h;
  const int i0 = std::max(0, static_cast<int>(std::floor(fi - w)));
  const int i1 = std::min(view.nu - 1, static_cast<int>(std::ceil(fi + w)));
  const int j0 = std::max(0, static_cast<int>(std::floor(fj - w)));
  const int j1 = std::min(view.nv - 1, static_cast<int>(std::ceil(fj + w)));
  const double r2 = radius * radius;
  for (int j = j0; j <= j1; ++j)
    for (int i = i0; i <= i1; ++i)
      if (view.face[std::size_t(j) * view.nu + i] >= 0 && (view.hit(i, j) - p).squaredNorm() < r2)
        return true;
  return false;
}

/// How squarely a surface sample faces a scanner looking along d (one-sided for closed meshes).
inline double facing(const Vec3& normal, const Vec3& d, bool two_sided) {
  const double c = -normal.dot(d);
  return two_sided ? std::abs(c) : c;
}

/// The widest-unexplored-cone choice. A working set of up to kActiveSamples uncovered samples
/// (the first in index order; the samples are i.i.d., so this is a random subset) is scored
/// against every candidate direction: a candidate earns a sample's weight when it sees the
/// sample unoccluded at an incidence within max_incidence. Visibility never changes, so it is
/// ray-tested once per (sample, candidate) and cached.
class ViewPlanner {
 public:
  ViewPlanner(const MeshIndex& index, const SurfaceSamples& samples, std::vector<Vec3> candidates,
              bool two_sided, double min_facing, double radius)
      : index_(index), samples_(samples), candidates_(std::move(candidates)), two_sided_(two_sided),
        min_facing_(min_facing), offset_(1e-7 * radius),
        known_(samples.points.size(), 0), visible_(samples.points.size() * candidates_.size(), 0),
        hopeless_(samples.points.size(), 0) {}

  /// Best candidate for the uncovered samples (ascending indices), or nullopt when no
  /// uncovered sample is visible from any candidate (the rest is unreachable).
  std::optional<std::size_t> choose(const std::vector<std::uint32_t>& uncovered,
                                    const std::vector<double>& weight) {
    const std::size_t k_count = candidates_.size();
    std::vector<std::uint32_t> active;
    std::size_t cursor = 0;
    while (true) {
      // Fill the working set, then make sure every member's visibility row is known.
      for (; cursor < uncovered.size() && active.size() < kActiveSamples; ++cursor)
        if (!hopeless_[uncovered[cursor]]) active.push_back(uncovered[cursor]);
      if (active.empty()) return std::nullopt;
      std::vector<std::uint32_t> fresh;
      for (const std::uint32_t i : active)
        if (!known_[i]) fresh.push_back(i);
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, fresh.size(), 4), [&](const auto& r) {
        for (std::size_t k = r.begin(); k != r.end(); ++k) fill_row(fresh[k]);
      });
      for (const std::uint32_t i : fresh) known_[i] = 1;
      // Samples no candidate can see are dropped for good; refill and retry.
      std::vector<std::uint32_t> keep;
      for (const std::uint32_t i : active) {
        bool any = false;
        for (std::size_t c = 0; c < k_count && !any; ++c) any = visible_[i * k_count + c] != 0;
        if (any) keep.push_back(i);
        else hopeless_[i] = 1;
      }
      if (keep.size() == active.size()) break;
      active.swap(keep);
    }
    std::vector<double> score(k_count, 0.0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, k_count, 16), [&](const auto& r) {
      for (std::size_t c = r.begin(); c != r.end(); ++c) {
        double s = 0.0;
        for (const std::uint32_t i : active)
          if (visible_[i * k_count + c]) s += weight[i] * (0.5 + 0.5 * facing(samples_.normals[i], candidates_[c], two_sided_));
        score[c] = s;
      }
    });
    std::size_t best = 0;
    for (std::size_t c = 1; c < k_count; ++c)
      if (score[c] > score[best]) best = c;
    if (!(score[best] > 0.0)) return std::nullopt;
    return best;
  }

  const Vec3& direction(std::size_t c) const { return candidates_[c]; }
  bool sees(std::uint32_t i, std::size_t c) const {
    return known_[i] && visible_[i * candidates_.size() + c];
  }

 private:
  static constexpr std::size_t kActiveSamples = 384;

  void fill_row(std::uint32_t i) {
    const Vec3& p = samples_.points[i];
    const Vec3& n = samples_.normals[i];
    for (std::size_t c = 0; c < candidates_.size(); ++c) {
      const Vec3& d = candidates_[c];
      if (!(facing(n, d, two_sided_) >= min_facing_)) continue;
      const Vec3 lift = (n.dot(d) < 0.0 ? n : Vec3(-n)) * offset_;  // off the surface, toward the scanner
      visible_[i * candidates_.size() + c] = index_.occluded(p + lift, -d) ? 0 : 1;
    }
  }

  const MeshIndex& index_;
  const SurfaceSamples& samples_;
  std::vector<Vec3> candidates_;
  bool two_sided_;
  double min_facing_, offset_;
  std::vector<char> known_, visible_, hopeless_;
};

}  // namespace

PointCloud scan_view(const MeshIndex& index, const Vec3& direction, double pitch) {
  PointCloud hits;
  const Mesh& mesh = index.mesh();
  if (mesh.vertices.empty() || !(direction.norm() > 0.0) || !finite(direction)) return hits;
  if (!(pitch > 0.0)) throw Error("ray pitch must be positive", "", "pitch");
  const Vec3 centre = mesh_bounds(mesh).center();
  double radius = 0.0;
  for (const auto& p : mesh.vertices) radius = std::max(radius, (p - centre).norm());
  if (std::pow(2.0 * radius / pitch + 2.0, 2.0) > kMaxPixels)
    throw Error("ray raster too fine for the object's size", "", "pitch");
  append_hits(mesh, cast_view(mesh, direction.normalized(), centre, radius, pitch), hits);
  return hits;
}

double surface_coverage(const MeshIndex& mesh, const std::vector<Vec3>& points, double radius,
                        std::uint64_t seed, int samples) {
  Rng rng(seed, kCoverageStream);
  const SurfaceSamples s = sample_surface(mesh.mesh(), samples, rng);
  if (s.points.empty() || points.empty()) return 0.0;
  const KdTree3 tree(points);
  std::vector<char> covered(s.points.size(), 0);
  const double r2 = radius * radius;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, s.points.size(), 256), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i)
      covered[i] = tree.nearest(s.points[i]).sq_distance <= r2 ? 1 : 0;
  });
  std::size_t n = 0;
  for (const char c : covered) n += static_cast<std::size_t>(c);
  return static_cast<double>(n) / static_cast<double>(s.points.size());
}

ScanResult scan_mesh(const MeshIndex& index, const ScanSettings& settings, std::uint64_t seed) {
  if (!(settings.fine_spacing > 0.0) || !(settings.coarse_voxel > 0.0))
    throw Error("scanner voxel sizes must be positive", "", "scan.fine_spacing/scan.coarse_voxel");
  if (!(settings.ray_pitch > 0.0)) throw Error("ray pitch must be positive", "", "scan.ray_pitch");
  if (!(settings.coverage_radius > 0.0))
    throw Error("coverage radius must be positive", "", "scan.coverage_radius");
  if (settings.coverage_samples < 1) throw Error("at least one coverage sample is needed", "", "scan.coverage_samples");
  if (settings.candidate_views < 1) throw Error("at least one candidate view is needed", "", "scan.candidate_views");

  ScanResult result;
  const Mesh& mesh = index.mesh();
  Rng tracking_rng(seed, kTrackingStream);
  const SurfaceSamples samples = sample_surface(mesh, settings.coverage_samples, tracking_rng);
  if (samples.points.empty()) return result;  // no area: nothing to scan (coverage 0)

  const auto box = mesh_bounds(mesh);
  const Vec3 centre = box.center();
  double radius = 0.0;
  for (const auto& p : mesh.vertices) radius = std::max(radius, (p - centre).norm());
  const double h = settings.ray_pitch * settings.fine_spacing;
  if (std::pow(2.0 * radius / h + 2.0, 2.0) > kMaxPixels)
    throw Error("ray raster too fine for the object's size (over " + std::to_string(kMaxPixels) +
                    " rays per view)", "", "scan.ray_pitch/scan.fine_spacing");
  const bool two_sided = !mesh_topology(mesh).closed();  // open sheets are seen from both sides

  const std::size_t n = samples.points.size();
  // Two phases. Phase 0 plans for dense data: a sample counts as scanned only when hit at an
  // incidence within max_incidence_deg. When that stalls (or nothing visible is left), phase 1
  // mops up what is reachable only at grazing incidence (deep bores, slots).
  const double deg = std::numbers::pi / 180.0;
  const double phase_facing[2] = {std::cos(settings.max_incidence_deg * deg),
                                  std::cos(std::max(settings.max_incidence_deg, settings.grazing_incidence_deg) * deg)};
  int phase = 0;
  const auto candidates = fibonacci_directions(settings.candidate_views);
  auto planner = std::make_unique<ViewPlanner>(index, samples, candidates, two_sided, phase_facing[0], radius);
  std::vector<double> weight(n, 1.0);
  std::vector<std::uint32_t> uncovered(n);
  for (std::size_t i = 0; i < n; ++i) uncovered[i] = static_cast<std::uint32_t>(i);
  int stalled = 0;
  // Switch to the grazing phase; false when already there (the scan is over).
  auto next_phase = [&] {
    if (phase == 1) return false;
    phase = 1;
    planner = std::make_unique<ViewPlanner>(index, samples, candidates, two_sided, phase_facing[1], radius);
    std::fill(weight.begin(), weight.end(), 1.0);
    stalled = 0;
    return true;
  };

  PointCloud hits;
  const int random_every = std::max(1, settings.random_every);
  while (result.views < settings.max_views) {
    if (1.0 - static_cast<double>(uncovered.size()) / n >= settings.target_coverage) break;
    const int v = result.views;
    const bool random_view = (v + 1) % random_every == 0;
    std::optional<std::size_t> chosen;
    Vec3 d;
    if (random_view) {
      d = Rng(seed, kRandomViewStream, static_cast<std::uint64_t>(v)).unit_vector();
    } else {
      chosen = planner->choose(uncovered, weight);
      if (!chosen) {
        // Nothing left is visible at this phase's incidence from any candidate direction.
        if (next_phase()) continue;
        break;
      }
      d = planner->direction(*chosen);
    }
    d.normalize();

    const View view = cast_view(mesh, d, centre, radius, h);
    result.views += 1;
    result.rays += view.t.size();
    result.directions.push_back(d);

    // Which uncovered samples does this view cover? Each sample writes its own flag.
    std::vector<char> now(uncovered.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, uncovered.size(), 256), [&](const auto& r) {
      for (std::size_t k = r.begin(); k != r.end(); ++k)
        now[k] = facing(samples.normals[uncovered[k]], d, two_sided) >= phase_facing[phase] &&
                         covered_by(view, samples.points[uncovered[k]], settings.coverage_radius)
                     ? 1 : 0;
    });
    std::vector<std::uint32_t> still;
    still.reserve(uncovered.size());
    for (std::size_t k = 0; k < uncovered.size(); ++k) {
      const std::uint32_t i = uncovered[k];
      if (now[k]) continue;
      still.push_back(i);
      // Seen by the chosen view yet not reached (raster or window effects): try others first.
      if (chosen && planner->sees(i, *chosen)) weight[i] *= kFailDecay;
    }
    const double gain = static_cast<double>(uncovered.size() - still.size()) / n;
    uncovered.swap(still);

    append_hits(mesh, view, hits);

    stalled = gain < settings.min_gain ? stalled + 1 : 0;
    if (stalled >= std::max(1, settings.stall_views) && !next_phase()) break;
  }

  result.fine = voxel_representatives(hits, settings.fine_spacing);
  // The coarse cloud keeps fine points too (not voxel centroids): keypoints stay on the
  // surface, and an open sheet seen from both sides does not average its normals to zero.
  result.coarse = voxel_representatives(result.fine, settings.coarse_voxel);
  result.coverage = surface_coverage(index, result.fine.points, settings.coverage_radius, seed,
                                     settings.coverage_samples);
  return result;
}

}  // namespace geometry
}  // namespace ts
