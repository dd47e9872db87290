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

/// Step 1. Returns false when the pair is degenerate.
inline bool pair_features(const Vec3& ps, const Vec3& ns, const Vec3& pt, const Vec3& nt,
                          double& f1, double& f2, double& f3) {
  Vec3 d = pt - ps;
  const double len = d.norm();
  if (len == 0.0) return false;
  const double a_s = ns.dot(d) / len;
  const double a_t = nt.dot(d) / len;
  const Vec3* u = &ns;
  const Vec3* other = &nt;
  // acos(|a_s|) > acos(|a_t|)  <=>  |a_s| < |a_t|: the target's normal is closer to the line.
  if (std::abs(a_s) < std::abs(a_t)) {
    u = &nt;
    other = &ns;
    d = -d;
    f3 = -a_t;
  } else {
    f3 = a_s;
  }
  Vec3 v = d.cross(*u);
  const double vn = v.norm();
  if (vn == 0.0) return false;
  v /= vn;
  const Vec3 w = u->cross(v);
  f2 = v.dot(*other);
  f1 = std::atan2(w.dot(*other), u->dot(*other));
  return true;
}

using Spfh = std::array<double, kFeatureDim>;

/// Step 2 for surface point `s` with its neighbourhood `nb` (s included).
Spfh spfh(const PointCloud& surface, std::uint32_t s, const std::vector<Neighbour>& nb) {
  Spfh h{};
  if (nb.size() < 2) return h;
  const double incr = 100.0 / static_cast<double>(nb.size() - 1);
  const Vec3& ps = surface.points[s];
  const Vec3& ns = surface.normals[s];
  for (const Neighbour& n : nb) {
    if (n.index == s) continue;
    double f1, f2, f3;
    if (!pair_features(ps, ns, surface.points[n.index], surface.normals[n.index], f1, f2, f3)) continue;
    h[bin_of(f1, -kPi, kPi)] += incr;
    h[kBins + bin_of(f2, -1.0, 1.0)] += incr;
    h[2 * kBins + bin_of(f3, -1.0, 1.0)] += incr;
  }
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

  std::vector<Spfh> hist(needed.size());
  tbb::parallel_for(std::size_t(0), needed.size(), [&](std::size_t j) {
    const std::uint32_t s = needed[j];
    hist[j] = spfh(surface, s, surface_tree.radius(surface.points[s], r));
  });

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
