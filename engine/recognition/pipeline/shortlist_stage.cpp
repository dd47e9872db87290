// Stage "shortlist", a screening (extension for large databases): only the shortlisted objects'
// candidates go on (and those of the objects the previous state holds), so only their geometry
// is loaded. Reads ShortlistSettings (outlier_distance in m).
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

namespace ts::inline recognition::pipeline {

namespace {

class ShortlistStage final : public Stage {
 public:
  std::string_view name() const override { return "shortlist"; }

  std::string skip_reason(const StepContext& c) const override {
    if (!c.stop_early.empty()) return c.stop_early;
    if (c.s.shortlist.objects == 0) return "shortlist.objects = 0";
    if (c.db.size() <= c.s.shortlist.min_database) return small_database(c.db, "the shortlist", c.s.shortlist.min_database);
    return {};
  }

  void run(StepContext& c) const override {
    const auto t0 = detail::Clock::now();
    std::vector<std::uint32_t> held;
    for (const Hypothesis& h : c.previous) held.push_back(h.object);
    c.shortlist = shortlist_objects(c.scene, c.db, c.cands, held, c.s.shortlist);
    const Shortlist& sl = *c.shortlist;
    if (sl.active) {
      std::erase_if(c.cands, [&](const Candidate& k) { return !sl.mask[k.object]; });
      for (std::uint32_t o = 0; o < sl.mask.size(); ++o)
        if (sl.mask[o]) c.res.shortlist.push_back(o);
    }
    c.res.times.shortlist_s = detail::seconds_since(t0);
  }
};

}  // namespace

std::unique_ptr<const Stage> shortlist_stage() { return std::make_unique<ShortlistStage>(); }

}  // namespace ts::recognition::pipeline
