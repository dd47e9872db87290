// What one recognition step reports: the state (hypotheses, best first), the answer and its
// fit, the posteriors, the stages that ran or were left out and why, their times, and the
// watched object's funnel (diagnostics).
#pragma once

#include "engine/core.hpp"
#include "engine/recognition/support.hpp"

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace ts {
inline namespace recognition {

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

/// Why a hypothesis scored what it did on the step's scene (Recognizer::explain): its ln wt split
/// into Eq. 6's two terms, the fit in absolute terms, the near-twin score and its object's
/// posterior. The step's own numbers, not a re-evaluation.
struct Evidence {
  std::uint32_t object = 0;
  Pose pose = Pose::Identity();     ///< T_world_object
  std::size_t rank = 0;             ///< 1-based, in the step's state (weight order)
  double log_weight = -std::numeric_limits<double>::infinity();  ///< ln wt, as the step scored it
  double contact_log_weight = 0.0;  ///< ln wt_cont (Eq. 5, 7): minus the mean Eq. 4 error
  double free_log_weight = 0.0;     ///< ln wt_free (Eq. 9): -lambda x the summed Eq. 8 error (0:
                                    ///< no free-space term)
  double floor_log_weight = 0.0;    ///< the floor term: minus what its pose lost for sinking the
                                    ///< object below the support plane (0: none; evaluate.hpp,
                                    ///< sink_penalty); ln wt is the sum of the three
  std::size_t free_points_checked = 0;  ///< free points near enough to its object to be checked
                                        ///< (Eq. 8 charges those within d_thresh of its surface)
  double offset_rms_m = 0.0;        ///< m, RMS of the per-grasp offsets fitted (0: none)
  AnswerFit fit;                    ///< contacts in sigmas after the offsets (as StepResult::fit)
  double twin_score = std::numeric_limits<double>::quiet_NaN();  ///< V of the near-twin
                                    ///< verification when it compared this one (lower wins)
  double posterior = 0.0;           ///< its object's posterior
};

/// One stage of a step's pipeline (engine/recognition/pipeline/): whether it ran, why not, and
/// its wall time (observers' time excluded).
struct StageRun {
  std::string name;                 ///< e.g. "ransac", "sparse", "shortlist"
  bool ran = false;
  std::string reason;               ///< why it was left out (empty when it ran)
  double seconds = 0.0;             ///< s
};

/// What explains one contact (stage "attribution").
enum class ContactLabel : std::uint8_t {
  object = 0,       ///< within support.attribution_m of the answer's surface
  support = 1,      ///< set aside as the support's (stage "support")
  unexplained = 2,  ///< neither: something else was touched, or the answer is wrong
};

struct StepResult {
  int step = 0;                     ///< 1-based
  bool valid = false;               ///< there is at least one hypothesis
  Hypothesis best;                  ///< the hypothesis with the largest weight
  double posterior = 0.0;           ///< posterior of best.object
  std::vector<Hypothesis> hypotheses;  ///< the state S_t, best first
  std::vector<double> posteriors;   ///< per database object: weights summed, normalized
  std::vector<double> prior_scores;  ///< per database object, the shape prior's score this step
                                     ///< (higher is better; stage "shape_prior", large databases;
                                     ///< empty when it did not run)
  std::size_t contacts = 0, free_points = 0;
  SupportSurface support;           ///< the support the step found (found = false: none, or
                                    ///< not looked for); its contacts are not in `contacts`
  std::vector<ContactLabel> attribution;  ///< per input contact, in its order (stage
                                          ///< "attribution"; empty when it did not run)
  int unobservable_dof = 6;         ///< pose DOF the contacts leave unconstrained (flat: 3)
  bool pose_ambiguous = true;       ///< unobservable_dof > 0: do not trust the pose
  bool observability_from_model = false;  ///< unobservable_dof judged on the answer's surface (the
                                          ///< contacts carried too few normals: stage "observability")
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
  std::vector<StageRun> stages;     ///< the step's pipeline, in order: ran or left out, and why
  /// Recognizer::explain: the answer's evidence, then its best rival's (the best hypothesis of
  /// another object; absent when the state holds one object), and what decided between them:
  /// "near_twin" (the verification's V), "contacts", "free_space" or "floor" (the term of ln wt
  /// that differs most), or "" (no rival).
  std::vector<Evidence> explanation;
  std::string decided_by;
  std::string stopped;              ///< why the step stopped before any matching ("no contacts",
                                    ///< "fewer than 3 distinct contacts (2)"; "" : it did not)
};

}  // namespace recognition
}  // namespace ts
