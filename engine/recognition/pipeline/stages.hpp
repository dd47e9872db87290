// The stages a step's pipeline is composed of (compose.hpp), each in its own file, in the order
// Algorithm 1 and Touchstone's extensions run them. Each names the settings it reads.
#pragma once

#include "engine/recognition/pipeline/stage.hpp"

#include <memory>

namespace ts::inline recognition::pipeline {

// ---- the query
std::unique_ptr<const Stage> support_stage();        ///< "support": the plane under the object
                                                     ///< and its contacts, set aside (SupportSettings)
std::unique_ptr<const Stage> scene_stage();          ///< "scene": the local frame, normals,
                                                     ///< features (SceneSettings); the objects
                                                     ///< that can span the contacts
// ---- candidate sources
std::unique_ptr<const Stage> shape_prior_stage();    ///< "shape_prior": ranks the objects for
                                                     ///< feature pruning (ShapePriorSettings)
std::unique_ptr<const Stage> ransac_source();        ///< "ransac": Batch RANSAC (RansacSettings)
std::unique_ptr<const Stage> sparse_source();        ///< "sparse": feature-free triplets (SparseSettings)
std::unique_ptr<const Stage> survivors_source();     ///< "survivors": S_{t-1} refined and
                                                     ///< evaluated (Algorithm 1, lines 3-7)
std::unique_ptr<const Stage> pose_transfer_source(); ///< "pose_transfer": the leader's pose on the
                                                     ///< objects that fit there (TwinSettings)
std::unique_ptr<const Stage> early_stop_stage();     ///< "early_stop": the survivors explain the
                                                     ///< step; no new hypotheses (early_stop_*)
// ---- screening
std::unique_ptr<const Stage> shortlist_stage();      ///< "shortlist": objects whose candidates go
                                                     ///< on (ShortlistSettings)
// ---- selection: the methods as policies (refinement and evaluation inside)
std::unique_ptr<const Stage> select_batch();         ///< "select": the n_p best by Eq. 5 (batch-ransac)
std::unique_ptr<const Stage> icp_each();             ///< "icp_each": every candidate refined,
                                                     ///< the n_p best (ransac-icp, ransac-icp-fs)
std::unique_ptr<const Stage> sequential_filter();    ///< "sequential_filter": Psi n_p survivors and
                                                     ///< (1-Psi) n_p new (Algorithm 1, lines 8-9)
// ---- the answer
std::unique_ptr<const Stage> posteriors_stage();     ///< "posteriors": per object, normalized
std::unique_ptr<const Stage> answer_rule_stage();    ///< "answer_rule": the best hypothesis, near
                                                     ///< ties re-decided by near-twin verification
std::unique_ptr<const Stage> state_stage();          ///< "state": S_t in world poses, the answer
                                                     ///< and its fit
std::unique_ptr<const Stage> observability_stage();  ///< "observability": the free pose DOF on the
                                                     ///< answer's surface (contacts without normals)
std::unique_ptr<const Stage> attribution_stage();    ///< "attribution": what explains each contact
                                                     ///< (the answer, the support, or nothing)

/// A hypothesis's fit in absolute terms (state_stage.cpp; StepResult::fit for the answer): the
/// contacts' distances after the per-grasp offsets against evaluate.grasp_contact_sigma.
AnswerFit absolute_fit(const Scene& scene, const Database& db, const Working& h, const EvaluateSettings& s);

/// The answer rule (answer_rule.cpp): the best hypothesis of `next` (sorted by `better`), unless
/// the near-twin verification of the leading objects' best hypotheses re-decides a near tie.
AnswerRule decide_answer(const Scene& scene, const Database& db, const std::vector<Working>& next,
                         const TwinSettings& twins);

}  // namespace ts::recognition::pipeline
