// Hypothesis evaluation (Section 4.3.2 "match evaluation" and Section 4.4 "Evaluate"):
//   e_cont(c) = min(1, (d_c / d_outlier)^2)                             (Eq. 4)
//   wt_cont   = prod_i exp(-e_cont(c_i) / C) = exp(-mean e_cont)         (Eq. 5, 7)
//   e_free(q) = (d_thresh^2 - d_q^2) / d_thresh^2 if d_q <= d_thresh, else 0   (Eq. 8)
//   wt_free   = prod_j exp(-lambda e_free(q_j))                          (Eq. 9)
//   wt        = wt_cont * wt_free                                       (Eq. 6)
// Weights are handled as logarithms (wt_free underflows for large free-space clouds).
// Extension, the background term (outlier_m > 0): d_c in Eq. 4 is counted at most outlier_m, so
// a contact that something else explains (the seabed, a neighbour) costs a bounded amount.
// Distances come from the object's distance field (O(1) per point); the paper's k-d tree
// nearest neighbour is available as an option. Without free-space data the free term is skipped.
//
// Extension, per-grasp offsets (grasp_offset_sigma > 0 and a scene with grasp groups): the arm
// pose error moves all contacts of one grasp together, by millimetres, which Eq. 4 cannot tell
// from a shape mismatch. Each grasp's contacts get the translation t_g that best fits them to
// the object under the hypothesis (Gauss-Newton on the distance field, Gaussian prior of
// grasp_offset_sigma per axis, |t_g| <= 3 sigma), and Eq. 4 is applied to the shifted contacts.
// The true object then fits to the contact noise while a look-alike keeps its shape error. The
// free-space term is unchanged.
//
// Early rejection, exact: the contact term only decreases as points are added, so after a
// prefix of the scene's fixed evaluation order, -sum(e)/C bounds ln wt from above. A hypothesis
// whose bound falls below a threshold that k fully evaluated hypotheses already reach cannot be
// in the top k; select_top() uses this without changing the ranking.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ts {
inline namespace recognition {

struct EvaluateSettings {
  double d_outlier = 0.20;            ///< m, outlier distance of Eq. 4 (paper: 20 cm)
  double outlier_m = 0.0;             ///< m, extension, the background term: a contact farther
                                      ///< than this from the object costs what one at this
                                      ///< distance does, as something else (the seabed, a
                                      ///< neighbour) may have been touched (0: off, Eq. 4 alone)
  bool free_space = true;             ///< Eq. 6 (contact x free space); false: Eq. 5 only
  double lambda = 0.02;               ///< Eq. 9 weight of free space (paper: 0.02)
  double res_free = 0.04;             ///< m, free-space resolution; d_thresh = res_free / 2
  double d_thresh = 0.0;              ///< m, Eq. 8 threshold if > 0 (overrides res_free / 2)
  double free_inside_margin = 0.0;    ///< m; that penalty only deeper than this (a probe's
                                      ///< path, free by its ball radius and measured with the
                                      ///< arm's error, can graze the true surface)
  bool free_inside_penalty = false;   ///< extension: a free point inside a closed object
                                      ///< (signed field < 0) costs e = 1 however deep
  bool use_distance_field = true;     ///< false: nearest fine-cloud point (paper's k-d tree)
  /// Contacts in the first rejection test (and per chunk). Speed only: select_top's ranking is
  /// exact for any value. 8 rather than 32: the first phase bounds every candidate (thousands a
  /// step) and a looser bound costs less than reading 32 contacts of each (CHANGELOG).
  std::size_t prefix = 8;
  std::size_t free_prefix = 128;      ///< free-space points in the first rejection test
  double grasp_offset_sigma = 0.0;    ///< m, extension: prior sigma (per axis) of a per-grasp
                                      ///< translation fitted before Eq. 4 (0: off; needs the
                                      ///< scene's grasp groups and a distance field)
  double grasp_contact_sigma = 0.001; ///< m, contact noise assumed by that fit: the prior
                                      ///< weighs (contact / offset sigma)^2 against each contact
  int grasp_offset_iterations = 2;    ///< Gauss-Newton iterations of that fit (at most)
  std::size_t grasp_fit_points = 16;  ///< contacts per grasp the fit uses (evenly spread over
                                      ///< the grasp's list; Eq. 4 then takes them all)
};

struct Evaluation {
  double log_weight = -std::numeric_limits<double>::infinity();  ///< ln wt; a bound if !complete
  double contact_error = 0.0;         ///< mean e_cont over the evaluated contacts
  double free_error = 0.0;            ///< sum of e_free over the evaluated free points
  std::uint32_t contacts = 0;         ///< contacts evaluated
  std::uint32_t free_points = 0;      ///< free points near enough to need a distance
  double grasp_offset_rms = 0.0;      ///< m, RMS length of the per-grasp offsets (when fitted)
  double sink_penalty = 0.0;          ///< ln wt lost to the floor term (sink_penalty), included
                                      ///< in log_weight
  bool complete = false;              ///< false: stopped early (log_weight is an upper bound)
};

/// The floor term (scene.floor on): how deep `T_scene_object` puts the object's lowest point
/// (ObjectGeometry::extremes) below the floor, d; 0 up to the floor's margin m, then
/// cost * min(1, (d - m) / m): the object never lies below its support, while the plane found
/// from a few grasps under the arm's error is tilted by a few degrees and off by millimetres.
/// 0 when the floor is off, and when more than half of the floor's `on_plane` contacts lie
/// within its tolerance of the object at that pose (the plane is then the object's own face,
/// which the support stage can take for a support when the object was touched from one side).
double sink_penalty(const Scene& scene, const ObjectGeometry& geometry, const Pose& T_scene_object);

/// A pose hypothesis for one object, in the scene frame.
struct Candidate {
  std::uint32_t object = 0;
  Pose T_scene_object = Pose::Identity();
  std::uint32_t slot = 0;             ///< provenance (triplet * R + registration, or index)
};

struct ScoredCandidate {
  std::uint32_t index = 0;            ///< into the candidate list
  Evaluation eval;
};

/// Evaluate one hypothesis. Stops (complete = false) as soon as the upper bound of ln wt
/// drops below `reject_below`.
Evaluation evaluate(const Scene& scene, const ObjectGeometry& geometry, const ObjectInfo& info,
                    const Pose& T_scene_object, const EvaluateSettings& settings,
                    double reject_below = -std::numeric_limits<double>::infinity());

/// The contact term with per-grasp offsets (see above).
struct GraspFit {
  double error_sum = 0.0;             ///< sum of Eq. 4 over the shifted contacts
  std::size_t contacts = 0;           ///< contacts of all grasps
  double offset_rms = 0.0;            ///< m, RMS of |t_g| over the grasps
  std::vector<Vec3> offsets;          ///< t_g per grasp, scene frame
  double clamped_sq_sum = 0.0;        ///< m^2, sum over the shifted contacts of
                                      ///< min(d^2, (3 grasp_contact_sigma)^2)
  std::size_t far = 0;                ///< shifted contacts farther than 3 grasp_contact_sigma
  std::size_t far10 = 0;              ///< ... farther than 10 grasp_contact_sigma
};
GraspFit fit_grasp_offsets(const Scene& scene, const DistanceField& field, const Pose& T_scene_object,
                           const EvaluateSettings& settings);

/// The same fit as an absolute measure of how well a hypothesis explains every contact: with
/// grasp groups and grasp_offset_sigma > 0, fit_grasp_offsets; otherwise the scene's contacts
/// unshifted (offsets empty, offset_rms 0). far/far10/clamped_sq_sum use grasp_contact_sigma.
GraspFit contact_fit(const Scene& scene, const DistanceField& field, const Pose& T_scene_object,
                     const EvaluateSettings& settings);

/// Per-grasp view of a fit (the open-set features of AnswerFit): how well each grasp's patch
/// is explained once shifted by its offset of `fit` (offsets empty: unshifted).
struct GraspDiagnostics {
  std::vector<double> rms;            ///< m, RMS distance of the grasp's shifted contacts, each
                                      ///< clamped to 3 grasp_contact_sigma (NaN: no contacts)
  std::vector<double> normal_angle;   ///< rad, angle between the patch's normal (PCA of its
                                      ///< contacts) and the model's mean surface normal there,
                                      ///< sign-agnostic, in [0, pi/2] (NaN: the patch has fewer
                                      ///< than 6 contacts, is not flat enough to have a normal,
                                      ///< or the field has no gradient there)
};
GraspDiagnostics grasp_diagnostics(const Scene& scene, const DistanceField& field, const Pose& T_scene_object,
                                   const GraspFit& fit, const EvaluateSettings& settings);

/// A contact term computed beforehand (sum of Eq. 4 over n contacts).
struct ContactTerm {
  double sum = 0.0;
  std::size_t n = 0;
};

/// The same over any batch distance function `fn(const Vec3* pts, std::size_t n,
/// const Pose& T_object_pts, double* out)` giving signed (or unsigned) distances of T * pts[i].
/// `floor_penalty` (the floor term, sink_penalty) is part of ln wt from the start, so every
/// rejection test and the bound count it.
template <class BatchFn>
Evaluation evaluate_batched(const Scene& scene, const BatchFn& distances, const Vec3& half_extent,
                            const Pose& T_scene_object, const EvaluateSettings& settings,
                            double reject_below = -std::numeric_limits<double>::infinity(),
                            const ContactTerm* contact_term = nullptr, double floor_penalty = 0.0);

/// The same, with any signed distance function of object-frame points (tests, oracles):
/// `distance(p_object)` returns the signed distance to the surface (negative inside, or
/// unsigned). `half_extent` bounds the object around its origin (free-space culling).
template <class DistanceFn>
Evaluation evaluate_with(const Scene& scene, const DistanceFn& distance, const Vec3& half_extent,
                         const Pose& T_scene_object, const EvaluateSettings& settings,
                         double reject_below = -std::numeric_limits<double>::infinity());

struct SelectStats {
  std::size_t candidates = 0;
  std::size_t full = 0;               ///< evaluated completely
  std::size_t rejected_prefix = 0;    ///< rejected after the first prefix
  std::size_t rejected_later = 0;     ///< rejected part-way
  double threshold = 0.0;             ///< the ln wt threshold used
};

/// The k best candidates by ln wt (ties: smaller index first), each completely evaluated, in
/// descending order; exact (the same as evaluating everything), deterministic and parallel.
/// Geometry is loaded (serially, ascending object order) only for objects in `candidates`.
std::vector<ScoredCandidate> select_top(const Scene& scene, const Database& db,
                                        const std::vector<Candidate>& candidates, std::size_t k,
                                        const EvaluateSettings& settings,
                                        SelectStats* stats = nullptr);

/// Evaluate every candidate completely (no rejection), in parallel; results in input order.
std::vector<Evaluation> evaluate_all(const Scene& scene, const Database& db,
                                     const std::vector<Candidate>& candidates,
                                     const EvaluateSettings& settings);

// ---- implementation of the template -------------------------------------------------------

namespace eq {   // Eq. 4 and Eq. 8 per point
/// Eq. 4, with the background term: |d| counted at most `background` (> 0; infinite: off).
inline double contact_error(double d, double d_outlier, double background) {
  d = std::min(std::abs(d), background);
  if (!(d < d_outlier)) return 1.0;
  const double x = d / d_outlier;
  return x * x;
}
/// The background distance of `s` for contact_error (infinite when the term is off).
inline double background(const EvaluateSettings& s) {
  return s.outlier_m > 0.0 ? s.outlier_m : std::numeric_limits<double>::infinity();
}
inline double free_error(double d, double d_thresh, bool inside_penalty, double margin = 0.0) {  // Eq. 8
  if (inside_penalty && d < -margin) return 1.0;
  d = std::abs(d);
  if (!(d <= d_thresh)) return 0.0;
  return (d_thresh * d_thresh - d * d) / (d_thresh * d_thresh);
}
}  // namespace eq

template <class BatchFn>
Evaluation evaluate_batched(const Scene& scene, const BatchFn& distances, const Vec3& half_extent,
                            const Pose& T_scene_object, const EvaluateSettings& s,
                            double reject_below, const ContactTerm* given, double floor_penalty) {
  Evaluation ev;
  const std::size_t C = given ? given->n : scene.contacts.size();
  if (C == 0 || (!given && scene.ordered.size() != C) || !T_scene_object.matrix().allFinite())
    return ev;
  const Pose T_object_scene = T_scene_object.inverse();
  const double invC = 1.0 / static_cast<double>(C);
  constexpr std::size_t kMax = 64;
  const std::size_t chunk = std::clamp<std::size_t>(s.prefix, 1, kMax);
  // reject_below = +inf asks for the bound from the prefixes only (select_top's first phase).
  const bool bound_only = reject_below == std::numeric_limits<double>::infinity();
  double buf[kMax];
  const double background = eq::background(s);

  // Contact term (Eq. 4, 5/7), in the scene's fixed pseudo-random order; with the floor term.
  double sum = given ? given->sum : 0.0;
  std::size_t nc = given ? C : 0;
  auto contact_part = [&](Evaluation& e) {
    e.contacts = static_cast<std::uint32_t>(nc);
    e.contact_error = sum / static_cast<double>(nc);
    e.log_weight = -sum * invC - floor_penalty;
    e.sink_penalty = floor_penalty;
    return e;
  };
  const std::size_t c_limit = bound_only ? std::min(C, chunk) : C;
  while (nc < c_limit) {
    const std::size_t m = std::min(chunk, c_limit - nc);
    distances(scene.ordered.data() + nc, m, T_object_scene, buf);
    for (std::size_t j = 0; j < m; ++j) sum += eq::contact_error(buf[j], s.d_outlier, background);
    nc += m;
    if (!bound_only && nc < C && -sum * invC - floor_penalty < reject_below) return contact_part(ev);
  }
  contact_part(ev);
  bool partial = nc < C;

  // Free-space term (Eq. 8, 9): points farther than d_thresh from the object's box cost 0 and
  // need no distance.
  if (s.free_space && scene.has_free_space() && s.lambda > 0.0) {
    const double d_thresh = s.d_thresh > 0.0 ? s.d_thresh : 0.5 * s.res_free;
    const Eigen::Array3d lim = half_extent.array() + d_thresh;
    const Pose I = Pose::Identity();
    const std::size_t Q = scene.free_space.size();
    const std::size_t q_limit = bound_only ? std::min(Q, s.free_prefix) : Q;
    Vec3 near[kMax];
    double fsum = 0.0;
    std::uint32_t count = 0;
    std::size_t k = 0;
    auto flush = [&] {
      distances(near, k, I, buf);
      for (std::size_t j = 0; j < k; ++j)
        fsum += eq::free_error(buf[j], d_thresh, s.free_inside_penalty, s.free_inside_margin);
      count += static_cast<std::uint32_t>(k);
      k = 0;
    };
    for (std::size_t q = 0; q < q_limit; ++q) {
      const Vec3 y = T_object_scene * scene.free_space[q];
      if ((y.array().abs() > lim).any()) continue;
      near[k++] = y;
      if (k == chunk) {
        flush();
        if (!bound_only && ev.log_weight - s.lambda * fsum < reject_below) {
          ev.free_points = count;
          ev.free_error = fsum;
          ev.log_weight -= s.lambda * fsum;
          return ev;
        }
      }
    }
    if (k > 0) flush();
    ev.free_points = count;
    ev.free_error = fsum;
    ev.log_weight -= s.lambda * fsum;
    partial = partial || q_limit < Q;
  }
  ev.complete = !partial;
  return ev;
}

template <class DistanceFn>
Evaluation evaluate_with(const Scene& scene, const DistanceFn& distance, const Vec3& half_extent,
                         const Pose& T_scene_object, const EvaluateSettings& s,
                         double reject_below) {
  auto batch = [&](const Vec3* p, std::size_t n, const Pose& T, double* out) {
    for (std::size_t i = 0; i < n; ++i) out[i] = distance(Vec3(T * p[i]));
  };
  return evaluate_batched(scene, batch, half_extent, T_scene_object, s, reject_below);
}

}  // namespace recognition
}  // namespace ts
