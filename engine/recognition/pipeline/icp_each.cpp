// Stage "icp_each", the selection of ransac-icp and ransac-icp-fs (Section 5.4): each RANSAC
// registration refined by ICP (with icp_top, only the best share by the raw score), then
// evaluated (Eq. 5, or Eq. 6 with free space), the n_p best kept.
// Reads icp_top (share), IcpSettings, n_p, dedupe, dedupe_distance (m).
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

#include <algorithm>
#include <cmath>

namespace ts::inline recognition::pipeline {

namespace {

class IcpEach final : public Stage {
 public:
  std::string_view name() const override { return "icp_each"; }

  void run(StepContext& c) const override {
    const RecognizerSettings& s = c.s;
    std::vector<Candidate> pool = c.cands;
    if (s.icp_top > 0.0 && s.icp_top < 1.0) {
      const auto k = static_cast<std::size_t>(std::ceil(s.icp_top * double(c.cands.size())));
      const std::vector<Working> pre = select_scored(c, c.cands, std::max(k, s.n_p), c.ev_raw);
      pool.clear();
      for (const Working& h : pre) pool.push_back(h.cand);
    }
    std::vector<Working> w(pool.size());
    for (std::size_t i = 0; i < pool.size(); ++i) w[i].cand = pool[i];
    const auto t0 = detail::Clock::now();
    refine_all(c.scene, c.db, s.icp, w);
    c.res.times.icp_s += detail::seconds_since(t0);
    std::vector<Candidate> refined(w.size());
    for (std::size_t i = 0; i < w.size(); ++i) refined[i] = w[i].cand;
    std::vector<Working> top = select_scored(c, refined, s.dedupe ? 4 * s.n_p : s.n_p, c.ev);
    for (Working& h : top)   // carry the ICP diagnostics over
      for (const Working& x : w)
        if (x.cand.slot == h.cand.slot) {
          h.icp_iterations = x.icp_iterations;
          h.icp_converged = x.icp_converged;
          break;
        }
    take(c.next, top, s.n_p, s.dedupe, s.dedupe_distance);
    std::sort(c.next.begin(), c.next.end(), better);
  }
};

}  // namespace

std::unique_ptr<const Stage> icp_each() { return std::make_unique<IcpEach>(); }

}  // namespace ts::recognition::pipeline
