// Stage "select", the selection of batch-ransac (Section 4.3.2): every step on its own, the
// n_p best candidates by Eq. 5 (raw, unrefined), duplicates dropped with `dedupe`.
// Reads n_p, dedupe, dedupe_distance (m).
#include "engine/recognition/pipeline/stages.hpp"

#include <algorithm>

namespace ts::inline recognition::pipeline {

namespace {

class SelectBatch final : public Stage {
 public:
  std::string_view name() const override { return "select"; }

  void run(StepContext& c) const override {
    const RecognizerSettings& s = c.s;
    take(c.next, select_scored(c, c.cands, s.n_p, c.ev_raw), s.n_p, s.dedupe, s.dedupe_distance);
    std::sort(c.next.begin(), c.next.end(), better);
  }
};

}  // namespace

std::unique_ptr<const Stage> select_batch() { return std::make_unique<SelectBatch>(); }

}  // namespace ts::recognition::pipeline
