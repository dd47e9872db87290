#include "engine/geometry/symmetry.hpp"
#include "engine/detail.hpp"

#include <array>
#include <map>

#include "engine/geometry/kabsch.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace ts {
inline namespace geometry {

namespace {

using detail::kPi;

Mat3 axis_rotation(const Vec3& axis, double angle) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

/// Everything the candidate checks need, in a frame centred on the model's centroid.
class Checker {
 public:
  Checker(const std::vector<Vec3>& points, const KdTree3& tree, const SymmetrySettings& s)
      : tree_(tree), s_(s) {
    const std::size_t n = points.size();
    Eigen::AlignedBox3d box;
    for (const Vec3& p : points) box.extend(p);
    diagonal_ = box.diagonal().norm();
    // Density-independent centre: one point (the mean) per occupied cell of a grid
    // centred on the bounding box, with cells coarser than the sparsest sampling (1 % of the
    // diagonal, or 3 x the 90th percentile of the nearest-neighbour distance). A scanner
    // samples the faces it sees head-on densely and the rest sparsely; the plain centroid of
    // such a cloud is millimetres off the body's centre, more than the tolerance, and every
    // symmetry about it then fails.
    {
      std::vector<double> nn;
      const std::size_t m = std::min<std::size_t>(n, 2000);
      for (std::size_t i = 0; i < m; ++i) {
        const auto k = tree_.knn(points[(i * n) / m], 2);
        if (k.size() == 2) nn.push_back(std::sqrt(k[1].sq_distance));
      }
      double p90 = 0.0;
      if (!nn.empty()) {
        const std::size_t q = (nn.size() * 9) / 10;
        std::nth_element(nn.begin(), nn.begin() + static_cast<std::ptrdiff_t>(q), nn.end());
        p90 = nn[q];
      }
      const double cell = std::max({0.01 * diagonal_, 3.0 * p90, 1e-12});
      const Vec3 mid = box.center();
      std::map<std::array<std::int64_t, 3>, std::pair<Vec3, std::size_t>> cells;
      for (const Vec3& p : points) {
        const Vec3 l = ((p - mid) / cell).array().round();
        auto& c = cells.try_emplace({static_cast<std::int64_t>(l.x()), static_cast<std::int64_t>(l.y()),
                                     static_cast<std::int64_t>(l.z())},
                                    Vec3::Zero(), std::size_t{0})
                      .first->second;
        c.first += p - mid;
        ++c.second;
      }
      Vec3 acc = Vec3::Zero();
      for (const auto& [k, c] : cells) acc += c.first / static_cast<double>(c.second);  // ascending keys
      centre_ = mid + acc / static_cast<double>(cells.size());
      // An evenly sampled cloud: its plain centroid is the more precise estimate of the two.
      Vec3 plain = Vec3::Zero();
      for (const Vec3& p : points) plain += p - mid;
      plain = mid + plain / static_cast<double>(n);
      if ((plain - centre_).norm() < 0.005 * diagonal_) centre_ = plain;
    }
    // A deterministic spread-out sample: stride over the points.
    const std::size_t m = std::min(n, s.sample_points);
    sample_.reserve(m);
    for (std::size_t i = 0; i < m; ++i) sample_.push_back(points[(i * n) / m] - centre_);
    // Point spacing: median distance to the nearest other point over the sample.
    std::vector<double> nn;
    for (const Vec3& x : sample_) {
      const auto k = tree_.knn(x + centre_, 2);
      if (k.size() == 2) nn.push_back(std::sqrt(k[1].sq_distance));
    }
    double spacing = 0.0;
    if (!nn.empty()) {
      std::nth_element(nn.begin(), nn.begin() + nn.size() / 2, nn.end());
      spacing = nn[nn.size() / 2];
    }
    tol_ = s.tolerance > 0.0 ? s.tolerance : std::max(s.tolerance_rel * diagonal_, 2.5 * spacing);
  }

  const Vec3& centre() const { return centre_; }
  double tolerance() const { return tol_; }
  const std::vector<Vec3>& sample() const { return sample_; }

  /// Fraction of the first `m` sample points that land within tolerance of the model.
  double fraction(const Mat3& R, std::size_t m) const {
    m = std::min(m, sample_.size());
    if (m == 0) return 0.0;
    const double tol2 = tol_ * tol_;
    std::size_t hit = 0;
    for (std::size_t i = 0; i < m; ++i)
      if (tree_.nearest(centre_ + R * sample_[i]).sq_distance <= tol2) ++hit;
    return static_cast<double>(hit) / static_cast<double>(m);
  }
  double fraction(const Mat3& R) const { return fraction(R, sample_.size()); }

  /// Quick test on a prefix, then the full sample.
  bool passes(const Mat3& R) const {
    if (fraction(R, 64) < 0.8 * s_.inlier_fraction) return false;
    return fraction(R) >= s_.inlier_fraction;
  }

  /// Rotation-only ICP about the centre (point-to-point, reflection-fixed).
  Mat3 refine(Mat3 R) const {
    const double gate2 = 9.0 * tol_ * tol_;
    for (int it = 0; it < 20; ++it) {
      Mat3 H = Mat3::Zero();
      std::size_t pairs = 0;
      for (const Vec3& x : sample_) {
        const Neighbour nb = tree_.nearest(centre_ + R * x);
        if (nb.sq_distance > gate2) continue;
        H.noalias() += x * (tree_.points()[nb.index] - centre_).transpose();
        ++pairs;
      }
      if (pairs < 3) return R;
      const Mat3 Rn = rotation_from_covariance(H);
      const double change = rotation_angle(Rn * R.transpose());
      R = Rn;
      if (change < 1e-7) break;
    }
    return R;
  }

 private:
  const KdTree3& tree_;
  const SymmetrySettings& s_;
  Vec3 centre_ = Vec3::Zero();
  std::vector<Vec3> sample_;
  double diagonal_ = 0.0;
  double tol_ = 0.0;
};

/// Adds R unless an element within 3 degrees is already there.
void add_unique(std::vector<Mat3>& group, const Mat3& R) {
  for (const Mat3& G : group)
    if (rotation_angle(G.transpose() * R) < 3.0 * kPi / 180.0) return;
  group.push_back(R);
}

/// Among passing test angles on a circle of `steps` samples, the best angle of each run of
/// consecutive passes. pass[i] < 0 means failed; otherwise it is the score.
std::vector<int> run_peaks(const std::vector<double>& score) {
  const int n = static_cast<int>(score.size());
  std::vector<int> peaks;
  int first_fail = -1;
  for (int i = 0; i < n; ++i)
    if (score[i] < 0.0) { first_fail = i; break; }
  if (first_fail < 0) return peaks;  // everything passes: a continuum, handled by the caller
  // Each run's peak is the middle of its top plateau: with 1-degree test angles, a run's top
  // score (all sample points within tolerance) is often flat over several degrees, and its
  // first angle would start the refinement needlessly far from the symmetry.
  int best = -1, last_best = -1;
  auto plateau_middle = [&] { return (best + ((last_best - best + n) % n) / 2) % n; };
  for (int k = 1; k <= n; ++k) {
    const int i = (first_fail + k) % n;
    if (score[i] >= 0.0) {
      if (best < 0 || score[i] > score[best]) best = last_best = i;
      else if (score[i] == score[best] && last_best == (i + n - 1) % n) last_best = i;
    } else if (best >= 0) {
      peaks.push_back(plateau_middle());
      best = last_best = -1;
    }
  }
  if (best >= 0) peaks.push_back(plateau_middle());
  std::sort(peaks.begin(), peaks.end());
  return peaks;
}

void try_candidate(const Checker& ck, std::vector<Mat3>& group, const Mat3& R0) {
  if (ck.fraction(R0, 64) < 0.5) return;
  const Mat3 R = ck.refine(R0);
  if (ck.passes(R)) add_unique(group, R);
}

/// Rotations about `axis` (excluding identity) and half-turns about axes perpendicular to it.
/// Returns true when every tested rotation about the axis passes (a body of revolution).
bool search_axis(const Checker& ck, const SymmetrySettings& s, const Vec3& axis,
                 std::vector<Mat3>& group) {
  const int steps = std::max(8, s.angle_steps);
  std::vector<double> score(static_cast<std::size_t>(steps), -1.0);
  // Identity: above any fraction, so it is the peak of its run and the angles next to it that
  // pass only because they move the surface by less than the tolerance (a thin bar turned a few
  // degrees about its axis) are never taken for a symmetry.
  score[0] = 2.0;
  int passed = 0;
  for (int m = 1; m < steps; ++m) {
    const Mat3 R = axis_rotation(axis, 2.0 * kPi * m / steps);
    if (ck.fraction(R, 64) < 0.8 * s.inlier_fraction) continue;
    const double f = ck.fraction(R);
    if (f >= s.inlier_fraction) {
      score[static_cast<std::size_t>(m)] = f;
      ++passed;
    }
  }
  const bool continuous = passed >= s.continuous_fraction * (steps - 1);
  if (!continuous) {
    for (int m : run_peaks(score))
      if (m != 0) try_candidate(ck, group, axis_rotation(axis, 2.0 * kPi * m / steps));
  }
  // Half-turns about perpendicular axes u(psi), psi in [0, pi).
  const Vec3 b1 = axis.unitOrthogonal();
  const Vec3 b2 = axis.cross(b1).normalized();
  const int half = std::max(4, steps / 2);
  std::vector<double> flip(static_cast<std::size_t>(half), -1.0);
  for (int m = 0; m < half; ++m) {
    const double psi = kPi * m / half;
    const Mat3 R = axis_rotation(std::cos(psi) * b1 + std::sin(psi) * b2, kPi);
    if (ck.fraction(R, 64) < 0.8 * s.inlier_fraction) continue;
    const double f = ck.fraction(R);
    if (f >= s.inlier_fraction) flip[static_cast<std::size_t>(m)] = f;
  }
  if (continuous) {
    // Modulo the continuum one half-turn represents them all.
    int best = -1;
    for (int m = 0; m < half; ++m)
      if (flip[m] >= 0.0 && (best < 0 || flip[m] > flip[best])) best = m;
    if (best >= 0) {
      const double psi = kPi * best / half;
      group.push_back(axis_rotation(std::cos(psi) * b1 + std::sin(psi) * b2, kPi));
    }
    return true;
  }
  // Peaks of the half-turn scores (not circular in psi: psi and psi + pi are the same axis, so
  // treat the sequence as circular too).
  std::vector<int> peaks = run_peaks(flip);
  if (peaks.empty() && flip[0] >= 0.0) peaks.push_back(0);
  for (int m : peaks) {
    const double psi = kPi * m / half;
    try_candidate(ck, group, axis_rotation(std::cos(psi) * b1 + std::sin(psi) * b2, kPi));
  }
  return false;
}

/// Self-registration for models whose principal variances are all alike (cube, regular solids):
/// map the extreme point p1 and a second extreme point p2 onto every pair (q1, q2) with the same
/// radii and the same angle, and test the rotations this defines.
void search_generic(const Checker& ck, const std::vector<Vec3>& points, std::vector<Mat3>& group) {
  std::vector<Vec3> centred;
  centred.reserve(points.size());
  for (const Vec3& p : points) centred.push_back(p - ck.centre());
  for (const Mat3& R : extreme_pair_rotations(centred, centred, ck.tolerance())) try_candidate(ck, group, R);
}

}  // namespace

std::vector<Mat3> extreme_pair_rotations(const std::vector<Vec3>& source, const std::vector<Vec3>& target, double tol) {
  std::vector<Mat3> out;
  std::size_t i1 = 0;
  double r1 = -1.0;
  for (std::size_t i = 0; i < source.size(); ++i) {
    const double r = source[i].norm();
    if (r > r1) { r1 = r; i1 = i; }
  }
  if (r1 <= 2.0 * tol) return out;
  const Vec3 u1 = source[i1];
  std::size_t i2 = source.size();
  double best = -1.0;
  for (std::size_t i = 0; i < source.size(); ++i) {
    const Vec3& v = source[i];
    const double r = v.norm();
    if (r <= 2.0 * tol) continue;
    const double cosang = u1.dot(v) / (r1 * r);
    const double score = r * std::sqrt(std::max(0.0, 1.0 - cosang * cosang));  // distance from axis u1
    if (score > best) { best = score; i2 = i; }
  }
  if (i2 == source.size() || best <= 2.0 * tol) return out;
  const Vec3 u2 = source[i2];
  const double r2 = u2.norm();
  const double ang12 = std::acos(std::clamp(u1.dot(u2) / (r1 * r2), -1.0, 1.0));

  // Greedy subsampling (at spacing tol, index order: deterministic) of the points whose radius
  // matches, capped.
  auto shell = [&](double r0) {
    std::vector<Vec3> q;
    for (const Vec3& v : target) {
      if (std::abs(v.norm() - r0) > tol) continue;
      bool near = false;
      for (const Vec3& w : q)
        if ((w - v).squaredNorm() < tol * tol) { near = true; break; }
      if (!near) q.push_back(v);
      if (q.size() >= 240) break;
    }
    return q;
  };
  const std::vector<Vec3> Q1 = shell(r1), Q2 = shell(r2);
  const double ang_tol = 2.0 * tol / std::min(r1, r2);
  const std::array<Vec3, 3> src{Vec3::Zero(), u1, u2};
  for (const Vec3& v1 : Q1) {
    for (const Vec3& v2 : Q2) {
      const double a = std::acos(std::clamp(v1.dot(v2) / (v1.norm() * v2.norm()), -1.0, 1.0));
      if (std::abs(a - ang12) > ang_tol) continue;
      const std::array<Vec3, 3> dst{Vec3::Zero(), v1, v2};
      const RigidFit fit = kabsch(src, dst);
      if (fit.valid) out.push_back(fit.T_target_source.linear());
    }
  }
  return out;
}

SymmetryGroup find_symmetries(const std::vector<Vec3>& points, const KdTree3& tree,
                              const SymmetrySettings& s) {
  SymmetryGroup g;
  if (points.size() < 10 || tree.size() != points.size()) return g;
  for (const Vec3& p : points)
    if (!finite(p)) return g;
  const Checker ck(points, tree, s);
  g.centre = ck.centre();
  g.tolerance = ck.tolerance();
  if (!(g.tolerance > 0.0)) return g;  // all points coincide

  Mat3 cov = Mat3::Zero();
  for (const Vec3& p : points) cov.noalias() += (p - g.centre) * (p - g.centre).transpose();
  cov /= static_cast<double>(points.size());
  Eigen::SelfAdjointEigenSolver<Mat3> es(cov);
  const Vec3 ev = es.eigenvalues();          // ascending
  const Mat3 E = es.eigenvectors();
  // Alike variances decide the candidate families. Sampled surfaces are not uniform (scans,
  // voxel grids), so "alike" is generous: a superset family only costs search time, while a
  // too strict test would miss symmetries (a hexagonal bar's in-plane variances can differ by
  // 10 % in its fine cloud).
  auto equal = [&](int i, int j) {
    return std::abs(ev[i] - ev[j]) <= s.eigen_equal_rel * std::max(ev[i], ev[j]);
  };
  const bool e01 = equal(0, 1), e12 = equal(1, 2), e02 = equal(0, 2);
  const int pairs = e02 ? 3 : int(e01) + int(e12);
  if (pairs == 0) {
    for (int k = 0; k < 3; ++k) try_candidate(ck, g.rotations, axis_rotation(E.col(k), kPi));
  } else if (pairs == 1) {
    const int unique = e01 ? 2 : 0;
    const Vec3 axis = E.col(unique).normalized();
    if (search_axis(ck, s, axis, g.rotations)) {
      g.kind = SymmetryGroup::Kind::axial;
      g.axis = axis;
    }
  } else {
    // All alike: first the sphere test with random rotations, then self-registration.
    Rng rng(s.seed, 0x5e11u);
    int passed = 0;
    const int trials = 48;
    for (int i = 0; i < trials; ++i)
      if (ck.passes(rng.rotation().toRotationMatrix())) ++passed;
    if (passed >= s.continuous_fraction * trials) {
      g.kind = SymmetryGroup::Kind::spherical;
      g.rotations = {Mat3::Identity()};
      return g;
    }
    search_generic(ck, points, g.rotations);
  }
  return g;
}

}  // namespace geometry
}  // namespace ts
