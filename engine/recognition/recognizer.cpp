#include "engine/recognition/recognizer.hpp"
#include "engine/detail.hpp"

#include "engine/geometry/kabsch.hpp"
#include "engine/recognition/shortlist.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <map>
#include <set>

namespace ts {

namespace {
using detail::seconds_since;

using Clock = std::chrono::steady_clock;


/// Hypotheses in the scene frame while a step works on them.
struct Working {
  Candidate cand;        ///< object, T_scene_object, slot
  Evaluation eval;
  int born = 0;
  int icp_iterations = 0;
  bool icp_converged = false;
};

/// The slot of the watched object's hypothesis at its true pose (diagnostics; above pose
/// transfer's kTransferSlot + object).
constexpr std::uint32_t kTruthSlot = 0xFFFFFFFFu;

/// Fixed total order: weight descending, then older first, then slot.
bool better(const Working& a, const Working& b) {
  if (a.eval.log_weight != b.eval.log_weight) return a.eval.log_weight > b.eval.log_weight;
  if (a.born != b.born) return a.born < b.born;
  return a.cand.slot < b.cand.slot;
}

GeometryPins pin(const Database& db, const std::vector<Working>& w) {
  return GeometryPins(db, w, [](const Working& h) { return h.cand.object; });
}

/// ICP every hypothesis against its own object (Algorithm 1, line 4), in parallel.
void refine_all(const Scene& scene, const Database& db, const IcpSettings& s,
                std::vector<Working>& w) {
  const GeometryPins geometry = pin(db, w);
  detail::parallel_each(w.size(), 1, [&](std::size_t i) {
    Working& h = w[i];
    const IcpResult r = icp(scene, geometry[h.cand.object], h.cand.T_scene_object, s);
    if (r.valid) h.cand.T_scene_object = r.T_scene_object;
    h.icp_iterations = r.iterations;
    h.icp_converged = r.converged;
  });
}

/// Complete evaluation of every hypothesis (Algorithm 1, line 5), in parallel.
void evaluate_each(const Scene& scene, const Database& db, const EvaluateSettings& s,
                   std::vector<Working>& w) {
  const GeometryPins geometry = pin(db, w);
  detail::parallel_each(w.size(), 1, [&](std::size_t i) {
    Working& h = w[i];
    h.eval = evaluate(scene, geometry[h.cand.object], db.info(h.cand.object),
                      h.cand.T_scene_object, s);
  });
}

/// The answer of a step (index into `next`, sorted by `better`): the best hypothesis, unless
/// the near-twin verification of the leading objects' best hypotheses re-decides a near tie.
/// (Answering the object of largest posterior instead was measured and rejected: the weights are
/// so flat that the posterior counts an object's hypotheses; 45 objects, 135 logs: 27 % right
/// against 91 %.) `leaders` and `v`: the hypotheses V was computed for and their V.
struct AnswerRule {
  std::size_t chosen = 0;
  std::vector<std::size_t> leaders;
  std::vector<double> v;
};

AnswerRule answer_rule(const Scene& scene, const Database& db, const std::vector<Working>& next,
                       const TwinSettings& twins) {
  AnswerRule out;
  std::vector<std::size_t> lead;  // first (best) hypothesis of each leading object, best first
  for (std::size_t i = 0; i < next.size() && lead.size() < twins.rivals; ++i) {
    if (!(next[i].eval.log_weight >= next.front().eval.log_weight - twins.max_gap)) break;
    bool seen = false;
    for (std::size_t j : lead) seen = seen || next[j].cand.object == next[i].cand.object;
    if (!seen) lead.push_back(i);
  }
  if (twins.rivals > 1 && !scene.grasps.empty() && lead.size() > 1) {
    std::vector<Working> leaders;
    for (std::size_t i : lead) leaders.push_back(next[i]);
    const GeometryPins geometry = pin(db, leaders);
    std::vector<double> v(lead.size());
    detail::parallel_each(lead.size(), 1, [&](std::size_t k) {
      v[k] = twin_score(scene, geometry[leaders[k].cand.object], leaders[k].cand.T_scene_object, twins);
    });
    std::size_t best_k = 0;
    for (std::size_t k = 1; k < v.size(); ++k)
      if (v[k] < v[best_k]) best_k = k;
    out.chosen = lead[best_k];
    out.leaders = std::move(lead);
    out.v = std::move(v);
  }
  return out;
}

/// The answer's fit in absolute terms (AnswerFit).
AnswerFit answer_fit(const Scene& scene, const Database& db, const Working& h, const EvaluateSettings& s) {
  AnswerFit out;
  const GeometryPins geometry = pin(db, std::vector<Working>{h});
  const ObjectGeometry& geo = geometry[h.cand.object];
  if (geo.field.empty()) return out;
  const GraspFit fit = contact_fit(scene, geo.field, h.cand.T_scene_object, s);
  if (fit.contacts == 0) return out;
  const double n = static_cast<double>(fit.contacts), sigma = s.grasp_contact_sigma;
  out.valid = true;
  out.contacts = fit.contacts;
  out.rms_sigma = std::sqrt(fit.clamped_sq_sum / n) / sigma;
  out.far_share = static_cast<double>(fit.far) / n;
  out.far10_share = static_cast<double>(fit.far10) / n;
  out.offset_rms_sigma = s.grasp_offset_sigma > 0.0 ? fit.offset_rms / s.grasp_offset_sigma : 0.0;
  out.free_conflict = h.eval.free_error / static_cast<double>(std::max<std::size_t>(scene.free_space.size(), 1));
  const GraspDiagnostics per = grasp_diagnostics(scene, geo.field, h.cand.T_scene_object, fit, s);
  const double cap = 30.0 * std::numbers::pi / 180.0;
  double angle_sq = 0.0;
  std::size_t angles = 0;
  for (std::size_t k = 0; k < per.rms.size(); ++k) {
    if (std::isfinite(per.rms[k])) out.worst_grasp_sigma = std::max(out.worst_grasp_sigma, per.rms[k] / sigma);
    if (!std::isfinite(per.normal_angle[k])) continue;
    const double a = std::min(per.normal_angle[k], cap);
    angle_sq += a * a;
    ++angles;
    out.normal_worst_deg = std::max(out.normal_worst_deg, a * 180.0 / std::numbers::pi);
  }
  if (angles > 0) out.normal_rms_deg = std::sqrt(angle_sq / static_cast<double>(angles)) * 180.0 / std::numbers::pi;
  return out;
}

bool duplicates(const Working& a, const Working& b, double distance) {
  if (a.cand.object != b.cand.object) return false;
  const Pose d = a.cand.T_scene_object.inverse() * b.cand.T_scene_object;
  return d.translation().norm() < distance &&
         rotation_angle(d.linear()) < 2.0 * std::numbers::pi / 180.0;
}

/// Append from `from` (sorted) to `into` until it holds `limit`, skipping duplicates if asked.
void take(std::vector<Working>& into, const std::vector<Working>& from, std::size_t limit,
          bool dedupe, double distance) {
  for (const Working& h : from) {
    if (into.size() >= limit) break;
    if (dedupe) {
      bool dup = false;
      for (const Working& k : into)
        if (duplicates(k, h, distance)) { dup = true; break; }
      if (dup) continue;
    }
    into.push_back(h);
  }
}

std::vector<Working> from_scored(const std::vector<Candidate>& cands,
                                 const std::vector<ScoredCandidate>& top, int born) {
  std::vector<Working> w;
  w.reserve(top.size());
  for (const ScoredCandidate& sc : top) {
    Working h;
    h.cand = cands[sc.index];
    h.eval = sc.eval;
    h.born = born;
    w.push_back(h);
  }
  return w;
}

}  // namespace

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
  prior_ = shape_prior(db_, s_);
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
  const auto t_start = Clock::now();
  ++step_;
  StepResult res;
  res.step = step_;
  res.posteriors.assign(db_.size(), 0.0);
  const auto step_u = static_cast<std::uint64_t>(step_);

  // The query in a local frame (Section 4.1.2 clouds; Section 4.3.1 normals and features).
  auto t0 = Clock::now();
  SceneSettings scs = s_.scene;
  scs.descriptor = db_.settings().descriptor;   // the queries' descriptor is the database's
  if (scs.free_clearance < 0.0)  // automatic: d_thresh of Eq. 8
    scs.free_clearance = s_.evaluate.d_thresh > 0.0 ? s_.evaluate.d_thresh : 0.5 * s_.evaluate.res_free;
  Scene scene = prepare_scene(contacts_world, free_world, db_.settings().fpfh, scs, s_.seed, step_u);
  if (s_.evaluate.grasp_offset_sigma > 0.0 || s_.twins.rivals > 0) set_grasps(scene, grasps);
  res.times.prepare_s = seconds_since(t0);
  res.contacts = scene.contacts.size();
  res.free_points = scene.free_space.size();
  res.unobservable_dof = scene.unobservable_dof;
  res.pose_ambiguous = scene.unobservable_dof > 0;
  if (scene.contacts.empty()) {  // nothing to match: the state waits for data
    res.geometry_loads = db_.geometry_loads();
    res.times.total_s = seconds_since(t_start);
    return res;
  }

  const bool with_free = s_.method == Method::ransac_icp_fs || s_.method == Method::bricpsf;
  EvaluateSettings ev = s_.evaluate;
  ev.free_space = ev.free_space && with_free;
  // Per-grasp offsets score refined hypotheses only: the raw RANSAC candidates are ranked by
  // the plain Eq. 4 (thousands of them), which only chooses the ones to refine.
  const bool grasp_fit = ev.grasp_offset_sigma > 0.0 && !scene.grasps.empty();
  EvaluateSettings ev_raw = ev;
  ev_raw.grasp_offset_sigma = 0.0;
  // ICP on every hypothesis of `w`, then the full evaluation, each stage timed.
  auto refine_and_evaluate = [&](std::vector<Working>& w) {
    auto t = Clock::now();
    refine_all(scene, db_, s_.icp, w);
    res.times.icp_s += seconds_since(t);
    t = Clock::now();
    evaluate_each(scene, db_, ev, w);
    res.times.evaluate_s += seconds_since(t);
  };

  // Batch RANSAC hypothesis generation (Section 4.3.2), every method, every step.
  std::vector<std::uint8_t> allowed = objects_spanning(scene, db_, s_.ransac.size_slack);
  if (!s_.objects.empty())
    for (std::size_t o = 0; o < allowed.size(); ++o) allowed[o] = allowed[o] && s_.objects[o];
  // Extension for large databases: the shape prior ranks the objects for feature pruning.
  std::vector<std::uint32_t> preferred;
  double prior_s = 0.0;
  if (prior_) {
    t0 = Clock::now();
    preferred = rank_by_prior(prior_->score(scene, allowed, s_.seed, step_u));
    prior_s = seconds_since(t0);
  }
  RansacStats rs;
  std::vector<Candidate> cands =
      ransac_candidates(scene, db_, search_, allowed, s_.ransac, s_.seed, step_u, &rs, preferred);
  rs.time_prune_s += prior_s;
  // With the shape prior (large databases) the sparse source matches only the prior's best
  // objects: its pair tables (up to 2.9 MB an object) are built for the objects it matches, and
  // every object's would not fit (4 500 objects: about 13 GB); no prior ranking, no matching.
  std::vector<std::uint8_t> sparse_mask = allowed;
  if (prior_) {
    sparse_mask.assign(allowed.size(), 0);
    for (std::size_t k = 0; k < std::min(preferred.size(), s_.ransac.prior_draws); ++k) sparse_mask[preferred[k]] = 1;
  }
  if (std::find(sparse_mask.begin(), sparse_mask.end(), 1) != sparse_mask.end() &&
      sparse_active(scene, s_.sparse)) {  // isolated contacts: feature-free triplets join in
    if (!sparse_) sparse_ = sparse_tables(db_, s_);
    SparseStats sp;
    const std::vector<Candidate> more = sparse_candidates(
        scene, *sparse_, sparse_contact_normals(scene, contacts_world, s_.sparse), sparse_mask, s_.sparse, s_.seed,
        step_u, &sp);
    cands.insert(cands.end(), more.begin(), more.end());
    res.sparse_active = true;
    res.sparse_candidates = sp.candidates;
    rs.time_register_s += sp.time_s;
  }
  const bool watching = watch_ && *watch_ < db_.size();
  if (watching) {
    const std::uint32_t w = *watch_;
    Funnel f;
    f.searched = w < rs.searched.size() && rs.searched[w];
    f.candidates = static_cast<std::size_t>(
        std::count_if(cands.begin(), cands.end(), [&](const Candidate& c) { return c.object == w; }));
    f.shortlisted = f.candidates > 0;   // unless the shortlist leaves it out (below)
    if (prior_) {
      const auto at = std::find(preferred.begin(), preferred.end(), w);
      f.prior_rank = at == preferred.end() ? 0 : static_cast<std::size_t>(at - preferred.begin()) + 1;
    }
    res.watched = f;
  }
  // Extension for large databases: only the shortlisted objects' candidates go on (and the
  // state's objects'), so only their geometry is loaded.
  if (s_.shortlist.objects > 0 && db_.size() > s_.shortlist.min_database) {
    t0 = Clock::now();
    std::vector<std::uint32_t> held;
    for (const Hypothesis& h : state_) held.push_back(h.object);
    const Shortlist sl = shortlist_objects(scene, db_, cands, held, s_.shortlist);
    if (sl.active) {
      if (watching) {   // diagnostics (not timed): how far its best candidate was from the cut
        const auto t_diag = Clock::now();
        Funnel& f = *res.watched;
        f.shortlisted = f.candidates > 0 && sl.mask[*watch_];
        if (f.candidates > 0) {   // every object's exact best score (no early stop)
          const std::vector<double> all = screen_objects(scene, db_, cands, s_.shortlist);
          f.screen_score = all[*watch_];
          f.screen_rank = 1 + static_cast<std::size_t>(std::count_if(all.begin(), all.end(), [&](double v) {
            return v < f.screen_score; }));
        }
        const std::size_t last = std::min(s_.shortlist.objects, sl.ranked.size());
        if (last > 0) f.screen_cut = sl.best[sl.ranked[last - 1]];
        const auto spent = Clock::now() - t_diag;
        t0 += spent;
        f.diagnostic_s += std::chrono::duration<double>(spent).count();
      }
      std::erase_if(cands, [&](const Candidate& c) { return !sl.mask[c.object]; });
      for (std::uint32_t o = 0; o < sl.mask.size(); ++o)
        if (sl.mask[o]) res.shortlist.push_back(o);
    }
    res.times.shortlist_s = seconds_since(t0);
  }
  res.times.prune_s = rs.time_prune_s;
  res.times.register_s = rs.time_register_s;
  res.candidates = rs.registrations;
  res.objects_allowed = rs.objects_allowed;
  res.objects_reached = rs.objects_reached;
  res.boundary_fallback = rs.boundary_fallback;

  const std::size_t n_p = s_.n_p;
  std::vector<Working> next;
  SelectStats ss;
  auto select = [&](const std::vector<Candidate>& c, std::size_t k, const EvaluateSettings& e) {
    const auto te = Clock::now();
    const auto top = select_top(scene, db_, c, k, e, &ss);
    res.times.evaluate_s += seconds_since(te);
    res.evaluated_full += ss.full;
    res.rejected_early += ss.rejected_prefix + ss.rejected_later;
    return from_scored(c, top, step_);
  };

  switch (s_.method) {
    case Method::batch_ransac: {
      take(next, select(cands, n_p, ev_raw), n_p, s_.dedupe, s_.dedupe_distance);
      break;
    }
    case Method::ransac_icp:
    case Method::ransac_icp_fs: {
      // Section 5.4: each registration refined by ICP, then evaluated.
      std::vector<Candidate> pool = cands;
      if (s_.icp_top > 0.0 && s_.icp_top < 1.0) {
        const auto k = static_cast<std::size_t>(std::ceil(s_.icp_top * double(cands.size())));
        std::vector<Working> pre = select(cands, std::max(k, n_p), ev_raw);
        pool.clear();
        for (const Working& h : pre) pool.push_back(h.cand);
      }
      std::vector<Working> w(pool.size());
      for (std::size_t i = 0; i < pool.size(); ++i) w[i].cand = pool[i];
      t0 = Clock::now();
      refine_all(scene, db_, s_.icp, w);
      res.times.icp_s += seconds_since(t0);
      std::vector<Candidate> refined(w.size());
      for (std::size_t i = 0; i < w.size(); ++i) refined[i] = w[i].cand;
      std::vector<Working> top = select(refined, s_.dedupe ? 4 * n_p : n_p, ev);
      // carry the ICP diagnostics over
      for (Working& h : top)
        for (const Working& x : w)
          if (x.cand.slot == h.cand.slot) {
            h.icp_iterations = x.icp_iterations;
            h.icp_converged = x.icp_converged;
            break;
          }
      take(next, top, n_p, s_.dedupe, s_.dedupe_distance);
      break;
    }
    case Method::bricpsf: {
      // Algorithm 1, lines 3-7: evolve the old hypotheses with ICP, evaluate with Eq. 6.
      std::vector<Working> old(state_.size());
      for (std::size_t i = 0; i < state_.size(); ++i) {
        old[i].cand.object = state_[i].object;
        old[i].cand.T_scene_object = scene.to_scene(state_[i].pose);
        old[i].cand.slot = state_[i].slot;
        old[i].born = state_[i].born;
      }
      refine_and_evaluate(old);
      std::sort(old.begin(), old.end(), better);

      // Line 8-9: new hypotheses from Batch RANSAC; resample Psi*n_p old + (1-Psi)*n_p new.
      const auto k_old = std::min(old.size(),
                                  static_cast<std::size_t>(std::lround(s_.psi * double(n_p))));
      take(next, old, k_old, s_.dedupe, s_.dedupe_distance);
      const std::size_t k_new = n_p - next.size();
      const std::size_t pool = std::max(s_.refine_pool, s_.dedupe || s_.new_per_object > 0 ? 2 * k_new : k_new);
      std::vector<Working> fresh = select(cands, pool, ev_raw);
      if (s_.refine_new) {
        t0 = Clock::now();
        refine_all(scene, db_, s_.icp, fresh);
        res.times.icp_s += seconds_since(t0);
      }
      if (s_.refine_new || grasp_fit) {  // refined, or the offsets re-score them: evaluate again
        t0 = Clock::now();
        evaluate_each(scene, db_, ev, fresh);
        res.times.evaluate_s += seconds_since(t0);
        std::sort(fresh.begin(), fresh.end(), better);
      }
      if (s_.new_per_object > 0) {
        // Diversity: at most new_per_object new hypotheses of one object.
        std::map<std::uint32_t, std::size_t> count;
        std::vector<Working> capped;
        for (const Working& h : fresh)
          if (count[h.cand.object]++ < s_.new_per_object) capped.push_back(h);
        fresh = std::move(capped);
      }
      take(next, fresh, n_p, s_.dedupe, s_.dedupe_distance);
      // Too few new ones: fill with the next-best old hypotheses.
      if (next.size() < n_p) {
        std::vector<Working> rest(old.begin() + static_cast<std::ptrdiff_t>(k_old), old.end());
        take(next, rest, n_p, s_.dedupe, s_.dedupe_distance);
      }
      break;
    }
  }
  std::sort(next.begin(), next.end(), better);

  // Extension for large databases: pose transfer. The leader's pose is tried on the objects
  // whose keypoints fit the contacts best there; refined and evaluated, they join the state on
  // their merit (the weakest hypotheses make room).
  if (s_.twins.transfer > 0 && db_.size() > s_.twins.transfer_min_database && !next.empty()) {
    t0 = Clock::now();
    const Working lead = next.front();
    std::vector<Candidate> probe;
    auto add_probe = [&](std::uint32_t o) {
      if (!allowed[o] || o == lead.cand.object) return;
      Candidate c = lead.cand;
      c.object = o;
      probe.push_back(c);
    };
    if (prior_ && s_.twins.transfer_pool > 0 && !preferred.empty()) {   // the prior's best (any order)
      for (std::size_t k = 0; k < std::min(preferred.size(), s_.twins.transfer_pool); ++k) add_probe(preferred[k]);
    } else {
      for (std::uint32_t o = 0; o < db_.size(); ++o) add_probe(o);
    }
    const std::vector<double> fit = screen_objects(scene, db_, probe, s_.shortlist, s_.twins.transfer);
    std::vector<std::uint32_t> order;
    for (const Candidate& c : probe)
      if (fit[c.object] < 1.0) order.push_back(c.object);
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
      return fit[a] != fit[b] ? fit[a] < fit[b] : a < b;
    });
    if (watching) {
      const auto at = std::find(order.begin(), order.end(), *watch_);
      res.watched->transfer_rank = at == order.end() ? 0 : static_cast<std::size_t>(at - order.begin()) + 1;
    }
    if (order.size() > s_.twins.transfer) order.resize(s_.twins.transfer);
    if (watching) res.watched->transferred = std::find(order.begin(), order.end(), *watch_) != order.end();
    res.times.shortlist_s += seconds_since(t0);
    std::vector<Working> moved;
    for (std::uint32_t o : order) {
      Working w = lead;
      w.cand.object = o;
      w.cand.slot = kTransferSlot + o;   // unique within the step
      w.born = step_;
      moved.push_back(w);
    }
    if (!moved.empty()) {
      refine_and_evaluate(moved);
      std::vector<Working> all = next;
      all.insert(all.end(), moved.begin(), moved.end());
      std::stable_sort(all.begin(), all.end(), better);
      next.clear();
      take(next, all, n_p, s_.dedupe, s_.dedupe_distance);
    }
  }

  // Posterior per object over the new state (log-sum-exp normalization: finite even when every
  // wt underflows).
  double max_lw = -std::numeric_limits<double>::infinity();
  for (const Working& h : next) max_lw = std::max(max_lw, h.eval.log_weight);
  double total = 0.0;
  for (const Working& h : next) {
    const double rel = std::isfinite(max_lw) ? std::exp(h.eval.log_weight - max_lw) : 1.0;
    res.posteriors[h.cand.object] += rel;
    total += rel;
  }
  if (total > 0.0)
    for (double& p : res.posteriors) p /= total;

  // The answer (answer_rule: the best hypothesis or the near-twin verification's choice).
  const std::size_t chosen = answer_rule(scene, db_, next, s_.twins).chosen;  // index into next

  // Diagnostics: the watched object at its true pose, through the step's ICP (none for
  // batch-ransac), evaluation and answer rule (Funnel::truth_pose_*). Not in the step's times;
  // changes none of its hypotheses, weights or answer.
  if (watching && watch_pose_) {
    const auto t_diag = Clock::now();
    Funnel& f = *res.watched;
    std::vector<Working> truth(1);
    truth[0].cand.object = *watch_;
    truth[0].cand.T_scene_object = scene.to_scene(*watch_pose_);
    truth[0].cand.slot = kTruthSlot;
    truth[0].born = step_;
    const bool refined = s_.method != Method::batch_ransac;   // the state's hypotheses' footing
    if (refined) refine_all(scene, db_, s_.icp, truth);
    evaluate_each(scene, db_, refined ? ev : ev_raw, truth);
    std::vector<Working> all = next;
    all.push_back(truth[0]);
    std::stable_sort(all.begin(), all.end(), better);
    const AnswerRule rule = answer_rule(scene, db_, all, s_.twins);
    f.truth_pose_evaluated = true;
    f.truth_pose_wins = all[rule.chosen].cand.object == *watch_ ||
                        (!next.empty() && next[chosen].cand.object == *watch_);
    f.truth_pose_log_weight = truth[0].eval.log_weight;
    if (!next.empty()) f.answer_log_weight = next[chosen].eval.log_weight;
    for (std::size_t k = 0; k < rule.leaders.size(); ++k) {
      const Working& h = all[rule.leaders[k]];
      if (h.cand.object == *watch_)   // its leading hypothesis: this one or a better of its own
        f.truth_pose_twin_score = rule.v[k];
      else
        f.rival_twin_score = std::min(f.rival_twin_score, rule.v[k]);
    }
    f.diagnostic_s += seconds_since(t_diag);
  }

  // The new state in world coordinates; the best hypothesis and the posterior per object.
  state_.clear();
  for (const Working& h : next) {
    Hypothesis out;
    out.object = h.cand.object;
    out.pose = scene.to_world(h.cand.T_scene_object);
    out.log_weight = h.eval.log_weight;
    out.weight = std::exp(h.eval.log_weight);
    out.born = h.born;
    out.slot = h.cand.slot;
    out.icp_iterations = h.icp_iterations;
    out.icp_converged = h.icp_converged;
    state_.push_back(out);
  }
  res.hypotheses = state_;
  if (watching)
    res.watched->hypotheses = static_cast<std::size_t>(std::count_if(
        state_.begin(), state_.end(), [&](const Hypothesis& h) { return h.object == *watch_; }));
  res.valid = !state_.empty();
  if (res.valid) {
    res.best = state_[chosen];
    res.posterior = res.posteriors[res.best.object];
    res.fit = answer_fit(scene, db_, next[chosen], s_.evaluate);
  }
  db_.trim();  // nothing of this step is pinned any more
  res.geometry_loads = db_.geometry_loads();
  res.geometry_resident = db_.geometry_resident();
  res.times.total_s = seconds_since(t_start) - (res.watched ? res.watched->diagnostic_s : 0.0);
  return res;
}

}  // namespace ts
