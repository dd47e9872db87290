#include "engine/recognition/twins.hpp"

#include <Eigen/Dense>

#include <cmath>
#include <limits>

namespace ts {

namespace {

EvaluateSettings fit_settings_of(const TwinSettings& s) {
  EvaluateSettings f;
  f.grasp_offset_sigma = s.offset_sigma;
  f.grasp_contact_sigma = s.contact_sigma;
  f.grasp_fit_points = s.fit_points;
  f.grasp_offset_iterations = s.iterations;
  return f;
}

double score_of(const GraspFit& fit, const TwinSettings& s) {
  double prior = 0.0;
  for (const Vec3& t : fit.offsets) prior += t.squaredNorm();
  return prior / (s.offset_sigma * s.offset_sigma) + fit.clamped_sq_sum / (s.contact_sigma * s.contact_sigma);
}

// One Gauss-Newton step of the pose and the grasp offsets together, on
//     sum_i d_i^2 / contact_sigma^2 + sum_g |t_g|^2 / offset_sigma^2
// over the contacts within `gate` of the surface (d_i of contact i of grasp g shifted by t_g).
// The pose and the offsets' common part are told apart only by the prior, so they are solved
// jointly (each grasp's 3 x 3 block eliminated by its Schur complement); a pose step with the
// offsets held would leave the common part in the offsets. Returns the new T_scene_object (the
// input when the system is degenerate).
Pose joint_step(const Scene& scene, const DistanceField& field, const Pose& T_so,
                const std::vector<Vec3>& offsets, const TwinSettings& s) {
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  using Mat63 = Eigen::Matrix<double, 6, 3>;
  const GraspGroups& G = scene.grasps;
  const double gate = 3.0 * s.contact_sigma;
  const double rho = std::pow(s.contact_sigma / s.offset_sigma, 2);
  const Pose T_os = T_so.inverse();
  const Eigen::Matrix3d R_so = T_so.linear();
  Vec3 centre = Vec3::Zero();
  for (const Vec3& p : G.points) centre += p;
  centre /= static_cast<double>(std::max<std::size_t>(G.points.size(), 1));
  Mat6 A = Mat6::Zero();
  Vec6 a = Vec6::Zero();
  std::vector<Vec3> q, g;
  std::vector<double> d;
  std::size_t used = 0;
  for (std::size_t k = 0; k < G.grasps(); ++k) {
    const std::size_t m = G.first[k + 1] - G.first[k];
    q.resize(m);
    d.resize(m);
    g.resize(m);
    for (std::size_t j = 0; j < m; ++j) q[j] = G.points[G.first[k] + j] + offsets[k];
    field.distances_gradients(q.data(), m, T_os, d.data(), g.data());
    Mat63 B = Mat63::Zero();
    Eigen::Matrix3d D = rho * Eigen::Matrix3d::Identity();
    Vec3 b = -rho * offsets[k];
    for (std::size_t j = 0; j < m; ++j) {
      const double gn = g[j].norm();
      if (!(std::abs(d[j]) < gate) || !(gn > 0.5)) continue;
      const Vec3 n = R_so * (g[j] / gn);   // scene frame
      Vec6 J;
      J.head<3>() = (q[j] - centre).cross(n);
      J.tail<3>() = n;
      A.noalias() += J * J.transpose();
      a.noalias() -= J * d[j];
      B.noalias() += J * n.transpose();
      D.noalias() += n * n.transpose();
      b -= n * d[j];
      ++used;
    }
    const Eigen::Matrix3d D_inv = D.inverse();   // D >= rho I: invertible
    A.noalias() -= B * D_inv * B.transpose();
    a.noalias() -= B * (D_inv * b);
  }
  if (used < 6) return T_so;
  const Vec6 x = A.ldlt().solve(a);
  if (!x.allFinite()) return T_so;
  // The contacts move by M (rotation about their centre, then translation); the object by M^-1.
  Pose M = Pose::Identity();
  const double angle = x.head<3>().norm();
  if (angle > 1e-15) M.linear() = Eigen::AngleAxisd(angle, x.head<3>() / angle).toRotationMatrix();
  M.translation() = centre - M.linear() * centre + x.tail<3>();
  return M.inverse() * T_so;
}

}  // namespace

double twin_score(const Scene& scene, const ObjectGeometry& geo, const Pose& T_scene_object,
                  const TwinSettings& s) {
  if (scene.grasps.grasps() == 0 || geo.field.empty()) return std::numeric_limits<double>::infinity();
  const EvaluateSettings f = fit_settings_of(s);
  Pose T = T_scene_object;
  GraspFit fit = fit_grasp_offsets(scene, geo.field, T, f);
  double v = score_of(fit, s);
  for (int it = 0; it < s.refine; ++it) {
    const Pose T_next = joint_step(scene, geo.field, T, fit.offsets, s);
    GraspFit next = fit_grasp_offsets(scene, geo.field, T_next, f);
    const double v_next = score_of(next, s);
    if (!(v_next < v)) break;   // V never rises: the refinement only accepts improvements
    T = T_next;
    fit = std::move(next);
    v = v_next;
  }
  return v;
}

}  // namespace ts
