#include "engine/icp.hpp"

#include "engine/kabsch.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>

namespace ts {

namespace {

struct Pair {
  double d2;
  std::uint32_t contact;   ///< index into scene.ordered
  std::uint32_t model;     ///< index into the fine cloud
};

/// One Gauss-Newton step of point-to-plane ICP in the object frame: the small motion
/// (omega, v) about the centroid c of the moved contacts y that minimizes
/// sum (n . (y + omega x (y - c) + v - z))^2. Returns false when the system is degenerate.
bool plane_step(const std::vector<Vec3>& y, const std::vector<Vec3>& z, const std::vector<Vec3>& n,
                Pose& delta) {
  const std::size_t m = y.size();
  Vec3 c = Vec3::Zero();
  for (const Vec3& p : y) c += p;
  c /= static_cast<double>(m);
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
  for (std::size_t i = 0; i < m; ++i) {
    Eigen::Matrix<double, 6, 1> J;
    J.head<3>() = (y[i] - c).cross(n[i]);
    J.tail<3>() = n[i];
    const double r = n[i].dot(y[i] - z[i]);
    H.noalias() += J * J.transpose();
    g.noalias() += J * r;
  }
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

}  // namespace

IcpResult icp(const Scene& scene, const ObjectGeometry& geo, const Pose& T_init,
              const IcpSettings& s) {
  IcpResult res;
  res.T_scene_object = T_init;
  const std::size_t C = scene.ordered.size();
  const std::size_t m = s.max_points == 0 ? C : std::min(C, s.max_points);
  const bool use_field = s.metric == IcpMetric::field && !geo.field.empty();
  const bool plane = use_field || (s.metric != IcpMetric::point_to_point && geo.fine.has_normals());
  if (m < 3 || (use_field ? geo.field.empty() : geo.tree.size() < 3) || !T_init.matrix().allFinite()) return res;
  res.valid = true;
  const double gate2 = s.max_correspondence > 0.0 ? s.max_correspondence * s.max_correspondence
                                                  : std::numeric_limits<double>::infinity();
  const double min_rot = s.min_rotation_deg * std::numbers::pi / 180.0;
  const double trim = std::clamp(s.trim_fraction, 0.0, 1.0);
  const std::span<const Vec3> model = geo.tree.points();

  std::vector<Pair> pairs(m);
  std::vector<Vec3> src, dst, nrm;
  // Field metric: per contact the moved point y, its distance d and gradient direction n.
  std::vector<Vec3> probe, ys, ns;
  std::vector<double> dist;
  const double h = s.gradient_step;
  const double far = geo.field.empty() ? 0.0 : geo.field.coarse_margin();
  if (use_field) {
    probe.resize(4 * m);
    dist.resize(4 * m);
    ys.resize(m);
    ns.resize(m);
  }
  src.reserve(m);
  dst.reserve(m);
  nrm.reserve(m);
  Pose T = T_init;
  double prev_rms = 0.0;
  int stalled = 0;
  for (int it = 0; it < s.max_iterations; ++it) {
    const Pose T_os = T.inverse();
    if (use_field) {
      for (std::size_t i = 0; i < m; ++i) {
        const Vec3 y = T_os * scene.ordered[i];
        ys[i] = y;
        Vec3* q = &probe[4 * i];
        q[0] = y;
        for (int a = 0; a < 3; ++a) {
          q[1 + a] = y;
          q[1 + a][a] += h;
        }
      }
      geo.field.distances(probe.data(), probe.size(), Pose::Identity(), dist.data());
      for (std::size_t i = 0; i < m; ++i) {
        const double* d = &dist[4 * i];
        const Vec3 g((d[1] - d[0]) / h, (d[2] - d[0]) / h, (d[3] - d[0]) / h);
        const double gn = g.norm();
        const bool usable = std::abs(d[0]) < far && gn > 0.5 && g.allFinite();
        ns[i] = usable ? Vec3(g / gn) : Vec3::Zero();
        // pairs[i].d2: squared distance; unusable contacts sort last and are never fitted
        pairs[i] = {usable ? d[0] * d[0] : std::numeric_limits<double>::infinity(),
                    static_cast<std::uint32_t>(i), 0};
      }
    } else {
      for (std::size_t i = 0; i < m; ++i) {
        const Neighbour nb = geo.tree.nearest(T_os * scene.ordered[i]);
        pairs[i] = {nb.sq_distance, static_cast<std::uint32_t>(i), nb.index};
      }
    }
    std::size_t keep = m;
    if (trim < 1.0) {
      keep = std::min(m, std::max<std::size_t>(3, static_cast<std::size_t>(std::ceil(trim * double(m)))));
      auto by_distance = [](const Pair& a, const Pair& b) {
        return a.d2 < b.d2 || (a.d2 == b.d2 && a.contact < b.contact);
      };
      std::nth_element(pairs.begin(), pairs.begin() + (keep - 1), pairs.end(), by_distance);
      std::sort(pairs.begin(), pairs.begin() + keep,
                [](const Pair& a, const Pair& b) { return a.contact < b.contact; });  // fixed order
    }
    src.clear();
    dst.clear();
    nrm.clear();
    double sq = 0.0;
    for (std::size_t j = 0; j < keep; ++j) {
      const Pair& p = pairs[j];
      if (p.d2 > gate2 || !std::isfinite(p.d2)) continue;
      sq += p.d2;
      if (use_field) {
        // closest-point estimate z = y - d n, so that n . (y - z) = d (signed distance)
        const std::uint32_t i = p.contact;
        const double d = dist[4 * i];
        src.push_back(ys[i]);
        nrm.push_back(ns[i]);
        dst.push_back(ys[i] - d * ns[i]);
        continue;
      }
      if (plane) {
        src.push_back(T_os * scene.ordered[p.contact]);  // contact in the object frame
        nrm.push_back(geo.fine.normals[p.model]);
      } else {
        src.push_back(model[p.model]);
      }
      dst.push_back(plane ? model[p.model] : scene.ordered[p.contact]);
    }
    res.iterations = it + 1;
    if (src.size() < 3) break;
    res.pairs = src.size();
    res.rms = std::sqrt(sq / static_cast<double>(src.size()));
    Pose delta;  // the update, as a motion of the scene frame
    if (plane) {
      Pose d_obj;
      if (!plane_step(src, dst, nrm, d_obj)) break;
      const Pose T_new = (d_obj * T_os).inverse();
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

}  // namespace ts
