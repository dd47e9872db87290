// PFH, SHOT and Spin Images as PCL 1.x computes them (pcl/features/impl/pfh.hpp, shot.hpp,
// shot_lrf.hpp, spin_image.hpp, and pcl::computePairFeatures in pcl/features/impl/pfh.hpp),
// rewritten for keypoints that need not belong to the surface, in double precision, with one
// TBB task per keypoint writing its own row (so the result does not depend on the thread count).
// FPFH is engine/features/fpfh.cpp. Where PCL has quirks (SHOT's cosine interpolation wrapping modulo the
// 10 shape bins into an 11-bin histogram, its outermost volumes voting less than 1 for
// themselves, PFH's increment counting degenerate pairs) they are kept: the point is to
// reproduce the descriptors the paper compared.
#include "engine/features/descriptors.hpp"
#include "engine/detail.hpp"

#include "engine/features/fpfh.hpp"

#include <Eigen/Eigenvalues>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace ts {
inline namespace features {

namespace {

using detail::kPi;

// ---- PFH (PCL's PFHEstimation::computePointPFHSignature, nr_split = 5) ----------------------

constexpr int kPfhSplit = 5;

/// pcl::computePairFeatures: f1 = atan2(w . n2', u . n2'), f2 = v . n2', f3 = u . d / |d| in the
/// Darboux frame of the point whose normal is closer to the connecting line; here f1 is left as
/// its two arguments, f = {w . n2', u . n2', f2, f3}. False when the pair is degenerate (the same
/// point, or the line along that normal).
bool pair_features(const Vec3& p1, const Vec3& n1, const Vec3& p2, const Vec3& n2, double f[4]) {
  Vec3 d = p2 - p1;
  const double len2 = d.squaredNorm();
  if (len2 == 0.0) return false;
  const double inv_len = 1.0 / std::sqrt(len2);
  const double a1 = n1.dot(d) * inv_len, a2 = n2.dot(d) * inv_len;
  const Vec3* u = &n1;
  const Vec3* other = &n2;
  // PCL: acos(|a1|) > acos(|a2|), i.e. |a1| < |a2|: the second point becomes the origin.
  if (std::abs(a1) < std::abs(a2)) {
    u = &n2;
    other = &n1;
    d = -d;
    f[3] = -a2;
  } else {
    f[3] = a1;
  }
  const Vec3 v = d.cross(*u);   // v and w = u x v are scaled by 1 / |v| only where used
  const double vn2 = v.squaredNorm();
  if (vn2 == 0.0) return false;
  const double inv_vn = 1.0 / std::sqrt(vn2);
  f[2] = v.dot(*other) * inv_vn;
  f[0] = u->cross(v).dot(*other) * inv_vn;
  f[1] = u->dot(*other);
  return true;
}

inline int split_bin(double unit) {   // unit in [0, 1] -> 0 .. kPfhSplit - 1 (floor, clamped)
  const int b = static_cast<int>(std::floor(kPfhSplit * unit));
  return std::clamp(b, 0, kPfhSplit - 1);
}

/// split_bin((atan2(y, x) + pi) / (2 pi)) without the atan2, which took a third of a PFH
/// database build: the five bins are the sectors [-pi, -0.6 pi), [-0.6 pi, -0.2 pi), [-0.2 pi,
/// 0.2 pi), [0.2 pi, 0.6 pi), [0.6 pi, pi], told apart by the sign of a cross product with each
/// boundary direction. A point on an axis or exactly on a boundary (signed zeros) takes atan2
/// itself. Within about 1e-14 rad of a boundary the two roundings may put a pair in the
/// neighbouring bin (PCL itself bins in float).
inline int angle_bin(double y, double x) {
  constexpr double c1 = 0.80901699437494742, s1 = 0.58778525229247314;    // cos, sin of 0.2 pi
  constexpr double c2 = -0.30901699437494742, s2 = 0.95105651629515357;   // cos, sin of 0.6 pi
  if (y != 0.0 && x != 0.0) {
    const double ya = std::abs(y);
    const double t1 = c1 * ya - s1 * x, t2 = c2 * ya - s2 * x;   // < 0: |angle| below the boundary
    if (t1 != 0.0 && t2 != 0.0) {
      if (y > 0.0) return t1 < 0.0 ? 2 : (t2 < 0.0 ? 3 : 4);
      return t1 < 0.0 ? 2 : (t2 < 0.0 ? 1 : 0);
    }
  }
  return split_bin((std::atan2(y, x) + kPi) / (2.0 * kPi));
}

bool pfh_row(const PointCloud& s, const std::vector<Neighbour>& nb, float* out) {
  const std::size_t n = nb.size();
  if (n < 2) return false;
  const double incr = 100.0 / (static_cast<double>(n) * static_cast<double>(n - 1) / 2.0);
  // The neighbours side by side (the surface is indexed at random); a non-finite point or normal
  // leaves its pairs out (PCL would bin NaN: undefined behaviour).
  std::vector<Vec3> pts, nrm;
  pts.reserve(n);
  nrm.reserve(n);
  for (const Neighbour& k : nb) {
    const Vec3 &p = s.points[k.index], &q = s.normals[k.index];
    if (finite(p) && finite(q)) pts.push_back(p), nrm.push_back(q);
  }
  const std::size_t m = pts.size();
  std::array<double, kPfhSplit * kPfhSplit * kPfhSplit> h{};
  bool any = false;
  for (std::size_t i = 0; i < m; ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      // PCL's PFHEstimation::computePairFeatures ignores pcl::computePairFeatures' false: a
      // degenerate pair (the same point twice, or the line along the normal) is binned with
      // f = (0, 0, 0), bin 2 + 5 * 2 + 25 * 2 = 62.
      int b = 62;
      double f[4];
      if (pair_features(pts[i], nrm[i], pts[j], nrm[j], f))
        b = angle_bin(f[0], f[1]) + kPfhSplit * split_bin((f[2] + 1.0) * 0.5) +
            kPfhSplit * kPfhSplit * split_bin((f[3] + 1.0) * 0.5);
      h[b] += incr;
      any = true;
    }
  }
  if (!any) return false;
  for (std::size_t b = 0; b < h.size(); ++b) out[b] = static_cast<float>(h[b]);
  return true;
}

// ---- SHOT (PCL's SHOTLocalReferenceFrameEstimation::getLocalRF and SHOTEstimation) ----------

constexpr int kShotShapeBins = 10;                 // PCL nr_shape_bins_
constexpr int kShotBinsPerVolume = kShotShapeBins + 1;
constexpr int kShotVolumes = 32;                   // PCL nr_grid_sector_ / maxAngularSectors_
constexpr double kRad45 = kPi / 4, kRad90 = kPi / 2, kRad135 = 3 * kPi / 4, kRad7_8 = 7 * kPi / 8;

/// The local reference frame: rows x, y, z. False (no frame) with fewer than 5 neighbours apart
/// from the keypoint itself or a non-finite decomposition. `nb` sorted by (distance, index), as
/// PCL's sorted radius search returns it (the order matters only to the median tie-break).
bool shot_frame(const Vec3& centre, const PointCloud& s, const std::vector<Neighbour>& nb, double radius,
                Mat3& rf) {
  std::vector<Vec3> vij;
  vij.reserve(nb.size());
  Mat3 cov = Mat3::Zero();
  double sum = 0.0;
  for (const Neighbour& n : nb) {
    const Vec3& p = s.points[n.index];
    if (p == centre) continue;
    const Vec3 v = p - centre;
    const double w = radius - std::sqrt(n.sq_distance);
    cov += w * (v * v.transpose());
    sum += w;
    vij.push_back(v);
  }
  const int valid = static_cast<int>(vij.size());
  if (valid < 5) return false;
  cov /= sum;
  const Eigen::SelfAdjointEigenSolver<Mat3> solver(cov);
  if (!solver.eigenvalues().allFinite()) return false;
  Vec3 x = solver.eigenvectors().col(2);   // largest eigenvalue
  Vec3 z = solver.eigenvectors().col(0);   // smallest
  // Sign disambiguation: each axis toward the majority of the neighbours; on a tie, toward the
  // majority of the 5 neighbours around the median (in the search order).
  const auto orient = [&](Vec3& axis) {
    int plus = 0;
    for (const Vec3& v : vij) plus += v.dot(axis) >= 0.0;
    plus = 2 * plus - valid;
    if (plus == 0) {
      const int median = valid / 2;
      for (int i = -2; i <= 2; ++i) plus += vij[median - i].dot(axis) > 0.0;
      if (plus < 3) axis = -axis;
    } else if (plus < 0) {
      axis = -axis;
    }
  };
  orient(x);
  orient(z);
  rf.row(0) = x.transpose();
  rf.row(2) = z.transpose();
  rf.row(1) = z.cross(x).transpose();
  return rf.allFinite();
}

/// SHOTEstimation::computePointSHOT: createBinDistanceShape, interpolateSingleChannel,
/// normalizeHistogram.
bool shot_row(const Vec3& centre, const Mat3& rf, const PointCloud& s, const std::vector<Neighbour>& nb,
              double radius, float* out) {
  if (nb.size() < 5) return false;
  const double r1_4 = radius / 4, r1_2 = radius / 2, r3_4 = 3 * radius / 4;
  std::array<double, kShotVolumes * kShotBinsPerVolume> shot{};
  const Vec3 fx = rf.row(0).transpose(), fy = rf.row(1).transpose(), fz = rf.row(2).transpose();
  for (const Neighbour& n : nb) {
    const Vec3& normal = s.normals[n.index];
    if (!finite(normal)) continue;
    const double cosine = std::clamp(normal.dot(fz), -1.0, 1.0);
    double bin_distance = (1.0 + cosine) * kShotShapeBins / 2;
    const double distance = std::sqrt(n.sq_distance);
    if (std::abs(distance) < 1e-8) continue;   // PCL's areEquals(distance, 0)
    const Vec3 delta = s.points[n.index] - centre;
    double x = delta.dot(fx), y = delta.dot(fy), z = delta.dot(fz);
    if (std::abs(x) < 1e-30) x = 0;
    if (std::abs(y) < 1e-30) y = 0;
    if (std::abs(z) < 1e-30) z = 0;

    // Volume: azimuth sector (8, from the quadrant and the diagonal), elevation, radius.
    const int bit4 = (y > 0 || (y == 0.0 && x < 0)) ? 1 : 0;
    const int bit3 = (x > 0 || (x == 0.0 && y > 0)) ? 1 - bit4 : bit4;
    int desc = ((bit4 << 3) + (bit3 << 2)) << 1;
    if (x * y > 0 || x == 0.0)
      desc += std::abs(x) >= std::abs(y) ? 0 : 4;
    else
      desc += std::abs(x) > std::abs(y) ? 4 : 0;
    desc += z > 0 ? 1 : 0;
    desc += distance > r1_2 ? 2 : 0;

    const int step = static_cast<int>(std::floor(bin_distance + 0.5));
    const int volume = desc * kShotBinsPerVolume;
    bin_distance -= step;
    double own = 1.0 - std::abs(bin_distance);   // the point's own bin collects 4 such weights
    // cosine: the neighbouring bin, modulo the 10 shape bins (as PCL)
    if (bin_distance > 0)
      shot[volume + (step + 1) % kShotShapeBins] += bin_distance;
    else
      shot[volume + (step - 1 + kShotShapeBins) % kShotShapeBins] -= bin_distance;
    // radius: shells centred at r/4 and 3r/4
    if (distance > r1_2) {
      const double rd = (distance - r3_4) / r1_2;
      if (distance > r3_4) {
        own += 1 - rd;
      } else {
        own += 1 + rd;
        shot[(desc - 2) * kShotBinsPerVolume + step] -= rd;
      }
    } else {
      const double rd = (distance - r1_4) / r1_2;
      if (distance < r1_4) {
        own += 1 + rd;
      } else {
        own += 1 - rd;
        shot[(desc + 2) * kShotBinsPerVolume + step] += rd;
      }
    }
    // elevation: hemispheres centred at inclinations 45 and 135 degrees
    // PCL tests inclination > 90 deg || (inclination == 90 deg && z <= 0), which is z <= 0, the
    // elevation bit: tested as the bit, so the neighbouring volume is always the other half.
    const double inclination = std::acos(std::clamp(z / distance, -1.0, 1.0));
    if ((desc & 1) == 0) {
      const double id = (inclination - kRad135) / kRad90;
      if (inclination > kRad135) {
        own += 1 - id;
      } else {
        own += 1 + id;
        shot[(desc + 1) * kShotBinsPerVolume + step] -= id;
      }
    } else {
      const double id = (inclination - kRad45) / kRad90;
      if (inclination < kRad45) {
        own += 1 + id;
      } else {
        own += 1 - id;
        shot[(desc - 1) * kShotBinsPerVolume + step] += id;
      }
    }
    // azimuth: sectors of 45 degrees from -180, wrapping
    if (y != 0.0 || x != 0.0) {
      const double azimuth = std::atan2(y, x);
      const int sel = desc >> 2;
      const double ad = std::clamp((azimuth - (-kRad7_8 + kRad45 * sel)) / kRad45, -0.5, 0.5);
      if (ad > 0) {
        own += 1 - ad;
        shot[((desc + 4) % kShotVolumes) * kShotBinsPerVolume + step] += ad;
      } else {
        own += 1 + ad;
        shot[((desc - 4 + kShotVolumes) % kShotVolumes) * kShotBinsPerVolume + step] -= ad;
      }
    }
    shot[volume + step] += own;
  }
  double norm = 0.0;
  for (double v : shot) norm += v * v;
  norm = std::sqrt(norm);
  if (!(norm > 0.0)) return false;
  for (std::size_t b = 0; b < shot.size(); ++b) out[b] = static_cast<float>(shot[b] / norm);
  return true;
}

// ---- Spin images (PCL's SpinImageEstimation::computeSiForPoint) -----------------------------
// Defaults followed: SpinImageEstimation(image_width = 8, support_angle_cos = 0.0,
// min_pts_neighb = 0), is_radial_ = false, is_angular_ = false, rotation axis = the keypoint's
// normal (no custom axis). With support_angle_cos = 0 no neighbour is rejected by its normal.

constexpr int kSpinWidth = 8;
constexpr int kSpinRows = kSpinWidth + 1, kSpinCols = 2 * kSpinWidth + 1;

bool spin_row(const Vec3& origin, const Vec3& axis, const PointCloud& s, const std::vector<Neighbour>& nb,
              double radius, float* out) {
  // The support: the cylinder of radius and half-height r / sqrt(2), inscribed in the search
  // sphere; square bins of that over the image width.
  const double bin = radius / kSpinWidth / std::sqrt(2.0);
  const double extent = bin * kSpinWidth;
  std::array<double, kSpinRows * kSpinCols> m{};
  for (const Neighbour& n : nb) {
    const Vec3 dir = s.points[n.index] - origin;
    const double dn = dir.norm();
    if (std::abs(dn) < 10 * std::numeric_limits<double>::epsilon()) continue;   // the point itself
    const double c = std::clamp(dir.dot(axis) / dn, -1.0, 1.0);
    double beta = dn * c;
    double alpha = dn * std::sqrt(1.0 - c * c);
    if (std::abs(beta) >= extent || alpha >= extent) continue;   // outside the cylinder
    int beta_bin = static_cast<int>(std::floor(beta / bin)) + kSpinWidth;
    int alpha_bin = static_cast<int>(std::floor(alpha / bin));
    if (alpha_bin == kSpinWidth) {   // border points (PCL's "HACK")
      --alpha_bin;
      alpha = bin * (alpha_bin + 1);
    }
    if (beta_bin == 2 * kSpinWidth) {
      --beta_bin;
      beta = bin * (beta_bin - kSpinWidth + 1);
    }
    const double a = alpha / bin - alpha_bin;
    const double b = beta / bin - (beta_bin - kSpinWidth);
    m[alpha_bin * kSpinCols + beta_bin] += (1 - a) * (1 - b);
    m[(alpha_bin + 1) * kSpinCols + beta_bin] += a * (1 - b);
    m[alpha_bin * kSpinCols + beta_bin + 1] += (1 - a) * b;
    m[(alpha_bin + 1) * kSpinCols + beta_bin + 1] += a * b;
  }
  double sum = 0.0;
  for (double v : m) sum += v;
  if (!(sum > 0.0)) return false;
  for (std::size_t i = 0; i < m.size(); ++i) out[i] = static_cast<float>(m[i] / sum);
  return true;
}

}  // namespace

std::string descriptor_name(Descriptor d) {
  switch (d) {
    case Descriptor::fpfh: return "fpfh";
    case Descriptor::pfh: return "pfh";
    case Descriptor::shot: return "shot";
    case Descriptor::spin: return "spin";
  }
  throw Error("descriptor_name: not a descriptor", {}, "descriptor");
}

Descriptor parse_descriptor(std::string_view name) {
  for (Descriptor d : kAllDescriptors)
    if (name == descriptor_name(d)) return d;
  throw Error("unknown descriptor '" + std::string(name) + "' (expected fpfh, pfh, shot or spin)", {},
              "descriptor");
}

int descriptor_dim(Descriptor d) {
  switch (d) {
    case Descriptor::fpfh: return kFeatureDim;
    case Descriptor::pfh: return kPfhSplit * kPfhSplit * kPfhSplit;
    case Descriptor::shot: return kShotVolumes * kShotBinsPerVolume;
    case Descriptor::spin: return kSpinRows * kSpinCols;
  }
  throw Error("descriptor_dim: not a descriptor", {}, "descriptor");
}

Descriptors compute_descriptors(Descriptor d, const std::vector<Vec3>& keypoints,
                                const std::vector<Vec3>& keypoint_normals, const PointCloud& surface,
                                const KdTree3& surface_tree, const DescriptorSettings& settings) {
  const std::string who = "compute_descriptors(" + descriptor_name(d) + "): ";
  if (!keypoint_normals.empty() && keypoint_normals.size() != keypoints.size())
    throw Error(who + "keypoint_normals size differs from keypoints", {}, "keypoint_normals");
  if (d == Descriptor::spin && keypoint_normals.size() != keypoints.size())
    throw Error(who + "spin images need one normal per keypoint (the spin axis)", {}, "keypoint_normals");
  if (!surface.empty() && !surface.has_normals())
    throw Error(who + "the surface cloud needs normals", {}, "surface.normals");
  if (surface_tree.size() != surface.size())
    throw Error(who + "surface_tree is not built over the surface points", {}, "surface_tree");
  if (!(settings.feature_radius > 0.0) || !std::isfinite(settings.feature_radius))
    throw Error(who + "feature_radius must be positive", {}, "feature_radius");
  if (!(settings.shot_lrf_radius >= 0.0) || !std::isfinite(settings.shot_lrf_radius))
    throw Error(who + "shot_lrf_radius must be 0 or positive", {}, "shot_lrf_radius");

  const std::size_t nk = keypoints.size();
  Descriptors out;
  out.dim = descriptor_dim(d);
  out.values.assign(nk * static_cast<std::size_t>(out.dim), 0.0f);
  out.valid.assign(nk, false);

  if (d == Descriptor::fpfh) {
    FpfhSettings fs;
    fs.feature_radius = settings.feature_radius;
    const FpfhResult f = compute_fpfh(keypoints, keypoint_normals, surface, surface_tree, fs);
    for (std::size_t i = 0; i < nk; ++i) {
      std::memcpy(out.values.data() + i * kFeatureDim, f.features[i].data(), sizeof(Feature));
      out.valid[i] = f.valid[i];
    }
    return out;
  }

  const double r = settings.feature_radius;
  const double lrf_r = settings.shot_lrf_radius > 0.0 ? settings.shot_lrf_radius : r;
  std::vector<char> valid(nk, 0);   // not vector<bool>: tasks write neighbouring slots
  tbb::parallel_for(std::size_t(0), nk, [&](std::size_t i) {
    const Vec3& kp = keypoints[i];
    if (!finite(kp)) return;
    float* row = out.values.data() + i * static_cast<std::size_t>(out.dim);
    const std::vector<Neighbour> nb = surface_tree.radius(kp, r);
    bool ok = false;
    switch (d) {
      case Descriptor::pfh: ok = pfh_row(surface, nb, row); break;
      case Descriptor::shot: {
        Mat3 rf = Mat3::Zero();
        ok = shot_frame(kp, surface, lrf_r == r ? nb : surface_tree.radius(kp, lrf_r), lrf_r, rf) &&
             shot_row(kp, rf, surface, nb, r, row);
        break;
      }
      case Descriptor::spin:
        if (finite(keypoint_normals[i])) ok = spin_row(kp, keypoint_normals[i], surface, nb, r, row);
        break;
      case Descriptor::fpfh: break;
    }
    if (!ok) std::fill(row, row + out.dim, 0.0f);
    valid[i] = ok ? 1 : 0;
  });
  for (std::size_t i = 0; i < nk; ++i) out.valid[i] = valid[i] != 0;
  return out;
}

}  // namespace features
}  // namespace ts
