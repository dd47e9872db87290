// `touchstone recognize`: recognize and localize the touched object, step by step, from a
// tactile log (or from a plain contact cloud as a single step without free space). Several
// logs or clouds (or a folder of clouds) are recognized in parallel in one process, sharing
// the loaded database; each input gets its own recognizer with the seed it would have alone.
#include "experiments/allocator.hpp"
#include "experiments/analysis/calibration.hpp"
#include "experiments/analysis/report.hpp"
#include "experiments/analysis/scene.hpp"
#include "experiments/cli/cli_common.hpp"
#include "experiments/cli/progress.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/resources.hpp"
#include "experiments/runs/log_steps.hpp"
#include "experiments/runs/recognition_engine.hpp"

#include "engine/database/feature_table.hpp"
#include "engine/database/symmetry_cache.hpp"
#include "engine/geometry/kabsch.hpp"
#include "engine/geometry/pose_error.hpp"
#include "engine/geometry/symmetry.hpp"
#include "engine/recognition/answer_set.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/touch/active_touch.hpp"
#include "engine/touch/fusion.hpp"
#include "io/cloud_io.hpp"
#include "io/db_store.hpp"
#include "io/log_store.hpp"
#include "io/result_store.hpp"

#include <nlohmann/json.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <numbers>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>

namespace ts::cli {

namespace {

namespace fs = std::filesystem;

struct RecognizeOptions {
  CommonOptions common;
  ProgressOptions progress;          ///< several inputs: --progress, --quiet
  std::string db, out, ground_truth, object;
  std::string calibration;           ///< --calibration: the confidence model (touchstone calibrate)
  std::optional<double> open_set_threshold;  ///< --open-set-threshold (unset: the calibration's)
  std::optional<double> alpha;               ///< --alpha: the answer sets' level (unset: the calibration's)
  std::vector<std::string> logs, clouds;  ///< --log files; --cloud files or folders
  std::string free;                  ///< --free: the free-space cloud of a single --cloud
  std::vector<std::string> only;     ///< --only: the objects the answer may name (empty: all)
  bool batch = false;                ///< several inputs (or a folder): per-input output
  std::string method = "bricpsf";
  std::string preset = "improved";   ///< improved | paper: the defaults the flags start from
  int steps = 0;                     ///< 0: every grasp of the log
  experiments::ParameterFlags flags;  ///< the method parameters' flags given (experiments/params/parameters.hpp)
  RecognizerSettings rs;             ///< the preset's method parameters with the flags applied
  double contact_voxel = 0.002;      ///< m, voxel filter of the cumulative contact cloud
  std::optional<double> memory_budget_mb;  ///< resident object geometry; unset: the default
  bool inside_margin = false;        ///< --free-inside-margin given (unset: 0; a probe: 1 cm)
  int suggest = 0;                   ///< --suggest N: the N best next grasps after the last step
  ActiveSettings active;             ///< the next-grasp planner's parameters (active.*)
  bool truth_pose = false;           ///< diagnostics.truth_pose: the truth_funnel's truth_pose_*
  bool explain = false;              ///< --explain: why the answer won over its best rival
  std::string scene;                 ///< --scene DIR: pictures of chosen steps (experiments/analysis/scene.hpp)
  std::vector<int> scene_steps;      ///< --scene-steps (empty: the last step)
  int exploration = 0;               ///< exploration.strategy (recorded; experiments act on it)
};

/// A 4x4 row-major object -> world matrix from a text file (whitespace or comma separated).
Pose read_ground_truth(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error("cannot open the ground-truth file", path);
  std::vector<double> v;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    for (char& c : line)
      if (c == ',' || c == ';' || c == '[' || c == ']') c = ' ';
    std::istringstream ls(line);
    std::string tok;
    while (ls >> tok) {
      char* end = nullptr;
      const double x = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || !std::isfinite(x))
        throw Error("not a finite number: '" + tok + "'", path, "line " + std::to_string(lineno));
      v.push_back(x);
    }
  }
  if (v.size() != 16)
    throw Error("expected 16 numbers (a 4x4 row-major matrix), found " + std::to_string(v.size()),
                path);
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) M(r, c) = v[static_cast<std::size_t>(4 * r + c)];
  if ((M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-6)
    throw Error("the last row must be 0 0 0 1", path, "line 4");
  const Mat3 R = M.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Mat3::Identity()).norm() > 1e-3 || R.determinant() < 0.0)
    throw Error("the upper-left 3x3 block is not a rotation", path);
  Pose T = Pose::Identity();
  T.linear() = rotation_from_covariance(R.transpose());  // the nearest rotation
  T.translation() = M.topRightCorner<3, 1>();
  return T;
}

nlohmann::ordered_json pose_json(const Pose& T) {
  Eigen::Quaterniond q(T.linear());
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Vec3 t = T.translation();
  return {{"t", {t.x(), t.y(), t.z()}}, {"q", {q.w(), q.x(), q.y(), q.z()}}};
}

/// The support a step found: its shape (a plane: normal . x = offset_m, normal up; a cylinder:
/// its axis, a point of it and its radius), the contacts and grasps it explains; null: none.
nlohmann::ordered_json support_json(const SupportSurface& u) {
  if (!u.found) return nullptr;
  nlohmann::ordered_json j;
  if (u.shape == SupportSurface::Shape::plane) {
    j["shape"] = "plane";
    j["normal"] = {u.normal.x(), u.normal.y(), u.normal.z()};
    j["offset_m"] = u.offset;
  } else {
    j["shape"] = "cylinder";
    j["axis"] = {u.axis.x(), u.axis.y(), u.axis.z()};
    j["point"] = {u.point.x(), u.point.y(), u.point.z()};
    j["radius_m"] = u.radius;
  }
  j["contacts"] = u.contacts_on;
  j["grasps"] = u.grasps_on;
  return j;
}

/// A step's attribution: counts, and the labels as one character a contact in the order of the
/// step's contact cloud (o: the object's, s: the support's, u: unexplained); null when the stage
/// "attribution" did not run.
nlohmann::ordered_json attribution_json(const std::vector<ContactLabel>& labels) {
  if (labels.empty()) return nullptr;
  std::size_t n[3] = {0, 0, 0};
  std::string text;
  for (ContactLabel l : labels) {
    ++n[static_cast<int>(l)];
    text += "osu"[static_cast<int>(l)];
  }
  return {{"object", n[0]}, {"support", n[1]}, {"unexplained", n[2]}, {"labels", text}};
}

nlohmann::ordered_json number_or_null(const std::optional<double>& x) {
  if (!x || !std::isfinite(*x)) return nullptr;
  return *x;
}

std::vector<std::pair<std::string, double>> params_of(const RecognizerSettings& s,
                                                     const RecognizeOptions& o) {
  experiments::MethodSettings m;
  m.recognizer = s;
  m.contact_voxel = o.contact_voxel;
  m.exploration = o.exploration;
  m.active = o.active;
  return experiments::stored_parameters(m);
}

/// One input of the command: a tactile log or a contact cloud.
struct Input {
  std::string path;
  bool is_log = true;
};

/// What every input shares: the options, the settings and the one loaded database.
struct Context {
  const RecognizeOptions& o;
  RecognizerSettings rs;
  const Database& db;
  double largest = 0.0;          ///< m, diagonal of the largest database object
  SymmetryCache& symmetries;     ///< thread-safe
  const io::CongruenceRecord* congruence = nullptr;   ///< the database's classes (null: not known)
  const experiments::Calibration* calibration = nullptr;  ///< --calibration (null: none)
  /// The calibration's answer sets for these contacts (null: no set answers; a calibration of
  /// several simulations names none for a log or a cloud).
  const experiments::AnswerSetCalibration* sets = nullptr;
  std::vector<std::uint32_t> class_of = {};  ///< object -> class of congruent objects (answer sets)
  std::size_t classes = 0;
};

/// The names of object i's congruent class (itself alone when in none, or when none are known).
nlohmann::ordered_json class_json(const Context& c, std::size_t i) {
  nlohmann::ordered_json names = nlohmann::ordered_json::array();
  for (std::size_t k : c.congruence ? c.congruence->class_of(i) : std::vector<std::size_t>{i})
    names.push_back(c.db.info(k).name);
  return names;
}

/// A step's set answer (the calibration's answer sets, at --alpha or the calibration's level), once
/// per step for the JSON and the result file.
struct StepSet {
  std::vector<double> gaps;          ///< per class
  const ConformalScores* scores;     ///< the calibration step's
  int calibrated_step;
  AnswerSet set;
};

StepSet step_set(const Context& c, const StepResult& r) {
  const experiments::AnswerSetCalibration& a = *c.sets;
  StepSet s{class_log_weight_gaps(r, c.class_of, c.classes), &a.at(r.step), a.calibrated_step(r.step), {}};
  s.set = conformal_set(s.gaps, *s.scores, c.o.alpha.value_or(a.alpha));
  return s;
}

/// The step's set answer (the calibration's answer sets, at --alpha or the calibration's level):
/// the classes of congruent objects that hold the truth with probability at least 1 - alpha, each
/// with its conformal p-value (it stays in the set for every alpha below it) and its log-weight gap
/// to the answer (null for a class without hypotheses, in the set by its shape-prior gap
/// "prior_gap"), or "informative": false when no class can be excluded.
nlohmann::ordered_json answer_set_json(const Context& c, const StepSet& s) {
  const AnswerSet& set = s.set;
  std::vector<std::vector<std::size_t>> members(c.classes);
  for (std::size_t i = 0; i < c.class_of.size(); ++i) members[c.class_of[i]].push_back(i);
  nlohmann::ordered_json j;
  j["alpha"] = set.alpha;
  j["informative"] = set.informative;
  j["size"] = set.size;
  j["calibrated_step"] = s.calibrated_step;
  j["members"] = nlohmann::ordered_json::array();
  for (const AnswerSetMember& m : set.members) {
    nlohmann::ordered_json names = nlohmann::ordered_json::array();
    for (std::size_t i : members[m.cls]) names.push_back(c.db.info(i).name);
    nlohmann::ordered_json member = {{"objects", names}, {"p_value", m.p_value}};
    if (outside_state(m.gap)) {   // no hypothesis in the state: there by the shape prior
      member["log_weight_gap"] = nullptr;
      member["prior_gap"] = m.gap - kOutsideState;
    } else {
      member["log_weight_gap"] = m.gap;
    }
    j["members"].push_back(std::move(member));
  }
  return j;
}

/// The same set for the result file: per object its class's p-value, gap and membership.
io::ResultAnswerSet stored_answer_set(const Context& c, const StepSet& s) {
  std::vector<std::uint8_t> member(c.classes, s.set.informative ? 0 : 1);
  for (const AnswerSetMember& m : s.set.members) member[m.cls] = 1;
  io::ResultAnswerSet out;
  out.informative = s.set.informative;
  out.size = s.set.size;
  out.calibrated_step = s.calibrated_step;
  for (const std::uint32_t k : c.class_of) {
    out.p_value.push_back(s.scores->p_value(s.gaps[k]));
    out.log_weight_gap.push_back(s.gaps[k]);
    out.in_set.push_back(member[k]);
  }
  return out;
}

/// One input's outcome.
struct InputRun {
  Input in;
  std::string truth_name;
  std::optional<Pose> truth_pose;
  std::vector<StepResult> results;
  std::vector<io::ResultStep> stored;
  std::vector<StepSet> sets;     ///< per step, with a calibration's answer sets (else empty)
  std::vector<double> fusion_time;
  std::vector<double> contact_distance;  ///< m, mean contact-to-model distance at each answer
  std::string written;           ///< the result file written ("" : none)
  std::string error;             ///< several inputs: why this one failed ("" : it did not)
  nlohmann::ordered_json suggestions;   ///< --suggest: the best next grasps (null: not asked)
  double suggest_time_s = 0.0;
  bool truth_outside = false;    ///< the log's object is not in the database (open set)
  std::vector<nlohmann::ordered_json> scenes;   ///< --scene: the chosen steps' scenes
};

/// The whole recognition of one input with its own recognizer (the context's seed), the result
/// file written to `out` when not empty. Throws ts::Error naming the input on bad input.
InputRun recognize_one(const Context& c, const Input& in, const std::string& out, bool progress) {
  const RecognizeOptions& o = c.o;
  const Database& db = c.db;
  InputRun run;
  run.in = in;

  // The input: a tactile log (K steps) or one contact cloud.
  std::optional<TactileLog> log;
  PointCloud single;
  std::optional<std::size_t> truth_object;
  int K = 1;
  if (in.is_log) {
    log = io::read_log(in.path);
    if (log->grasps.empty()) throw Error("the log has no grasps", in.path, "/grasps");
    const int n = static_cast<int>(log->grasps.size());
    if (o.steps > n)
      throw Error("--steps " + std::to_string(o.steps) + " exceeds the log's " + std::to_string(n) +
                      " grasps", in.path, "--steps");
    K = o.steps > 0 ? o.steps : n;
    if (log->truth) run.truth_pose = log->truth->object_pose;
    run.truth_name = log->object;
    if (!run.truth_name.empty()) {
      // An object outside the database (the open-set case) is recognized and scored: naming any
      // database object is then wrong.
      const std::size_t i = db.find(run.truth_name);
      if (i < db.size())
        truth_object = i;
      else
        run.truth_outside = true;
    }
  } else {
    single = io::read_cloud(in.path);
    if (o.steps > 1) throw Error("a contact cloud is one step", in.path, "--steps");
  }
  std::vector<Vec3> single_free;   // --free: a user's free-space cloud beside the contacts
  if (!o.free.empty()) {
    single_free = io::read_cloud(o.free).points;
    for (std::size_t i = 0; i < single_free.size(); ++i)
      if (!single_free[i].allFinite())
        throw Error("free-space point " + std::to_string(i) + " is not finite", o.free, "--free");
  }
  if (!o.ground_truth.empty()) run.truth_pose = read_ground_truth(o.ground_truth);
  if (!o.object.empty()) {
    const std::size_t i = db.find(o.object);
    if (i == db.size()) throw Error("no object '" + o.object + "' in the database", o.db, "--object");
    truth_object = i;
    run.truth_name = o.object;
  }

  // A probe's path: free by the ball radius only, unless the flags say otherwise (log_steps.hpp).
  const RecognizerSettings rs = log ? experiments::log_settings(c.rs, *log, o.inside_margin) : c.rs;
  Recognizer rec(db, rs);
  rec.explain(o.explain);
  if (truth_object)   // the JSON's truth_funnel (with --diagnostics.truth-pose and a true pose: truth_pose_*)
    rec.watch(static_cast<std::uint32_t>(*truth_object), c.o.truth_pose ? run.truth_pose : std::nullopt);
  const SymmetryGroup* sym = nullptr;
  if (truth_object && run.truth_pose) sym = &c.symmetries.get(db, *truth_object);

  std::optional<Exploration> ex;
  if (log) ex.emplace(*log, experiments::log_exploration(db, c.rs, o.contact_voxel));
  const bool with_free = c.rs.method == Method::bricpsf || c.rs.method == Method::ransac_icp_fs;
  std::vector<int> draw;   // --scene: the steps to draw
  if (!o.scene.empty()) draw = experiments::scene_steps(o.scene_steps, K, in.path);
  const std::string stem = fs::path(in.path).stem().string();

  for (int k = 1; k <= K; ++k) {
    PointCloud contacts;
    std::vector<Vec3> free;
    GraspGroups grasps;
    const auto t0 = std::chrono::steady_clock::now();
    if (ex) {
      experiments::StepInput step = experiments::step_input(*ex, static_cast<std::size_t>(k), c.rs.method);
      contacts = std::move(step.contacts);
      free = std::move(step.free);
      grasps = std::move(step.grasps);
    } else {
      contacts = single;
      if (with_free) free = single_free;
    }
    run.fusion_time.push_back(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    StepResult r = rec.step(contacts, free, grasps);
    // Units sanity check: contacts far wider than any object mean the log and the database
    // disagree (e.g. millimetres against metres).
    if (r.contacts > 0) {
      Eigen::AlignedBox3d box;
      for (const Vec3& p : contacts.points) box.extend(p);
      const double span = box.diagonal().norm();
      if (span > 4.0 * c.largest + 0.5)
        throw Error("the contacts span " + std::to_string(span) + " m but the largest database object " +
                        std::to_string(c.largest) + " m: do the log and the database use the same units?",
                    in.path, log ? "/grasps" : "points");
    }
    run.contact_distance.push_back(
        r.valid && !contacts.empty()
            ? mean_contact_distance(*db.geometry(r.best.object), r.best.pose, contacts.points)
            : std::numeric_limits<double>::quiet_NaN());
    if (std::find(draw.begin(), draw.end(), k) != draw.end())
      run.scenes.push_back(experiments::scene_json(
          db, r, contacts, free, truth_object, run.truth_pose, stem, stem + ", step " + std::to_string(k),
          c.calibration && r.valid ? std::optional(c.calibration->object_confidence(r.step, experiments::confidence_features(r)))
                                   : std::nullopt));
    run.stored.push_back(io::to_result_step(r, truth_object, run.truth_pose, sym));
    if (run.truth_outside) run.stored.back().correct = !r.valid;
    if (c.sets) {
      run.sets.push_back(step_set(c, r));
      run.stored.back().answer_set = stored_answer_set(c, run.sets.back());
    }
    run.results.push_back(std::move(r));
    if (progress) std::fprintf(stderr, "\rstep %d/%d", k, K);
  }
  if (progress) std::fprintf(stderr, "\n");

  if (o.suggest > 0) {
    // The N best next grasps on the state after the last step (engine/touch/active_touch.hpp).
    if (!log) throw Error("--suggest plans the next grasp of a tactile log (not a contact cloud)", in.path, "--suggest");
    if (log->sensing == Sensing::probe)
      throw Error("--suggest plans grasps of a gripper with pads; this is a probe log", in.path, "/sensing");
    if (rec.hypotheses().empty())
      throw Error("no hypothesis after " + std::to_string(K) +
                      " step(s) to plan the next grasp from: no contact yet, or no database object fits "
                      "the contacts (touch the object again, e.g. any grasp toward it)",
                  in.path, "--suggest");
    const auto t0 = std::chrono::steady_clock::now();
    std::optional<GraspPlanner> planner;
    try {
      planner.emplace(log->gripper, o.active);
    } catch (const Error& e) {
      throw Error(e.message(), in.path, e.field().empty() ? "/gripper" : "/gripper " + e.field());
    }
    ex->advance_to(static_cast<std::size_t>(K));
    const auto best = planner->plan(rec.hypotheses(), database_plan_objects(db), rs.seed,
                                    static_cast<std::size_t>(o.suggest), ex->contact_cloud().points);
    run.suggest_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    run.suggestions = nlohmann::ordered_json::array();
    const Gripper& G = log->gripper;
    for (std::size_t i = 0; i < best.size(); ++i) {
      const PlannedGrasp& g = best[i];
      nlohmann::ordered_json s;
      s["rank"] = i + 1;
      s["T_EEF"] = pose_json(g.command.T_world_eef);
      nlohmann::ordered_json m = nlohmann::ordered_json::array();
      for (int r = 0; r < 4; ++r)
        for (int col = 0; col < 4; ++col) m.push_back(g.command.T_world_eef.matrix()(r, col));
      s["T_EEF_matrix"] = m;
      const Vec3 a = g.command.approach;
      s["approach"] = {a.x(), a.y(), a.z()};
      const Vec3 t = g.command.target;
      s["target"] = {t.x(), t.y(), t.z()};
      nlohmann::ordered_json joints;
      for (int j = 0; j < G.joint_count(); ++j) {
        const int f = G.finger_of_joint(j);
        joints[G.spec().fingers[static_cast<std::size_t>(f)].name + "." + G.link(j).name] =
            g.command.joints[static_cast<std::size_t>(j)] * 180.0 / std::numbers::pi;
      }
      s["joints_deg"] = joints;
      s["expected_information_nats"] = g.information;
      s["expected_object_information_nats"] = g.object_information;
      s["blocked_weight"] = g.blocked_weight;
      s["coverage"] = g.coverage;
      s["score"] = g.score;
      s["aimed_object"] = db.info(g.aimed_object).name;
      run.suggestions.push_back(std::move(s));
    }
  }

  if (!out.empty()) {
    io::ResultHeader h;
    h.method = std::string(method_name(c.rs.method));
    h.seed = c.rs.seed;
    h.database = o.db;
    h.input = in.path;
    h.input_kind = log ? "log" : "cloud";
    for (std::size_t i = 0; i < db.size(); ++i) h.objects.push_back(db.info(i).name);
    h.truth_object = run.truth_name;
    h.truth_pose = run.truth_pose;
    h.params = params_of(c.rs, o);
    if (c.sets) {
      h.answer_set_alpha = o.alpha.value_or(c.sets->alpha);
      h.calibration = o.calibration;
    }
    io::write_result(out, h, run.stored);
    run.written = out;
  }
  return run;
}

/// --explain: a step's answer and its best rival, each with its evidence (StepResult::explanation).
nlohmann::ordered_json explanation_json(const Context& c, const StepResult& r) {
  if (r.explanation.empty()) return nullptr;
  nlohmann::ordered_json j;
  j["decided_by"] = r.decided_by.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(r.decided_by);
  auto& hyps = j["hypotheses"] = nlohmann::ordered_json::array();
  for (const Evidence& e : r.explanation) {
    nlohmann::ordered_json h;
    h["role"] = &e == &r.explanation.front() ? "answer" : "rival";
    h["object"] = c.db.info(e.object).name;
    h["rank"] = e.rank;
    h["pose"] = pose_json(e.pose);
    h["log_weight"] = e.log_weight;
    h["contact_log_weight"] = e.contact_log_weight;
    h["free_log_weight"] = e.free_log_weight;
    h["floor_log_weight"] = e.floor_log_weight;
    h["free_points_checked"] = e.free_points_checked;
    h["offset_rms_m"] = e.offset_rms_m;
    h["contact_rms_sigma"] = e.fit.valid ? nlohmann::ordered_json(e.fit.rms_sigma) : nullptr;
    h["contacts_beyond_3_sigma"] = e.fit.valid ? nlohmann::ordered_json(e.fit.far_share) : nullptr;
    h["twin_score"] = number_or_null(std::isnan(e.twin_score) ? std::nullopt : std::optional(e.twin_score));
    h["posterior"] = e.posterior;
    hyps.push_back(std::move(h));
  }
  return j;
}

/// --explain, the table's form: the last step's answer beside its best rival, term by term.
void print_explanation(const Context& c, const StepResult& r) {
  if (r.explanation.empty()) return;
  const Evidence& a = r.explanation.front();
  const std::string an = c.db.info(a.object).name;
  if (r.explanation.size() < 2) {
    std::printf("\nwhy %s: every hypothesis of the state is of %s (no rival)\n", an.c_str(), an.c_str());
    return;
  }
  const Evidence& b = r.explanation[1];
  const std::string bn = c.db.info(b.object).name;
  std::printf("\nwhy %s and not %s (step %d; its best hypothesis is #%zu of the state):\n", an.c_str(), bn.c_str(),
              r.step, b.rank);
  std::printf("  %-34s %12.12s %12.12s %12s\n", "", an.c_str(), bn.c_str(), "difference");
  auto row = [](const char* what, double x, double y) {
    std::printf("  %-34s %12.4g %12.4g %+12.4g\n", what, x, y, x - y);
  };
  row("ln wt (Eq. 6)", a.log_weight, b.log_weight);
  row("  contacts: - mean Eq. 4 error", a.contact_log_weight, b.contact_log_weight);
  row("  free space: - lambda x Eq. 8 sum", a.free_log_weight, b.free_log_weight);
  if (a.floor_log_weight != 0.0 || b.floor_log_weight != 0.0)
    row("  floor: sunk below the support", a.floor_log_weight, b.floor_log_weight);
  std::printf("  %-34s %12zu %12zu\n", "free points checked near it", a.free_points_checked, b.free_points_checked);
  auto opt = [](bool have, double x, const char* fmt) {
    char buf[32];
    if (!have || !std::isfinite(x)) return std::string("-");
    std::snprintf(buf, sizeof buf, fmt, x);
    return std::string(buf);
  };
  std::printf("  %-34s %12s %12s\n", "contact RMS after offsets (sigma)", opt(a.fit.valid, a.fit.rms_sigma, "%.2f").c_str(),
              opt(b.fit.valid, b.fit.rms_sigma, "%.2f").c_str());
  std::printf("  %-34s %12s %12s\n", "contacts beyond 3 sigma", opt(a.fit.valid, 100 * a.fit.far_share, "%.1f %%").c_str(),
              opt(b.fit.valid, 100 * b.fit.far_share, "%.1f %%").c_str());
  std::printf("  %-34s %12s %12s\n", "per-grasp offsets, RMS", opt(a.offset_rms_m > 0, 1e3 * a.offset_rms_m, "%.2f mm").c_str(),
              opt(b.offset_rms_m > 0, 1e3 * b.offset_rms_m, "%.2f mm").c_str());
  std::printf("  %-34s %12s %12s\n", "near-twin score V (lower wins)", opt(true, a.twin_score, "%.1f").c_str(),
              opt(true, b.twin_score, "%.1f").c_str());
  std::printf("  %-34s %12.3f %12.3f\n", "object posterior", a.posterior, b.posterior);
  if (r.decided_by == "near_twin")
    std::printf("decided by the near-twin verification: their ln wt were within its gap, and %s's V is lower\n",
                an.c_str());
  else
    std::printf("decided by ln wt, mostly its %s term\n", r.decided_by == "free_space" ? "free-space" : "contact");
}

nlohmann::ordered_json steps_json(const Context& c, const InputRun& run) {
  nlohmann::ordered_json steps = nlohmann::ordered_json::array();
  for (std::size_t k = 0; k < run.results.size(); ++k) {
    const StepResult& r = run.results[k];
    const io::ResultStep& s = run.stored[k];
    nlohmann::ordered_json st;
    st["step"] = r.step;
    st["object"] = r.valid ? nlohmann::ordered_json(c.db.info(r.best.object).name) : nullptr;
    st["weight"] = r.valid ? nlohmann::ordered_json(r.best.weight) : nullptr;
    st["posterior"] = r.valid ? nlohmann::ordered_json(r.posterior) : nullptr;
    // Calibrated: P(the named object is right), P(and its position within 1 cm) (--calibration).
    // Open set: below the threshold the answer is "not in the database" (the object the
    // evidence fits best stays as best_guess).
    bool refused = false;
    if (c.calibration) {
      const std::vector<double> f = experiments::confidence_features(r);
      const auto in_database = c.calibration->in_database(r.step, f);  // the open-set score
      st["confidence"] = {{"object", c.calibration->object_confidence(r.step, f)},
                          {"pose", c.calibration->pose_confidence(r.step, f)},
                          {"in_database", in_database ? nlohmann::ordered_json(*in_database) : nullptr}};
      const auto threshold = c.o.open_set_threshold ? c.o.open_set_threshold : c.calibration->open_set_threshold;
      refused = r.valid && threshold && in_database && *in_database < *threshold;
    } else {
      st["confidence"] = nullptr;
    }
    st["answer_set"] = k < run.sets.size() ? answer_set_json(c, run.sets[k]) : nullptr;
    // Why there is no object: "not_in_database" (the open-set score), "not_enough_contacts" (the
    // step stopped before matching: none, or fewer than 3 distinct), "no_hypothesis" (nothing fit).
    st["reason"] = refused ? nlohmann::ordered_json("not_in_database")
                   : r.valid ? nlohmann::ordered_json(nullptr)
                   : nlohmann::ordered_json(r.stopped.empty() ? "no_hypothesis" : "not_enough_contacts");
    st["reason_detail"] = !r.valid && !r.stopped.empty() ? nlohmann::ordered_json(r.stopped) : nullptr;
    st["best_guess"] = refused ? st["object"] : nullptr;
    if (refused) st["object"] = nullptr;
    st["pose"] = r.valid ? pose_json(r.best.pose) : nullptr;
    const auto e = s.error;
    st["position_error_m"] = number_or_null(e ? std::optional(e->position_m) : std::nullopt);
    st["orientation_error_deg"] = number_or_null(e ? std::optional(e->orientation_deg) : std::nullopt);
    st["symmetric_orientation_error_deg"] =
        number_or_null(e ? std::optional(e->symmetric_orientation_deg) : std::nullopt);
    st["time_s"] = r.times.total_s;
    // extensions
    // A refused answer is right exactly when the touched object is not in the database.
    st["correct"] = !s.correct ? nlohmann::ordered_json(nullptr)
                    : refused  ? nlohmann::ordered_json(run.truth_outside)
                               : nlohmann::ordered_json(*s.correct);
    // The named object's class of congruent objects (no touch tells them apart), and whether the
    // answer lies in the true object's class.
    st["object_class"] = r.valid ? class_json(c, r.best.object) : nullptr;
    if (s.correct) {
      const std::size_t truth = c.db.find(run.truth_name);
      st["correct_class"] = refused ? run.truth_outside : r.valid && truth < c.db.size() &&
                            (c.congruence ? c.congruence->same_class(r.best.object, truth) : r.best.object == truth);
    } else {
      st["correct_class"] = nullptr;
    }
    st["symmetric_position_error_m"] =
        number_or_null(e ? std::optional(e->symmetric_position_m) : std::nullopt);
    st["log_weight"] = r.valid ? nlohmann::ordered_json(r.best.log_weight) : nullptr;
    st["contacts"] = r.contacts;
    st["free_points"] = r.free_points;
    // The support under the object (support.mode plane or cylinder): its surface and the
    // contacts set aside.
    st["support"] = support_json(r.support);
    // Found, or why not (the test the candidate with the most contacts on it failed); null: not
    // looked for.
    st["support_verdict"] = r.support.verdict == SupportVerdict::not_looked ? nlohmann::ordered_json(nullptr)
                                                                             : nlohmann::ordered_json(to_string(r.support.verdict));
    // What explains each contact (stage "attribution"): the answer, the support, or nothing.
    st["attribution"] = attribution_json(r.attribution);
    st["unobservable_dof"] = r.unobservable_dof;
    st["pose_ambiguous"] = r.pose_ambiguous;
    // Judged by the contacts' own normals, or (too few of them) on the answer's surface.
    st["observability"] = r.observability_from_model ? "answer_surface" : "contact_normals";
    // Mean |distance| of the step's contacts to the answer's surface at its pose (Vezzani et al.)
    st["contact_model_distance_m"] = number_or_null(
        std::isfinite(run.contact_distance[k]) ? std::optional(run.contact_distance[k]) : std::nullopt);
    st["candidates"] = r.candidates;
    st["sparse_active"] = r.sparse_active;
    st["sparse_candidates"] = r.sparse_candidates;
    st["hypotheses"] = r.hypotheses.size();
    st["objects_allowed"] = r.objects_allowed;
    st["objects_reached"] = r.objects_reached;
    st["objects_shortlisted"] = r.shortlist.empty() ? r.objects_reached : r.shortlist.size();
    if (r.watched) {   // where the known object stood in the search (see Funnel)
      const Funnel& f = *r.watched;
      st["truth_funnel"] = {{"searched", f.searched},       {"candidates", f.candidates},
                            {"shortlisted", f.shortlisted}, {"transferred", f.transferred},
                            {"transfer_rank", f.transfer_rank}, {"prior_rank", f.prior_rank}, {"screen_score", f.screen_score},
                            {"screen_cut", f.screen_cut}, {"screen_rank", f.screen_rank},
                            {"hypotheses", f.hypotheses}};
      if (f.truth_pose_evaluated) {
        auto& t = st["truth_funnel"];
        t["truth_pose_wins"] = f.truth_pose_wins;
        t["truth_pose_log_weight"] = number_or_null(f.truth_pose_log_weight);
        t["answer_log_weight"] = number_or_null(f.answer_log_weight);
        t["truth_pose_twin_score"] = number_or_null(f.truth_pose_twin_score);
        t["rival_twin_score"] = number_or_null(f.rival_twin_score);
      }
    }
    if (c.o.explain) st["explanation"] = explanation_json(c, r);
    st["geometry_loads"] = r.geometry_loads;
    st["geometry_resident"] = r.geometry_resident;
    // The step's pipeline: the stages that ran, the ones its scene did not need (and why), and
    // the ran ones' times (apart, as every time is: the rest is the same for any --threads).
    auto ran = nlohmann::ordered_json::array(), skipped = nlohmann::ordered_json::array();
    auto pipeline_s = nlohmann::ordered_json::object();
    for (const StageRun& g : r.stages) {
      if (g.ran) {
        ran.push_back(g.name);
        pipeline_s[g.name] = g.seconds;
      } else {
        skipped.push_back({{"stage", g.name}, {"reason", g.reason}});
      }
    }
    st["stages_ran"] = std::move(ran);
    st["stages_skipped"] = std::move(skipped);
    st["pipeline_s"] = std::move(pipeline_s);
    st["stages_s"] = {{"fusion", run.fusion_time[k]}, {"prepare", r.times.prepare_s},
                      {"prune", r.times.prune_s},     {"register", r.times.register_s},
                      {"shortlist", r.times.shortlist_s},
                      {"icp", r.times.icp_s},         {"evaluate", r.times.evaluate_s}};
    steps.push_back(std::move(st));
  }
  return steps;
}

/// One input's JSON object: method, preset, steps (or error), [database,] input, truth_object.
nlohmann::ordered_json input_json(const Context& c, const InputRun& run, bool with_database) {
  nlohmann::ordered_json j;
  j["method"] = std::string(method_name(c.rs.method));
  j["preset"] = c.o.preset;
  if (run.error.empty())
    j["steps"] = steps_json(c, run);
  else
    j["error"] = run.error;
  if (with_database) j["database"] = c.o.db;
  j["input"] = run.in.path;
  j["truth_object"] = run.truth_name.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(run.truth_name);
  j["truth_in_database"] = run.truth_name.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(!run.truth_outside);
  if (!run.suggestions.is_null()) {
    j["suggestions"] = run.suggestions;
    j["suggest_time_s"] = run.suggest_time_s;
  }
  return j;
}

/// The fields every input shares: seed, threads, machine, params.
void add_shared_json(nlohmann::ordered_json& j, const Context& c) {
  j["seed"] = c.rs.seed;
  j["threads"] = thread_count(c.o.common);
  j["machine"] = experiments::machine_description();
  j["congruent_classes_known"] = c.congruence != nullptr;   // else "object_class" is the object alone
  nlohmann::ordered_json p;
  for (const auto& [name, value] : params_of(c.rs, c.o)) p[name] = value;
  j["params"] = p;
}

std::string input_label(const InputRun& run) {
  return "input " + run.in.path + (run.truth_name.empty() ? "" : " (object " + run.truth_name + ")");
}

/// One input's table (and notes) for people.
void print_table(const Context& c, const InputRun& run) {
  std::printf("%5s  %-24s %9s %9s %10s %9s %9s %8s\n", "step", "object", "weight", "posterior",
              "pos_err_m", "ori_deg", "sym_deg", "time_s");
  for (std::size_t k = 0; k < run.results.size(); ++k) {
    const StepResult& r = run.results[k];
    const auto& e = run.stored[k].error;
    auto num = [](bool have, double x, const char* fmt) {
      char buf[32];
      if (!have || !std::isfinite(x)) return std::string("-");
      std::snprintf(buf, sizeof buf, fmt, x);
      return std::string(buf);
    };
    std::string name = r.valid ? c.db.info(r.best.object).name : "(none)";
    if (r.valid && r.pose_ambiguous) name += " ?";
    std::printf("%5d  %-24s %9s %9s %10s %9s %9s %8.3f\n", r.step, name.c_str(),
                num(r.valid, r.best.weight, "%.4f").c_str(), num(r.valid, r.posterior, "%.3f").c_str(),
                num(e.has_value(), e ? e->position_m : 0, "%.4f").c_str(),
                num(e.has_value(), e ? e->orientation_deg : 0, "%.1f").c_str(),
                num(e.has_value(), e ? e->symmetric_orientation_deg : 0, "%.1f").c_str(),
                r.times.total_s);
  }
  if (!run.results.empty() && run.results.back().valid) {
    const auto members = class_json(c, run.results.back().best.object);
    if (members.size() > 1) {
      std::cout << "note: congruent objects, no touch tells them apart:";
      for (const auto& n : members) std::cout << ' ' << n.get<std::string>();
      std::cout << '\n';
    }
  }
  if (!run.results.empty() && !run.results.back().valid) {
    const StepResult& last = run.results.back();
    std::cout << "no answer: "
              << (last.stopped.empty() ? std::string("no hypothesis fits the contacts")
                                       : last.stopped + "; a pose needs at least 3")
              << '\n';
  } else if (!run.results.empty() && run.results.back().pose_ambiguous) {
    const StepResult& last = run.results.back();
    if (last.observability_from_model)
      std::cout << "? on " << c.db.info(last.best.object).name << "'s surface the contacts leave " << last.unobservable_dof
                << " pose DOF free (e.g. a turn about a cylinder's axis): that part of the pose is not determined\n";
    else
      std::cout << "? the contacts leave " << last.unobservable_dof
                << " pose DOF unobservable (e.g. a single flat patch): the pose is not reliable\n";
  }
  if (c.o.explain && !run.results.empty()) {
    std::cout << std::flush;
    print_explanation(c, run.results.back());
    std::fflush(stdout);
  }
  if (!run.written.empty()) std::cout << "wrote " << run.written << '\n';
}

std::string lowercase(std::string s) {
  for (char& ch : s) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return s;
}

/// The inputs in command-line order; a --cloud folder gives its .ply/.pcd files sorted by name.
std::vector<Input> expand_inputs(const RecognizeOptions& o) {
  std::vector<Input> inputs;
  for (const std::string& p : o.logs) inputs.push_back({p, true});
  for (const std::string& p : o.clouds) {
    if (!fs::is_directory(p)) {
      inputs.push_back({p, false});
      continue;
    }
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(p)) {
      const std::string ext = lowercase(entry.path().extension().string());
      if (entry.is_regular_file() && (ext == ".ply" || ext == ".pcd"))
        names.push_back(entry.path().filename().string());
    }
    if (names.empty()) throw Error("the folder holds no .ply or .pcd file", p, "--cloud");
    std::sort(names.begin(), names.end());
    for (const std::string& n : names) inputs.push_back({(fs::path(p) / n).string(), false});
  }
  return inputs;
}

/// Several inputs with --out DIR: each result is DIR/<stem>.h5. Refuse (before any work) two
/// inputs with one stem, a result file that would replace an input, and an --out that is a file.
std::vector<std::string> result_paths(const RecognizeOptions& o, const std::vector<Input>& inputs) {
  std::vector<std::string> paths(inputs.size());
  if (o.out.empty()) return paths;
  if (fs::exists(o.out) && !fs::is_directory(o.out))
    throw Error("with several inputs --out takes a folder (one <stem>.h5 per input), not a file", o.out,
                "--out");
  std::map<std::string, std::string> by_stem;
  std::set<fs::path> input_files;
  for (const Input& in : inputs) input_files.insert(fs::weakly_canonical(in.path));
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const std::string stem = fs::path(inputs[i].path).stem().string();
    const fs::path target = fs::path(o.out) / (stem + ".h5");
    const auto [it, fresh] = by_stem.emplace(stem, inputs[i].path);
    if (!fresh)
      throw Error("the inputs " + it->second + " and " + inputs[i].path + " share the name '" + stem +
                      "': both results would be " + target.string() + " (nothing was done)", o.out, "--out");
    if (input_files.count(fs::weakly_canonical(target)))
      throw Error("the result " + target.string() + " would replace the input of that name (nothing was done)",
                  o.out, "--out");
    paths[i] = target.string();
  }
  return paths;
}

/// The error line of a failed input: names the file (ts::Error's own message does when it is
/// about the input; otherwise the input is added).
std::string input_error(const Input& in, const std::exception& e) {
  const auto* te = dynamic_cast<const Error*>(&e);
  if (te && te->file() == in.path) return e.what();
  return std::string(e.what()) + " (input " + in.path + ")";
}

/// --scene: every recognized input's chosen steps drawn into the folder (a PNG and an HTML page
/// each, by the plot script); the scenes' data in DIR/scenes.json.
void draw_scenes(const RecognizeOptions& o, const std::vector<const InputRun*>& runs) {
  if (o.scene.empty()) return;
  nlohmann::ordered_json j;
  j["scenes"] = nlohmann::ordered_json::array();
  for (const InputRun* run : runs)
    for (const auto& s : run->scenes) j["scenes"].push_back(s);
  if (j["scenes"].empty()) return;
  const auto files = experiments::write_plots(j, o.scene, "scenes.json");
  if (!o.common.json)
    std::cerr << "scene: " << files.size() << " files written to " << o.scene << "\n";
}

/// Several inputs in parallel (each with its own recognizer and the shared database); a
/// failing input is reported and the others go on. Exit code 1 when any failed.
int recognize_many(const Context& c, const std::vector<Input>& inputs,
                   const std::vector<std::string>& outs) {
  const RecognizeOptions& o = c.o;
  if (!o.out.empty()) fs::create_directories(o.out);
  std::vector<InputRun> runs(inputs.size());
  ProgressReport progress(o.progress, "recognize", "inputs", stderr_is_terminal(), o.common.json, std::cerr);
  std::mutex progress_mutex;
  std::size_t done = 0;
  // Every input's recognizer shares one FeatureTable, held here for the whole batch
  // (FeatureTable::shared keeps a table only while someone holds it).
  const auto table = c.rs.ransac.feature_table ? FeatureTable::shared(c.db, c.rs.objects) : nullptr;
  const auto prior = Recognizer::shape_prior(c.db, c.rs);   // the same: built once, not per input
  const auto sparse = Recognizer::sparse_tables(c.db, c.rs);   // and the pair tables, as inputs want them
  experiments::release_free_memory();   // what building them freed (experiments/allocator.hpp)
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, inputs.size(), 1),
      [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          // Isolated: a thread waiting inside one input's parallel work takes no other input.
          tbb::this_task_arena::isolate([&] {
            try {
              runs[i] = recognize_one(c, inputs[i], outs[i], false);
            } catch (const std::exception& e) {
              runs[i] = InputRun{};
              runs[i].in = inputs[i];
              runs[i].error = input_error(inputs[i], e);
            }
          });
          experiments::release_free_memory();   // what the input freed, before the next
          if (progress.active()) {
            std::lock_guard<std::mutex> lock(progress_mutex);
            progress.update(++done, inputs.size());
          }
        }
      },
      tbb::simple_partitioner());
  progress.finish();
  std::vector<const InputRun*> drawn;
  for (const InputRun& run : runs)
    if (run.error.empty()) drawn.push_back(&run);
  draw_scenes(o, drawn);

  std::size_t failed = 0;
  for (const InputRun& run : runs)
    if (!run.error.empty()) {
      std::cerr << "touchstone: error: " << run.error << '\n';
      ++failed;
    }
  if (o.common.json) {
    nlohmann::ordered_json j;
    j["database"] = o.db;
    add_shared_json(j, c);
    j["inputs"] = nlohmann::ordered_json::array();
    for (const InputRun& run : runs) j["inputs"].push_back(input_json(c, run, false));
    std::cout << j.dump(2) << '\n';
  } else {
    std::cout << "method " << method_name(c.rs.method) << ", " << c.db.size() << " objects, "
              << inputs.size() << " inputs\n";
    for (const InputRun& run : runs) {
      std::cout << '\n' << input_label(run) << '\n';
      if (run.error.empty())
        print_table(c, run);
      else
        std::cout << "error: " << run.error << '\n';
    }
    std::cout << '\n' << inputs.size() - failed << " of " << inputs.size() << " inputs recognized";
    std::cout << (failed ? ", " + std::to_string(failed) + " failed (see the errors above)\n" : "\n");
  }
  return failed ? 1 : 0;
}

int run_recognize(const RecognizeOptions& o) {
  const std::vector<Input> inputs = expand_inputs(o);
  const bool many = o.batch;
  const std::vector<std::string> outs = many ? result_paths(o, inputs) : std::vector<std::string>{o.out};

  RecognizerSettings rs = o.rs;  // (the improved preset was applied before the flags)
  rs.method = *parse_method(o.method);
  rs.seed = o.common.seed;       // the same seed for every input, as if each ran alone

  auto source = std::make_shared<io::DbReader>(o.db);
  Database db(source);
  if (db.size() == 0) throw Error("the database has no objects", o.db, "/objects");
  db.set_surface(needs_surface(rs, db.settings()));
  if (!o.only.empty()) {   // --only: the answer is one of these (one name: localize a known object)
    rs.objects.assign(db.size(), 0);
    for (const std::string& name : o.only) {
      const std::size_t i = db.find(name);
      if (i == db.size()) throw Error("no object '" + name + "' in the database", o.db, "--only");
      rs.objects[i] = 1;
    }
  }
  experiments::set_memory_budget(db, o.memory_budget_mb, o.db);
  double largest = 0.0;
  for (std::size_t i = 0; i < db.size(); ++i) largest = std::max(largest, db.info(i).extent.norm());
  SymmetryCache symmetries;
  std::optional<experiments::Calibration> calibration;   // fitted for this database, or an error
  if (!o.calibration.empty())
    calibration = experiments::read_calibration(o.calibration, experiments::file_fingerprint(*source));
  else if (o.open_set_threshold)
    throw Error("an open-set threshold needs a confidence calibration (--calibration)", {}, "--open-set-threshold");
  if (calibration && o.open_set_threshold && !calibration->in_database(1, std::vector<double>(calibration->features.size(), 0.0)))
    throw Error("the calibration has no open-set (in-database) model: fit it with leave-one-out runs too",
                o.calibration, "steps[0].in_database");
  // Set answers: the calibration's one simulation's. A calibration of several (a noise sweep's)
  // names none for these contacts: an error with --alpha, else its confidences without sets.
  const experiments::AnswerSetCalibration* sets = nullptr;
  if (calibration && calibration->answer_sets.size() == 1) sets = &calibration->answer_sets.front();
  if (calibration && calibration->answer_sets.size() > 1) {
    if (o.alpha) calibration->single_answer_sets(o.calibration);   // throws, naming the simulations
    std::cerr << "touchstone: note: " << o.calibration << " holds answer sets for "
              << calibration->answer_sets.size()
              << " simulations and these contacts name none: no set answers (its confidences are used)\n";
  }
  if (o.alpha && (!calibration || calibration->answer_sets.empty()))
    throw Error(calibration ? "the calibration has no answer sets: fit it with `touchstone calibrate` on run stores "
                              "of this version"
                            : "set answers need a calibration (--calibration)",
                calibration ? o.calibration : std::string(), calibration ? "answer_sets" : "--alpha");
  Context c{o, rs, db, largest, symmetries, source->congruence(), calibration ? &*calibration : nullptr, sets};
  c.class_of = class_indices(db.size(), source->congruence() ? source->congruence()->classes()
                                                             : std::vector<std::vector<std::size_t>>{}, c.classes);
  if (many) return recognize_many(c, inputs, outs);

  const InputRun run = recognize_one(c, inputs.front(), o.out, stderr_is_terminal() && !o.common.json);
  draw_scenes(o, {&run});
  if (o.common.json) {
    nlohmann::ordered_json j = input_json(c, run, true);
    add_shared_json(j, c);
    std::cout << j.dump(2) << '\n';
  } else {
    std::cout << "method " << method_name(rs.method) << ", " << db.size() << " objects, "
              << input_label(run) << '\n';
    print_table(c, run);
    if (!run.suggestions.is_null()) {
      std::printf("\nnext grasps (planned in %.3f s; --json for T_EEF and the joint targets):\n", run.suggest_time_s);
      std::printf("%5s  %-24s %12s %9s  %s\n", "rank", "aimed object", "information", "blocked", "target (world, m)");
      for (const auto& g : run.suggestions)
        std::printf("%5d  %-24s %12.3f %9.3f  %.4f %.4f %.4f\n", g["rank"].get<int>(),
                    g["aimed_object"].get<std::string>().c_str(), g["expected_information_nats"].get<double>(),
                    g["blocked_weight"].get<double>(), g["target"][0].get<double>(), g["target"][1].get<double>(),
                    g["target"][2].get<double>());
    }
  }
  return 0;
}

}  // namespace

void register_recognize(CLI::App& app) {
  auto o = std::make_shared<RecognizeOptions>();
  auto* sub = app.add_subcommand(
      "recognize", "Recognize the touched object and its 6-DOF pose, step by step");
  sub->add_option("--db", o->db, "Object database (HDF5)")->required()->check(CLI::ExistingFile);
  auto* log = sub->add_option("--log", o->logs, "Tactile log(s) (HDF5); several are recognized in parallel")
                  ->check(CLI::ExistingFile);
  auto* cloud = sub->add_option("--cloud", o->clouds,
                                "Plain contact cloud(s) (.ply/.pcd), each recognized as one step without "
                                "free space; a folder gives its .ply/.pcd files in name order")
                    ->check(CLI::ExistingPath);
  log->excludes(cloud);
  auto* free = sub->add_option("--free", o->free,
                               "Free-space cloud (.ply/.pcd) of a single --cloud: points the sensor passed "
                               "through (e.g. a probe's path), evidence against poses that put the object there");
  free->needs(cloud)->check(CLI::ExistingFile);
  sub->add_option("--only", o->only,
                  "Objects the answer may name, NAME[,NAME...] (one name: localize a known object)")
      ->delimiter(',');
  sub->add_flag("--explain", o->explain,
                "Say why the answer won over its best rival (the best hypothesis of another object): ln wt "
                "split into the contact and free-space terms, the fit, the near-twin score, the posteriors "
                "(the last step's table; JSON: every step's explanation)");
  sub->add_option("--method", o->method, "bricpsf | batch-ransac | ransac-icp | ransac-icp-fs")
      ->check(CLI::IsMember({"bricpsf", "batch-ransac", "ransac-icp", "ransac-icp-fs"}));
  sub->add_option("--steps", o->steps, "Steps (grasps) to process (default: all)")
      ->check(CLI::Range(1, 1 << 30));
  sub->add_option("--out", o->out,
                  "Write every step's hypotheses to RESULT.h5 (several inputs: a folder, created if "
                  "missing, with one <stem>.h5 per input)");
  sub->add_option("--ground-truth", o->ground_truth,
                  "Text file with the true 4x4 row-major object->world matrix")
      ->check(CLI::ExistingFile);
  sub->add_option("--object", o->object, "Name of the touched object (ground truth), if known");
  sub->add_option("--calibration", o->calibration,
                  "Confidence calibration of this database (touchstone calibrate): each step's JSON "
                  "gets \"confidence\" {object, pose, in_database}; below its open-set threshold the "
                  "in-database score makes the answer "
                  "\"object\": null, \"reason\": \"not_in_database\"");
  sub->add_option("--alpha", o->alpha,
                  "Set answers (a calibration with answer sets): each step's \"answer_set\" holds the true "
                  "object's class with probability at least 1 - alpha (default: the calibration's, 0.05); --out "
                  "stores them (/answer_sets)")
      ->check(CLI::Range(1e-9, 1.0 - 1e-9));
  sub->add_option("--open-set-threshold", o->open_set_threshold,
                  "In-database score below which the answer is \"not in the database\" (default: the "
                  "calibration file's, chosen on its calibration runs; 0: always name an object)")
      ->check(CLI::Range(0.0, 1.0));

  sub->add_option("--preset", o->preset,
                  "improved (default): Touchstone's extensions (per-object feature pruning, free "
                  "space inside objects, duplicate removal, ICP on new hypotheses, diversity); "
                  "paper: the paper's method exactly. The flags below apply on top")
      ->check(CLI::IsMember({"paper", "improved"}));
  // Every method parameter (experiments/params/parameters.cpp): --KEY with `_` written `-`, and its
  // older flags; the preset's value where not given.
  experiments::add_parameter_flags(*sub, o->flags,
                                   "Method parameters (defaults: the preset's; `touchstone params` lists them)");
  sub->add_option("--suggest", o->suggest,
                  "After the last step, the N best next grasps (world T_EEF, approach, finger joint targets, "
                  "expected information) in the JSON (\"suggestions\"): the next-grasp planner, active.* "
                  "parameters. A single tactile log; an error when no grasp touched yet")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--scene", o->scene,
                  "Pictures of the scene into this folder: for each input and chosen step, the contacts, the "
                  "free-space points, the answer and its leading rivals (by object posterior) at their poses and the true object when "
                  "known, as scene_<input>_step<k>.png (two views) and .html (interactive, self-contained)");
  sub->add_option("--scene-steps", o->scene_steps, "The steps --scene draws (default: the last)")
      ->delimiter(',');
  sub->add_option("--memory-budget", o->memory_budget_mb,
                  "Resident object geometry in MB, loaded on demand and evicted least-recently-used "
                  "(default 256; 0: no limit). Never changes results")
      ->check(CLI::NonNegativeNumber);
  add_common(sub, o->common);
  add_progress(sub, o->progress);
  sub->callback([o] {
    // The preset's parameters, then the flags given (a bad value: a usage error naming the flag).
    experiments::MethodSettings m = experiments::MethodSettings::preset(o->preset);
    experiments::apply_flags(o->flags, m);
    o->rs = m.recognizer;
    o->contact_voxel = m.contact_voxel;
    o->active = m.active;
    o->exploration = m.exploration;
    o->truth_pose = m.truth_pose;
    if (m.oracle_belief > 0)
      throw CLI::ValidationError("--diagnostics.oracle-belief",
                                 "is a diagnostic of simulated experiments (touchstone experiment), where the planner "
                                 "executes its grasps; recognize only suggests them");
    o->inside_margin = o->flags.given.count("evaluate.free_inside_margin_m") > 0;
    if (o->logs.empty() && o->clouds.empty())
      throw CLI::RequiredError("--log or --cloud");
    o->batch = o->logs.size() + o->clouds.size() > 1 ||
               std::any_of(o->clouds.begin(), o->clouds.end(), [](const std::string& p) { return fs::is_directory(p); });
    if (o->suggest > 0 && (o->batch || o->logs.empty()))
      throw CLI::ValidationError("--suggest", "takes a single --log (the next grasp of that exploration)");
    if (o->batch && !o->free.empty())
      throw CLI::ValidationError("--free", "takes a single --cloud (its free space)");
    for (const auto& [flag, value] : {std::pair{"--ground-truth", &o->ground_truth}, {"--object", &o->object}})
      if (o->batch && !value->empty())
        throw CLI::ValidationError(flag, "takes a single input; with several inputs each log carries its own "
                                         "ground truth");
    run_command(o->common, [o] { return run_recognize(*o); });
  });
}

}  // namespace ts::cli
