#include "experiments/recognition_engine.hpp"

#include "datasets/simulator.hpp"
#include "experiments/calibration.hpp"
#include "engine/feature_table.hpp"
#include "engine/fusion.hpp"
#include "engine/pose_error.hpp"
#include "engine/recognizer.hpp"
#include "engine/symmetry.hpp"
#include "experiments/cli_common.hpp"
#include "experiments/metrics.hpp"
#include "experiments/parameters.hpp"
#include "io/db_store.hpp"
#include "io/sha256.hpp"

#include <tbb/parallel_for.h>
#include <tbb/version.h>

#include <algorithm>
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

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr std::uint64_t kPoolStream = 0x706f6f6cULL;  // "pool"
constexpr std::uint64_t kRunPoolStream = 0x72706f6cULL;  // "rpol": a run's own pool (independent)
constexpr std::uint64_t kRecognizerStream = 0x72656367ULL;  // "recg"

/// A database restricted to some objects of another (study 4 and 7: smaller databases from the
/// same file). Index i here is objects[i] there.
class SubsetSource final : public ObjectSource {
 public:
  SubsetSource(std::shared_ptr<const ObjectSource> base, std::vector<std::size_t> objects)
      : base_(std::move(base)), objects_(std::move(objects)) {}
  std::size_t size() const override { return objects_.size(); }
  const ObjectInfo& info(std::size_t i) const override { return base_->info(objects_.at(i)); }
  const DatabaseSettings& settings() const override { return base_->settings(); }
  ObjectFeatures load_features(std::size_t i) const override { return base_->load_features(objects_.at(i)); }
  PointCloud load_coarse(std::size_t i) const override { return base_->load_coarse(objects_.at(i)); }
  PointCloud load_fine(std::size_t i) const override { return base_->load_fine(objects_.at(i)); }
  DistanceField load_field(std::size_t i) const override { return base_->load_field(objects_.at(i)); }

 private:
  std::shared_ptr<const ObjectSource> base_;
  std::vector<std::size_t> objects_;
};

/// One recognizer database (a subset of the file), shared by the variants that use it.
struct DatabaseGroup {
  std::vector<std::size_t> objects;            ///< file indices, in recognizer order
  std::vector<std::int32_t> to_file;           ///< recognizer index -> file index
  std::map<std::size_t, std::uint32_t> to_local;  ///< file index -> recognizer index
  std::unique_ptr<Database> database;
  std::shared_ptr<const FeatureIndex> index;   ///< built in prepare() where a variant needs it
  /// The FeatureTables of its variants (FeatureTable::shared keeps one only while it is held):
  /// built once in prepare(), not once per run.
  std::vector<std::shared_ptr<const FeatureTable>> tables;
};

struct VariantData {
  ExperimentConfig config;
  std::size_t group = 0;                       ///< DatabaseGroup index
  std::string pool_key;                        ///< what determines the grasp pools
  bool shared_pool = false;                    ///< protocol "shared_pool": one pool per object
  bool hide_each = false;                      ///< hidden = "each": the explored object masked
                                               ///< out of the recognizer in its own runs
  datasets::SimulatorSettings simulation;      ///< without grasps count and seed
  RecognizerSettings recognizer;
  double contact_voxel = 0.002;                ///< m, voxel filter of the cumulative contacts
};

/// The object's symmetries and a model sample, for the symmetry-aware errors and MSSD.
struct ObjectTruthModel {
  SymmetryGroup symmetry;
  std::vector<Pose> mssd_symmetries;           ///< discrete elements as object-frame transforms
  std::vector<Vec3> model_points;              ///< <= 500 points of the fine cloud
};

/// MSSD (BOP) for a symmetry group that may be continuous.
double group_mssd(const Pose& estimate, const Pose& truth, const ObjectTruthModel& m) {
  const SymmetryGroup& g = m.symmetry;
  if (g.kind == SymmetryGroup::Kind::spherical) {
    // Any rotation about the centre is a symmetry: the best one aligns the orientations, and
    // every point then moves by the displacement of the centre.
    return (estimate * g.centre - truth * g.centre).norm();
  }
  if (g.kind == SymmetryGroup::Kind::discrete) return mssd(estimate, truth, m.mssd_symmetries, m.model_points);
  // Axial: rotations about the axis (5-degree grid, then 0.25 degrees around the best) times
  // the discrete elements.
  auto at = [&](double angle) {
    const Mat3 spin = Eigen::AngleAxisd(angle, g.axis).toRotationMatrix();
    double best = std::numeric_limits<double>::infinity();
    for (const Mat3& r : g.rotations) {
      const Pose s = g.transform(spin * r);
      best = std::min(best, mssd(estimate, truth * s, {}, m.model_points));
    }
    return best;
  };
  const double coarse = 5.0 * std::numbers::pi / 180.0;
  double best = std::numeric_limits<double>::infinity(), best_angle = 0.0;
  for (int i = 0; i < 72; ++i) {
    const double v = at(i * coarse);
    if (v < best) best = v, best_angle = i * coarse;
  }
  for (int i = -20; i <= 20; ++i) best = std::min(best, at(best_angle + i * coarse / 20.0));
  return best;
}

datasets::SimulatorSettings simulation_settings(const ExperimentConfig& c) {
  datasets::SimulatorSettings s;
  s.sensors = c.sensors;
  s.noise = datasets::noise_profile(c.noise);
  const NoiseOverrides& n = c.noise_params;
  if (n.arm_position_sigma_m) s.noise.arm_position_sigma = *n.arm_position_sigma_m;
  if (n.arm_rotation_sigma_deg) s.noise.arm_rotation_sigma_deg = *n.arm_rotation_sigma_deg;
  if (n.sensel_noise) s.noise.signal_noise = *n.sensel_noise;
  if (n.force_noise) s.noise.force_noise = *n.force_noise;
  if (n.contact_sigma_m) s.noise.lateral_sigma = *n.contact_sigma_m;
  s.sensing = parse_sensing(c.sensing, {}, "sensing");
  if (s.sensing == Sensing::probe && n.contact_sigma_m) {   // the probe's own contact noise
    s.probe.contact_sigma = *n.contact_sigma_m;
    s.noise.lateral_sigma = 0.0;
  }
  s.grasps = static_cast<std::size_t>(c.pool);
  return s;
}

std::string pool_key(const datasets::SimulatorSettings& s) {
  std::ostringstream k;
  k.precision(17);
  k << s.noise.name << '|' << s.noise.arm_position_sigma << '|' << s.noise.arm_rotation_sigma_deg
    << '|' << s.noise.joint_sigma_deg << '|' << s.noise.signal_noise << '|' << s.noise.force_noise
    << '|' << s.noise.lateral_sigma << '|' << s.noise.fold_detect << '|' << s.sensors << '|'
    << s.grasps << '|' << to_string(s.sensing) << '|' << s.probe.contact_sigma;
  return k.str();
}

/// The method settings of a variant: the preset's, a probe's free-space defaults, then every
/// parameter the configuration sets (experiments/parameters.cpp).
MethodSettings method_settings(const ExperimentConfig& c) {
  MethodSettings m = MethodSettings::preset(c.preset);
  RecognizerSettings& s = m.recognizer;
  // A probe's path: free by the ball radius only, measured with the arm's error (sparse_hypotheses.hpp).
  if (c.sensing == "probe") {
    s.evaluate.d_thresh = kProbeFreeThreshold;
    s.evaluate.free_inside_penalty = true;
    s.evaluate.free_inside_margin = kProbeInsideMargin;
  }
  const auto method = parse_method(c.method);
  if (!method) throw Error("unknown method '" + c.method + "'", {}, "method");
  s.method = *method;
  for (const Parameter& p : method_parameters()) {
    const auto it = c.params.find(p.key);
    if (it != c.params.end()) apply(m, p, it->second);
  }
  return m;
}

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
        cli::set_memory_budget(*groups_[it->second].database, config.memory_budget_mb, db_label, "memory_budget_mb");
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
        g.database = std::make_unique<Database>(source);
        g.database->set_surface(surface);
        cli::set_memory_budget(*g.database, config.memory_budget_mb, db_label, "memory_budget_mb");
        groups_.push_back(std::move(g));
      }
      VariantData d;
      d.config = v.config;
      d.group = it->second;
      d.simulation = simulation_settings(v.config);
      d.pool_key = pool_key(d.simulation);
      d.shared_pool = v.config.protocol == "shared_pool";
      d.hide_each = r.hide_each;
      d.recognizer = rs;
      d.contact_voxel = ms.contact_voxel;
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
    if (!config.calibration.empty())
      calibration_ = read_calibration(config.calibration, db["fingerprint"].get<std::string>());
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
    header_.machine = cli::machine_description();
    header_.steps = config.steps;
    header_.variant_labels = labels_;
    header_.variant_configs = configs_;
    header_.objects = explored_;
    header_.database_objects = names;
    header_.stages = recognition_stages();
    header_.step_values = recognition_step_values();
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
    if (!todo.empty()) {
      if (note_) note_("Simulating " + std::to_string(todo.size()) + " grasp pool(s) of " +
                       std::to_string(config_.pool) + " grasps...");
      std::map<std::string, const VariantData*> by_key;
      for (const VariantData& v : variants_)
        if (v.shared_pool) by_key.emplace(v.pool_key, &v);
      std::vector<datasets::SimulationResult> results(todo.size());
      const auto start = Clock::now();
      tbb::parallel_for(std::size_t{0}, todo.size(), [&](std::size_t i) {
        const auto& [key, object] = todo[i];
        datasets::SimulatorSettings s = by_key.at(key)->simulation;
        const std::string& name = explored_[static_cast<std::size_t>(object)];
        s.seed = pool_seed(config_.seed, name, std::nullopt);
        datasets::Simulator sim(db_.load_mesh(explored_file_[static_cast<std::size_t>(object)]),
                                name, Gripper(), s);
        results[i] = sim.run();
      });
      for (std::size_t i = 0; i < todo.size(); ++i) {
        if (!results[i].log.truth)
          throw Error("the simulator gave no ground truth", {}, explored_[static_cast<std::size_t>(todo[i].second)]);
        pools_.emplace(todo[i], std::move(results[i].log));
      }
      if (note_) {
        std::ostringstream s;
        s.precision(3);
        s << "  pools ready in " << seconds_since(start) << " s";
        note_(s.str());
      }
    }
    // The search structures of the databases in use: a FLANN index only where a variant searches
    // with one (the paper's preset), a FeatureTable per object mask for the others, held for the
    // whole experiment. An unused index of 4 500 objects held 2.9 GB and took minutes to build,
    // and a table rebuilt for every run cost 3 GB of churn and seconds per run.
    for (std::size_t g : groups) {
      DatabaseGroup& group = groups_[g];
      std::set<std::vector<std::uint8_t>> masks;   // one table per object mask
      for (const VariantData& v : variants_) {
        if (v.group != g) continue;
        if (v.recognizer.ransac.feature_table) {
          if (!masks.insert(v.recognizer.objects).second) continue;
          if (note_) note_("Building the feature table of a " + std::to_string(group.objects.size()) + "-object database...");
          group.tables.push_back(FeatureTable::shared(*group.database, v.recognizer.objects));
        } else if (!group.index) {
          if (note_) note_("Building the feature index of a " + std::to_string(group.objects.size()) + "-object database...");
          group.index = std::make_shared<const FeatureIndex>(build_feature_index(*group.database, v.recognizer.index));
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
      const PointCloud fine = reader_->load_fine(file);
      auto m = std::make_unique<ObjectTruthModel>();
      KdTree3 tree(fine.points);
      m->symmetry = find_symmetries(fine.points, tree);
      for (const Mat3& r : m->symmetry.rotations) m->mssd_symmetries.push_back(m->symmetry.transform(r));
      const std::size_t stride = std::max<std::size_t>(1, fine.points.size() / 500);
      for (std::size_t k = 0; k < fine.points.size(); k += stride) m->model_points.push_back(fine.points[k]);
      models[i] = std::move(m);
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
    TactileLog log = v.shared_pool ? log_from_pool(pools_.at({v.pool_key, task.object}), rec.grasps)
                                   : simulate_run_log(v, task, rec.grasps);
    rec.truth = log.truth->object_pose;

    RecognizerSettings rs = v.recognizer;
    if (v.hide_each) {
      rs.objects.assign(group.objects.size(), 1);
      rs.objects.at(local_true) = 0;
    }
    rs.seed = Rng(config_.seed, kRecognizerStream, name_hash(name), static_cast<std::uint64_t>(task.run)).next();
    Recognizer recognizer(*group.database, group.index, rs);
    ExplorationSettings es;  // as `touchstone recognize`: B from the database's largest object
    es.contact_voxel = v.contact_voxel;
    es.free.res_free = rs.evaluate.res_free;
    es.free.s_obj_max = largest_object_extent(*group.database);
    Exploration exploration(log, es);
    const auto run_start = Clock::now();
    for (int k = 1; k <= v.config.steps; ++k) {
      if (stop && stop->load()) return std::nullopt;
      const auto t0 = Clock::now();
      exploration.advance_to(static_cast<std::size_t>(k));
      const PointCloud contacts = exploration.contact_cloud();
      const PointCloud free = exploration.free_cloud();
      const GraspGroups& grasps = exploration.grasp_groups();  // unused when the offsets are off
      const double fusion_s = seconds_since(t0);
      const auto t1 = Clock::now();
      const StepResult sr = recognizer.step(contacts, free.points, grasps);
      const double recognize_s = seconds_since(t1);

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
      for (double p : sr.posteriors)
        if (p > 0.0) s.posterior_entropy -= p * std::log(p);
      // The confidences (NaN without a calibration) and the features they come from.
      const std::vector<double> features = confidence_features(sr);
      const double nan = std::numeric_limits<double>::quiet_NaN();
      s.values = {calibration_ ? calibration_->object_confidence(features) : nan,
                  calibration_ ? calibration_->pose_confidence(features) : nan};
      s.values.insert(s.values.end(), features.begin(), features.end());
      const PoseError e = pose_error(s.pose, rec.truth, &model.symmetry);
      s.position_error_m = e.position_m;
      s.orientation_error_rad = e.orientation_deg * std::numbers::pi / 180.0;
      s.symmetric_orientation_error_rad = e.symmetric_orientation_deg * std::numbers::pi / 180.0;
      s.mssd_m = group_mssd(s.pose, rec.truth, model);
      s.time_s = fusion_s + recognize_s;
      const StageTimes& t = sr.times;
      const double known = t.prepare_s + t.prune_s + t.register_s + t.icp_s + t.evaluate_s;
      s.stage_times_s = {fusion_s, t.prepare_s, t.prune_s, t.register_s, t.icp_s, t.evaluate_s,
                         std::max(0.0, recognize_s - known)};
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
  std::vector<std::string> labels_, configs_;
  io::RunStoreHeader header_;
  std::map<std::pair<std::string, int>, TactileLog> pools_;
  std::map<int, std::unique_ptr<ObjectTruthModel>> truth_models_;
  std::optional<Calibration> calibration_;

  /// The drawn grasps of a shared pool, in the order drawn.
  static TactileLog log_from_pool(const TactileLog& pool, const std::vector<std::int32_t>& grasps) {
    TactileLog log;
    log.object = pool.object;
    log.noise = pool.noise;
    log.seed = pool.seed;
    log.gripper = pool.gripper;
    log.pads = pool.pads;
    log.gains = pool.gains;
    log.sensing = pool.sensing;   // a probe pool stays a probe log
    log.probe = pool.probe;
    LogGroundTruth truth;
    truth.object_pose = pool.truth->object_pose;
    for (std::int32_t g : grasps) {
      const auto gi = static_cast<std::size_t>(g);
      log.grasps.push_back(pool.grasps.at(gi));
      if (gi < pool.truth->arm_poses.size()) truth.arm_poses.push_back(pool.truth->arm_poses[gi]);
      if (gi < pool.truth->joints.size()) truth.joints.push_back(pool.truth->joints[gi]);
    }
    log.truth = std::move(truth);
    return log;
  }

  /// Protocol "independent": the run's own pool (object pose, gains, `pool` grasps) from its own
  /// seed; only the drawn grasps are simulated (a grasp depends on the seed and its index alone,
  /// so this equals picking them from the whole simulated pool). Nothing outlives the run.
  TactileLog simulate_run_log(const VariantData& v, const RunTask& task,
                              const std::vector<std::int32_t>& grasps) const {
    const auto object = static_cast<std::size_t>(task.object);
    const std::string& name = explored_.at(object);
    datasets::SimulatorSettings s = v.simulation;
    s.seed = pool_seed(config_.seed, name, task.run);
    s.grasps = 0;  // run() below gives the log's header (pose, gains) without grasps
    datasets::Simulator sim(db_.load_mesh(explored_file_.at(object)), name, Gripper(), s);
    TactileLog log = sim.run().log;
    if (!log.truth) throw Error("the simulator gave no ground truth", {}, name);
    std::vector<datasets::Simulator::Grasp> drawn(grasps.size());
    tbb::parallel_for(std::size_t{0}, grasps.size(),
                      [&](std::size_t i) { drawn[i] = sim.grasp(static_cast<std::size_t>(grasps[i])); });
    for (auto& g : drawn) {
      log.grasps.push_back(std::move(g.measured));
      log.truth->arm_poses.push_back(g.true_arm_pose);
      log.truth->joints.push_back(std::move(g.true_joints));
    }
    return log;
  }
};

}  // namespace

std::uint64_t pool_seed(std::uint64_t seed, const std::string& object, std::optional<int> run) {
  if (!run) return Rng(seed, kPoolStream, name_hash(object)).next();
  return Rng(seed, kRunPoolStream, name_hash(object), static_cast<std::uint64_t>(*run)).next();
}

const std::vector<std::string>& recognition_step_values() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n{"confidence_object", "confidence_pose"};
    for (const std::string& f : confidence_feature_names()) n.push_back("feature." + f);
    return n;
  }();
  return names;
}

const std::vector<std::string>& recognition_stages() {
  static const std::vector<std::string> stages{"fusion", "prepare", "prune", "register",
                                               "icp", "evaluate", "other"};
  return stages;
}

std::unique_ptr<RunEngine> make_recognition_engine(const ExperimentConfig& config,
                                                   EngineDatabase database, int threads,
                                                   std::function<void(const std::string&)> note) {
  return std::make_unique<RecognitionEngine>(config, std::move(database), threads, std::move(note));
}

std::string source_fingerprint(const ObjectSource& source) {
  io::Sha256 h;
  auto add = [&](const std::string& s) {
    h.update(s);
    h.update("\n");
  };
  std::ostringstream settings;
  settings.precision(17);
  const DatabaseSettings& d = source.settings();
  settings << d.max_extent << ' ' << d.fpfh.normal_radius << ' ' << d.fpfh.feature_radius;
  add(settings.str());
  for (std::size_t i = 0; i < source.size(); ++i) {
    const ObjectInfo& o = source.info(i);
    std::ostringstream s;
    s.precision(17);
    s << o.name << ' ' << o.mesh_sha256 << ' ' << o.scale << ' ' << o.fine_points << ' '
      << o.coarse_points;
    add(s.str());
  }
  return h.hex_digest();
}

std::string file_fingerprint(const io::DbReader& reader) {
  // The content fingerprint plus the build seeds: a rebuilt database with other seeds is another
  // database even when its names and sizes agree.
  io::Sha256 h;
  h.update(source_fingerprint(reader));
  h.update(std::to_string(reader.schema_version()) + " " + std::to_string(reader.build_seed()));
  for (std::size_t i = 0; i < reader.size(); ++i) h.update(" " + std::to_string(reader.object_seed(i)));
  return h.hex_digest();
}

EngineDatabase open_database(const std::filesystem::path& path) {
  auto reader = std::make_shared<io::DbReader>(path);
  EngineDatabase db;
  db.source = reader;
  db.load_mesh = [reader](std::size_t i) { return reader->load_mesh(i); };
  std::error_code ec;
  const auto absolute = std::filesystem::absolute(path, ec);
  db.description["path"] = ec ? path.string() : absolute.string();
  db.description["fingerprint"] = file_fingerprint(*reader);
  db.description["objects"] = reader->size();
  db.description["schema_version"] = reader->schema_version();
  db.description["build_seed"] = reader->build_seed();
  db.description["max_extent_m"] = reader->settings().max_extent;
  // Classes of congruent objects (names), which reports count class-aware rates with; absent
  // when the database recorded none.
  if (const io::CongruenceRecord* c = reader->congruence()) {
    nlohmann::ordered_json classes = nlohmann::ordered_json::array();
    for (const auto& members : c->classes()) {
      nlohmann::ordered_json names = nlohmann::ordered_json::array();
      for (std::size_t i : members) names.push_back(reader->info(i).name);
      classes.push_back(names);
    }
    db.description["congruent_classes"] = classes;
  }
  return db;
}

EngineDatabase memory_database(std::vector<BuiltObject> objects, const DatabaseSettings& settings) {
  auto meshes = std::make_shared<std::vector<Mesh>>();
  for (const BuiltObject& o : objects) meshes->push_back(o.mesh);
  EngineDatabase db;
  db.source = std::make_shared<MemorySource>(std::move(objects), settings);
  db.load_mesh = [meshes](std::size_t i) { return meshes->at(i); };
  db.description["path"] = "(memory)";
  db.description["fingerprint"] = source_fingerprint(*db.source);
  db.description["objects"] = db.source->size();
  return db;
}

}  // namespace ts::experiments
