#include "engine/recognition/evaluate.hpp"
#include "engine/detail.hpp"

#include <Eigen/Eigenvalues>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <functional>
#include <set>

namespace ts {
inline namespace recognition {

namespace {

/// Half extent of the object's box around its origin, slightly grown (free-space culling).
Vec3 half_extent_of(const ObjectInfo& info) {
  return 0.5 * info.extent.array() + 0.01 * info.extent.norm();
}

}  // namespace

GraspFit fit_grasp_offsets(const Scene& scene, const DistanceField& field, const Pose& T_so,
                           const EvaluateSettings& s) {
  GraspFit fit;
  const GraspGroups& G = scene.grasps;
  if (G.grasps() == 0 || field.empty() || !T_so.matrix().allFinite()) return fit;
  const double sigma = s.grasp_offset_sigma;
  const double rho = sigma > 0.0 ? std::pow(s.grasp_contact_sigma / sigma, 2) : 0.0;
  const double max_offset = 3.0 * sigma;
  // Contacts farther than this from the surface are outliers to the fit (not to the score).
  const double gate = max_offset + 3.0 * s.grasp_contact_sigma;
  const Pose T_os = T_so.inverse();
  const Eigen::Matrix3d R_so = T_so.linear();
  std::vector<double> d;
  std::vector<Vec3> g, sub;
  double off2 = 0.0;
  fit.offsets.assign(G.grasps(), Vec3::Zero());
  for (std::size_t k = 0; k < G.grasps(); ++k) {
    const Vec3* p = G.points.data() + G.first[k];
    const std::size_t m = G.first[k + 1] - G.first[k];
    // The fit's subset: evenly spread over the grasp's list (pads, then sensels).
    const std::size_t ms = std::min(m, std::max<std::size_t>(s.grasp_fit_points, 3));
    sub.resize(ms);
    for (std::size_t j = 0; j < ms; ++j) sub[j] = p[j * m / ms];
    d.resize(m);
    g.resize(ms);
    Vec3 t = Vec3::Zero();
    for (int it = 0; sigma > 0.0 && it < s.grasp_offset_iterations; ++it) {
      // Distances of T_os (p + t) = T_os p + R_os t.
      Pose T = T_os;
      T.translation() += T_os.linear() * t;
      field.distances_gradients(sub.data(), ms, T, d.data(), g.data());
      Eigen::Matrix3d H = rho * Eigen::Matrix3d::Identity();
      Vec3 b = -rho * t;
      for (std::size_t i = 0; i < ms; ++i) {
        const double gn = g[i].norm();
        if (!(std::abs(d[i]) < gate) || !(gn > 0.5)) continue;
        const Vec3 J = R_so * (g[i] / gn);
        H.noalias() += J * J.transpose();
        b -= J * d[i];
      }
      const Vec3 step = H.ldlt().solve(b);
      if (!step.allFinite()) break;
      t += step;
      if (t.norm() > max_offset) t *= max_offset / t.norm();
      if (step.norm() < 1e-3 * s.grasp_contact_sigma) break;
    }
    Pose T = T_os;
    T.translation() += T_os.linear() * t;
    field.distances(p, m, T, d.data());
    const double clamp2 = 9.0 * s.grasp_contact_sigma * s.grasp_contact_sigma;
    for (std::size_t i = 0; i < m; ++i) {
      fit.error_sum += eq::contact_error(d[i], s.d_outlier, eq::background(s));
      fit.clamped_sq_sum += std::min(d[i] * d[i], clamp2);
      fit.far += d[i] * d[i] > clamp2 ? 1 : 0;
      fit.far10 += std::abs(d[i]) > 10.0 * s.grasp_contact_sigma ? 1 : 0;
    }
    fit.contacts += m;
    fit.offsets[k] = t;
    off2 += t.squaredNorm();
  }
  fit.offset_rms = std::sqrt(off2 / static_cast<double>(G.grasps()));
  return fit;
}

GraspDiagnostics grasp_diagnostics(const Scene& scene, const DistanceField& field, const Pose& T_so,
                                   const GraspFit& fit, const EvaluateSettings& s) {
  GraspDiagnostics out;
  const GraspGroups& G = scene.grasps;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  out.rms.assign(G.grasps(), nan);
  out.normal_angle.assign(G.grasps(), nan);
  if (field.empty() || !T_so.matrix().allFinite()) return out;
  const Pose T_os = T_so.inverse();
  const double clamp2 = 9.0 * s.grasp_contact_sigma * s.grasp_contact_sigma;
  std::vector<double> d;
  std::vector<Vec3> g;
  for (std::size_t k = 0; k < G.grasps(); ++k) {
    const Vec3* p = G.points.data() + G.first[k];
    const std::size_t m = G.first[k + 1] - G.first[k];
    if (m == 0) continue;
    const Vec3 t = k < fit.offsets.size() ? fit.offsets[k] : Vec3::Zero();
    Pose T = T_os;
    T.translation() += T_os.linear() * t;
    d.resize(m);
    g.resize(m);
    field.distances_gradients(p, m, T, d.data(), g.data());
    double sq = 0.0;
    Vec3 model = Vec3::Zero();
    for (std::size_t i = 0; i < m; ++i) {
      sq += std::min(d[i] * d[i], clamp2);
      const double gn = g[i].norm();
      if (gn > 0.5) {   // a gradient of a distance field has norm ~1 where it is defined
        const Vec3 u = g[i] / gn;
        model += model.dot(u) < 0.0 ? Vec3(-u) : u;   // sign-agnostic mean
      }
    }
    out.rms[k] = std::sqrt(sq / static_cast<double>(m));
    if (m < 6 || model.norm() < 1e-9) continue;
    // The patch's normal: the least eigenvector of its contacts' covariance, when the patch is
    // spread in two directions and flat in the third (else a line or blob has none).
    Vec3 c = Vec3::Zero();
    for (std::size_t i = 0; i < m; ++i) c += p[i];
    c /= static_cast<double>(m);
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (std::size_t i = 0; i < m; ++i) C.noalias() += (p[i] - c) * (p[i] - c).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(C);
    const Vec3 ev = eig.eigenvalues();
    if (!(ev(1) > 0.0) || ev(0) > 0.25 * ev(1)) continue;
    const Vec3 n_scene = eig.eigenvectors().col(0);
    const Vec3 n_model = T_so.linear() * model.normalized();   // to the scene frame
    out.normal_angle[k] = std::acos(std::clamp(std::abs(n_scene.dot(n_model)), 0.0, 1.0));
  }
  return out;
}

GraspFit contact_fit(const Scene& scene, const DistanceField& field, const Pose& T_so,
                     const EvaluateSettings& s) {
  if (s.grasp_offset_sigma > 0.0 && scene.grasps.grasps() > 0) return fit_grasp_offsets(scene, field, T_so, s);
  GraspFit fit;
  const std::vector<Vec3>& p = scene.contacts.points;
  if (p.empty() || field.empty() || !T_so.matrix().allFinite()) return fit;
  std::vector<double> d(p.size());
  field.distances(p.data(), p.size(), T_so.inverse(), d.data());
  const double clamp2 = 9.0 * s.grasp_contact_sigma * s.grasp_contact_sigma;
  for (double x : d) {
    fit.error_sum += eq::contact_error(x, s.d_outlier, eq::background(s));
    fit.clamped_sq_sum += std::min(x * x, clamp2);
    fit.far += x * x > clamp2 ? 1 : 0;
    fit.far10 += std::abs(x) > 10.0 * s.grasp_contact_sigma ? 1 : 0;
  }
  fit.contacts = p.size();
  return fit;
}

double sink_penalty(const Scene& scene, const ObjectGeometry& geo, const Pose& T) {
  const Scene::Floor& f = scene.floor;
  if (!f.on || !(f.cost > 0.0)) return 0.0;
  const Vec3 n_object = T.linear().transpose() * f.normal;
  double lowest = std::numeric_limits<double>::infinity();
  for (const Vec3& p : geo.extremes()) lowest = std::min(lowest, n_object.dot(p));
  if (!std::isfinite(lowest)) return 0.0;
  const double depth = f.offset - (lowest + f.normal.dot(T.translation()));
  if (!(depth > f.margin)) return 0.0;
  // The plane is this hypothesis's own face when it explains most of the plane's contacts.
  if (!f.on_plane.empty() && (!geo.field.empty() || !geo.fine.points.empty())) {
    std::vector<double> d(f.on_plane.size());
    const Pose T_object_scene = T.inverse();
    if (!geo.field.empty()) {
      geo.field.distances(f.on_plane.data(), f.on_plane.size(), T_object_scene, d.data());
    } else {
      for (std::size_t i = 0; i < d.size(); ++i)
        d[i] = std::sqrt(geo.tree.nearest(T_object_scene * f.on_plane[i]).sq_distance);
    }
    const auto own = std::count_if(d.begin(), d.end(), [&](double x) { return std::abs(x) < f.tolerance; });
    if (2 * static_cast<std::size_t>(own) > d.size()) return 0.0;
  }
  return f.cost * std::min(1.0, f.margin > 0.0 ? (depth - f.margin) / f.margin : 1.0);
}

namespace {

/// Eq. 4-9 less the floor term `sink` (sink_penalty).
Evaluation evaluate_terms(const Scene& scene, const ObjectGeometry& geo, const ObjectInfo& info,
                          const Pose& T_scene_object, const EvaluateSettings& s, double reject_below,
                          double sink) {
  const Vec3 half = half_extent_of(info);
  auto by_tree = [&](const Vec3* p, std::size_t n, const Pose& T, double* out) {
    for (std::size_t i = 0; i < n; ++i)
      out[i] = std::sqrt(geo.tree.nearest(T * p[i]).sq_distance);
  };
  if (!s.use_distance_field || geo.field.empty())
    return evaluate_batched(scene, by_tree, half, T_scene_object, s, reject_below, nullptr, sink);
  const double margin = geo.field.coarse_margin();
  // Beyond the coarse grid the field returns only a lower bound; Eq. 4 saturates at d_outlier,
  // so the bound is exact enough unless d_outlier exceeds the margin: then ask the k-d tree.
  const bool exact_far = s.d_outlier > margin;
  auto by_field = [&](const Vec3* p, std::size_t n, const Pose& T, double* out) {
    geo.field.distances(p, n, T, out);
    if (exact_far)
      for (std::size_t i = 0; i < n; ++i)
        if (std::abs(out[i]) >= margin) out[i] = std::sqrt(geo.tree.nearest(T * p[i]).sq_distance);
  };
  if (s.grasp_offset_sigma > 0.0 && scene.grasps.grasps() > 0) {  // needs the field's gradient
    const GraspFit fit = fit_grasp_offsets(scene, geo.field, T_scene_object, s);
    const ContactTerm term{fit.error_sum, fit.contacts};
    Evaluation ev = evaluate_batched(scene, by_field, half, T_scene_object, s, reject_below, &term, sink);
    ev.grasp_offset_rms = fit.offset_rms;
    return ev;
  }
  return evaluate_batched(scene, by_field, half, T_scene_object, s, reject_below, nullptr, sink);
}

}  // namespace

Evaluation evaluate(const Scene& scene, const ObjectGeometry& geo, const ObjectInfo& info,
                    const Pose& T_scene_object, const EvaluateSettings& s, double reject_below) {
  // The floor term only lowers ln wt: taken first, it tightens the early rejection.
  return evaluate_terms(scene, geo, info, T_scene_object, s, reject_below, sink_penalty(scene, geo, T_scene_object));
}

namespace {

GeometryPins pin(const Database& db, const std::vector<Candidate>& cands) {
  return GeometryPins(db, cands, [](const Candidate& c) { return c.object; });
}


}  // namespace

std::vector<Evaluation> evaluate_all(const Scene& scene, const Database& db,
                                     const std::vector<Candidate>& cands,
                                     const EvaluateSettings& s) {
  const GeometryPins geometry = pin(db, cands);
  std::vector<Evaluation> out(cands.size());
  detail::parallel_each(cands.size(), 8, [&](std::size_t i) {
    const Candidate& c = cands[i];
    out[i] = evaluate(scene, geometry[c.object], db.info(c.object), c.T_scene_object, s);
  });
  return out;
}

std::vector<ScoredCandidate> select_top(const Scene& scene, const Database& db,
                                        const std::vector<Candidate>& cands, std::size_t k,
                                        const EvaluateSettings& s, SelectStats* stats) {
  const std::size_t n = cands.size();
  SelectStats st;
  st.candidates = n;
  std::vector<ScoredCandidate> out;
  if (n == 0 || k == 0 || scene.contacts.empty()) {
    if (stats) *stats = st;
    return out;
  }
  const GeometryPins geometry = pin(db, cands);
  auto eval = [&](std::size_t i, double reject_below) {
    const Candidate& c = cands[i];
    return evaluate(scene, geometry[c.object], db.info(c.object), c.T_scene_object, s,
                    reject_below);
  };
  constexpr double kInf = std::numeric_limits<double>::infinity();

  // Phase 1: the bound after the first prefix of the fixed evaluation order, for everyone.
  std::vector<Evaluation> ev(n);
  detail::parallel_each(n, 8, [&](std::size_t i) { ev[i] = eval(i, kInf); });

  // Phase 2: best-first by bound, in fixed chunks. After each chunk the threshold tau is the
  // k-th best exact weight found so far, which the k-th best overall reaches; a candidate
  // whose bound is below tau cannot enter the top k. The chunks and thresholds do not depend
  // on the thread count, so neither does anything else.
  std::vector<std::uint32_t> idx(n);
  std::iota(idx.begin(), idx.end(), 0u);
  std::sort(idx.begin(), idx.end(), [&](std::uint32_t a, std::uint32_t b) {
    if (ev[a].log_weight != ev[b].log_weight) return ev[a].log_weight > ev[b].log_weight;
    return a < b;
  });
  const std::size_t chunk = std::max<std::size_t>(k, 64);
  double tau = -kInf;
  std::vector<double> best;  // exact weights found so far (for tau)
  for (std::size_t pos = 0; pos < n; pos += chunk) {
    if (ev[idx[pos]].log_weight < tau) break;  // sorted by bound: nobody further can enter
    const std::size_t end = std::min(n, pos + chunk);
    detail::parallel_each(end - pos, 8, [&](std::size_t j) {
      const std::uint32_t i = idx[pos + j];
      if (!ev[i].complete && ev[i].log_weight >= tau) ev[i] = eval(i, tau);
    });
    for (std::size_t j = pos; j < end; ++j)
      if (ev[idx[j]].complete) best.push_back(ev[idx[j]].log_weight);
    if (best.size() >= k) {
      std::nth_element(best.begin(), best.begin() + static_cast<std::ptrdiff_t>(k - 1), best.end(),
                       std::greater<double>());
      tau = std::max(tau, best[k - 1]);
      best.resize(k);
    }
  }
  st.threshold = tau;

  for (std::size_t i = 0; i < n; ++i) {
    if (ev[i].complete) {
      ++st.full;
      out.push_back({static_cast<std::uint32_t>(i), ev[i]});
    }
  }
  for (std::size_t i = 0; i < n; ++i)
    if (!ev[i].complete) {
      if (ev[i].contacts <= std::max<std::size_t>(1, s.prefix) && ev[i].contacts < scene.contacts.size())
        ++st.rejected_prefix;
      else ++st.rejected_later;
    }
  std::sort(out.begin(), out.end(), [](const ScoredCandidate& a, const ScoredCandidate& b) {
    if (a.eval.log_weight != b.eval.log_weight) return a.eval.log_weight > b.eval.log_weight;
    return a.index < b.index;
  });
  if (out.size() > k) out.resize(k);
  if (stats) *stats = st;
  return out;
}

}  // namespace recognition
}  // namespace ts
