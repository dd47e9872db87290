// The recognizer's step as a pipeline of stages (after Open3D's registration pipeline and PCL's
// estimators and rejectors). A step's stages share one StepContext: the inputs, the scene, the
// candidates the sources propose, the hypotheses the selection keeps and the answer. Each stage
// says, from the context, whether the step needs it (skip_reason: empty, or why it is left out);
// the step records every stage's outcome and time (StepResult::stages). Observers see each
// stage before and after it and change nothing the step answers (diagnostics: the watched
// object's funnel, its true pose). A method is a list of stage names (compose.hpp).
//
// Internal to the recognizer: installed headers name only recognizer.hpp and the types it uses.
#pragma once

#include "engine/recognition/shape_prior.hpp"
#include "engine/recognition/pipeline/hypotheses.hpp"
#include "engine/recognition/settings.hpp"
#include "engine/recognition/shortlist.hpp"
#include "engine/recognition/sparse_hypotheses.hpp"
#include "engine/recognition/step_result.hpp"

#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace ts::inline recognition::pipeline {

/// The answer rule's outcome (answer.hpp): the chosen hypothesis (index into `next`), and when
/// the near-twin verification re-decided a near tie, the leaders it compared and their V.
struct AnswerRule {
  std::size_t chosen = 0;
  std::vector<std::size_t> leaders;
  std::vector<double> v;
};

/// Everything one step's stages read and write.
struct StepContext {
  // ---- inputs (the recognizer's, for the step's duration)
  const Database& db;
  const RecognizerSettings& s;
  const FeatureSearch& search;
  const ShapePrior* prior;                  ///< null: the shape prior does not act
  std::shared_ptr<SparseTables>& sparse_tables;  ///< taken when the sparse source first runs
  const std::vector<Hypothesis>& previous;  ///< S_{t-1}, world poses, best first
  const PointCloud& contacts_world;
  const std::vector<Vec3>& free_world;
  const GraspGroups& grasps;
  int step = 0;                             ///< 1-based
  StepResult& res;

  std::uint64_t step_u() const { return static_cast<std::uint64_t>(step); }

  // ---- the support (stage "support"): when it finds one, the contacts the step matches are
  // the inputs without the support's
  PointCloud object_contacts{};
  GraspGroups object_grasps{};
  const PointCloud& contacts() const { return res.support.found ? object_contacts : contacts_world; }
  const GraspGroups& grasp_groups() const { return res.support.found ? object_grasps : grasps; }

  // ---- the scene (stage "scene")
  Scene scene{};
  EvaluateSettings ev{};                    ///< the evaluation of refined hypotheses
  EvaluateSettings ev_raw{};                ///< of raw candidates: no per-grasp offsets
  bool grasp_fit = false;                   ///< per-grasp offsets re-score hypotheses
  std::vector<std::uint8_t> allowed{};      ///< objects that can span the contacts (and --only)

  // ---- candidate sources and screening
  std::vector<std::uint32_t> preferred{};   ///< objects best first by the shape prior
  double prior_s = 0.0;                     ///< s, the shape prior's ranking
  std::vector<Candidate> cands{};           ///< the sources' candidates, screened
  RansacStats rs{};
  std::optional<Shortlist> shortlist{};     ///< when the shortlist ran

  // ---- selection and the answer
  std::vector<Working> old{};               ///< the previous state's survivors, evolved
  std::vector<Working> next{};              ///< the new state, sorted by `better`
  std::vector<std::uint32_t> transfer_ranked{};  ///< pose transfer's screened objects, best first
  std::size_t transfer_kept = 0;            ///< ... of which the first this many were tried
  AnswerRule rule{};
  /// Set by stage "early_stop" when the survivors explain the step (why); the candidate sources
  /// and their screening are then left out with this reason.
  std::string stop_early{};

  /// Set by a stage when the rest of the step has nothing to work on (e.g. no contacts): the
  /// remaining stages are left out with this reason and the recognizer's state is kept.
  std::optional<std::string> finished{};
};

/// One stage: a candidate source, a screening, a refinement, an evaluation or a selection.
class Stage {
 public:
  virtual ~Stage() = default;
  virtual std::string_view name() const = 0;
  /// Why this step does not need the stage (empty: it runs).
  virtual std::string skip_reason(const StepContext&) const { return {}; }
  virtual void run(StepContext& c) const = 0;
};

/// Sees every stage of a step (before it and after it, ran or left out) and changes nothing the
/// step answers; may write diagnostics into c.res (e.g. c.res.watched).
class StepObserver {
 public:
  virtual ~StepObserver() = default;
  virtual void before(std::string_view /*stage*/, bool /*runs*/, StepContext& /*c*/) {}
  virtual void after(std::string_view /*stage*/, bool /*ran*/, StepContext& /*c*/) {}
};

using Pipeline = std::vector<std::unique_ptr<const Stage>>;

// ---- what several stages do ---------------------------------------------------------------

/// The k best of `cands` by the evaluation `e` (select_top: exact, with early rejection), as
/// hypotheses born this step; its time and counts go to c.res.
std::vector<Working> select_scored(StepContext& c, const std::vector<Candidate>& cands, std::size_t k,
                                   const EvaluateSettings& e);

/// ICP on every hypothesis of `w`, then the complete evaluation (c.ev), each timed into c.res.
void refine_and_evaluate(StepContext& c, std::vector<Working>& w);

/// "database of N objects (NAME acts above M)": the reason a large-database extension is left out.
std::string small_database(const Database& db, std::string_view what, std::size_t above);

/// Runs the stages in order, recording each one's outcome and time in c.res.stages. An
/// observer's exception, and a stage's other than an Error (which names its file and field),
/// comes out as an Error naming the stage (field "stage.NAME").
void run_pipeline(const Pipeline& stages, StepContext& c, std::span<StepObserver* const> observers);

}  // namespace ts::recognition::pipeline
