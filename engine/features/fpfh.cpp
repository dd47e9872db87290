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
#include "engine/features/fpfh.hpp"
#include "engine/detail.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "engine/target_clones.hpp"

#include <cmath>
#include <limits>
#include <memory>

namespace ts {
inline namespace features {

namespace {

constexpr int kBins = 11;
using detail::kPi;

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

/// Step 1 for a source (s) and a batch of targets, written for the compiler to vectorize: each
/// lane does pair_bins's arithmetic operation for operation (Eigen's 3-vector dot products and
/// norms sum left to right, (x + y) + z, as Eigen 3.4 evaluates them with its SIMD path, the
/// default; under EIGEN_DONT_VECTORIZE they associate the other way and a bin could differ; its
/// cross product is the textbook formula), so the bins are pair_bins's bit for bit. A lane whose
/// angle lies within the guard of a bin edge (or whose atan2 has no argument) is marked for
/// pair_bins itself.
struct PairBatch {
  static constexpr int kSize = 128;
  int n = 0;
  std::uint32_t target[kSize];
  double px[kSize], py[kSize], pz[kSize], nx[kSize], ny[kSize], nz[kSize];   // targets
  std::int32_t b0[kSize], b1[kSize], b2[kSize];
  std::int32_t state[kSize];     // kDegenerate (no bins), kOk, or kRedo (pair_bins decides)
  static constexpr std::int32_t kDegenerate = 0, kOk = 1, kRedo = 2;
  std::int32_t ordered[kSize];   // |a_s| != |a_t| (the same origin either way)
};

TS_TARGET_CLONES
void batch_bins(double psx, double psy, double psz, double nsx, double nsy, double nsz, PairBatch& B) {
  constexpr double kScale = kBins / (2.0 * kPi);
  constexpr double kGuard = 1e-3 * kScale;
  const int n = B.n;
  for (int k = 0; k < n; ++k) {
    double dx = B.px[k] - psx, dy = B.py[k] - psy, dz = B.pz[k] - psz;
    const double ntx = B.nx[k], nty = B.ny[k], ntz = B.nz[k];
    const double len = std::sqrt((dx * dx + dy * dy) + dz * dz);
    const double a_s = (nsx * dx + nsy * dy) + nsz * dz;
    const double a_t = (ntx * dx + nty * dy) + ntz * dz;
    const double abs_s = std::abs(a_s), abs_t = std::abs(a_t);
    const bool swap = abs_s < abs_t;
    const double ux = swap ? ntx : nsx, uy = swap ? nty : nsy, uz = swap ? ntz : nsz;
    const double ox = swap ? nsx : ntx, oy = swap ? nsy : nty, oz = swap ? nsz : ntz;
    dx = swap ? -dx : dx;
    dy = swap ? -dy : dy;
    dz = swap ? -dz : dz;
    const double ud = swap ? -a_t : a_s;
    const double cx = dy * uz - dz * uy, cy = dz * ux - dx * uz, cz = dx * uy - dy * ux;
    const double vn = std::sqrt((cx * cx + cy * cy) + cz * cz);
    const double un = (ux * ox + uy * oy) + uz * oz;
    const double wn = (((dx * ox + dy * oy) + dz * oz) - ud * un) / vn;
    // angle_bin(wn, un): approx_atan2, then the guard.
    const double ax = std::abs(un), ay = std::abs(wn);
    const double lo = ay < ax ? ay : ax, hi = ax < ay ? ay : ax;   // std::min, std::max
    const double a = lo / hi;
    const double sq = a * a;
    double r = ((-0.0464964749 * sq + 0.15931422) * sq - 0.327622764) * sq * a + a;
    r = ay > ax ? 0.5 * kPi - r : r;
    r = un < 0 ? kPi - r : r;
    r = wn < 0 ? -r : r;
    const double t = (r + kPi) * kScale;
    const double fl = std::floor(t);
    const bool redo = ((un == 0.0) & (wn == 0.0)) | (t - fl < kGuard) | (fl + 1.0 - t < kGuard);
    const double f2 = std::floor(kBins * (((cx * ox + cy * oy) + cz * oz) / vn - -1.0) / (1.0 - -1.0));
    const double f3 = std::floor(kBins * (ud / len - -1.0) / (1.0 - -1.0));
    // (bin_of's clamp; NaN, from a degenerate lane whose bins are not used, to 0)
    const auto clamp = [](double f) { return !(f >= 0.0) ? 0.0 : (f >= kBins ? kBins - 1.0 : f); };
    B.b0[k] = static_cast<std::int32_t>(clamp(fl));
    B.b1[k] = static_cast<std::int32_t>(clamp(f2));
    B.b2[k] = static_cast<std::int32_t>(clamp(f3));
    const bool ordered = (abs_s < abs_t) | (abs_t < abs_s);
    B.ordered[k] = ordered ? 1 : 0;
    const bool degenerate = (len == 0.0) | (vn == 0.0);
    B.state[k] = degenerate ? PairBatch::kDegenerate : (redo ? PairBatch::kRedo : PairBatch::kOk);
  }
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

  /// Cells of the half shell of cell c: the 13 neighbours whose key comes after c's (x + 1:
  /// 9 cells; x, y + 1: 3; x, y, z + 1: 1), as ranges [first, last) of cell indices.
  void half_shell(std::size_t c, std::vector<std::pair<std::size_t, std::size_t>>& out) const {
    out.clear();
    const Key& k = key[c];
    const auto run = [&](const Key& lo, const Key& hi) {
      auto a = std::lower_bound(key.begin(), key.end(), lo);
      auto b = std::upper_bound(a, key.end(), hi);
      if (a != b) out.push_back({static_cast<std::size_t>(a - key.begin()), static_cast<std::size_t>(b - key.begin())});
    };
    for (std::int64_t dj = -1; dj <= 1; ++dj) run({k[0] + 1, k[1] + dj, k[2] - 1}, {k[0] + 1, k[1] + dj, k[2] + 1});
    run({k[0], k[1] + 1, k[2] - 1}, {k[0], k[1] + 1, k[2] + 1});
    run({k[0], k[1], k[2] + 1}, {k[0], k[1], k[2] + 1});
  }
};

/// Integer SPFH counts of one surface point: 33 bins, then |N| (its r-neighbourhood, itself
/// included). Integers, so the order in which pairs add to them does not matter.
using SpfhCount = std::array<std::int32_t, kFeatureDim + 1>;

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

  // SPFHs: every pair of surface points within r once (the cell of the first in key order, or
  // the later of two in one cell, visits it), each needed point counting its own bins. The
  // tasks of one pass are the cells of one x column, every other column: a pair writes only
  // to points of its column and the next, so tasks of a pass never write the same count.
  std::vector<Spfh> hist(needed.size());
  if (!needed.empty()) {
    const CellGrid grid(surface.points, r);
    const double r2 = r * r;
    std::vector<SpfhCount> count(needed.size(), SpfhCount{});
    std::vector<std::size_t> column{0};   // cells of x column m: [column[m], column[m + 1])
    for (std::size_t c = 1; c < grid.key.size(); ++c)
      if (grid.key[c][0] != grid.key[c - 1][0]) column.push_back(c);
    column.push_back(grid.key.size());
    const std::size_t columns = column.size() - 1;
    // Step 2 for the pairs (s, t) of one source s, both within r of each other: batch_bins for
    // its targets (in the order visited), then each of the two adds the pair's bins to its own
    // count when it is needed (row != kNone). bins(s, t) = bins(t, s) bit for bit unless |a_s| =
    // |a_t| exactly (negating d negates every product of the dot products and cross product, and
    // the swap then picks the same origin), where the source stays the origin: computed twice then.
    const auto flush = [&](std::uint32_t s, PairBatch& B) {
      const Vec3 &ps = surface.points[s], &ns = surface.normals[s];
      batch_bins(ps.x(), ps.y(), ps.z(), ns.x(), ns.y(), ns.z(), B);
      const std::uint32_t rs = row[s];
      const auto add = [&](std::uint32_t r, const int b[3]) {
        ++count[r][b[0]];
        ++count[r][kBins + b[1]];
        ++count[r][2 * kBins + b[2]];
      };
      for (int k = 0; k < B.n; ++k) {
        const std::uint32_t t = B.target[k], rt = row[t];
        const Vec3 &pt = surface.points[t], &nt = surface.normals[t];
        int bs[3] = {B.b0[k], B.b1[k], B.b2[k]};
        bool ok_s = B.state[k] != PairBatch::kDegenerate;
        if (B.state[k] == PairBatch::kRedo) ok_s = pair_bins(ps, ns, pt, nt, bs);
        if (rs != kNone) {
          ++count[rs][kFeatureDim];
          if (ok_s) add(rs, bs);
        }
        if (rt == kNone) continue;
        ++count[rt][kFeatureDim];
        if (B.ordered[k]) {   // bins(t, s) = bins(s, t) bit for bit
          if (ok_s) add(rt, bs);
          continue;
        }
        int bt[3];
        if (pair_bins(pt, nt, ps, ns, bt)) add(rt, bt);
      }
      B.n = 0;
    };
    const auto visit = [&](std::size_t m, std::vector<std::pair<std::size_t, std::size_t>>& shell, PairBatch& B) {
      for (std::size_t c = column[m]; c < column[m + 1]; ++c) {
        grid.half_shell(c, shell);
        for (std::uint32_t i = grid.first[c]; i < grid.first[c + 1]; ++i) {
          const std::uint32_t s = grid.order[i];
          const Vec3& ps = surface.points[s];
          const bool s_needed = row[s] != kNone;
          const auto pair = [&](std::uint32_t t) {
            const Vec3& pt = surface.points[t];
            if ((pt - ps).squaredNorm() > r2) return;
            if (!s_needed && row[t] == kNone) return;
            const Vec3& nt = surface.normals[t];
            const int k = B.n++;
            B.target[k] = t;
            B.px[k] = pt.x(), B.py[k] = pt.y(), B.pz[k] = pt.z();
            B.nx[k] = nt.x(), B.ny[k] = nt.y(), B.nz[k] = nt.z();
            if (B.n == PairBatch::kSize) flush(s, B);
          };
          for (std::uint32_t j = i + 1; j < grid.first[c + 1]; ++j) pair(grid.order[j]);
          for (const auto& [g0, g1] : shell)
            for (std::uint32_t j = grid.first[g0]; j < grid.first[g1]; ++j) pair(grid.order[j]);
          if (B.n > 0) flush(s, B);
        }
      }
    };
    for (std::size_t parity = 0; parity < 2; ++parity)
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, (columns + 1 - parity) / 2),
                        [&](const tbb::blocked_range<std::size_t>& range) {
                          std::vector<std::pair<std::size_t, std::size_t>> shell;
                          auto batch = std::make_unique<PairBatch>();
                          for (std::size_t h = range.begin(); h != range.end(); ++h)
                            visit(2 * h + parity, shell, *batch);   // keys of columns m, m + 2 differ by >= 2
                        });
    for (std::size_t k = 0; k < needed.size(); ++k) {
      // |N| counts the point itself; a point alone has no SPFH
      const std::int32_t n = count[k][kFeatureDim] + 1;
      if (n < 2) continue;
      const double incr = 100.0 / static_cast<double>(n - 1);
      for (int i = 0; i < kFeatureDim; ++i) hist[k][i] = count[k][i] * incr;
    }
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

}  // namespace features
}  // namespace ts
