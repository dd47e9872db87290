// FPFH as PCL's FPFHEstimation computes it (pcl/features/impl/fpfh.hpp, pcl::computePairFeatures),
// rewritten for keypoints that need not belong to the surface and for deterministic TBB use.
//
//  1. Pair features (Rusu et al. 2009, Sec. III; PCL's computePairFeatures). For a source point
//     (p_s, n_s) and a target (p_t, n_t) with d = p_t - p_s: the point whose normal makes the
//     smaller angle with the connecting line becomes the frame origin (u = its normal, the line
//     reversed when swapped); v = d x u / |d x u|, w = u x v; then
//        f1 = atan2(w . n_t', u . n_t')  in [-pi, pi]   (angle of the other normal in the u-w plane)
//        f2 = v . n_t'                   in [-1, 1]
//        f3 = (u . d) / |d|              in [-1, 1]
//     A pair with |d| = 0 or d parallel to u contributes nothing (PCL skips it).
//  2. SPFH of a surface point: 11 bins per feature, each pair adding 100 / (|N| - 1) where N is
//     its radius neighbourhood in `surface`, itself included.
//  3. FPFH of a keypoint: sum over its neighbours p_k in `surface` with d_k > 0 of
//     SPFH(p_k) / d_k^2 (PCL weights by the squared distance its radius search returns), then
//     each 11-bin block rescaled to sum to 100. Like PCL (and unlike Rusu 2009, Eq. 2) the
//     keypoint's own SPFH is not added, so the keypoint's normal plays no part.
#include "engine/fpfh.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>

namespace ts {

namespace {

constexpr int kBins = 11;
constexpr double kPi = 3.14159265358979323846;

/// Bin of x in [lo, hi] split into kBins, clamped (PCL's floor-and-clamp).
inline int bin_of(double x, double lo, double hi) {
  const int b = static_cast<int>(std::floor(kBins * (x - lo) / (hi - lo)));
  return b < 0 ? 0 : (b >= kBins ? kBins - 1 : b);
}

/// Polynomial atan2 (max error about 1e-5 rad; octant reduction of a minimax atan on [0, 1]).
inline double approx_atan2(double y, double x) {
  const double ax = std::abs(x), ay = std::abs(y);
  const double a = std::min(ax, ay) / std::max(ax, ay);
  const double s = a * a;
  double r = ((-0.0464964749 * s + 0.15931422) * s - 0.327622764) * s * a + a;
  if (ay > ax) r = 0.5 * kPi - r;
  if (x < 0) r = kPi - r;
  return y < 0 ? -r : r;
}

/// Bin of atan2(y, x) over [-pi, pi], identical to bin_of(std::atan2(y, x), -pi, pi): the
/// polynomial decides unless the angle lies within 1e-3 rad of a bin edge (0.35% of pairs),
/// where std::atan2 does. atan2 was a fifth of the FPFH time.
inline int angle_bin(double y, double x) {
  if (x == 0.0 && y == 0.0) return bin_of(std::atan2(y, x), -kPi, kPi);
  constexpr double kScale = kBins / (2.0 * kPi);
  constexpr double kGuard = 1e-3 * kScale;   // 100x the polynomial's error, in bins
  const double t = (approx_atan2(y, x) + kPi) * kScale;
  const double fl = std::floor(t);
  if (t - fl < kGuard || fl + 1.0 - t < kGuard) return bin_of(std::atan2(y, x), -kPi, kPi);
  const int b = static_cast<int>(fl);
  return b < 0 ? 0 : (b >= kBins ? kBins - 1 : b);
}

/// Step 1: the bins of (f1, f2, f3) for one pair. Returns false when the pair is degenerate.
/// With u the origin's normal, n' the other normal, d the line from the origin and v, w as in
/// the file comment: v = (d x u)/|d x u|, so f2 = v . n' and, as u x (d x u) = d - u (u . d)
/// for a unit u, w . n' = (d . n' - (u . d)(u . n')) / |d x u|; f1 = atan2 of that and u . n'.
inline bool pair_bins(const Vec3& ps, const Vec3& ns, const Vec3& pt, const Vec3& nt, int bins[3]) {
  Vec3 d = pt - ps;
  const double len = d.norm();
  if (len == 0.0) return false;
  const double a_s = ns.dot(d);
  const double a_t = nt.dot(d);
  const Vec3* u = &ns;
  const Vec3* other = &nt;
  double ud = a_s;
  // acos(|a_s|/len) > acos(|a_t|/len)  <=>  |a_s| < |a_t|: the target's normal is closer to
  // the line, so it becomes the origin and the line is reversed.
  if (std::abs(a_s) < std::abs(a_t)) {
    u = &nt;
    other = &ns;
    d = -d;
    ud = -a_t;
  }
  const Vec3 c = d.cross(*u);
  const double vn = c.norm();
  if (vn == 0.0) return false;
  const double un = u->dot(*other);
  const double wn = (d.dot(*other) - ud * un) / vn;
  bins[0] = angle_bin(wn, un);                         // f1 = atan2(w . n', u . n')
  bins[1] = bin_of(c.dot(*other) / vn, -1.0, 1.0);    // f2 = v . n'
  bins[2] = bin_of(ud / len, -1.0, 1.0);               // f3 = u . d / |d|
  return true;
}

using Spfh = std::array<double, kFeatureDim>;

/// Points grouped by cells of edge r: a point's r-neighbours lie in the 27 cells around its own,
/// which form 9 runs of consecutive keys in the sorted cell list. For the SPFH of (nearly) every
/// surface point this is about 2x faster than one k-d tree radius query per point.
struct CellGrid {
  using Key = std::array<std::int64_t, 3>;
  std::vector<Key> key;                // occupied cells, sorted
  std::vector<std::uint32_t> first;    // cell c holds order[first[c] .. first[c + 1])
  std::vector<std::uint32_t> order;    // point indices, grouped by cell, increasing within one

  CellGrid(const std::vector<Vec3>& pts, double r) {
    std::vector<std::pair<Key, std::uint32_t>> kv;
    kv.reserve(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i)
      if (finite(pts[i]))
        kv.push_back({{static_cast<std::int64_t>(std::floor(pts[i].x() / r)),
                       static_cast<std::int64_t>(std::floor(pts[i].y() / r)),
                       static_cast<std::int64_t>(std::floor(pts[i].z() / r))},
                      static_cast<std::uint32_t>(i)});
    std::sort(kv.begin(), kv.end());
    for (std::size_t i = 0; i < kv.size(); ++i) {
      if (i == 0 || kv[i].first != kv[i - 1].first) {
        key.push_back(kv[i].first);
        first.push_back(static_cast<std::uint32_t>(i));
      }
      order.push_back(kv[i].second);
    }
    first.push_back(static_cast<std::uint32_t>(kv.size()));
  }

  /// Points of the 27 cells around cell c, in cell-key order.
  void candidates(std::size_t c, std::vector<std::uint32_t>& out) const {
    out.clear();
    const Key& k = key[c];
    for (std::int64_t di = -1; di <= 1; ++di)
      for (std::int64_t dj = -1; dj <= 1; ++dj) {
        const Key lo{k[0] + di, k[1] + dj, k[2] - 1}, hi{k[0] + di, k[1] + dj, k[2] + 1};
        for (auto it = std::lower_bound(key.begin(), key.end(), lo); it != key.end() && *it <= hi; ++it) {
          const auto g = static_cast<std::size_t>(it - key.begin());
          out.insert(out.end(), order.begin() + first[g], order.begin() + first[g + 1]);
        }
      }
  }
};

/// Step 2 for surface point `s`: pairs with every surface point within r (its neighbourhood N,
/// s included), among the candidates.
Spfh spfh(const PointCloud& surface, std::uint32_t s, const std::vector<std::uint32_t>& candidates, double r2) {
  std::array<int, kFeatureDim> count{};
  std::size_t n = 0;
  const Vec3& ps = surface.points[s];
  const Vec3& ns = surface.normals[s];
  for (const std::uint32_t t : candidates) {
    if ((surface.points[t] - ps).squaredNorm() > r2) continue;
    ++n;
    if (t == s) continue;
    int b[3];
    if (!pair_bins(ps, ns, surface.points[t], surface.normals[t], b)) continue;
    ++count[b[0]];
    ++count[kBins + b[1]];
    ++count[2 * kBins + b[2]];
  }
  Spfh h{};
  if (n < 2) return h;
  const double incr = 100.0 / static_cast<double>(n - 1);
  for (int i = 0; i < kFeatureDim; ++i) h[i] = count[i] * incr;
  return h;
}

}  // namespace

FpfhResult compute_fpfh(const std::vector<Vec3>& keypoints, const std::vector<Vec3>& keypoint_normals,
                        const PointCloud& surface, const KdTree3& surface_tree,
                        const FpfhSettings& settings) {
  if (!keypoint_normals.empty() && keypoint_normals.size() != keypoints.size())
    throw Error("compute_fpfh: keypoint_normals size differs from keypoints", {}, "keypoint_normals");
  if (!surface.empty() && !surface.has_normals())
    throw Error("compute_fpfh: the surface cloud needs normals", {}, "surface.normals");
  if (surface_tree.size() != surface.size())
    throw Error("compute_fpfh: surface_tree is not built over the surface points", {}, "surface_tree");
  if (!(settings.feature_radius > 0.0) || !std::isfinite(settings.feature_radius))
    throw Error("compute_fpfh: feature_radius must be positive", {}, "feature_radius");

  const double r = settings.feature_radius;
  const std::size_t nk = keypoints.size();
  FpfhResult out;
  out.features.assign(nk, Feature{});
  std::vector<char> valid(nk, 0);   // not vector<bool>: tasks write neighbouring slots

  // Keypoint neighbourhoods (each task fills its own slot).
  std::vector<std::vector<Neighbour>> knb(nk);
  tbb::parallel_for(std::size_t(0), nk, [&](std::size_t i) {
    if (finite(keypoints[i])) knb[i] = surface_tree.radius(keypoints[i], r);
  });

  // Surface points whose SPFH is needed, in increasing index order (serial, deterministic).
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> row(surface.size(), kNone);
  std::vector<std::uint32_t> needed;
  for (const auto& nb : knb)
    for (const Neighbour& n : nb)
      if (n.sq_distance > 0.0 && row[n.index] == kNone) row[n.index] = 0;
  for (std::uint32_t s = 0; s < row.size(); ++s)
    if (row[s] != kNone) {
      row[s] = static_cast<std::uint32_t>(needed.size());
      needed.push_back(s);
    }

  // SPFHs, cell by cell (each point's histogram is written by one task; the order in which a
  // neighbourhood is visited does not matter, every pair adds the same increment).
  std::vector<Spfh> hist(needed.size());
  if (!needed.empty()) {
    const CellGrid grid(surface.points, r);
    const double r2 = r * r;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, grid.key.size(), 4),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        std::vector<std::uint32_t> candidates;
                        for (std::size_t c = range.begin(); c != range.end(); ++c) {
                          bool any = false;
                          for (std::uint32_t m = grid.first[c]; m < grid.first[c + 1] && !any; ++m)
                            any = row[grid.order[m]] != kNone;
                          if (!any) continue;
                          grid.candidates(c, candidates);
                          for (std::uint32_t m = grid.first[c]; m < grid.first[c + 1]; ++m) {
                            const std::uint32_t s = grid.order[m];
                            if (row[s] != kNone) hist[row[s]] = spfh(surface, s, candidates, r2);
                          }
                        }
                      });
  }

  // Step 3: weighted sum, per-block normalization. Neighbours come sorted by (distance, index),
  // so the summation order is fixed.
  tbb::parallel_for(std::size_t(0), nk, [&](std::size_t i) {
    std::size_t others = 0;
    Spfh f{};
    for (const Neighbour& n : knb[i]) {
      if (n.sq_distance == 0.0) continue;
      ++others;
      const Spfh& h = hist[row[n.index]];
      const double wgt = 1.0 / n.sq_distance;
      for (int b = 0; b < kFeatureDim; ++b) f[b] += h[b] * wgt;
    }
    if (others < 2) return;
    for (int block = 0; block < 3; ++block) {
      double sum = 0.0;
      for (int b = 0; b < kBins; ++b) sum += f[block * kBins + b];
      if (!(sum > 0.0)) return;   // every neighbour's SPFH empty: nothing to describe
      const double scale = 100.0 / sum;
      for (int b = 0; b < kBins; ++b)
        out.features[i][block * kBins + b] = static_cast<float>(f[block * kBins + b] * scale);
    }
    valid[i] = 1;
  });
  out.valid.assign(nk, false);
  for (std::size_t i = 0; i < nk; ++i) {
    out.valid[i] = valid[i] != 0;
    if (!valid[i]) out.features[i] = Feature{};   // no partially normalized blocks
  }
  return out;
}

}  // namespace ts
