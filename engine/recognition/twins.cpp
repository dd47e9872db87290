#include "engine/recognition/twins.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace ts {
inline namespace recognition {

namespace {

EvaluateSettings fit_settings_of(const TwinSettings& s) {
  EvaluateSettings f;
  f.grasp_offset_sigma = s.offset_sigma;
  f.grasp_contact_sigma = s.contact_sigma;
  f.grasp_fit_points = s.fit_points;
  f.grasp_offset_iterations = s.iterations;
  return f;
}

// A grasp's arm error as V models it: a rotation R (rotation vector w, about the grasp's pivot
// c, the measured end effector) then a translation t: a point p of the grasp is explained at
// R (p - c) + c + t. Without rotations (rotation_sigma 0 or no pivots) R = I and c unused.
struct GraspOffset {
  Vec3 w = Vec3::Zero();
  Vec3 t = Vec3::Zero();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Vec3 apply(const Vec3& p, const Vec3& c) const { return R * (p - c) + c + t; }
};

Eigen::Matrix3d rotation_of(const Vec3& w) {
  const double a = w.norm();
  if (!(a > 1e-15)) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(a, w / a).toRotationMatrix();
}

// What one twin_score call reuses: each grasp's pivot, and its hand samples near enough to
// the hypothesis to matter (the rest are farther outside than any offset can bring them).
struct Model {
  bool rotate = false;
  bool legacy = true;                    // translation offsets by fit_grasp_offsets, no free term
  std::vector<Vec3> pivot;               // per grasp (zero without rotations)
  std::vector<std::vector<Vec3>> free;   // per grasp, the samples kept
};

Model model_of(const Scene& scene, const DistanceField& field, const Pose& T_so, const TwinSettings& s) {
  const GraspGroups& G = scene.grasps;
  Model m;
  m.rotate = s.rotation_sigma > 0.0 && G.pivots.size() == G.grasps();
  const bool use_free = s.free_sigma > 0.0 && !G.free.empty() && field.is_signed() &&
                        G.free_first.size() == G.first.size();
  m.legacy = !m.rotate && !use_free;
  if (m.legacy) return m;
  m.pivot.resize(G.grasps());
  m.free.resize(G.grasps());
  const Pose T_os = T_so.inverse();
  // Farther outside than this, no offset within its limits (3 sigma of translation, and of
  // rotation at a 25 cm lever, more than the hand's reach) and no refinement step brings a
  // sample inside.
  const double keep = 0.02 + 3.0 * s.offset_sigma + 3.0 * (s.rotation_sigma * std::numbers::pi / 180.0) * 0.25;
  std::vector<double> d;
  for (std::size_t k = 0; k < G.grasps(); ++k) {
    m.pivot[k] = m.rotate ? G.pivots[k] : Vec3(Vec3::Zero());   // without rotations R = I: unused
    if (!use_free) continue;
    const std::size_t n = G.free_first[k + 1] - G.free_first[k];
    d.resize(n);
    field.distances(G.free.data() + G.free_first[k], n, T_os, d.data());
    for (std::size_t j = 0; j < n; ++j)
      if (d[j] < keep) m.free[k].push_back(G.free[G.free_first[k] + j]);
  }
  return m;
}

struct TwinFit {
  std::vector<GraspOffset> offsets;
  double v = std::numeric_limits<double>::infinity();
};

// The fit's constants: inverse variances, caps and the contacts' gate (fit_all).
struct TwinTerms {
  TwinTerms(const TwinSettings& s, bool rotate)
      : inv_c(1.0 / (s.contact_sigma * s.contact_sigma)),
        inv_t(1.0 / (s.offset_sigma * s.offset_sigma)),
        sigma_r(s.rotation_sigma * std::numbers::pi / 180.0),
        inv_r(rotate ? 1.0 / (sigma_r * sigma_r) : 0.0),
        inv_f(s.free_sigma > 0.0 ? 1.0 / (s.free_sigma * s.free_sigma) : 0.0),
        max_t(3.0 * s.offset_sigma),
        max_w(3.0 * sigma_r),
        gate(max_t + 3.0 * s.contact_sigma),
        cap_c2(9.0 * s.contact_sigma * s.contact_sigma),
        cap_f(3.0 * s.free_sigma),
        dof(rotate ? 6 : 3) {}
  double inv_c, inv_t, sigma_r, inv_r, inv_f, max_t, max_w, gate, cap_c2, cap_f;
  int dof;
};

// Scratch of fit_all's grasps (reused between them).
struct TwinScratch {
  std::vector<Vec3> sub, q, g;
  std::vector<double> d;
};

// One grasp's offset (contacts p[0..n), its hand samples `free`, pivot c): Gauss-Newton in
// units of the contact noise: residuals d / contact_sigma, so the priors and the free samples
// weigh (contact_sigma / their sigma)^2.
GraspOffset fit_grasp(const Vec3* p, std::size_t n, const std::vector<Vec3>& free, const Vec3& c,
                      const DistanceField& field, const Pose& T_os, const Eigen::Matrix3d& R_so, const Model& m,
                      const TwinSettings& s, const TwinTerms& k, TwinScratch& w) {
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  const std::size_t ns = std::min(n, std::max<std::size_t>(s.fit_points, 3));
  w.sub.resize(ns);
  for (std::size_t j = 0; j < ns; ++j) w.sub[j] = p[j * n / ns];
  GraspOffset o;
  for (int it = 0; it < s.iterations; ++it) {
    Mat6 H = Mat6::Zero();
    Vec6 b = Vec6::Zero();
    auto add = [&](const Vec3& qi, const Vec3& grad, double di, double weight) {
      const double gn = grad.norm();
      if (!(gn > 0.5)) return;
      const Vec3 nrm = R_so * (grad / gn);
      Vec6 J;
      J.head<3>() = (qi - c - o.t).cross(nrm);   // the rotation turns R (p - c)
      J.tail<3>() = nrm;
      H.noalias() += weight * J * J.transpose();
      b.noalias() -= weight * J * di;
    };
    const std::size_t total = ns + free.size();
    w.q.resize(total);
    w.g.resize(total);
    w.d.resize(total);
    for (std::size_t j = 0; j < ns; ++j) w.q[j] = o.apply(w.sub[j], c);
    for (std::size_t j = 0; j < free.size(); ++j) w.q[ns + j] = o.apply(free[j], c);
    field.distances_gradients(w.q.data(), total, T_os, w.d.data(), w.g.data());
    for (std::size_t j = 0; j < ns; ++j)
      if (std::abs(w.d[j]) < k.gate) add(w.q[j], w.g[j], w.d[j], 1.0);
    for (std::size_t j = ns; j < total; ++j)   // one-sided: only samples inside pull
      if (w.d[j] < 0.0 && w.d[j] > -k.cap_f) add(w.q[j], w.g[j], w.d[j], s.contact_sigma * s.contact_sigma * k.inv_f);
    const double rho_r = s.contact_sigma * s.contact_sigma * k.inv_r;
    const double rho_t = s.contact_sigma * s.contact_sigma * k.inv_t;
    H.topLeftCorner<3, 3>() += (m.rotate ? rho_r : 1.0) * Eigen::Matrix3d::Identity();
    H.bottomRightCorner<3, 3>() += rho_t * Eigen::Matrix3d::Identity();
    b.head<3>() -= rho_r * o.w;
    b.tail<3>() -= rho_t * o.t;
    Vec6 step = Vec6::Zero();
    if (k.dof == 6) {
      step = H.ldlt().solve(b);
    } else {
      step.tail<3>() = H.bottomRightCorner<3, 3>().ldlt().solve(b.tail<3>());
    }
    if (!step.allFinite()) break;
    o.w += step.head<3>();
    o.t += step.tail<3>();
    if (o.w.norm() > k.max_w) o.w *= k.max_w / o.w.norm();
    if (o.t.norm() > k.max_t) o.t *= k.max_t / o.t.norm();
    o.R = rotation_of(o.w);
    if (step.tail<3>().norm() + step.head<3>().norm() * 0.1 < 1e-3 * s.contact_sigma) break;
  }
  return o;
}

// Every grasp's offset at object pose T_so, and V. Legacy: fit_grasp_offsets (translations,
// contacts only). Otherwise Gauss-Newton on each grasp's 3 or 6 offset parameters over its
// contacts within the gate, its hand samples inside the object (one-sided), and the priors.
TwinFit fit_all(const Scene& scene, const DistanceField& field, const Pose& T_so, const Model& m,
                const TwinSettings& s) {
  TwinFit out;
  const GraspGroups& G = scene.grasps;
  if (m.legacy) {
    const GraspFit fit = fit_grasp_offsets(scene, field, T_so, fit_settings_of(s));
    double prior = 0.0;
    out.offsets.resize(fit.offsets.size());
    for (std::size_t k = 0; k < fit.offsets.size(); ++k) {
      out.offsets[k].t = fit.offsets[k];
      prior += fit.offsets[k].squaredNorm();
    }
    // Written as before the new terms existed, so that the default V is the same to the bit.
    out.v = prior / (s.offset_sigma * s.offset_sigma) + fit.clamped_sq_sum / (s.contact_sigma * s.contact_sigma);
    return out;
  }
  const TwinTerms k(s, m.rotate);
  const Pose T_os = T_so.inverse();
  const Eigen::Matrix3d R_so = T_so.linear();
  TwinScratch w;
  double v = 0.0;
  out.offsets.resize(G.grasps());
  for (std::size_t g = 0; g < G.grasps(); ++g) {
    const Vec3* p = G.points.data() + G.first[g];
    const std::size_t n = G.first[g + 1] - G.first[g];
    const std::vector<Vec3>& free = m.free[g];
    const Vec3& c = m.pivot[g];
    const GraspOffset o = fit_grasp(p, n, free, c, field, T_os, R_so, m, s, k, w);
    // V's terms of this grasp: its prior, every contact (clamped), every kept hand sample.
    w.q.resize(n + free.size());
    w.d.resize(n + free.size());
    for (std::size_t j = 0; j < n; ++j) w.q[j] = o.apply(p[j], c);
    for (std::size_t j = 0; j < free.size(); ++j) w.q[n + j] = o.apply(free[j], c);
    field.distances(w.q.data(), w.q.size(), T_os, w.d.data());
    v += o.t.squaredNorm() * k.inv_t + o.w.squaredNorm() * k.inv_r;
    for (std::size_t j = 0; j < n; ++j) v += std::min(w.d[j] * w.d[j], k.cap_c2) * k.inv_c;
    for (std::size_t j = n; j < w.q.size(); ++j)
      if (w.d[j] < 0.0) v += std::pow(std::min(-w.d[j], k.cap_f), 2) * k.inv_f;
    out.offsets[g] = o;
  }
  out.v = v;
  return out;
}

// One Gauss-Newton step of the pose and the grasp offsets together, on
//     sum_i d_i^2 / contact_sigma^2 + sum_g |t_g|^2 / offset_sigma^2
// over the contacts within `gate` of the surface (d_i of contact i of grasp g shifted by t_g).
// The pose and the offsets' common part are told apart only by the prior, so they are solved
// jointly (each grasp's 3 x 3 block eliminated by its Schur complement); a pose step with the
// offsets held would leave the common part in the offsets. The offsets' rotations, when V
// models them, are held in this step (the next fit refits them). Returns the new T_scene_object (the
// input when the system is degenerate).
Pose joint_step(const Scene& scene, const DistanceField& field, const Pose& T_so,
                const std::vector<GraspOffset>& offsets, const Model& model, const TwinSettings& s) {
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
    for (std::size_t j = 0; j < m; ++j)
      q[j] = model.legacy ? Vec3(G.points[G.first[k] + j] + offsets[k].t)
                          : offsets[k].apply(G.points[G.first[k] + j], model.pivot[k]);
    field.distances_gradients(q.data(), m, T_os, d.data(), g.data());
    Mat63 B = Mat63::Zero();
    Eigen::Matrix3d D = rho * Eigen::Matrix3d::Identity();
    Vec3 b = -rho * offsets[k].t;
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
  const Model model = model_of(scene, geo.field, T_scene_object, s);
  Pose T = T_scene_object;
  TwinFit fit = fit_all(scene, geo.field, T, model, s);
  for (int it = 0; it < s.refine; ++it) {
    const Pose T_next = joint_step(scene, geo.field, T, fit.offsets, model, s);
    TwinFit next = fit_all(scene, geo.field, T_next, model, s);
    if (!(next.v < fit.v)) break;   // V never rises: the refinement only accepts improvements
    T = T_next;
    fit = std::move(next);
  }
  return fit.v;
}

}  // namespace recognition
}  // namespace ts
