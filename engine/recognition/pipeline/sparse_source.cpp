// Stage "sparse", a candidate source: feature-free contact triplets matched on point-pair
// distances and angles (engine/recognition/sparse_hypotheses.hpp). Its candidates join
// RANSAC's. Reads SparseSettings (lengths in m, angles in degrees).
#include "engine/recognition/pipeline/stages.hpp"

#include <algorithm>

namespace ts::inline recognition::pipeline {

namespace {

/// The objects the source matches: the allowed ones; with the shape prior (large databases)
/// only the prior's best, since the pair tables (up to 2.9 MB an object) are built for the
/// objects matched and every object's would not fit (4 500 objects: about 13 GB).
std::vector<std::uint8_t> sparse_objects(const StepContext& c) {
  if (!c.prior) return c.allowed;
  std::vector<std::uint8_t> mask(c.allowed.size(), 0);
  for (std::size_t k = 0; k < std::min(c.preferred.size(), c.s.ransac.prior_draws); ++k) mask[c.preferred[k]] = 1;
  return mask;
}

class SparseSource final : public Stage {
 public:
  std::string_view name() const override { return "sparse"; }

  std::string skip_reason(const StepContext& c) const override {
    const SparseSettings& s = c.s.sparse;
    if (!c.stop_early.empty()) return c.stop_early;
    if (s.mode == kSparseNever) return "sparse.mode = never";
    const std::vector<std::uint8_t> mask = sparse_objects(c);
    if (std::find(mask.begin(), mask.end(), 1) == mask.end()) return "no object to match";
    if (!sparse_active(c.scene, s))
      return s.mode == kSparseAuto ? "too few isolated contacts (sparse.mode = auto)" : "fewer than 3 contacts";
    return {};
  }

  void run(StepContext& c) const override {
    if (!c.sparse_tables) c.sparse_tables = SparseTables::shared(c.db, c.s.sparse);
    SparseStats sp;
    const std::vector<Candidate> more =
        sparse_candidates(c.scene, *c.sparse_tables, sparse_contact_normals(c.scene, c.contacts(), c.s.sparse),
                          sparse_objects(c), c.s.sparse, c.s.seed, c.step_u(), &sp);
    c.cands.insert(c.cands.end(), more.begin(), more.end());
    c.res.sparse_active = true;
    c.res.sparse_candidates = sp.candidates;
    c.res.times.register_s += sp.time_s;
  }
};

}  // namespace

std::unique_ptr<const Stage> sparse_source() { return std::make_unique<SparseSource>(); }

}  // namespace ts::recognition::pipeline
