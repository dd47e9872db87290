#include "engine/recognition/icp.hpp"

#include "engine/geometry/eigen_solvers.hpp"
#include "engine/geometry/kabsch.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>

namespace ts {
inline namespace recognition {

namespace {

struct Pair {
  double d2;
  std::uint32_t contact;   ///< index into scene.ordered
  std::uint32_t model;     ///< index into the fine cloud
};

using Matrix6 = Eigen::Matrix<double, 6, 6>;

Vec3 mean_point(const std::vector<Vec3>& y) {
  Vec3 c = Vec3::Zero();
  for (const Vec3& p : y) c += p;
  return c / static_cast<double>(y.size());
}

/// H = sum J J^T with J = [(y - c) x n; n]: the point-to-plane normal matrix about c.
Matrix6 normal_matrix(const std::vector<Vec3>& y, const std::vector<Vec3>& n, const Vec3& c,
                      const std::vector<Vec3>* z = nullptr, Eigen::Matrix<double, 6, 1>* g = nullptr) {
  Matrix6 H = Matrix6::Zero();
  for (std::size_t i = 0; i < y.size(); ++i) {
    Eigen::Matrix<double, 6, 1> J;
    J.head<3>() = (y[i] - c).cross(n[i]);
    J.tail<3>() = n[i];
    H.noalias() += J * J.transpose();
    if (g) g->noalias() += J * n[i].dot(y[i] - (*z)[i]);
  }
  return H;
}

/// One Gauss-Newton step of point-to-plane ICP in the object frame: the small motion
/// (omega, v) about the centroid c of the moved contacts y that minimizes
/// sum (n . (y + omega x (y - c) + v - z))^2. Returns false when the system is degenerate.
bool plane_step(const std::vector<Vec3>& y, const std::vector<Vec3>& z, const std::vector<Vec3>& n,
                Pose& delta) {
  const std::size_t m = y.size();
  const Vec3 c = mean_point(y);
  Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
  Matrix6 H = normal_matrix(y, n, c, &z, &g);
  // A little damping keeps directions the contacts do not constrain (a flat patch) still.
  const double mu = 1e-9 * H.trace() + 1e-300;
  H.diagonal().array() += mu;
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(H);
  if (ldlt.info() != Eigen::Success) return false;
  Eigen::Matrix<double, 6, 1> x = -ldlt.solve(g);
  if (!x.allFinite()) return false;
  // Trust region: the linearization holds for small motions only; far from the optimum (a
  // wrong object, few contacts) an unlimited step can turn by 90 degrees or jump away. Limit a
  // step to 0.1 rad and to a fifth of the contacts' spread (the whole step scaled alike).
  double spread2 = 0.0;
  for (const Vec3& p : y) spread2 += (p - c).squaredNorm();
  const double spread = std::sqrt(spread2 / static_cast<double>(m));
  const double rot = x.head<3>().norm(), trans = x.tail<3>().norm();
  double scale = 1.0;
  if (rot > 0.1) scale = std::min(scale, 0.1 / rot);
  if (spread > 0.0 && trans > 0.2 * spread) scale = std::min(scale, 0.2 * spread / trans);
  x *= scale;
  const Vec3 omega = x.head<3>(), v = x.tail<3>();
  const double angle = omega.norm();
  Mat3 R = Mat3::Identity();
  if (angle > 0.0) R = Eigen::AngleAxisd(angle, omega / angle).toRotationMatrix();
  delta = Pose::Identity();
  delta.linear() = R;
  delta.translation() = c + v - R * c;
  return true;
}

/// The pairs of one ICP iteration: the first max_points contacts of the scene's evaluation
/// order, moved into the object frame by the pose, paired with the object (nearest fine point
/// and its normal, or the distance field's closest-point estimate), gated and trimmed.
class Pairing {
 public:
  Pairing(const Scene& scene, const ObjectGeometry& geo, const IcpSettings& s)
      : scene_(scene), geo_(geo) {
    const std::size_t C = scene.ordered.size();
    m_ = s.max_points == 0 ? C : std::min(C, s.max_points);
    use_field_ = s.metric == IcpMetric::field && !geo.field.empty();
    plane_ = use_field_ || (s.metric != IcpMetric::point_to_point && geo.fine.has_normals());
    usable_ = m_ >= 3 && (use_field_ ? !geo.field.empty() : geo.tree.size() >= 3);
    gate2_ = s.max_correspondence > 0.0 ? s.max_correspondence * s.max_correspondence
                                        : std::numeric_limits<double>::infinity();
    trim_ = std::clamp(s.trim_fraction, 0.0, 1.0);
    far_ = geo.field.empty() ? 0.0 : geo.field.coarse_margin();
    pairs_.resize(m_);
    if (use_field_) {
      dist_.resize(m_);
      grad_.resize(m_);
      ys_.resize(m_);
      ns_.resize(m_);
    }
    src.reserve(m_);
    dst.reserve(m_);
    nrm.reserve(m_);
  }

  bool usable() const { return usable_; }
  /// Point-to-plane (or field) pairs: src are contacts in the object frame, dst the paired
  /// surface points, nrm their normals. Point-to-point: src model points, dst contacts.
  bool plane() const { return plane_; }
  bool field() const { return use_field_; }

  /// Pair the contacts at T (T_scene_object); returns the sum of the squared distances.
  double collect(const Pose& T) {
    const Pose T_os = T.inverse();
    const std::size_t m = m_;
    if (use_field_) {
      // The distance and its gradient from one interpolation: the analytic derivative of the
      // trilinear interpolant (zero where the field only knows a lower bound).
      for (std::size_t i = 0; i < m; ++i) ys_[i] = T_os * scene_.ordered[i];
      geo_.field.distances_gradients(ys_.data(), m, Pose::Identity(), dist_.data(), grad_.data());
      for (std::size_t i = 0; i < m; ++i) {
        const double d = dist_[i];
        const Vec3& g = grad_[i];
        const double gn = g.norm();
        const bool usable = std::abs(d) < far_ && gn > 0.5 && g.allFinite();
        ns_[i] = usable ? Vec3(g / gn) : Vec3::Zero();
        // pairs_[i].d2: squared distance; unusable contacts sort last and are never fitted
        pairs_[i] = {usable ? d * d : std::numeric_limits<double>::infinity(),
                     static_cast<std::uint32_t>(i), 0};
      }
    } else {
      for (std::size_t i = 0; i < m; ++i) {
        const Neighbour nb = geo_.tree.nearest(T_os * scene_.ordered[i]);
        pairs_[i] = {nb.sq_distance, static_cast<std::uint32_t>(i), nb.index};
      }
    }
    std::size_t keep = m;
    if (trim_ < 1.0) {
      keep = std::min(m, std::max<std::size_t>(3, static_cast<std::size_t>(std::ceil(trim_ * double(m)))));
      auto by_distance = [](const Pair& a, const Pair& b) {
        return a.d2 < b.d2 || (a.d2 == b.d2 && a.contact < b.contact);
      };
      std::nth_element(pairs_.begin(), pairs_.begin() + (keep - 1), pairs_.end(), by_distance);
      std::sort(pairs_.begin(), pairs_.begin() + keep,
                [](const Pair& a, const Pair& b) { return a.contact < b.contact; });  // fixed order
    }
    src.clear();
    dst.clear();
    nrm.clear();
    const std::span<const Vec3> model = geo_.tree.points();
    double sq = 0.0;
    for (std::size_t j = 0; j < keep; ++j) {
      const Pair& p = pairs_[j];
      if (p.d2 > gate2_ || !std::isfinite(p.d2)) continue;
      sq += p.d2;
      if (use_field_) {
        // closest-point estimate z = y - d n, so that n . (y - z) = d (signed distance)
        const std::uint32_t i = p.contact;
        const double d = dist_[i];
        src.push_back(ys_[i]);
        nrm.push_back(ns_[i]);
        dst.push_back(ys_[i] - d * ns_[i]);
        continue;
      }
      if (plane_) {
        src.push_back(T_os * scene_.ordered[p.contact]);  // contact in the object frame
        nrm.push_back(geo_.fine.normals[p.model]);
      } else {
        src.push_back(model[p.model]);
      }
      dst.push_back(plane_ ? model[p.model] : scene_.ordered[p.contact]);
    }
    return sq;
  }

  std::vector<Vec3> src, dst, nrm;

 private:
  const Scene& scene_;
  const ObjectGeometry& geo_;
  std::size_t m_ = 0;
  bool use_field_ = false, plane_ = false, usable_ = false;
  double gate2_ = 0.0, trim_ = 1.0, far_ = 0.0;
  std::vector<Pair> pairs_;
  // Field metric: per contact the moved point y, its distance d, the interpolant's gradient
  // and its direction n.
  std::vector<Vec3> ys_, grad_, ns_;
  std::vector<double> dist_;
};

}  // namespace

IcpResult icp(const Scene& scene, const ObjectGeometry& geo, const Pose& T_init,
              const IcpSettings& s) {
  IcpResult res;
  res.T_scene_object = T_init;
  Pairing pairing(scene, geo, s);
  if (!pairing.usable() || !T_init.matrix().allFinite()) return res;
  res.valid = true;
  const double min_rot = s.min_rotation_deg * std::numbers::pi / 180.0;
  const std::vector<Vec3>&src = pairing.src, &dst = pairing.dst, &nrm = pairing.nrm;
  Pose T = T_init;
  double prev_rms = 0.0;
  int stalled = 0;
  for (int it = 0; it < s.max_iterations; ++it) {
    const double sq = pairing.collect(T);
    res.iterations = it + 1;
    if (src.size() < 3) break;
    res.pairs = src.size();
    res.rms = std::sqrt(sq / static_cast<double>(src.size()));
    Pose delta;  // the update, as a motion of the scene frame
    if (pairing.plane()) {
      Pose d_obj;
      if (!plane_step(src, dst, nrm, d_obj)) break;
      const Pose T_new = (d_obj * T.inverse()).inverse();
      delta = T_new * T.inverse();
      T = T_new;
    } else {
      const RigidFit fit = kabsch(src, dst);
      if (!fit.valid) break;
      delta = fit.T_target_source * T.inverse();
      T = fit.T_target_source;
    }
    if (!T.matrix().allFinite()) {
      T = res.T_scene_object;
      break;
    }
    res.T_scene_object = T;
    if (delta.translation().norm() < s.min_translation && rotation_angle(delta.linear()) < min_rot) {
      res.converged = true;
      break;
    }
    // Stalled: the fit has not improved its RMS by min_improvement for two iterations (noisy
    // contacts make the last fraction of a millimetre jitter instead of converging).
    if (prev_rms > 0.0 && res.rms > prev_rms * (1.0 - s.min_improvement)) {
      if (++stalled >= 2) {
        res.converged = true;
        break;
      }
    } else {
      stalled = 0;
    }
    prev_rms = res.rms;
  }
  res.T_scene_object = T;
  return res;
}

IcpSystem icp_system(const Scene& scene, const ObjectGeometry& geo, const Pose& T,
                     const IcpSettings& settings) {
  IcpSystem out;
  IcpSettings s = settings;
  if (s.metric == IcpMetric::point_to_point) s.metric = IcpMetric::point_to_plane;
  Pairing pairing(scene, geo, s);
  if (!pairing.usable() || !pairing.plane() || !T.matrix().allFinite()) return out;
  pairing.collect(T);
  const std::vector<Vec3>& y = pairing.src;
  const std::vector<Vec3>& n = pairing.nrm;
  out.pairs = y.size();
  if (y.size() < 6) return out;
  const Vec3 c = mean_point(y);
  double spread2 = 0.0;
  for (const Vec3& p : y) spread2 += (p - c).squaredNorm();
  out.radius = std::sqrt(spread2 / static_cast<double>(y.size()));
  const Matrix6 H = normal_matrix(y, n, c);
  const auto condition = [](const Matrix6& A, int* small) {
    const Eigen::Matrix<double, 6, 1> ev = symmetric_eigenvalues(A);  // ascending
    const double top = ev(5);
    if (!(top > 0.0) || !std::isfinite(top)) return kIcpSingular;
    if (small) *small = static_cast<int>((ev.array() < 0.01 * top).count());
    return ev(0) * kIcpSingular <= top ? kIcpSingular : top / ev(0);
  };
  out.condition_raw = condition(H, nullptr);
  if (out.radius > 0.0) {
    // Rotation parameters as motions at the contacts' radius: J' = diag(1/r, 1) J.
    Eigen::Matrix<double, 6, 1> d;
    d << Vec3::Constant(1.0 / out.radius), Vec3::Ones();
    out.condition = condition(d.asDiagonal() * H * d.asDiagonal(), &out.unobservable_dof);
  } else {
    out.condition = kIcpSingular;
  }
  out.valid = out.condition < kIcpSingular;
  return out;
}

}  // namespace recognition
}  // namespace ts
