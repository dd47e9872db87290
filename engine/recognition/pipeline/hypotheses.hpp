// The hypotheses a step works on, in the scene frame, and the operations every stage shares on
// them: the fixed order, ICP and the complete evaluation of a set in parallel, and the
// de-duplicating merge of the sequential filter. Internal to the recognizer's pipeline.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/evaluate.hpp"
#include "engine/recognition/icp.hpp"
#include "engine/recognition/ransac.hpp"
#include "engine/recognition/scene.hpp"

#include <cstdint>
#include <vector>

namespace ts::inline recognition::pipeline {

/// A hypothesis while a step works on it (scene frame).
struct Working {
  Candidate cand;        ///< object, T_scene_object, slot
  Evaluation eval;
  int born = 0;          ///< the step that made it
  int icp_iterations = 0;
  bool icp_converged = false;
};

/// The slot of the watched object's hypothesis at its true pose (diagnostics; above pose
/// transfer's kTransferSlot + object).
constexpr std::uint32_t kTruthSlot = 0xFFFFFFFFu;

/// Fixed total order: weight descending, then older first, then slot.
bool better(const Working& a, const Working& b);

/// The geometry of every object of `w`, loaded (and held) for the duration of a stage.
GeometryPins pin(const Database& db, const std::vector<Working>& w);

/// ICP of every hypothesis against its own object (Algorithm 1, line 4), in parallel.
void refine_all(const Scene& scene, const Database& db, const IcpSettings& s, std::vector<Working>& w);

/// Complete evaluation of every hypothesis (Algorithm 1, line 5), in parallel.
void evaluate_each(const Scene& scene, const Database& db, const EvaluateSettings& s,
                   std::vector<Working>& w);

/// Same object, poses within `distance` (m) and 2 degrees.
bool duplicates(const Working& a, const Working& b, double distance);

/// Append from `from` (sorted) to `into` until it holds `limit`, skipping duplicates if asked.
void take(std::vector<Working>& into, const std::vector<Working>& from, std::size_t limit,
          bool dedupe, double distance);

/// The scored candidates `top` (indices into `cands`) as hypotheses born at `born`.
std::vector<Working> from_scored(const std::vector<Candidate>& cands,
                                 const std::vector<ScoredCandidate>& top, int born);

}  // namespace ts::recognition::pipeline
