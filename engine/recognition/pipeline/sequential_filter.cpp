// Stage "sequential_filter", the selection of bricpsf (Algorithm 1, lines 8-9): the best
// Psi n_p survivors, then (1-Psi) n_p new hypotheses from the sources' candidates (the best
// refine_pool by Eq. 6, refined by ICP with refine_new, re-evaluated, at most new_per_object of
// one object), then, if too few, the next-best survivors.
// Reads n_p, psi (share), refine_new, refine_pool, new_per_object, dedupe, dedupe_distance (m).
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

#include <algorithm>
#include <cmath>
#include <map>

namespace ts::inline recognition::pipeline {

namespace {

/// The new hypotheses' pool: the best `pool` candidates, refined and re-evaluated as asked, at
/// most new_per_object of one object.
std::vector<Working> fresh_hypotheses(StepContext& c, std::size_t pool) {
  const RecognizerSettings& s = c.s;
  std::vector<Working> fresh = select_scored(c, c.cands, pool, c.ev_raw);
  if (s.refine_new) {
    const auto t0 = detail::Clock::now();
    refine_all(c.scene, c.db, s.icp, fresh);
    c.res.times.icp_s += detail::seconds_since(t0);
  }
  if (s.refine_new || c.grasp_fit) {  // refined, or the offsets re-score them: evaluate again
    const auto t0 = detail::Clock::now();
    evaluate_each(c.scene, c.db, c.ev, fresh);
    c.res.times.evaluate_s += detail::seconds_since(t0);
    std::sort(fresh.begin(), fresh.end(), better);
  }
  if (s.new_per_object > 0) {   // diversity: at most new_per_object new hypotheses of one object
    std::map<std::uint32_t, std::size_t> count;
    std::vector<Working> capped;
    for (const Working& h : fresh)
      if (count[h.cand.object]++ < s.new_per_object) capped.push_back(h);
    fresh = std::move(capped);
  }
  return fresh;
}

class SequentialFilter final : public Stage {
 public:
  std::string_view name() const override { return "sequential_filter"; }

  void run(StepContext& c) const override {
    const RecognizerSettings& s = c.s;
    const std::size_t n_p = s.n_p;
    const auto k_old = std::min(c.old.size(), static_cast<std::size_t>(std::lround(s.psi * double(n_p))));
    take(c.next, c.old, k_old, s.dedupe, s.dedupe_distance);
    const std::size_t k_new = n_p - c.next.size();
    const std::size_t pool = std::max(s.refine_pool, s.dedupe || s.new_per_object > 0 ? 2 * k_new : k_new);
    take(c.next, fresh_hypotheses(c, pool), n_p, s.dedupe, s.dedupe_distance);
    if (c.next.size() < n_p) {   // too few new ones: the next-best survivors
      const std::vector<Working> rest(c.old.begin() + static_cast<std::ptrdiff_t>(k_old), c.old.end());
      take(c.next, rest, n_p, s.dedupe, s.dedupe_distance);
    }
    std::sort(c.next.begin(), c.next.end(), better);
  }
};

}  // namespace

std::unique_ptr<const Stage> sequential_filter() { return std::make_unique<SequentialFilter>(); }

}  // namespace ts::recognition::pipeline
