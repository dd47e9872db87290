// Stage "pose_transfer", a candidate source (extension for large databases): the leader's pose
// is tried on the objects whose keypoints fit the contacts best there (among the shape prior's
// transfer_pool best, or all objects); refined and evaluated, they join the state on their
// merit (the weakest hypotheses make room). Reads TwinSettings (transfer, transfer_pool,
// transfer_min_database), ShortlistSettings (the screening), n_p, dedupe.
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

#include <algorithm>

namespace ts::inline recognition::pipeline {

namespace {

/// The objects that fit the contacts at the leader's pose, best first.
std::vector<std::uint32_t> screened_at_leader(const StepContext& c, const Working& lead) {
  std::vector<Candidate> probe;
  auto add_probe = [&](std::uint32_t o) {
    if (!c.allowed[o] || o == lead.cand.object) return;
    Candidate k = lead.cand;
    k.object = o;
    probe.push_back(k);
  };
  const TwinSettings& t = c.s.twins;
  if (c.prior && t.transfer_pool > 0 && !c.preferred.empty()) {   // the prior's best (any order)
    for (std::size_t k = 0; k < std::min(c.preferred.size(), t.transfer_pool); ++k) add_probe(c.preferred[k]);
  } else {
    for (std::uint32_t o = 0; o < c.db.size(); ++o) add_probe(o);
  }
  const std::vector<double> fit = screen_objects(c.scene, c.db, probe, c.s.shortlist, t.transfer);
  std::vector<std::uint32_t> order;
  for (const Candidate& k : probe)
    if (fit[k.object] < 1.0) order.push_back(k.object);
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return fit[a] != fit[b] ? fit[a] < fit[b] : a < b;
  });
  return order;
}

class PoseTransfer final : public Stage {
 public:
  std::string_view name() const override { return "pose_transfer"; }

  std::string skip_reason(const StepContext& c) const override {
    const TwinSettings& t = c.s.twins;
    if (t.transfer == 0) return "twins.transfer = 0";
    if (c.db.size() <= t.transfer_min_database) return small_database(c.db, "pose transfer", t.transfer_min_database);
    if (c.next.empty()) return "no hypothesis to transfer";
    return {};
  }

  void run(StepContext& c) const override {
    const auto t0 = detail::Clock::now();
    const Working lead = c.next.front();
    c.transfer_ranked = screened_at_leader(c, lead);
    c.transfer_kept = std::min(c.transfer_ranked.size(), c.s.twins.transfer);
    c.res.times.shortlist_s += detail::seconds_since(t0);
    std::vector<Working> moved;
    for (std::size_t k = 0; k < c.transfer_kept; ++k) {
      const std::uint32_t o = c.transfer_ranked[k];
      Working w = lead;
      w.cand.object = o;
      w.cand.slot = kTransferSlot + o;   // unique within the step
      w.born = c.step;
      moved.push_back(w);
    }
    if (moved.empty()) return;
    refine_and_evaluate(c, moved);
    std::vector<Working> all = c.next;
    all.insert(all.end(), moved.begin(), moved.end());
    std::stable_sort(all.begin(), all.end(), better);
    c.next.clear();
    take(c.next, all, c.s.n_p, c.s.dedupe, c.s.dedupe_distance);
  }
};

}  // namespace

std::unique_ptr<const Stage> pose_transfer_source() { return std::make_unique<PoseTransfer>(); }

}  // namespace ts::recognition::pipeline
