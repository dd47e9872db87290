#include "engine/recognition/recognizer.hpp"
#include "engine/detail.hpp"

#include "engine/recognition/pipeline/compose.hpp"
#include "engine/recognition/pipeline/observers.hpp"

#include <algorithm>

namespace ts {
inline namespace recognition {

const std::vector<std::string>& pipeline_stage_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (std::string_view s : pipeline::known_stages()) n.emplace_back(s);
    return n;
  }();
  return names;
}

std::string_view method_name(Method m) {
  switch (m) {
    case Method::batch_ransac: return "batch-ransac";
    case Method::ransac_icp: return "ransac-icp";
    case Method::ransac_icp_fs: return "ransac-icp-fs";
    case Method::bricpsf: return "bricpsf";
  }
  return "bricpsf";
}

std::optional<Method> parse_method(std::string_view name) {
  for (Method m : {Method::batch_ransac, Method::ransac_icp, Method::ransac_icp_fs,
                   Method::bricpsf})
    if (method_name(m) == name) return m;
  return std::nullopt;
}

RecognizerSettings RecognizerSettings::paper() { return RecognizerSettings{}; }

RecognizerSettings RecognizerSettings::improved() {
  RecognizerSettings s;
  s.evaluate.free_inside_penalty = true;
  s.dedupe = true;
  s.refine_new = true;
  s.refine_pool = 60;
  s.new_per_object = 5;
  s.ransac.prune_per_object = 200;
  s.evaluate.grasp_offset_sigma = 0.003;
  // Large databases: each triplet searches the objects of 100 draws (all of them up to about
  // 100 objects; 450 objects: 200 draws gave 65 % at step 20 for 0.27 s a step, 100 gave 62 %
  // for 0.20 s, 50 gave 52 % for 0.15 s, study 7); on databases of more than 48 objects, at
  // most 16 objects' candidates (and the state's objects) go on per step; near-ties between
  // the leading objects are re-decided by the near-twin verification.
  s.ransac.object_draws = 100;
  s.shortlist.objects = 16;
  s.shortlist.min_database = 48;
  // ... and on them, per-object pruning reads each object's 8 blocks of 128 features nearest to
  // the query (450 objects: 0.181 s a step against 0.191 s exact, 62 % at step 20 either way).
  s.ransac.prune_blocks = 8;
  s.ransac.prune_blocks_min_database = 48;
  s.twins.rivals = 5;
  // ... each rival's pose and per-grasp offsets refined together under V first (450 objects:
  // 82 % at step 20 against 70 % judging each rival at its ICP pose, study 7).
  s.twins.refine = 4;
  // ... and the leader's pose is tried on the 2 objects that fit the contacts best there (450
  // objects: 75 % at step 20 against 62 % without; 4 and 8 objects gave 72 %, study 7).
  s.twins.transfer = 2;
  s.twins.transfer_min_database = 48;
  // ... among the shape prior's 300 best objects of the step (4 500 catalogue objects: the
  // screening of every object took most of the 61 ms of the step's other stages).
  s.twins.transfer_pool = 300;
  // ... and 60 of each triplet's 100 object draws are the step's best objects by the shape
  // prior (4 500 catalogue objects, runs 0-1 of study 7: 62 % at step 20 against
  // 40 %; 450 stretched variants: 80 % against 82 %).
  s.ransac.prior_draws = 60;
  s.prior_min_database = 48;
  // The feature-free source on every step, pads too: its triplets span grasps, which FPFH's
  // neighbourhoods never relate (scripts/results compare, study 3 and the standard tier; the
  // paired figures are in CHANGELOG.md, 0.3.0).
  s.sparse.mode = kSparseAlways;
  // A step that the leading survivor alone explains within noise takes no new candidates
  // (study 3, shortened: the same recognition at step 20, 0.3 s -> 0.02 s a step on
  // bench_recognize; CHANGELOG.md), on databases of any size: study 7 at 450 catalogue objects,
  // paired over 100 runs, the same recognition within one run at every step (91 -> 92 % at step
  // 20, 96 -> 95 % at step 40) and the median step at step 40 329 -> 52 ms
  // (docs/results/study7_cat450_sets).
  s.early_stop = true;
  s.early_stop_max_database = 0;
  return s;
}

bool needs_surface(const RecognizerSettings& s, const DatabaseSettings& database) {
  return s.icp.metric != IcpMetric::field || !s.evaluate.use_distance_field ||
         s.evaluate.d_outlier > database.field.coarse_margin;
}

RecognizerSettings RecognizerSettings::scaled(double f) const {
  RecognizerSettings s = *this;
  s.dedupe_distance *= f;
  s.scene.query_voxel *= f;
  if (s.scene.free_clearance > 0.0) s.scene.free_clearance *= f;
  s.ransac.min_spacing *= f;
  s.ransac.distance_tolerance *= f;
  s.ransac.size_slack *= f;
  s.icp.min_translation *= f;
  s.icp.max_correspondence *= f;
  s.evaluate.d_outlier *= f;
  s.evaluate.outlier_m *= f;
  s.evaluate.res_free *= f;
  s.evaluate.grasp_offset_sigma *= f;
  s.evaluate.grasp_contact_sigma *= f;
  s.shortlist.outlier_distance *= f;
  s.twins.contact_sigma *= f;
  s.twins.offset_sigma *= f;
  s.twins.free_sigma *= f;
  s.prior.distance_bin *= f;
  s.prior.min_pair_distance *= f;
  s.sparse.distance_tolerance *= f;
  s.sparse.model_spacing *= f;
  s.support.tolerance *= f;
  if (s.support.free_margin > 0.0) s.support.free_margin *= f;
  s.support.attribution *= f;
  s.support.sink *= f;
  s.support.min_radius *= f;
  return s;
}

Recognizer::Recognizer(const Database& db, std::shared_ptr<const FeatureIndex> index,
                       RecognizerSettings settings)
    : db_(db), s_(std::move(settings)) {
  if (!s_.objects.empty() && s_.objects.size() != db_.size())
    throw Error("object mask has " + std::to_string(s_.objects.size()) + " entries, the database " +
                std::to_string(db_.size()) + " objects", {}, "objects");
  if (s_.ransac.feature_table) {
    search_.table = FeatureTable::shared(db_, s_.objects);
  } else {
    search_.index = index ? std::move(index)
                          : std::make_shared<FeatureIndex>(build_feature_index(db_, s_.index, s_.objects));
    const int dim = descriptor_dim(db_.settings().descriptor);
    if (search_.index->size() > 0 && search_.index->dim() != dim)
      throw Error("the shared feature index has " + std::to_string(search_.index->dim()) + " values a row, the " +
                      descriptor_name(db_.settings().descriptor) + " database " + std::to_string(dim),
                  {}, "descriptor");
  }
  if (!(s_.psi >= 0.0 && s_.psi <= 1.0)) throw Error("psi must be in [0, 1]", {}, "psi");
  if (!db_.surface() && needs_surface(s_, db_.settings()))
    throw Error("these recognizer settings need the objects' fine clouds, but the database loads distance "
                "fields only (Database::set_surface)", {}, "icp.metric");
  if (s_.n_p == 0) throw Error("n_p must be positive", {}, "n_p");
  // With the background term on, ICP pairs no contact farther than twice its distance from the
  // object (unless icp.max_correspondence says otherwise): what the evaluation takes for the
  // seabed or a neighbour must not pull the fit either (measured by study15_cluttered; CHANGELOG).
  if (s_.evaluate.outlier_m > 0.0 && s_.icp.max_correspondence == 0.0)
    s_.icp.max_correspondence = 2.0 * s_.evaluate.outlier_m;
  prior_ = shape_prior(db_, s_);
  stages_ = std::make_shared<const pipeline::Pipeline>(pipeline::compose(pipeline::method_stages(s_.method)));
}

std::shared_ptr<const ShapePrior> Recognizer::shape_prior(const Database& db, const RecognizerSettings& s) {
  if (s.ransac.prior_draws > 0 && s.ransac.object_draws > 0 && db.size() > s.prior_min_database)
    return ShapePrior::shared(db, s.prior, s.objects);
  return nullptr;
}

std::shared_ptr<SparseTables> Recognizer::sparse_tables(const Database& db, const RecognizerSettings& s) {
  return s.sparse.mode == kSparseNever ? nullptr : SparseTables::shared(db, s.sparse);
}

Recognizer::Recognizer(const Database& db, RecognizerSettings settings)
    : Recognizer(db, nullptr, std::move(settings)) {}

void Recognizer::reset() {
  step_ = 0;
  state_.clear();
}

StepResult Recognizer::step(const PointCloud& contacts_world, const std::vector<Vec3>& free_world,
                            const GraspGroups& grasps) {
  const auto t_start = detail::Clock::now();
  StepResult res;
  res.step = step_ + 1;
  res.posteriors.assign(db_.size(), 0.0);
  pipeline::StepContext c{.db = db_, .s = s_, .search = search_, .prior = prior_.get(), .sparse_tables = sparse_,
                          .previous = state_, .contacts_world = contacts_world, .free_world = free_world,
                          .grasps = grasps, .step = res.step, .res = res};
  std::optional<pipeline::FunnelObserver> funnel;
  std::vector<pipeline::StepObserver*> observers;
  if (watch_ && *watch_ < db_.size()) observers.push_back(&funnel.emplace(*watch_, watch_pose_));
  std::optional<pipeline::ExplainObserver> explainer;
  if (explain_) observers.push_back(&explainer.emplace());
  pipeline::run_pipeline(*stages_, c, observers);
  step_ = res.step;   // a stage or an observer that throws leaves the recognizer as it was
  if (c.finished) {   // e.g. no contacts: the state waits for data
    res.stopped = *c.finished;
    res.geometry_loads = db_.geometry_loads();
    res.times.total_s = detail::seconds_since(t_start);
    return res;
  }
  state_ = res.hypotheses;
  db_.trim();  // nothing of this step is pinned any more
  res.geometry_loads = db_.geometry_loads();
  res.geometry_resident = db_.geometry_resident();
  res.times.total_s = detail::seconds_since(t_start) - (res.watched ? res.watched->diagnostic_s : 0.0) -
                     (explainer ? explainer->seconds : 0.0);
  return res;
}

}  // namespace recognition
}  // namespace ts
