#include "engine/evaluate.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <functional>
#include <set>

namespace ts {

namespace {

/// Half extent of the object's box around its origin, slightly grown (free-space culling).
Vec3 half_extent_of(const ObjectInfo& info) {
  return 0.5 * info.extent.array() + 0.01 * info.extent.norm();
}

}  // namespace

Evaluation evaluate(const Scene& scene, const ObjectGeometry& geo, const ObjectInfo& info,
                    const Pose& T_scene_object, const EvaluateSettings& s, double reject_below) {
  const Vec3 half = half_extent_of(info);
  auto by_tree = [&](const Vec3* p, std::size_t n, const Pose& T, double* out) {
    for (std::size_t i = 0; i < n; ++i)
      out[i] = std::sqrt(geo.tree.nearest(T * p[i]).sq_distance);
  };
  if (!s.use_distance_field || geo.field.empty())
    return evaluate_batched(scene, by_tree, half, T_scene_object, s, reject_below);
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
  return evaluate_batched(scene, by_field, half, T_scene_object, s, reject_below);
}

namespace {

void preload(const Database& db, const std::vector<Candidate>& cands) {
  std::set<std::uint32_t> objects;
  for (const Candidate& c : cands) objects.insert(c.object);
  for (std::uint32_t o : objects) (void)db.geometry(o);  // ascending, one thread
}

template <class F>
void parallel_each(std::size_t n, F&& f) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 8),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
                    });
}

}  // namespace

std::vector<Evaluation> evaluate_all(const Scene& scene, const Database& db,
                                     const std::vector<Candidate>& cands,
                                     const EvaluateSettings& s) {
  preload(db, cands);
  std::vector<Evaluation> out(cands.size());
  parallel_each(cands.size(), [&](std::size_t i) {
    const Candidate& c = cands[i];
    out[i] = evaluate(scene, db.geometry(c.object), db.info(c.object), c.T_scene_object, s);
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
  preload(db, cands);
  auto eval = [&](std::size_t i, double reject_below) {
    const Candidate& c = cands[i];
    return evaluate(scene, db.geometry(c.object), db.info(c.object), c.T_scene_object, s,
                    reject_below);
  };
  constexpr double kInf = std::numeric_limits<double>::infinity();

  // Phase 1: the bound after the first prefix of the fixed evaluation order, for everyone.
  std::vector<Evaluation> ev(n);
  parallel_each(n, [&](std::size_t i) { ev[i] = eval(i, kInf); });

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
    parallel_each(end - pos, [&](std::size_t j) {
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

}  // namespace ts
