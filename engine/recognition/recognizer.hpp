// Sequential object recognition and 6-DOF localization (Section 4.4): BRICPSF, Batch RANSAC
// with ICP and Free Space, and its ablations, as one code path.
//
//   batch-ransac   Section 4.3.2: every step on its own; hypotheses scored by Eq. 5.
//   ransac-icp     Section 5.4: every RANSAC hypothesis refined by ICP, scored by Eq. 5.
//   ransac-icp-fs  Section 5.4: as ransac-icp, scored by Eq. 6 (contact x free space).
//   bricpsf        Algorithm 1: the n_p hypotheses of the previous step are refined by ICP and
//                  re-evaluated (Eq. 6); Batch RANSAC proposes new ones (Eq. 6); the best
//                  Psi*n_p old and (1-Psi)*n_p new form the new state. A hypothesis keeps its
//                  object for life.
//
// A step takes the cumulative contact and free-space clouds in world coordinates; all work is
// done in a frame centred on the contacts, and poses are reported as T_world_object.
// Deterministic for a seed and any thread count (the caller's task arena decides the threads).
#pragma once

#include "engine/database/database.hpp"
#include "engine/features/shape_prior.hpp"
#include "engine/recognition/evaluate.hpp"
#include "engine/recognition/icp.hpp"
#include "engine/recognition/ransac.hpp"
#include "engine/recognition/scene.hpp"
#include "engine/recognition/shortlist.hpp"
#include "engine/recognition/sparse_hypotheses.hpp"
#include "engine/recognition/twins.hpp"

#include <limits>
#include <memory>
#include <optional>
#include <string_view>

namespace ts {

enum class Method { batch_ransac, ransac_icp, ransac_icp_fs, bricpsf };
std::string_view method_name(Method m);                  ///< "bricpsf", "batch-ransac", ...
std::optional<Method> parse_method(std::string_view name);

struct RecognizerSettings {
  Method method = Method::bricpsf;
  std::size_t n_p = 100;            ///< hypotheses kept per step (Section 5.5: 100)
  double psi = 0.8;                 ///< share of evolved old hypotheses in resampling (0.8)
  bool refine_new = false;          ///< extension: ICP on the new RANSAC hypotheses chosen in
                                    ///< resampling before they join (bricpsf)
  std::size_t refine_pool = 0;      ///< extension: best RANSAC candidates considered for the
                                    ///< (1-Psi) n_p new ones (refined first with refine_new);
                                    ///< 0: (1-Psi) n_p, or twice that with dedupe or a cap
  std::size_t new_per_object = 0;   ///< extension: at most this many new hypotheses of one
                                    ///< object per step (0: no cap)
  bool dedupe = false;              ///< extension: drop hypotheses that duplicate a better one
                                    ///< (same object, pose within dedupe_distance / 2 degrees)
  double dedupe_distance = 0.002;   ///< m
  double icp_top = 0.0;             ///< ransac-icp(-fs): ICP only the best share of candidates
                                    ///< by pre-ICP score (0: all, as in the paper)
  std::uint64_t seed = 1;           ///< every random draw derives from (seed, step, task)
  std::vector<std::uint8_t> objects;  ///< objects the recognizer may answer (1 = yes), by
                                      ///< database index; empty: all
  ShortlistSettings shortlist;      ///< extension: objects whose candidates are evaluated in full
                                    ///< per step (large databases)
  TwinSettings twins;               ///< extension: near-twin verification of the leading objects
  ShapePriorSettings prior;         ///< extension: the shape prior that ranks the objects
                                    ///< for feature pruning (ransac.prior_draws > 0)
  std::size_t prior_min_database = 0;  ///< the shape prior acts only on databases of more
                                       ///< objects than this
  SparseSettings sparse;            ///< extension: feature-free triplet matching when the
                                    ///< contacts are isolated (touch probes; sparse_hypotheses.hpp)
  SceneSettings scene{.free_clearance = -1.0};  ///< free_clearance < 0: d_thresh (Eq. 8)
  RansacSettings ransac;
  IcpSettings icp;
  EvaluateSettings evaluate;
  FeatureIndexSettings index;

  /// Every length multiplied by `factor` (objects of another size scale).
  RecognizerSettings scaled(double factor) const;

  /// The paper's method (the defaults): Section 4.3-4.4 and 5.5 parameters, no extensions.
  static RecognizerSettings paper();
  /// The paper's method with Touchstone's extensions for accuracy: free space inside a closed
  /// object is penalized, duplicate hypotheses are dropped, the best 60 RANSAC candidates are
  /// refined by ICP before the (1-Psi) n_p new ones are chosen, at most 5 of them per object,
  /// and feature pruning keeps the 200 nearest features of every object (not 3000 overall).
  /// Measured on simulated underwater logs of the 45 objects at step 20: see docs/results/
  /// (bench_recognize; the history in CHANGELOG.md).
  static RecognizerSettings improved();
};

/// Slots of hypotheses made by pose transfer (TwinSettings::transfer): kTransferSlot + object,
/// apart from RANSAC's triplet * R + r.
constexpr std::uint32_t kTransferSlot = 0x80000000u;

struct Hypothesis {
  std::uint32_t object = 0;
  Pose pose = Pose::Identity();     ///< T_world_object
  double log_weight = -std::numeric_limits<double>::infinity();  ///< ln wt (Eq. 5 or 6)
  double weight = 0.0;              ///< wt = exp(log_weight)
  int born = 0;                     ///< step that created it
  std::uint32_t slot = 0;           ///< RANSAC slot that created it (triplet * R + r), or
                                    ///< kTransferSlot + object for a pose transfer
  int icp_iterations = 0;           ///< of the last refinement (0: none)
  bool icp_converged = false;
};

struct StageTimes {
  double prepare_s = 0.0;           ///< normals, FPFH, interior points of the contacts
  double shortlist_s = 0.0;         ///< screening the candidates for the object shortlist
  double prune_s = 0.0;             ///< triplet sampling + W-nearest feature queries (and the
                                    ///< shape prior that chooses the objects searched)
  double register_s = 0.0;          ///< triplet registrations (Kabsch)
  double icp_s = 0.0;               ///< ICP of hypotheses
  double evaluate_s = 0.0;          ///< Eq. 4-9 (with early rejection)
  double total_s = 0.0;
};

/// Where one watched object stood in a step's search (Recognizer::watch; diagnostics, e.g. the
/// explored object of a simulated run: was it lost to the search or to the evaluation?).
struct Funnel {
  bool searched = false;          ///< some RANSAC triplet's pruning searched its features
  std::size_t candidates = 0;     ///< RANSAC registrations on it
  bool shortlisted = false;       ///< some of them went on to ICP and evaluation
  bool transferred = false;       ///< pose transfer moved the leader's pose onto it
  double screen_score = -1.0;     ///< the shortlist's screening score of its best candidate
                                  ///< (lower is better; -1: no candidate or no shortlist)
  double screen_cut = -1.0;       ///< the score the shortlist's last kept object reached
  std::size_t screen_rank = 0;    ///< rank (1 = best) of its best candidate among the objects'
                                  ///< best (0: no candidate or no shortlist)
  std::size_t prior_rank = 0;     ///< its rank (1 = best) by the shape prior (0: no prior)
  std::size_t transfer_rank = 0;  ///< its rank (1 = best) in pose transfer's screening at the
                                  ///< leader's pose; 0: not screened or no fit
  std::size_t hypotheses = 0;     ///< its hypotheses in the state after the step
  /// At its true pose (Recognizer::watch with a pose; diagnostics): the watched object's
  /// hypothesis made from the true pose, refined by the step's ICP and evaluated by its Eq. 6
  /// (as the state's hypotheses are: batch-ransac neither refines nor takes the grasp offsets),
  /// then put beside the state through the step's answer rule (the best ln wt, near ties
  /// re-decided by the near-twin score V). `truth_pose_wins`: the step named the watched object,
  /// or the rule would with this hypothesis added (the answer a perfect search could give with
  /// this evidence and this rule); otherwise the evidence favours another object even against
  /// the true pose.
  bool truth_pose_evaluated = false;
  bool truth_pose_wins = false;
  double truth_pose_log_weight = -std::numeric_limits<double>::infinity();  ///< its ln wt
  double answer_log_weight = -std::numeric_limits<double>::infinity();      ///< the answer's
  /// V (twins.hpp) of the watched object's leading hypothesis (this one, or a better one of its
  /// own in the state) and the lowest of the other leading objects' when the rule compared them
  /// (+inf: not compared)
  double truth_pose_twin_score = std::numeric_limits<double>::infinity();
  double rival_twin_score = std::numeric_limits<double>::infinity();  ///< lowest V of the others
  /// Time of all the watch's diagnostics (the shortlist's full screening, the true pose): not
  /// in the step's stage times or its total_s. Watching changes no hypothesis, weight or
  /// answer; the geometry counters and the cache's eviction order may differ.
  double diagnostic_s = 0.0;
};

/// How well the answer (the best hypothesis) explains all the evidence in absolute terms: its
/// contacts' distances to the model after the per-grasp offsets against the assumed contact
/// noise (evaluate.grasp_contact_sigma), and the free space it conflicts with. Features of the
/// open-set ("in the database") score (experiments/analysis/calibration.hpp).
struct AnswerFit {
  bool valid = false;               ///< computed (a valid answer with a distance field)
  std::size_t contacts = 0;
  double rms_sigma = 0.0;           ///< RMS distance, each clamped to 3 sigma, in sigmas
  double far_share = 0.0;           ///< share of contacts farther than 3 sigma
  double far10_share = 0.0;         ///< share of contacts farther than 10 sigma
  double offset_rms_sigma = 0.0;    ///< RMS per-grasp offset / grasp_offset_sigma (0: no offsets)
  double free_conflict = 0.0;       ///< Eq. 8 error summed over the free points, per free point
  // Per grasp (grasp_diagnostics; 0 without grasp groups):
  double worst_grasp_sigma = 0.0;   ///< largest RMS distance of one grasp's contacts (clamped to
                                    ///< 3 sigma) in sigmas: the grasp the answer explains worst
  double normal_rms_deg = 0.0;      ///< RMS over the grasps of the angle between the patch's
                                    ///< normal and the model's (each clamped to 30 degrees)
  double normal_worst_deg = 0.0;    ///< the largest of those angles (clamped likewise)
};

struct StepResult {
  int step = 0;                     ///< 1-based
  bool valid = false;               ///< there is at least one hypothesis
  Hypothesis best;                  ///< the hypothesis with the largest weight
  double posterior = 0.0;           ///< posterior of best.object
  std::vector<Hypothesis> hypotheses;  ///< the state S_t, best first
  std::vector<double> posteriors;   ///< per database object: weights summed, normalized
  std::size_t contacts = 0, free_points = 0;
  int unobservable_dof = 6;         ///< pose DOF the contacts leave unconstrained (flat: 3)
  bool pose_ambiguous = true;       ///< unobservable_dof > 0: do not trust the pose
  std::size_t candidates = 0;       ///< RANSAC registrations this step
  std::size_t evaluated_full = 0;   ///< candidates evaluated completely
  std::size_t rejected_early = 0;   ///< candidates rejected by the exact bound
  std::size_t objects_allowed = 0;  ///< objects large enough to span the contacts
  std::size_t objects_reached = 0;  ///< objects with at least one RANSAC candidate
  std::vector<std::uint32_t> shortlist;  ///< objects whose candidates went on, when a shortlist
                                         ///< left some out (empty otherwise)
  std::size_t geometry_loads = 0;   ///< geometry loads of the database so far (reloads counted)
  std::size_t geometry_resident = 0;  ///< objects whose geometry is in memory after the step
  bool boundary_fallback = false;   ///< triplets had to use patch-boundary points
  bool sparse_active = false;       ///< the sparse-contact source ran (isolated contacts)
  std::size_t sparse_candidates = 0;  ///< its candidates (beside RANSAC's `candidates`)
  std::optional<Funnel> watched;    ///< the watched object's funnel, when one is watched
  AnswerFit fit;                    ///< of the answer (best)
  StageTimes times;
};

/// Whether recognition with `s` reads the objects' fine clouds and k-d trees (ICP other than
/// the field metric, the evaluation without the field, or d_outlier beyond the field's coarse
/// margin); when not, Database::set_surface(false) loads the distance fields alone.
bool needs_surface(const RecognizerSettings& s, const DatabaseSettings& database);

class Recognizer {
 public:
  /// The W-nearest feature search: with settings.ransac.feature_table (default) the exact
  /// batched FeatureTable, shared by every recognizer over the same database and object mask
  /// (FeatureTable::shared); otherwise `index`, which may be shared between recognizers (build
  /// it with build_feature_index(db, settings.index, settings.objects)) or is built here.
  Recognizer(const Database& db, std::shared_ptr<const FeatureIndex> index,
             RecognizerSettings settings);
  Recognizer(const Database& db, RecognizerSettings settings);

  /// One exploration step with the cumulative clouds (world frame). Free space may be empty.
  /// `grasps`: the same contacts grouped by grasp (Exploration::grasp_groups()), for the
  /// per-grasp offsets of the evaluation (evaluate.grasp_offset_sigma); empty: not used.
  StepResult step(const PointCloud& contacts_world, const std::vector<Vec3>& free_world,
                  const GraspGroups& grasps = {});
  void reset();                     ///< forget the hypotheses; the next step is step 1
  /// Report each step's Funnel of this database object (nullopt: none). Changes no result.
  /// The shape prior a recognizer with these settings uses on `db` (null: none acts). Shared
  /// while held (ShapePrior::shared): a caller that runs many recognizers on one database holds
  /// it, so that it is built once (4 500 objects: about 4 s), not once per recognizer.
  static std::shared_ptr<const ShapePrior> shape_prior(const Database& db, const RecognizerSettings& settings);
  /// The sparse source's pair-table cache a recognizer with these settings uses on `db` (null:
  /// the source is off), shared alike (SparseTables::shared): held by a caller that runs many
  /// recognizers, each table is built once (when first wanted), not once per recognizer.
  static std::shared_ptr<SparseTables> sparse_tables(const Database& db, const RecognizerSettings& settings);
  /// With `T_world_object`, the object's true pose, each step also evaluates the object there
  /// (Funnel::truth_pose_*; an ICP and an evaluation more per step, not in the stage times).
  void watch(std::optional<std::uint32_t> object, std::optional<Pose> T_world_object = std::nullopt) {
    watch_ = object;
    watch_pose_ = object ? T_world_object : std::nullopt;
  }
  int steps_done() const { return step_; }
  const std::vector<Hypothesis>& hypotheses() const { return state_; }
  const RecognizerSettings& settings() const { return s_; }
  const Database& database() const { return db_; }

 private:
  const Database& db_;
  FeatureSearch search_;
  RecognizerSettings s_;
  int step_ = 0;
  std::vector<Hypothesis> state_;   ///< S_t, world poses, best first
  std::optional<std::uint32_t> watch_;
  std::optional<Pose> watch_pose_;
  std::shared_ptr<const ShapePrior> prior_;  ///< when the shape prior acts (large databases)
  std::shared_ptr<SparseTables> sparse_;  ///< taken (SparseTables::shared) when the sparse source first runs
};

}  // namespace ts
