#include "experiments/runs/recognition_engine.hpp"
#include "engine/detail.hpp"

#include "datasets/simulator.hpp"
#include "engine/database/feature_table.hpp"
#include "engine/geometry/mesh.hpp"
#include "engine/geometry/pose_error.hpp"
#include "engine/geometry/symmetry.hpp"
#include "engine/recognition/answer_set.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/touch/active_touch.hpp"
#include "engine/touch/fusion.hpp"
#include "experiments/analysis/calibration.hpp"
#include "experiments/analysis/metrics.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/resources.hpp"
#include "experiments/runs/grasp_pools.hpp"
#include "experiments/runs/truth_model.hpp"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/version.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <numbers>
#include <set>
#include <sstream>

#ifndef TS_VERSION
#define TS_VERSION "unknown"
#endif

namespace ts::experiments {

namespace {

using detail::Clock;
using detail::seconds_since;

constexpr std::uint64_t kRecognizerStream = 0x72656367ULL;  // "recg"
constexpr std::uint64_t kPlannerStream = 0x706c616eULL;     // "plan"

struct VariantData {
  ExperimentConfig config;
  std::size_t group = 0;                       ///< DatabaseGroup index
  std::string pool_key;                        ///< what determines the grasp pools
  bool shared_pool = false;                    ///< protocol "shared_pool": one pool per object
  bool hide_each = false;                      ///< hidden = "each": the explored object masked
                                               ///< out of the recognizer in its own runs
  bool known_each = false;                     ///< database = "each": the explored object alone
                                               ///< unmasked in its own runs
  datasets::SimulatorSettings simulation;      ///< without grasps count and seed
  RecognizerSettings recognizer;
  double contact_voxel = 0.002;                ///< m, voxel filter of the cumulative contacts
  bool active = false;                         ///< exploration.strategy = active
  ActiveSettings planner;                      ///< the next-grasp planner's settings
  bool truth_pose = false;                     ///< diagnostics.truth_pose
  double oracle_belief = 0.0;                  ///< diagnostics.oracle_belief
  /// The calibration's answer sets for this variant's simulation (nullptr: no set answers).
  const AnswerSetCalibration* answer_sets = nullptr;
};

std::size_t index_of(const std::vector<std::string>& names, const std::string& name) {
  const auto it = std::find(names.begin(), names.end(), name);
  if (it == names.end()) throw Error("unknown object '" + name + "'", {}, "objects");
  return static_cast<std::size_t>(it - names.begin());
}

class RecognitionEngine final : public RunEngine {
 public:
  RecognitionEngine(const ExperimentConfig& config, EngineDatabase database, int threads,
                    std::function<void(const std::string&)> note)
      : config_(config), note_(std::move(note)), db_(std::move(database)) {
    if (!db_.source || !db_.load_mesh) throw Error("the experiment has no database", {}, "--db");
    reader_ = db_.source;
    std::vector<std::string> names;
    for (std::size_t i = 0; i < reader_->size(); ++i) names.push_back(reader_->info(i).name);

    const std::vector<Variant> variants = expand_variants(config);
    std::map<std::vector<std::size_t>, std::size_t> group_of;
    for (const Variant& v : variants) {
      const ResolvedObjects r = resolve_objects(v.config, names);
      if (explored_.empty()) {
        explored_ = r.explored;
      } else if (explored_ != r.explored) {
        throw Error("sweep variants must explore the same objects", {}, "objects");
      }
      std::vector<std::size_t> objects;
      for (const auto& n : r.database) objects.push_back(index_of(names, n));
      // The recognizer sees its objects in the file's order (the whole file: the file itself),
      // so an experiment over the full database recognizes exactly as `touchstone recognize`.
      std::sort(objects.begin(), objects.end());
      const MethodSettings ms = method_settings(v.config);
      const RecognizerSettings& rs = ms.recognizer;
      const bool surface = needs_surface(rs, reader_->settings());
      const std::string db_label = db_.description.value("path", std::string("database"));
      auto [it, inserted] = group_of.emplace(objects, groups_.size());
      if (!inserted && surface && !groups_[it->second].database->surface()) {
        // A later variant needs the fine clouds the group's first one did not: load them too.
        groups_[it->second].database->set_surface(true);
        experiments::set_memory_budget(*groups_[it->second].database, config.memory_budget_mb, db_label, "memory_budget_mb");
      }
      if (inserted) {
        DatabaseGroup g;
        g.objects = objects;
        for (std::size_t i = 0; i < objects.size(); ++i) {
          g.to_file.push_back(static_cast<std::int32_t>(objects[i]));
          g.to_local[objects[i]] = static_cast<std::uint32_t>(i);
        }
        std::shared_ptr<const ObjectSource> source;
        if (objects.size() == reader_->size())
          source = reader_;
        else
          source = std::make_shared<SubsetSource>(reader_, objects);
        {  // classes of congruent objects among the group's, by the database's recorded classes
          std::vector<std::vector<std::size_t>> members;
          if (db_.description.is_object() && db_.description.contains("congruent_classes"))
            for (const auto& names_of_class : db_.description["congruent_classes"]) {
              std::vector<std::size_t> m;
              for (const auto& n : names_of_class) {
                const auto local = g.to_local.find(index_of(names, n.get<std::string>()));
                if (local != g.to_local.end()) m.push_back(local->second);
              }
              members.push_back(std::move(m));
            }
          g.class_of = class_indices(objects.size(), members, g.classes);
        }
        g.database = std::make_unique<Database>(source);
        g.database->set_surface(surface);
        experiments::set_memory_budget(*g.database, config.memory_budget_mb, db_label, "memory_budget_mb");
        groups_.push_back(std::move(g));
      }
      VariantData d;
      d.config = v.config;
      d.group = it->second;
      d.simulation = simulation_settings(v.config);
      d.pool_key = pool_key(d.simulation);
      d.shared_pool = v.config.protocol == "shared_pool";
      d.hide_each = r.hide_each;
      d.known_each = r.known_each;
      d.recognizer = rs;
      d.contact_voxel = ms.contact_voxel;
      d.active = ms.exploration == 1;
      d.planner = ms.active;
      d.truth_pose = ms.truth_pose;
      d.oracle_belief = ms.oracle_belief;
      if (d.oracle_belief > 0 && !d.active)
        throw Error("diagnostics.oracle_belief plans with the truth in the belief: it needs exploration.strategy = "
                    "\"active\"", {}, "diagnostics.oracle_belief");
      truth_pose_ = truth_pose_ || d.truth_pose;
      if (d.active && d.simulation.sensing == Sensing::probe)
        throw Error("active exploration plans grasps of a gripper with pads, not probe touches", {},
                    "exploration.strategy");
      variants_.push_back(std::move(d));
      labels_.push_back(v.label);
      configs_.push_back(to_json(v.config).dump());
    }
    for (const auto& n : explored_) explored_file_.push_back(index_of(names, n));

    header_.config_json = to_json(config).dump();
    nlohmann::ordered_json db = db_.description;
    if (!db.is_object() || !db.contains("fingerprint")) db["fingerprint"] = source_fingerprint(*reader_);
    // The confidence model, fitted for this database (checked: another database's or version's
    // file is an error naming the file and the key).
    if (!config.calibration.empty()) {
      calibration_ = read_calibration(config.calibration, db["fingerprint"].get<std::string>());
      // Set answers hold for runs simulated as the calibration runs were.
      // Set answers hold for runs simulated as the calibration runs were: each variant takes the
      // entry of its simulation (a calibration fitted on a noise sweep holds one per level).
      if (!calibration_->answer_sets.empty())
        for (std::size_t k = 0; k < variants_.size(); ++k) {
          const auto sim = simulation_of(nlohmann::ordered_json::parse(configs_[k]));
          variants_[k].answer_sets = calibration_->answer_sets_for(sim);
          if (!variants_[k].answer_sets) {
            throw Error("the calibration's answer sets were calibrated on runs simulated with " +
                        calibration_->answer_set_simulations() + ", variant '" +
                        labels_[k] + "' simulates " + sim.dump() + ": calibrate on runs like these",
                        config.calibration, "answer_sets");
          }
        }
    }
    header_.database_json = db.dump();
    nlohmann::ordered_json ver;
    ver["touchstone"] = TS_VERSION;
    ver["compiler"] = __VERSION__;
    ver["tbb"] = TBB_VERSION_STRING;
    ver["eigen"] = std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) +
                   "." + std::to_string(EIGEN_MINOR_VERSION);
#ifdef NDEBUG
    ver["build"] = "release";
#else
    ver["build"] = "debug";
#endif
    ver["threads"] = threads;
    ver["schedule"] = config.schedule;
    header_.versions_json = ver.dump();
    header_.machine = experiments::machine_description();
    header_.steps = config.steps;
    header_.variant_labels = labels_;
    header_.variant_configs = configs_;
    header_.objects = explored_;
    header_.database_objects = names;
    header_.stages = recognition_stages();
    header_.step_values = recognition_step_values();
    if (truth_pose_)
      header_.step_values.insert(header_.step_values.end(), truth_pose_step_values().begin(),
                                 truth_pose_step_values().end());
  }

  const io::RunStoreHeader& header() const override { return header_; }

  void prepare(const std::vector<RunTask>& tasks) override {
    // Shared pools (protocol shared_pool): one per (noise/sensor setting, explored object) that
    // some task needs, simulated here. Independent runs simulate their own grasps in run().
    std::set<std::pair<std::string, int>> needed;
    std::set<std::size_t> groups;
    for (const RunTask& t : tasks) {
      const VariantData& v = variants_[static_cast<std::size_t>(t.variant)];
      if (v.shared_pool) needed.insert({v.pool_key, t.object});
      groups.insert(v.group);
    }
    std::vector<std::pair<std::string, int>> todo;
    for (const auto& k : needed)
      if (!pools_.count(k)) todo.push_back(k);
    if (lazy_pools_) todo.clear();   // each simulated by the first run that needs it (pool())
    if (!todo.empty()) {
      if (note_) note_("Simulating " + std::to_string(todo.size()) + " grasp pool(s) of " +
                       std::to_string(config_.pool) + " grasps...");
      std::vector<TactileLog> results(todo.size());
      const auto start = Clock::now();
      tbb::parallel_for(std::size_t{0}, todo.size(), [&](std::size_t i) { results[i] = simulate_pool(todo[i]); });
      for (std::size_t i = 0; i < todo.size(); ++i) pools_.emplace(todo[i], std::move(results[i]));
      if (note_) {
        std::ostringstream s;
        s.precision(3);
        s << "  pools ready in " << seconds_since(start) << " s";
        note_(s.str());
      }
    }
    // The search structures of the databases in use: a FLANN index only where a variant searches
    // with one (the paper's preset; one per index setting), a FeatureTable per object mask for the others, held for the
    // whole experiment. An unused index of 4 500 objects held 2.9 GB and took minutes to build,
    // and a table rebuilt for every run cost 3 GB of churn and seconds per run.
    for (std::size_t g : groups) {
      DatabaseGroup& group = groups_[g];
      std::set<std::vector<std::uint8_t>> masks;   // one table per object mask
      for (const VariantData& v : variants_) {
        if (v.group != g) continue;
        if (auto prior = Recognizer::shape_prior(*group.database, v.recognizer)) group.priors.push_back(std::move(prior));
        if (auto t = Recognizer::sparse_tables(*group.database, v.recognizer)) group.sparse_tables.push_back(std::move(t));
        if (v.recognizer.ransac.feature_table) {
          if (!masks.insert(v.recognizer.objects).second) continue;
          if (note_) note_("Building the feature table of a " + std::to_string(group.objects.size()) + "-object database...");
          group.tables.push_back(FeatureTable::shared(*group.database, v.recognizer.objects));
        } else if (!group.index_for(v.recognizer.index)) {   // a sweep of index.* builds one per setting
          if (note_) note_("Building the feature index of a " + std::to_string(group.objects.size()) + "-object database...");
          group.indices.emplace_back(v.recognizer.index, std::make_shared<const FeatureIndex>(
                                                             build_feature_index(*group.database, v.recognizer.index)));
        }
      }
    }
    // Symmetries and model samples of the explored objects.
    std::set<int> objects;
    for (const RunTask& t : tasks) objects.insert(t.object);
    if (note_) note_("Finding the symmetries of " + std::to_string(objects.size()) + " object(s)...");
    std::vector<int> list(objects.begin(), objects.end());
    std::vector<std::unique_ptr<ObjectTruthModel>> models(list.size());
    tbb::parallel_for(std::size_t{0}, list.size(), [&](std::size_t i) {
      if (truth_models_.count(list[i])) return;
      const std::size_t file = explored_file_[static_cast<std::size_t>(list[i])];
      models[i] = std::make_unique<ObjectTruthModel>(truth_model(reader_->load_fine(file)));
    });
    for (std::size_t i = 0; i < list.size(); ++i)
      if (models[i]) truth_models_.emplace(list[i], std::move(models[i]));
  }

  std::optional<io::RunRecord> run(const RunTask& task, const std::atomic<bool>* stop) override {
    const VariantData& v = variants_.at(static_cast<std::size_t>(task.variant));
    const DatabaseGroup& group = groups_[v.group];
    const std::string& name = explored_.at(static_cast<std::size_t>(task.object));
    const ObjectTruthModel& model = *truth_models_.at(task.object);
    const std::size_t file_index = explored_file_[static_cast<std::size_t>(task.object)];
    // Open set: a hidden object is not in the recognizer's database, or (leave-one-out) masked out
    // of it in its own runs; no answer can then be right.
    const auto found = group.to_local.find(file_index);
    const bool hidden = found == group.to_local.end() || v.hide_each;
    const std::uint32_t local_true = found == group.to_local.end() ? std::numeric_limits<std::uint32_t>::max()
                                                                    : found->second;

    io::RunRecord rec;
    rec.variant = task.variant;
    rec.object = task.object;
    rec.run = task.run;
    rec.grasps = draw_grasps(config_.seed, name, task.run, v.config.pool, v.config.steps);
    // The run's log: the drawn grasps of its pool, in order.
    TactileLog log = v.shared_pool ? log_from_pool(pool({v.pool_key, task.object}), rec.grasps)
                                   : simulate_run_log(v, task, rec.grasps);
    rec.truth = log.truth->object_pose;
    // Active exploration: the first grasp is the run's first drawn grasp; each later one is the
    // planner's choice among the pool's other grasps (the operator's aims, scored on the
    // recognizer's state), executed on the true object by the run's own simulator: the same
    // object pose, gains and per-grasp noise streams as the random runs' pool.
    std::optional<datasets::Simulator> simulator;
    std::optional<GraspPlanner> planner;
    if (v.active) {
      datasets::SimulatorSettings ss = v.simulation;
      ss.seed = pool_seed(config_.seed, name, v.shared_pool ? std::nullopt : std::optional<int>(task.run));
      simulator.emplace(db_.load_mesh(file_index), name, log.gripper, ss);
      planner.emplace(log.gripper, v.planner);
      log.grasps.resize(1);
      log.truth->arm_poses.resize(1);
      if (!log.truth->joints.empty()) log.truth->joints.resize(1);
    }
    const PlanObjects plan_objects = database_plan_objects(*group.database);
    std::set<std::size_t> used;                          // pool grasps executed so far
    std::vector<std::optional<GraspCommand>> aims;       // the operator's aims, by pool grasp
    if (v.active) {
      used.insert(static_cast<std::size_t>(rec.grasps.front()));
      aims.resize(static_cast<std::size_t>(v.config.pool));
    }

    RecognizerSettings rs = v.recognizer;
    if (v.known_each) {
      rs.objects.assign(group.objects.size(), 0);
      rs.objects.at(local_true) = 1;
    }
    if (v.hide_each) {
      rs.objects.assign(group.objects.size(), 1);
      rs.objects.at(local_true) = 0;
    }
    rs.seed = Rng(config_.seed, kRecognizerStream, name_hash(name), static_cast<std::uint64_t>(task.run)).next();
    Recognizer recognizer(*group.database, rs.ransac.feature_table ? nullptr : group.index_for(rs.index), rs);
    if (v.truth_pose && !hidden) recognizer.watch(local_true, rec.truth);
    ExplorationSettings es;  // as `touchstone recognize`: B from the database's largest object
    es.contact_voxel = v.contact_voxel;
    es.free.res_free = rs.evaluate.res_free;
    es.free.s_obj_max = largest_object_extent(*group.database);
    Exploration exploration(log, es);
    // A scene's support, and everything in it but the target (the support and a cluttered
    // scene's neighbours), to tell which contacts truly touched the target (attribution).
    std::optional<MeshIndex> support, others;
    std::vector<std::string> neighbour_names;
    if (log.truth && !log.truth->support.faces.empty()) {
      support.emplace(log.truth->support);
      if (!log.truth->neighbours.empty()) {
        Mesh all = log.truth->support;
        for (const LogGroundTruth::Neighbour& n : log.truth->neighbours) {
          const int base = static_cast<int>(all.vertices.size());
          all.vertices.insert(all.vertices.end(), n.mesh.vertices.begin(), n.mesh.vertices.end());
          for (const auto& f : n.mesh.faces) all.faces.push_back(f + Eigen::Vector3i::Constant(base));
          neighbour_names.push_back(n.name);
        }
        others.emplace(std::move(all));
      }
    }
    const MeshIndex* off_target_surfaces = others ? &*others : support ? &*support : nullptr;
    const auto run_start = Clock::now();
    std::vector<Vec3> contacts_so_far;   // active: the contact cloud of the previous step
    const double nan = std::numeric_limits<double>::quiet_NaN();
    double previous_entropy = nan;       // of the posterior over objects after the previous step
    for (int k = 1; k <= v.config.steps; ++k) {
      if (stop && stop->load()) return std::nullopt;
      double plan_s = 0.0;
      double expected_information = nan, expected_object_information = nan;   // the chosen grasp's
      if (v.active && k > 1) {
        // The operator's aims at the pool's grasps not yet executed (as many as
        // active.candidates, a seeded choice when more remain), ranked by the planner on the
        // state after the previous step; the best one is executed. Nothing to plan from (no
        // hypothesis yet): the drawn grasp.
        std::size_t g = static_cast<std::size_t>(rec.grasps.at(static_cast<std::size_t>(k - 1)));
        if (used.count(g) || !recognizer.hypotheses().empty()) {
          const auto tp = Clock::now();
          const std::uint64_t seed =
              Rng(config_.seed, kPlannerStream, name_hash(name), static_cast<std::uint64_t>(task.run) * 4096u + k).next();
          std::vector<std::size_t> unused;
          for (std::size_t i = 0; i < aims.size(); ++i)
            if (!used.count(i)) unused.push_back(i);
          Rng pick(seed);
          for (std::size_t i = unused.size(); i > 1; --i) std::swap(unused[i - 1], unused[pick.index(i)]);
          if (unused.size() > v.planner.candidates) unused.resize(v.planner.candidates);
          std::sort(unused.begin(), unused.end());
          tbb::parallel_for(std::size_t{0}, unused.size(), [&](std::size_t i) {
            if (!aims[unused[i]]) aims[unused[i]] = simulator->aim(unused[i]);
          });
          if (!recognizer.hypotheses().empty()) {
            std::vector<GraspCommand> commands;
            for (std::size_t i : unused) commands.push_back(*aims[i]);
            const auto scored =
                planner->evaluate(commands, v.oracle_belief > 0 && !hidden ? with_leader(recognizer.hypotheses(), local_true, rec.truth, v.oracle_belief, v.planner.temperature)
                                                                : recognizer.hypotheses(),
                                  plan_objects, contacts_so_far);
            std::size_t best = 0;
            for (std::size_t i = 1; i < scored.size(); ++i)
              if (scored[i].score > scored[best].score) best = i;
            g = unused.at(best);
            expected_information = scored[best].information;
            expected_object_information = scored[best].object_information;
          } else {
            g = unused.front();   // the drawn grasp was executed already: the first unused one
          }
          plan_s = seconds_since(tp);
        }
        used.insert(g);
        rec.grasps[static_cast<std::size_t>(k - 1)] = static_cast<std::int32_t>(g);
        datasets::Simulator::Grasp next = simulator->grasp(g);
        log.grasps.push_back(std::move(next.measured));
        log.truth->arm_poses.push_back(next.true_arm_pose);
        if (!next.true_joints.empty()) log.truth->joints.push_back(next.true_joints);
      }
      const auto t0 = Clock::now();
      exploration.advance_to(static_cast<std::size_t>(k));
      const PointCloud contacts = exploration.contact_cloud();
      if (v.active) contacts_so_far = contacts.points;
      const PointCloud free = exploration.free_cloud();
      const GraspGroups& grasps = exploration.grasp_groups();  // unused when the offsets are off
      const double fusion_s = seconds_since(t0);
      const auto t1 = Clock::now();
      const StepResult sr = recognizer.step(contacts, free.points, grasps);
      double recognize_s = seconds_since(t1);
      if (sr.watched) recognize_s = std::max(0.0, recognize_s - sr.watched->diagnostic_s);

      io::RunStepRecord s;
      s.hypotheses = static_cast<std::int32_t>(sr.hypotheses.size());
      s.contacts = static_cast<std::int32_t>(sr.contacts);
      s.free_points = static_cast<std::int32_t>(sr.free_points);
      if (sr.valid) {
        s.best_object = group.to_file.at(sr.best.object);
        s.correct = !hidden && sr.best.object == local_true;
        s.weight = sr.best.weight;
        s.posterior_best = sr.posterior;
        s.pose = sr.best.pose;
      }
      if (local_true < sr.posteriors.size()) {
        const double pt = sr.posteriors[local_true];
        s.posterior_true = pt;
        if (pt > 0.0) {
          s.true_rank = 1;
          for (double p : sr.posteriors) s.true_rank += p > pt ? 1 : 0;
        }
      }
      s.posterior_entropy = posterior_entropy(sr.posteriors);
      const double entropy_drop = previous_entropy - s.posterior_entropy;   // NaN at step 1
      previous_entropy = s.posterior_entropy;
      // The confidences (NaN without a calibration) and the features they come from.
      const std::vector<double> features = confidence_features(sr);
      s.values = {calibration_ ? calibration_->object_confidence(features) : nan,
                  calibration_ ? calibration_->pose_confidence(features) : nan};
      s.values.insert(s.values.end(), features.begin(), features.end());
      // Per pipeline stage: 1 ran, 0 left out (its scene did not need it), NaN not in the method.
      for (const std::string& stage : pipeline_stage_names()) {
        const auto g = std::find_if(sr.stages.begin(), sr.stages.end(), [&](const StageRun& x) { return x.name == stage; });
        s.values.push_back(g == sr.stages.end() ? nan : g->ran ? 1.0 : 0.0);
      }
      // Set answers: the true class's log-weight gap to the answer (what `calibrate` fits on; NaN for a hidden
      // object), and with a calibration's answer sets the set's size and whether it holds the truth.
      const std::vector<double> gaps = class_log_weight_gaps(sr, group.class_of, group.classes);
      s.values.push_back(hidden ? nan : gaps.at(group.class_of.at(local_true)));
      if (v.answer_sets) {
        const AnswerSetCalibration& a = *v.answer_sets;
        const AnswerSet set = conformal_set(gaps, a.at(k), a.alpha);
        const bool covers = set.informative ? std::any_of(set.members.begin(), set.members.end(), [&](const AnswerSetMember& m) {
          return !hidden && m.cls == group.class_of.at(local_true);
        }) : !hidden;
        s.values.insert(s.values.end(), {static_cast<double>(set.size), covers ? 1.0 : 0.0, set.informative ? 1.0 : 0.0});
      } else {
        s.values.insert(s.values.end(), {nan, nan, nan});
      }
      // Active touch: what the planner expected of the grasp it chose (nats; NaN when it did not
      // choose) and what the step gave: the drop of the posterior's entropy over objects.
      s.values.insert(s.values.end(), {expected_information, expected_object_information, entropy_drop});
      // How well the answer explains the contacts, as on real data without a truth (what
      // `recognize` prints as contact_model_distance_m).
      s.values.push_back(sr.valid && !contacts.empty()
                             ? mean_contact_distance(*group.database->geometry(sr.best.object), sr.best.pose,
                                                     contacts.points)
                             : nan);
      // A scene's contacts: the share truly off the target (nearer the support than the object
      // at its true pose), and the share the step's attribution labelled right, target or not.
      {
        double right_share = nan, off_share = nan;
        if (off_target_surfaces && !hidden && !contacts.empty()) {
          const GeometryRef truth_geo = group.database->geometry(local_true);
          std::vector<double> d(contacts.size());
          truth_geo->field.distances(contacts.points.data(), contacts.size(), rec.truth.inverse(), d.data());
          std::size_t off = 0, right = 0;
          const bool labelled = sr.attribution.size() == contacts.size();
          for (std::size_t i = 0; i < contacts.size(); ++i) {
            const bool on_target = std::abs(d[i]) <= off_target_surfaces->closest(contacts.points[i]).distance;
            off += on_target ? 0 : 1;
            right += labelled && (sr.attribution[i] == ContactLabel::object) == on_target ? 1 : 0;
          }
          const double n = static_cast<double>(contacts.size());
          off_share = static_cast<double>(off) / n;
          if (labelled) right_share = static_cast<double>(right) / n;
        }
        s.values.insert(s.values.end(), {right_share, off_share});
        // A cluttered scene: whether the step named one of the neighbours (NaN without them).
        s.values.push_back(neighbour_names.empty() || !sr.valid ? nan
                           : std::find(neighbour_names.begin(), neighbour_names.end(),
                                       group.database->info(sr.best.object).name) != neighbour_names.end()
                               ? 1.0
                               : 0.0);
        // The support the step found against the true one under the object: found (NaN: not
        // looked for), its tilt (degrees) and its height there (m, signed, up positive).
        const bool looked = std::any_of(sr.stages.begin(), sr.stages.end(), [](const StageRun& x) {
          return x.name == "support" && x.ran;
        });
        double found = looked ? (sr.support.found ? 1.0 : 0.0) : nan, tilt = nan, height = nan;
        if (support && sr.support.found) {
          const ClosestPoint under = support->closest(rec.truth.translation());
          const Vec3 found_normal = sr.support.normal_at(under.point);
          tilt = std::acos(std::min(1.0, std::abs(under.normal.dot(found_normal)))) * 180.0 / std::numbers::pi;
          height = sr.support.signed_distance(under.point);
        }
        // Why it was not found (SupportVerdict's code; NaN: not looked for).
        s.values.insert(s.values.end(), {found, tilt, height, looked ? static_cast<double>(sr.support.verdict) : nan});
      }
      if (truth_pose_) {
        const std::optional<Funnel>& f = sr.watched;
        if (f && f->truth_pose_evaluated) {
          s.values.insert(s.values.end(), {f->truth_pose_wins ? 1.0 : 0.0, f->truth_pose_log_weight,
                                           f->answer_log_weight, f->truth_pose_twin_score, f->rival_twin_score});
        } else {
          s.values.insert(s.values.end(), truth_pose_step_values().size(), nan);
        }
      }

      const PoseError e = pose_error(s.pose, rec.truth, &model.symmetry);
      s.position_error_m = e.position_m;
      s.orientation_error_rad = e.orientation_deg * std::numbers::pi / 180.0;
      s.symmetric_orientation_error_rad = e.symmetric_orientation_deg * std::numbers::pi / 180.0;
      s.mssd_m = group_mssd(s.pose, rec.truth, model);
      s.time_s = fusion_s + recognize_s + plan_s;
      const StageTimes& t = sr.times;
      const double known = t.prepare_s + t.prune_s + t.register_s + t.icp_s + t.evaluate_s;
      s.stage_times_s = {fusion_s, t.prepare_s, t.prune_s, t.register_s, t.icp_s, t.evaluate_s,
                         std::max(0.0, recognize_s - known), plan_s};
      rec.steps.push_back(std::move(s));
    }
    rec.wall_time_s = seconds_since(run_start);
    return rec;
  }

 private:
  ExperimentConfig config_;
  std::function<void(const std::string&)> note_;
  EngineDatabase db_;
  std::shared_ptr<const ObjectSource> reader_;
  std::vector<std::string> explored_;
  std::vector<std::size_t> explored_file_;
  std::vector<DatabaseGroup> groups_;
  std::vector<VariantData> variants_;
  bool truth_pose_ = false;                    ///< some variant sets diagnostics.truth_pose
  std::vector<std::string> labels_, configs_;
  io::RunStoreHeader header_;
  std::map<std::pair<std::string, int>, TactileLog> pools_;   // simulated by prepare()
  /// With lazy pools (prepare_lazily), a pool is simulated by the first run that needs it.
  struct LazyPool {
    std::once_flag once;
    TactileLog log;
  };
  bool lazy_pools_ = false;
  std::mutex lazy_mutex_;
  std::map<std::pair<std::string, int>, LazyPool> lazy_;

  /// The grasp pool of (pool key, explored object): the same log however and wherever it is
  /// simulated (its seed depends only on the experiment's seed and the object's name).
  TactileLog simulate_pool(const std::pair<std::string, int>& key) const {
    const VariantData* v = nullptr;
    for (const VariantData& d : variants_)
      if (d.shared_pool && d.pool_key == key.first) {
        v = &d;
        break;
      }
    if (!v) throw Error("no variant simulates the grasp pool " + key.first, {}, "pool");
    datasets::SimulatorSettings s = v->simulation;
    const std::string& name = explored_[static_cast<std::size_t>(key.second)];
    s.seed = pool_seed(config_.seed, name, std::nullopt);
    const std::size_t file = explored_file_[static_cast<std::size_t>(key.second)];
    s.neighbours = neighbours_of(s.scene, file, s.seed);
    datasets::Simulator sim(db_.load_mesh(file), name, Gripper(), s);
    TactileLog log = sim.run().log;
    if (!log.truth) throw Error("the simulator gave no ground truth", {}, name);
    return log;
  }

  const TactileLog& pool(const std::pair<std::string, int>& key) {
    if (const auto it = pools_.find(key); it != pools_.end()) return it->second;
    LazyPool* entry = nullptr;
    {
      std::lock_guard<std::mutex> lock(lazy_mutex_);
      entry = &lazy_[key];   // std::map nodes stay where they are
    }
    // Isolated: while the simulator's parallel loop waits, this thread must not pick up another
    // run (which could need this same pool and enter call_once again: a deadlock).
    std::call_once(entry->once, [&] { tbb::this_task_arena::isolate([&] { entry->log = simulate_pool(key); }); });
    return entry->log;
  }

 public:
  void prepare_lazily(const std::vector<RunTask>& tasks) override {
    lazy_pools_ = true;
    prepare(tasks);
  }

 private:
  std::map<int, std::unique_ptr<ObjectTruthModel>> truth_models_;
  std::optional<Calibration> calibration_;

  /// Protocol "independent": the run's own pool (grasp_pools.hpp).
  TactileLog simulate_run_log(const VariantData& v, const RunTask& task,
                              const std::vector<std::int32_t>& grasps) const {
    const auto object = static_cast<std::size_t>(task.object);
    const std::string& name = explored_.at(object);
    const std::uint64_t seed = pool_seed(config_.seed, name, task.run);
    datasets::SimulatorSettings s = v.simulation;
    s.neighbours = neighbours_of(s.scene, explored_file_.at(object), seed);
    return simulate_run_pool(db_.load_mesh(explored_file_.at(object)), name, s, seed, grasps);
  }

  /// A cluttered scene's neighbours around database object `file` (none for another scene),
  /// drawn from the whole database file by the pool's seed.
  std::vector<datasets::SceneObject> neighbours_of(const datasets::SceneSettings& scene, std::size_t file,
                                                   std::uint64_t seed) const {
    return datasets::scene_neighbours(scene, db_.source->size(), file, seed, [&](std::size_t i) {
      return datasets::SceneObject{db_.source->info(i).name, db_.load_mesh(i)};
    });
  }
};

}  // namespace

const std::vector<std::string>& recognition_step_values() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n{"confidence_object", "confidence_pose"};
    for (const std::string& f : confidence_feature_names()) n.push_back("feature." + f);
    for (const std::string& stage : pipeline_stage_names()) n.push_back("ran." + stage);
    n.insert(n.end(), {"set.truth_score", "answer_set.size", "answer_set.covers", "answer_set.informative",
                       "plan.expected_information", "plan.expected_object_information", "plan.entropy_drop",
                       "fit.contact_distance_m", "attribution.right_share", "contacts.off_target_share",
                       "scene.answer_is_neighbour", "support.found", "support.tilt_deg", "support.height_error_m",
                       "support.verdict"});
    return n;
  }();
  return names;
}

const std::vector<std::string>& truth_pose_step_values() {
  static const std::vector<std::string> names{"truth_pose.wins", "truth_pose.log_weight",
                                              "truth_pose.answer_log_weight", "truth_pose.twin_score",
                                              "truth_pose.rival_twin_score"};
  return names;
}

const std::vector<std::string>& recognition_stages() {
  static const std::vector<std::string> stages{"fusion", "prepare", "prune", "register",
                                               "icp", "evaluate", "other", "plan"};
  return stages;
}

std::unique_ptr<RunEngine> make_recognition_engine(const ExperimentConfig& config,
                                                   EngineDatabase database, int threads,
                                                   std::function<void(const std::string&)> note) {
  return std::make_unique<RecognitionEngine>(config, std::move(database), threads, std::move(note));
}

}  // namespace ts::experiments
