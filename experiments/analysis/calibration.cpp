#include "experiments/analysis/calibration.hpp"

#include "io/atomic_file.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <tuple>

namespace ts::experiments {

namespace {
constexpr const char* kFormat = "touchstone-calibration";
constexpr double kAgreementRadius = 0.01;  ///< m: hypotheses within this of the best agree
}  // namespace

const std::vector<std::string>& confidence_feature_names() {
  static const std::vector<std::string> names{
      "posterior_best",     // posterior of the named object (weights summed by object)
      "posterior_margin",   // minus the largest posterior of another object
      "log_residual",       // ln(-ln wt) of the best hypothesis: its Eq. 4-9 misfit
      "agreement",          // share of hypotheses on the named object within 1 cm of its pose
      "log_contacts",       // ln(1 + contacts)
      "log_step",           // ln(step)
      "fit_rms_sigma",      // the answer's RMS contact distance after the per-grasp offsets,
                            // each clamped to 3 sigma, in contact sigmas (AnswerFit)
      "fit_far_share",      // share of its contacts farther than 3 sigma
      "fit_far10_share",    // ... farther than 10 sigma
      "fit_offset_sigma",   // RMS per-grasp offset in offset sigmas
      "free_conflict",      // Eq. 8 error of the free space per free point
      "fit_worst_grasp_sigma",  // the worst-explained grasp's RMS contact distance (AnswerFit)
      "fit_normal_rms_deg",     // RMS angle between the grasps' patch normals and the model's
      "fit_normal_worst_deg",   // the largest of those angles
      "posterior_entropy"}; // nats, of the posterior over objects
  return names;
}

double posterior_entropy(std::span<const double> posteriors) {
  double h = 0.0;
  for (double p : posteriors)
    if (p > 0.0) h -= p * std::log(p);
  return h;
}

std::vector<double> confidence_features(const StepResult& r) {
  double best = 0.0, other = 0.0, misfit = 1.0, agreement = 0.0;
  // No answer: the worst fit (every contact far, the offsets at their bound).
  double rms = 3.0, far = 1.0, far10 = 1.0, offset = 3.0, free = 0.0, worst = 3.0, normal_rms = 30.0,
         normal_worst = 30.0, entropy = 0.0;
  if (r.valid) {
    best = r.posterior;
    for (std::size_t i = 0; i < r.posteriors.size(); ++i)
      if (i != r.best.object) other = std::max(other, r.posteriors[i]);
    if (std::isfinite(r.best.log_weight)) misfit = std::clamp(-r.best.log_weight, 1e-12, 1e3);
    std::size_t agree = 0;
    for (const Hypothesis& h : r.hypotheses)
      if (h.object == r.best.object &&
          (h.pose.translation() - r.best.pose.translation()).norm() < kAgreementRadius)
        ++agree;
    if (!r.hypotheses.empty()) agreement = static_cast<double>(agree) / static_cast<double>(r.hypotheses.size());
    if (r.fit.valid) {
      rms = r.fit.rms_sigma;
      far = r.fit.far_share;
      far10 = r.fit.far10_share;
      offset = r.fit.offset_rms_sigma;
      free = r.fit.free_conflict;
      worst = r.fit.worst_grasp_sigma;
      normal_rms = r.fit.normal_rms_deg;
      normal_worst = r.fit.normal_worst_deg;
    }
    entropy = posterior_entropy(r.posteriors);
  }
  return {best, best - other, std::log(misfit), agreement, std::log1p(static_cast<double>(r.contacts)),
          std::log(static_cast<double>(std::max(r.step, 1))), rms, far, far10, offset, free, worst, normal_rms,
          normal_worst, entropy};
}

int feature_step(std::span<const double> f) {
  static const std::size_t at = static_cast<std::size_t>(
      std::find(confidence_feature_names().begin(), confidence_feature_names().end(), "log_step") -
      confidence_feature_names().begin());
  if (f.size() <= at || !std::isfinite(f[at]))
    throw Error("the features carry no step (log_step)", {}, "features");
  return static_cast<int>(std::lround(std::exp(f[at])));
}

const std::vector<int>& default_step_ranges() {
  static const std::vector<int> first{1, 2, 3, 5, 7, 9, 12, 16};
  return first;
}

const StepModels& Calibration::at(int step) const {
  if (ranges.empty()) throw Error("the calibration has no models", {}, "steps");
  std::size_t k = 0;
  while (k + 1 < ranges.size() && ranges[k + 1].first_step <= step) ++k;
  return ranges[k];
}

const ConformalScores& AnswerSetCalibration::at(int step) const {
  if (steps.empty()) throw Error("the calibration has no answer-set scores", {}, "answer_sets.steps");
  return steps[static_cast<std::size_t>(calibrated_step(step) - 1)];
}

int AnswerSetCalibration::calibrated_step(int step) const {
  return std::clamp(step, 1, static_cast<int>(steps.size()));
}

const AnswerSetCalibration* Calibration::answer_sets_for(const nlohmann::ordered_json& simulation) const {
  const nlohmann::ordered_json key = simulation_of(simulation);   // (idempotent: as the entries were read)
  for (const AnswerSetCalibration& a : answer_sets)
    if (simulation_of(a.simulation) == key) return &a;
  return nullptr;
}

std::string Calibration::answer_set_simulations() const {
  std::string sims;
  for (const AnswerSetCalibration& a : answer_sets) sims += (sims.empty() ? "" : ", ") + a.simulation.dump();
  return sims;
}

const AnswerSetCalibration& Calibration::single_answer_sets(const std::string& file) const {
  if (answer_sets.empty()) throw Error("the calibration has no answer sets", file, "answer_sets");
  if (answer_sets.size() > 1)
    throw Error("the calibration holds answer sets for " + std::to_string(answer_sets.size()) +
                " simulations (" + answer_set_simulations() + "), and these contacts name none: calibrate on runs of the one "
                "that matches them (touchstone calibrate on a store of one variant)", file, "answer_sets");
  return answer_sets.front();
}

nlohmann::ordered_json simulation_of(const nlohmann::ordered_json& config) {
  if (!config.is_object()) return nlohmann::ordered_json::object();
  // Sorted by key (nlohmann::json's std::map), so that two simulations compare and print alike
  // whatever order their keys were declared or written in.
  nlohmann::json s = nlohmann::json::object();
  for (const auto& [key, value] : config.items()) {
    const bool simulated = key == "noise" || key.starts_with("noise.") || key == "sensing" || key == "sensors" ||
                           key == "scene" || key.starts_with("scene.") || key.starts_with("probe.") ||
                           key.starts_with("fingertips.");
    // An unset override is the profile's value, no scene is water alone, and an arm scale of 1 is
    // the profile's arm: as if the key did not exist (a file written before a key existed stays
    // valid; a sweep's level 1 is the runs without the key).
    const bool neutral = (key == "scene" && value == "none") || (key == "noise.arm_scale" && value == 1.0);
    if (simulated && !value.is_null() && !neutral) s[key] = value;
  }
  return nlohmann::ordered_json(s);
}

namespace {
/// A term standardized by its mean and scale, clamped to [-clamp, clamp] when clamp > 0.
inline double standardized(double v, double mean, double scale, double clamp) {
  const double t = (v - mean) / scale;
  return clamp > 0.0 ? std::clamp(t, -clamp, clamp) : t;
}
}  // namespace

std::vector<double> quadratic_terms(std::span<const double> f) {
  std::vector<double> t(f.begin(), f.end());
  for (double x : f) t.push_back(x * x);
  return t;
}

double LogisticModel::predict(std::span<const double> features) const {
  std::vector<double> terms;
  if (quadratic) terms = quadratic_terms(features);
  const std::span<const double> f = quadratic ? std::span<const double>(terms) : features;
  if (f.size() + 1 != coef.size() || mean.size() != f.size() || scale.size() != f.size())
    throw Error("the confidence model expects " + std::to_string(quadratic ? mean.size() / 2 : mean.size()) +
                " features, got " + std::to_string(features.size()), {}, "features");
  double z = coef[0];
  for (std::size_t i = 0; i < f.size(); ++i) z += coef[i + 1] * standardized(f[i], mean[i], scale[i], clamp);
  // Stable in both tails.
  return z >= 0 ? 1.0 / (1.0 + std::exp(-z)) : std::exp(z) / (1.0 + std::exp(z));
}

LogisticModel fit_logistic(const std::vector<std::vector<double>>& rows, const std::vector<int>& labels,
                           double l2, double clamp) {
  if (rows.empty() || rows.size() != labels.size())
    throw Error("a logistic fit needs as many labels as rows, and at least one", {}, "calibration");
  const std::size_t n = rows.size(), f = rows.front().size();
  LogisticModel m;
  m.clamp = clamp;
  m.mean.assign(f, 0.0);
  m.scale.assign(f, 0.0);
  for (const auto& r : rows) {
    if (r.size() != f) throw Error("rows of a logistic fit differ in length", {}, "calibration");
    for (std::size_t j = 0; j < f; ++j) {
      if (!std::isfinite(r[j])) throw Error("a non-finite feature in a logistic fit", {}, "calibration");
      m.mean[j] += r[j];
    }
  }
  for (double& v : m.mean) v /= static_cast<double>(n);
  for (const auto& r : rows)
    for (std::size_t j = 0; j < f; ++j) m.scale[j] += (r[j] - m.mean[j]) * (r[j] - m.mean[j]);
  for (double& v : m.scale) v = std::max(std::sqrt(v / static_cast<double>(n)), 1e-9);
  Eigen::MatrixXd x(n, f + 1);
  Eigen::VectorXd y(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (labels[i] != 0 && labels[i] != 1) throw Error("labels of a logistic fit must be 0 or 1", {}, "calibration");
    x(static_cast<Eigen::Index>(i), 0) = 1.0;
    for (std::size_t j = 0; j < f; ++j)
      x(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j + 1)) = standardized(rows[i][j], m.mean[j], m.scale[j], clamp);
    y(static_cast<Eigen::Index>(i)) = labels[i];
  }
  const auto k = static_cast<Eigen::Index>(f + 1);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(k);
  Eigen::MatrixXd penalty = Eigen::MatrixXd::Identity(k, k) * l2 * static_cast<double>(n);
  penalty(0, 0) = 1e-9;  // the bias is not shrunk (a tiny ridge keeps all-0/all-1 labels finite)
  for (int it = 0; it < 100; ++it) {
    const Eigen::VectorXd z = x * w;
    Eigen::VectorXd p(z.size()), s(z.size());
    for (Eigen::Index i = 0; i < z.size(); ++i) {
      p(i) = z(i) >= 0 ? 1.0 / (1.0 + std::exp(-z(i))) : std::exp(z(i)) / (1.0 + std::exp(z(i)));
      s(i) = std::max(p(i) * (1.0 - p(i)), 1e-12);
    }
    const Eigen::VectorXd g = x.transpose() * (y - p) - penalty * w;
    const Eigen::MatrixXd h = x.transpose() * s.asDiagonal() * x + penalty;
    const Eigen::VectorXd step = h.ldlt().solve(g);
    w += step;
    if (step.lpNorm<Eigen::Infinity>() < 1e-10) break;
  }
  // Labels all alike leave the bias to the tiny ridge: keep it within a sane range.
  w(0) = std::clamp(w(0), -30.0, 30.0);
  m.coef.assign(w.data(), w.data() + w.size());
  return m;
}

const std::vector<double>& default_l2_grid() {
  static const std::vector<double> grid{1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.3};
  return grid;
}

double choose_l2(const std::vector<std::vector<double>>& rows, const std::vector<int>& labels,
                 const std::vector<int>& groups, const std::vector<double>& grid, int folds, double clamp) {
  if (grid.empty()) throw Error("an empty grid of L2 penalties", {}, "l2");
  if (grid.size() == 1 || folds < 2) return grid.front();
  std::vector<int> fold(rows.size());
  std::vector<std::size_t> in_fold(static_cast<std::size_t>(folds), 0);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    fold[i] = ((groups.at(i) % folds) + folds) % folds;
    ++in_fold[static_cast<std::size_t>(fold[i])];
  }
  if (std::count_if(in_fold.begin(), in_fold.end(), [](std::size_t n) { return n > 0; }) < 2) return grid.front();
  double best = grid.front(), best_loss = std::numeric_limits<double>::infinity();
  for (double l2 : grid) {
    double loss = 0.0;
    for (int f = 0; f < folds; ++f) {
      if (in_fold[static_cast<std::size_t>(f)] == 0) continue;
      std::vector<std::vector<double>> train;
      std::vector<int> y;
      for (std::size_t i = 0; i < rows.size(); ++i)
        if (fold[i] != f) {
          train.push_back(rows[i]);
          y.push_back(labels[i]);
        }
      const LogisticModel m = fit_logistic(train, y, l2, clamp);
      for (std::size_t i = 0; i < rows.size(); ++i)
        if (fold[i] == f) {
          const double p = std::clamp(m.predict(rows[i]), 1e-6, 1.0 - 1e-6);
          loss -= labels[i] ? std::log(p) : std::log(1.0 - p);
        }
    }
    if (loss < best_loss) {
      best_loss = loss;
      best = l2;
    }
  }
  return best;
}

std::vector<double> out_of_fold_in_database(const std::vector<CalibrationRow>& rows, const std::vector<int>& first,
                                            int step, double l2, int folds, double clamp) {
  std::size_t k = 0;
  while (k + 1 < first.size() && first[k + 1] <= step) ++k;
  const int lo = first.at(k), hi = k + 1 < first.size() ? first[k + 1] : std::numeric_limits<int>::max();
  auto fold_of = [&](const CalibrationRow& r) { return ((r.group % folds) + folds) % folds; };
  std::vector<double> out(rows.size(), std::numeric_limits<double>::quiet_NaN());
  for (int f = 0; f < folds; ++f) {
    std::vector<std::vector<double>> train;
    std::vector<int> y;
    bool held = false;
    for (const CalibrationRow& r : rows) {
      if (r.step < lo || r.step >= hi) continue;
      if (fold_of(r) == f) {
        held = held || r.step == step;
        continue;
      }
      train.push_back(r.features);
      y.push_back(in_database_label(r));
    }
    if (!held || train.empty()) continue;
    const LogisticModel m = fit_logistic(train, y, l2, clamp);
    for (std::size_t i = 0; i < rows.size(); ++i)
      if (rows[i].step == step && fold_of(rows[i]) == f) out[i] = m.predict(rows[i].features);
  }
  return out;
}

std::vector<StepModels> fit_step_models(const std::vector<CalibrationRow>& rows, const std::vector<int>& first,
                                        const std::vector<double>& l2_grid) {
  if (first.empty() || first.front() != 1 || !std::is_sorted(first.begin(), first.end()) ||
      std::adjacent_find(first.begin(), first.end()) != first.end())
    throw Error("the ranges of steps must start at step 1 and ascend", {}, "--step-ranges");
  const bool open_set = std::any_of(rows.begin(), rows.end(), [](const CalibrationRow& r) { return r.hidden; });
  std::vector<StepModels> out;
  for (std::size_t k = 0; k < first.size(); ++k) {
    const int lo = first[k], hi = k + 1 < first.size() ? first[k + 1] : std::numeric_limits<int>::max();
    std::vector<std::vector<double>> known, all;
    std::vector<int> right, pose_right, in_db, known_group, all_group;
    for (const CalibrationRow& r : rows) {
      if (r.step < lo || r.step >= hi) continue;
      all.push_back(r.features);
      in_db.push_back(in_database_label(r));
      all_group.push_back(r.group);
      if (r.hidden) continue;
      known.push_back(quadratic_terms(r.features));
      right.push_back(r.right ? 1 : 0);
      pose_right.push_back(r.pose_right ? 1 : 0);
      known_group.push_back(r.group);
    }
    const std::string steps = "steps " + std::to_string(lo) + (hi == std::numeric_limits<int>::max()
                                                                    ? std::string(" on")
                                                                    : '-' + std::to_string(hi - 1));
    if (known.empty()) throw Error("no answers of known objects at " + steps + " to fit on", {}, "--step-ranges");
    StepModels m;
    m.first_step = lo;
    m.l2[0] = choose_l2(known, right, known_group, l2_grid, 5, kTermClamp);
    m.object = fit_logistic(known, right, m.l2[0], kTermClamp);
    m.object.quadratic = true;
    m.l2[1] = choose_l2(known, pose_right, known_group, l2_grid, 5, kTermClamp);
    m.pose = fit_logistic(known, pose_right, m.l2[1], kTermClamp);
    m.pose.quadratic = true;
    if (open_set) {
      if (known.size() == all.size())
        throw Error("no runs of hidden objects at " + steps + " to fit the open-set score on", {}, "--step-ranges");
      m.l2[2] = choose_l2(all, in_db, all_group, l2_grid, 5, kTermClamp);
      m.in_database = fit_logistic(all, in_db, m.l2[2], kTermClamp);
    }
    out.push_back(std::move(m));
  }
  return out;
}

double choose_open_set_threshold(std::vector<double> right, std::size_t runs, double max_drop) {
  if (!(max_drop >= 0.0 && max_drop < 1.0))
    throw Error("the open-set drop must lie in [0, 1)", {}, "--open-set-drop");
  const auto k = static_cast<std::size_t>(std::floor(max_drop * static_cast<double>(runs) + 1e-9));
  if (k >= right.size()) return 1.0;
  std::sort(right.begin(), right.end());
  return right[k];
}

double choose_open_set_threshold_clustered(std::vector<KnownAnswer> answers, double max_drop, double confidence,
                                           int resamples, std::uint64_t seed) {
  if (!(max_drop >= 0.0 && max_drop < 1.0))
    throw Error("the open-set drop must lie in [0, 1)", {}, "--open-set-drop");
  if (!(confidence >= 0.0 && confidence < 1.0))
    throw Error("the open-set confidence must lie in [0, 1)", {}, "--open-set-confidence");
  if (resamples < 1) throw Error("at least one resample is needed", {}, "resamples");
  auto right_scores = [](const std::vector<const KnownAnswer*>& a) {
    std::vector<double> r;
    for (const KnownAnswer* x : a)
      if (x->right) r.push_back(x->score);
    return r;
  };
  // Clusters in a canonical order, each its answers sorted, so the input order does not matter.
  std::sort(answers.begin(), answers.end(), [](const KnownAnswer& a, const KnownAnswer& b) {
    return std::tie(a.group, a.right, a.score) < std::tie(b.group, b.right, b.score);
  });
  std::vector<std::vector<const KnownAnswer*>> clusters;
  for (std::size_t i = 0; i < answers.size(); ++i) {
    if (i == 0 || answers[i].group != answers[i - 1].group) clusters.emplace_back();
    clusters.back().push_back(&answers[i]);
  }
  std::vector<const KnownAnswer*> all;
  for (const auto& c : clusters) all.insert(all.end(), c.begin(), c.end());
  if (confidence == 0.0 || clusters.empty()) return choose_open_set_threshold(right_scores(all), all.size(), max_drop);
  Rng rng(seed);
  std::vector<double> t(static_cast<std::size_t>(resamples));
  std::vector<const KnownAnswer*> sample;
  for (double& x : t) {
    sample.clear();
    for (std::size_t k = 0; k < clusters.size(); ++k) {
      const auto& c = clusters[rng.index(clusters.size())];
      sample.insert(sample.end(), c.begin(), c.end());
    }
    x = choose_open_set_threshold(right_scores(sample), sample.size(), max_drop);
  }
  std::sort(t.begin(), t.end());
  const auto k = static_cast<std::size_t>(std::floor((1.0 - confidence) * static_cast<double>(resamples) + 1e-9));
  return t[std::min(k, t.size() - 1)];
}

namespace {

nlohmann::ordered_json model_json(const LogisticModel& m) {
  nlohmann::ordered_json j;
  j["mean"] = m.mean;
  j["scale"] = m.scale;
  j["coef"] = m.coef;
  j["terms"] = m.quadratic ? "quadratic" : "linear";
  j["clamp"] = m.clamp;
  return j;
}

LogisticModel model_from(const nlohmann::ordered_json& j, const std::string& key, std::size_t features,
                         const std::string& file, const std::string& prefix) {
  const std::string at = prefix + "." + key;
  if (!j.contains(key) || !j[key].is_object()) throw Error("missing the model object", file, at);
  const auto& m = j[key];
  LogisticModel out;
  if (m.contains("terms")) {   // absent: linear (version 2)
    if (m["terms"] == "quadratic") out.quadratic = true;
    else if (m["terms"] != "linear") throw Error("terms must be \"linear\" or \"quadratic\"", file, at + ".terms");
  }
  if (m.contains("clamp")) {   // absent: 0, not clamped (version 2)
    if (!m["clamp"].is_number() || !(m["clamp"].get<double>() >= 0.0) || !std::isfinite(m["clamp"].get<double>()))
      throw Error("the clamp must be a number >= 0", file, at + ".clamp");
    out.clamp = m["clamp"].get<double>();
  }
  const std::size_t terms = out.quadratic ? 2 * features : features;
  auto numbers = [&](const char* name, std::size_t size) {
    const std::string where = at + "." + name;
    if (!m.contains(name) || !m[name].is_array() || m[name].size() != size)
      throw Error("expected an array of " + std::to_string(size) + " numbers", file, where);
    std::vector<double> v;
    for (const auto& x : m[name]) {
      if (!x.is_number() || !std::isfinite(x.get<double>())) throw Error("expected finite numbers", file, where);
      v.push_back(x.get<double>());
    }
    return v;
  };
  out.mean = numbers("mean", terms);
  out.scale = numbers("scale", terms);
  out.coef = numbers("coef", terms + 1);
  for (double s : out.scale)
    if (!(s > 0.0)) throw Error("scales must be positive", file, at + ".scale");
  return out;
}

}  // namespace

namespace {
/// The answer sets' part of a calibration file, every count and number checked.
AnswerSetCalibration read_answer_sets(const nlohmann::ordered_json& s, const std::string& file, const std::string& at) {
  if (!s.is_object()) throw Error("expected an object", file, at);
  AnswerSetCalibration a;
  if (!s.contains("alpha") || !s["alpha"].is_number() || !(s["alpha"].get<double>() > 0.0 && s["alpha"].get<double>() < 1.0))
    throw Error("alpha must be a number in (0, 1)", file, at + ".alpha");
  a.alpha = s["alpha"].get<double>();
  if (s.contains("tie_nats") && !(s["tie_nats"].is_number() && std::isfinite(s["tie_nats"].get<double>()) &&
                                  s["tie_nats"].get<double>() >= 0.0 && s["tie_nats"].get<double>() <= 100.0))
    throw Error("tie_nats must be a number in [0, 100]", file, at + ".tie_nats");
  a.tie_nats = s.contains("tie_nats") ? s["tie_nats"].get<double>() : 0.0;
  if (s.contains("simulation") && !s["simulation"].is_object())
    throw Error("expected an object (the noise, sensing and sensors settings)", file, at + ".simulation");
  // As simulation_of gives it: sorted, unset overrides (null, as version 5 wrote them) left out,
  // so that a file stays valid when a key is added.
  a.simulation = s.contains("simulation") ? simulation_of(s["simulation"]) : nlohmann::ordered_json::object();
  if (!s.contains("steps") || !s["steps"].is_array() || s["steps"].empty())
    throw Error("missing the scores per step (a non-empty array)", file, at + ".steps");
  for (std::size_t k = 0; k < s["steps"].size(); ++k) {
    const auto& r = s["steps"][k];
    const std::string where = at + ".steps[" + std::to_string(k) + "]";
    if (!r.is_object()) throw Error("expected an object", file, where);
    if (!r.contains("step") || !r["step"].is_number_integer() || r["step"].get<long long>() != static_cast<long long>(k + 1))
      throw Error("steps must be 1, 2, ... in order", file, where + ".step");
    if (!r.contains("gaps") || !r["gaps"].is_array()) throw Error("expected an array of gaps", file, where + ".gaps");
    if (!r.contains("infinite") || !r["infinite"].is_number_unsigned())
      throw Error("expected a count of runs without a hypothesis of their class", file, where + ".infinite");
    const std::size_t infinite = r["infinite"].get<std::size_t>();
    if (!r.contains("runs") || !r["runs"].is_number_unsigned() || r["runs"].get<std::size_t>() != r["gaps"].size() + infinite ||
        infinite > r["runs"].get<std::size_t>())
      throw Error("runs must be the number of gaps plus the infinite ones", file, where + ".runs");
    if (r["runs"].get<std::size_t>() == 0) throw Error("a step without runs", file, where + ".runs");
    std::vector<double> gaps;
    gaps.reserve(r["gaps"].size());
    for (const auto& g : r["gaps"]) {
      if (!g.is_number() || !std::isfinite(g.get<double>()) || g.get<double>() < 0.0)
        throw Error("gaps must be finite numbers >= 0", file, where + ".gaps");
      gaps.push_back(g.get<double>());
    }
    a.steps.emplace_back(std::move(gaps), infinite);
    a.steps.back().set_tie(a.tie_nats);
  }
  return a;
}
}  // namespace

nlohmann::ordered_json to_json(const Calibration& c) {
  nlohmann::ordered_json j;
  j["format"] = kFormat;
  j["version"] = Calibration::kVersion;
  j["database_fingerprint"] = c.database_fingerprint;
  j["features"] = c.features;
  j["steps"] = nlohmann::ordered_json::array();
  for (const StepModels& m : c.ranges) {
    nlohmann::ordered_json r;
    r["first_step"] = m.first_step;
    r["object"] = model_json(m.object);
    r["pose"] = model_json(m.pose);
    r["in_database"] = m.in_database ? model_json(*m.in_database) : nlohmann::ordered_json(nullptr);
    r["l2"] = m.l2;   // the penalties the fit chose (informational)
    j["steps"].push_back(r);
  }
  j["open_set_threshold"] = c.open_set_threshold ? nlohmann::ordered_json(*c.open_set_threshold) : nullptr;
  // One entry per simulation the runs were drawn with (an empty array: no answer sets).
  j["answer_sets"] = nlohmann::ordered_json::array();
  for (const AnswerSetCalibration& a : c.answer_sets) {
    nlohmann::ordered_json s;
    s["alpha"] = a.alpha;
    s["score"] = "log-weight gap of the true class of congruent objects to the answer; outside the state 1e6 plus its "
                 "shape-prior gap (engine/recognition/answer_set.hpp)";
    s["tie_nats"] = a.tie_nats;
    s["simulation"] = a.simulation;
    s["steps"] = nlohmann::ordered_json::array();
    for (std::size_t k = 0; k < a.steps.size(); ++k)
      s["steps"].push_back({{"step", k + 1}, {"runs", a.steps[k].size()}, {"infinite", a.steps[k].infinite()},
                            {"gaps", a.steps[k].finite()}});
    j["answer_sets"].push_back(s);
  }
  j["provenance"] = c.provenance.is_null() ? nlohmann::ordered_json::object() : c.provenance;
  return j;
}

void write_calibration(const std::filesystem::path& file, const Calibration& c) {
  io::AtomicOutput out(file);
  {
    std::ofstream f(out.temp_path());
    f << to_json(c).dump(1) << "\n";
    f.close();
    if (!f) throw Error("cannot write the calibration file", file.string());
  }
  out.commit();
}

Calibration read_calibration(const std::filesystem::path& path, const std::string& database_fingerprint) {
  const std::string file = path.string();
  std::ifstream in(path);
  if (!in) throw Error("cannot read the calibration file", file);
  std::ostringstream text;
  text << in.rdbuf();
  const auto j = nlohmann::ordered_json::parse(text.str(), nullptr, false);
  if (j.is_discarded() || !j.is_object()) throw Error("the calibration file is not a JSON object", file);
  if (!j.contains("format") || j["format"] != kFormat)
    throw Error("not a Touchstone calibration file (format must be \"" + std::string(kFormat) + "\")", file, "format");
  if (!j.contains("version") || !j["version"].is_number_integer() ||
      j["version"].get<long long>() < Calibration::kOldestVersion || j["version"].get<long long>() > Calibration::kVersion)
    throw Error("calibration version " + (j.contains("version") ? j["version"].dump() : std::string("absent")) +
                " is not supported (this build reads versions " + std::to_string(Calibration::kOldestVersion) + " to " +
                std::to_string(Calibration::kVersion) + "): refit it with `touchstone calibrate`",
                file, "version");
  Calibration c;
  if (!j.contains("database_fingerprint") || !j["database_fingerprint"].is_string())
    throw Error("missing the database fingerprint", file, "database_fingerprint");
  c.database_fingerprint = j["database_fingerprint"].get<std::string>();
  if (!database_fingerprint.empty() && c.database_fingerprint != database_fingerprint)
    throw Error("the calibration was fitted for another database (fingerprint " +
                c.database_fingerprint.substr(0, 12) + "..., this one " + database_fingerprint.substr(0, 12) +
                "...): fit one on runs of this database with `touchstone calibrate`", file, "database_fingerprint");
  if (!j.contains("features") || !j["features"].is_array()) throw Error("missing the feature names", file, "features");
  for (const auto& f : j["features"]) {
    if (!f.is_string()) throw Error("feature names must be strings", file, "features");
    c.features.push_back(f.get<std::string>());
  }
  if (c.features != confidence_feature_names())
    throw Error("the calibration's features differ from this build's (" + j["features"].dump() +
                "): refit it with this version", file, "features");
  if (!j.contains("steps") || !j["steps"].is_array() || j["steps"].empty())
    throw Error("missing the models per range of steps (a non-empty array)", file, "steps");
  for (std::size_t k = 0; k < j["steps"].size(); ++k) {
    const auto& r = j["steps"][k];
    const std::string where = "steps[" + std::to_string(k) + "]";
    if (!r.is_object()) throw Error("expected an object", file, where);
    StepModels m;
    if (!r.contains("first_step") || !r["first_step"].is_number_integer())
      throw Error("expected an integer first step", file, where + ".first_step");
    m.first_step = r["first_step"].get<int>();
    if (k == 0 ? m.first_step != 1 : m.first_step <= c.ranges.back().first_step)
      throw Error("the ranges must start at step 1 and ascend", file, where + ".first_step");
    m.object = model_from(r, "object", c.features.size(), file, where);
    m.pose = model_from(r, "pose", c.features.size(), file, where);
    if (r.contains("in_database") && !r["in_database"].is_null())
      m.in_database = model_from(r, "in_database", c.features.size(), file, where);
    c.ranges.push_back(std::move(m));
  }
  if (j.contains("open_set_threshold") && !j["open_set_threshold"].is_null()) {
    const auto& t = j["open_set_threshold"];
    if (!t.is_number() || !(t.get<double>() >= 0.0 && t.get<double>() <= 1.0))
      throw Error("the open-set threshold must be a number in [0, 1] or null", file, "open_set_threshold");
    for (std::size_t k = 0; k < c.ranges.size(); ++k)
      if (!c.ranges[k].in_database)
        throw Error("an open-set threshold needs the in-database model of every range of steps", file,
                    "steps[" + std::to_string(k) + "].in_database");
    c.open_set_threshold = t.get<double>();
  }
  if (j.contains("answer_sets") && !j["answer_sets"].is_null() && j["answer_sets"] != nlohmann::ordered_json::array()) {
    if (j["version"].get<long long>() < 5)
      throw Error("the answer sets of a version " + j["version"].dump() +
                  " calibration scored classes against the ln w leader, which left the truth out when the near-twin "
                  "verification chose a lighter twin; refit with `touchstone calibrate` (version 5 scores against the answer)",
                  file, "answer_sets");
    const auto& s = j["answer_sets"];
    if (j["version"].get<long long>() == 5) {   // one simulation's, an object
      c.answer_sets.push_back(read_answer_sets(s, file, "answer_sets"));
    } else {
      if (!s.is_array()) throw Error("expected an array (one entry per simulation) or null", file, "answer_sets");
      for (std::size_t k = 0; k < s.size(); ++k) {
        const std::string at = "answer_sets[" + std::to_string(k) + "]";
        AnswerSetCalibration a = read_answer_sets(s[k], file, at);
        if (c.answer_sets_for(a.simulation))
          throw Error("a second entry for the simulation " + a.simulation.dump() + ": one per simulation", file,
                      at + ".simulation");
        c.answer_sets.push_back(std::move(a));
      }
    }
  }
  c.provenance = j.contains("provenance") ? j["provenance"] : nlohmann::ordered_json::object();
  return c;
}

}  // namespace ts::experiments
