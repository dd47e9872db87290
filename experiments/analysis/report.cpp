#include "experiments/analysis/report.hpp"

#include "engine/core.hpp"
#include "engine/recognition/support.hpp"
#include "experiments/analysis/calibration.hpp"
#include "io/atomic_file.hpp"

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <map>
#include <numbers>
#include <set>
#include <ostream>
#include <sstream>

#ifndef TS_SOURCE_DIR
#define TS_SOURCE_DIR ""
#endif

namespace ts::experiments {

ClassMap class_map(const io::RunStoreHeader& h) {
  ClassMap out;
  const auto db = nlohmann::json::parse(h.database_json, nullptr, false);
  if (!db.is_object() || !db.contains("congruent_classes") || !db["congruent_classes"].is_array()) return out;
  std::size_t k = 0;
  for (const auto& members : db["congruent_classes"]) {
    if (!members.is_array()) continue;
    for (const auto& name : members)
      if (name.is_string()) out[name.get<std::string>()] = k;
    ++k;
  }
  return out;
}

bool correct_in_class(const io::RunStoreHeader& h, const io::RunRecord& r, const io::RunStepRecord& s,
                      const ClassMap& classes) {
  if (s.correct) return true;
  if (s.best_object < 0 || static_cast<std::size_t>(s.best_object) >= h.database_objects.size() ||
      static_cast<std::size_t>(r.object) >= h.objects.size())
    return false;
  const auto a = classes.find(h.database_objects[static_cast<std::size_t>(s.best_object)]);
  const auto b = classes.find(h.objects[static_cast<std::size_t>(r.object)]);
  return a != classes.end() && b != classes.end() && a->second == b->second;
}

namespace {

using J = nlohmann::ordered_json;
constexpr double kDeg = 180.0 / std::numbers::pi;

J opt(const std::optional<double>& v, double scale = 1.0) {
  return v ? J(*v * scale) : J(nullptr);
}
J interval(const std::optional<Interval>& v, double scale = 1.0) {
  return v ? J::array({v->lo * scale, v->hi * scale}) : J(nullptr);
}

/// The four keys of one error: _median, _p95, _mean_bounded, _mean_bounded_ci95.
void put_error(J& j, const std::string& prefix, const ErrorSummary& e, double scale) {
  j[prefix + "_median"] = opt(e.median, scale);
  j[prefix + "_p95"] = opt(e.p95, scale);
  j[prefix + "_mean_bounded"] = e.bounded_mean * scale;
  j[prefix + "_mean_bounded_ci95"] = interval(e.bounded_mean_ci95, scale);
}

/// Per-step JSON rows for a set of runs (all of the same step count). `clustered`: the runs span
/// several explored objects, so rates also get the cluster bootstrap over objects (null in the
/// rows of one object).
J per_step_json(const io::RunStoreHeader& h, const std::vector<const io::RunRecord*>& runs, int steps,
                const ErrorBounds& bounds, const ClassMap& classes, bool clustered) {
  const std::vector<std::string>& stages = h.stages;
  // Set answers (a calibration's answer sets in the run): the set's size, whether it held the
  // truth, whether it was informative.
  auto column = [&](const char* name) {
    const auto it = std::find(h.step_values.begin(), h.step_values.end(), name);
    return it == h.step_values.end() ? std::size_t(-1) : static_cast<std::size_t>(it - h.step_values.begin());
  };
  const std::size_t size_col = column("answer_set.size"), covers_col = column("answer_set.covers"),
                    informative_col = column("answer_set.informative");
  const std::size_t expected_col = column("plan.expected_object_information"), drop_col = column("plan.entropy_drop");
  const std::size_t fit_col = column("fit.contact_distance_m");
  const std::size_t right_col = column("attribution.right_share"), off_col = column("contacts.off_target_share"),
                    neighbour_col = column("scene.answer_is_neighbour");
  const std::size_t found_col = column("support.found"), tilt_col = column("support.tilt_deg"),
                    height_col = column("support.height_error_m"), verdict_col = column("support.verdict");
  J rows = J::array();
  for (int k = 0; k < steps; ++k) {
    std::map<int, ClusterCounts> covered_by_object;
    std::vector<double> set_sizes, expected, drop_planned, drop_all, fit, attributed, off_target, named_neighbour,
        found, tilt, height, verdicts;
    std::size_t covered = 0, informative = 0;
    std::map<int, ClusterCounts> strict_by_object, class_by_object;
    std::vector<StepSample> samples;
    std::vector<std::vector<double>> stage_times(stages.size());
    std::vector<double> posterior, hyps, contacts;
    for (const io::RunRecord* r : runs) {
      const io::RunStepRecord& s = r->steps[static_cast<std::size_t>(k)];
      samples.push_back({s.correct, s.position_error_m, s.orientation_error_rad,
                         s.symmetric_orientation_error_rad, s.mssd_m, s.time_s, correct_in_class(h, *r, s, classes)});
      ClusterCounts& strict = strict_by_object[r->object];
      ClusterCounts& in_class = class_by_object[r->object];
      ++strict.trials;
      ++in_class.trials;
      strict.successes += samples.back().correct ? 1 : 0;
      in_class.successes += samples.back().correct || samples.back().correct_class ? 1 : 0;
      for (std::size_t i = 0; i < stages.size() && i < s.stage_times_s.size(); ++i)
        stage_times[i].push_back(s.stage_times_s[i]);
      posterior.push_back(s.posterior_true);
      contacts.push_back(s.contacts);
      if (covers_col < s.values.size() && size_col < s.values.size() && informative_col < s.values.size() &&
          !std::isnan(s.values[covers_col])) {
        const bool c = s.values[covers_col] == 1.0;
        set_sizes.push_back(s.values[size_col]);
        covered += c ? 1 : 0;
        informative += s.values[informative_col] == 1.0 ? 1 : 0;
        ClusterCounts& by = covered_by_object[r->object];
        ++by.trials;
        by.successes += c ? 1 : 0;
      }
      // A named value of the step, when the store has it and it is not NaN.
      auto take = [&](std::size_t col, std::vector<double>& into, bool magnitude = false) {
        if (col < s.values.size() && !std::isnan(s.values[col])) into.push_back(magnitude ? std::abs(s.values[col]) : s.values[col]);
      };
      take(fit_col, fit);
      take(right_col, attributed);
      take(off_col, off_target);
      take(neighbour_col, named_neighbour);
      take(found_col, found);
      take(tilt_col, tilt);
      take(height_col, height, true);
      take(verdict_col, verdicts);
      // Active touch: the planner's expectation of the chosen grasp and the step's entropy drop.
      if (drop_col < s.values.size() && !std::isnan(s.values[drop_col])) {
        drop_all.push_back(s.values[drop_col]);
        if (expected_col < s.values.size() && !std::isnan(s.values[expected_col])) {
          expected.push_back(s.values[expected_col]);
          drop_planned.push_back(s.values[drop_col]);
        }
      }
    }
    const StepSummary m = summarize_step(k + 1, samples, bounds);
    J row;
    row["step"] = k + 1;
    row["runs"] = m.runs;
    row["correct"] = m.correct;
    row["recognition_rate"] = m.recognition_rate;
    row["recognition_rate_ci95"] = J::array({m.recognition_rate_ci95.lo, m.recognition_rate_ci95.hi});
    // The cluster bootstrap over explored objects (see "intervals" in the report).
    auto bootstrap = [&](const std::map<int, ClusterCounts>& by_object) {
      if (!clustered) return J(nullptr);
      std::vector<ClusterCounts> c;
      for (const auto& [object, counts] : by_object) c.push_back(counts);
      const Interval i = cluster_bootstrap_interval(c);
      return J::array({i.lo, i.hi});
    };
    row["recognition_rate_cluster_ci95"] = bootstrap(strict_by_object);
    // Class-aware: an answer congruent with the true object counts as right (the strict rate
    // above is kept as it was).
    row["correct_class"] = m.correct_class;
    row["recognition_rate_class"] = m.recognition_rate_class;
    row["recognition_rate_class_ci95"] =
        J::array({m.recognition_rate_class_ci95.lo, m.recognition_rate_class_ci95.hi});
    row["recognition_rate_class_cluster_ci95"] = bootstrap(class_by_object);
    // Set answers: the share of runs whose set held the true class (Wilson: runs independent;
    // the bootstrap: objects independent), the sets' sizes in classes (an uninformative set
    // counts as every class), the share of informative sets. Null without answer sets.
    if (!set_sizes.empty()) {
      const std::size_t n = set_sizes.size();
      const Interval w = wilson_interval(covered, n);
      row["set_coverage"] = double(covered) / double(n);
      row["set_coverage_ci95"] = J::array({w.lo, w.hi});
      row["set_coverage_cluster_ci95"] = bootstrap(covered_by_object);
      row["set_size_median"] = opt(median(set_sizes));
      row["set_size_mean"] = mean_t_interval(set_sizes).mean;
      row["set_size_p90"] = opt(quantile(set_sizes, 0.9));
      row["set_informative_share"] = double(informative) / double(n);
    } else {
      for (const char* key : {"set_coverage", "set_coverage_ci95", "set_coverage_cluster_ci95", "set_size_median",
                              "set_size_mean", "set_size_p90", "set_informative_share"})
        row[key] = nullptr;
    }
    // Active touch, per step: the expected information about the object of the grasps the
    // planner chose (nats, median), what those steps gave (the drop of the posterior's entropy
    // over objects, median), and the drop over every run of the step (random runs included).
    row["plan_expected_object_information_median"] = opt(median(expected));
    row["plan_entropy_drop_median"] = opt(median(drop_planned));
    row["entropy_drop_median"] = opt(median(drop_all));
    // The mean contact-to-model distance of the answer at its pose, median over the runs that
    // answered (right or not): what real data without a truth can check.
    row["contact_distance_m_median"] = opt(median(fit));
    // Scenes: the share of contacts truly off the target (mean over runs), and the share the
    // step's attribution labelled right, target or not (mean over runs; null when it did not run).
    auto mean_or_null = [](const std::vector<double>& v) { return v.empty() ? J(nullptr) : J(mean_t_interval(v).mean); };
    row["off_target_share_mean"] = mean_or_null(off_target);
    row["attribution_accuracy_mean"] = mean_or_null(attributed);
    // A cluttered scene: the share of runs whose answer named a neighbour (null without them).
    row["neighbour_answer_share"] = mean_or_null(named_neighbour);
    // The support stage on a scene: the share of runs that found a support, and against the true
    // one under the object the found plane's tilt and |height| there (medians over those found).
    row["support_found_share"] = mean_or_null(found);
    row["support_tilt_deg_median"] = opt(median(tilt));
    row["support_height_error_m_median"] = opt(median(height));
    // Where it was looked for, the share of runs at each verdict (found, or the test the
    // candidate with the most contacts on it failed: engine/recognition/support.hpp); null when
    // not looked.
    J shares = nullptr;
    for (const double v : verdicts) {
      const std::string name = to_string(static_cast<SupportVerdict>(static_cast<int>(v)));
      if (shares.is_null()) shares = J::object();
      shares[name] = shares.value(name, 0.0) + 1.0 / static_cast<double>(verdicts.size());
    }
    row["support_verdict_shares"] = shares;
    // The interface's keys first, then the rest.
    row["position_error_m_median"] = opt(m.position_m.median);
    row["orientation_error_deg_median"] = opt(m.orientation_rad.median, kDeg);
    row["symmetric_orientation_error_deg_median"] = opt(m.symmetric_orientation_rad.median, kDeg);
    row["time_s_median"] = opt(m.time_s_median);
    row["time_s_p95"] = opt(m.time_s_p95);
    row["time_s_mean"] = opt(m.time_s_mean);
    put_error(row, "position_error_m", m.position_m, 1.0);
    put_error(row, "orientation_error_deg", m.orientation_rad, kDeg);
    put_error(row, "symmetric_orientation_error_deg", m.symmetric_orientation_rad, kDeg);
    put_error(row, "mssd_m", m.mssd_m, 1.0);
    row["posterior_true_median"] = opt(median(posterior));
    row["contacts_median"] = opt(median(contacts));
    J st = J::object();
    for (std::size_t i = 0; i < stages.size(); ++i) st[stages[i]] = opt(median(stage_times[i]));
    row["stage_times_s_median"] = st;
    rows.push_back(row);
  }
  return rows;
}

/// First step from which the recognition rate stays >= level to the end; null if never.
J steps_to_rate(const J& per_step, double level) {
  J first = nullptr;
  for (const auto& row : per_step) {
    if (row["recognition_rate"].get<double>() >= level) {
      if (first.is_null()) first = row["step"];
    } else {
      first = nullptr;
    }
  }
  return first;
}

J summary_json(const J& per_step, const std::vector<const io::RunRecord*>& runs) {
  J s;
  const J& last = per_step.back();
  s["runs"] = runs.size();
  s["final_step"] = last["step"];
  s["recognition_rate_final"] = last["recognition_rate"];
  s["recognition_rate_final_ci95"] = last["recognition_rate_ci95"];
  // Step 20 is where the paper quotes its figures (Sections 5.5, 5.7.2).
  const std::size_t k20 = std::min<std::size_t>(20, per_step.size()) - 1;
  s["recognition_rate_step20"] = per_step[k20]["recognition_rate"];
  s["recognition_rate_step20_ci95"] = per_step[k20]["recognition_rate_ci95"];
  s["recognition_rate_step20_cluster_ci95"] = per_step[k20]["recognition_rate_cluster_ci95"];
  s["recognition_rate_class_final"] = last["recognition_rate_class"];
  s["recognition_rate_class_final_ci95"] = last["recognition_rate_class_ci95"];
  s["recognition_rate_class_step20"] = per_step[k20]["recognition_rate_class"];
  s["recognition_rate_class_step20_cluster_ci95"] = per_step[k20]["recognition_rate_class_cluster_ci95"];
  s["position_error_m_median_final"] = last["position_error_m_median"];
  s["orientation_error_deg_median_final"] = last["orientation_error_deg_median"];
  s["symmetric_orientation_error_deg_median_final"] = last["symmetric_orientation_error_deg_median"];
  s["set_coverage_step20"] = per_step[k20]["set_coverage"];
  s["set_coverage_step20_cluster_ci95"] = per_step[k20]["set_coverage_cluster_ci95"];
  s["set_size_median_step20"] = per_step[k20]["set_size_median"];
  s["steps_to_90_percent"] = steps_to_rate(per_step, 0.9);
  std::vector<double> times;
  for (const io::RunRecord* r : runs)
    for (const auto& st : r->steps) times.push_back(st.time_s);
  s["time_s_per_step_mean"] = times.empty() ? J(nullptr) : J(mean_t_interval(times).mean);
  s["time_s_per_step_median"] = opt(median(times));
  s["time_s_per_step_p95"] = opt(quantile(times, 0.95));
  return s;
}

/// diagnostics.truth_pose (the store's truth_pose.* values): per step, the runs where the true
/// object at its true pose would be named by the step's answer rule (what a perfect search could
/// answer with this evidence and rule), and the misses split into those the search lost (the
/// truth at its pose would have won) and those the evidence lost (another object beats even the
/// true pose). Null when the store has no such values.
J truth_pose_json(const io::RunStoreHeader& h, const std::vector<const io::RunRecord*>& runs, bool clustered) {
  const auto it = std::find(h.step_values.begin(), h.step_values.end(), "truth_pose.wins");
  if (it == h.step_values.end()) return nullptr;
  const auto col = static_cast<std::size_t>(it - h.step_values.begin());
  J rows = J::array();
  std::size_t evaluated_any = 0;
  for (int k = 0; k < h.steps; ++k) {
    std::size_t n = 0, wins = 0, right = 0, search = 0, evidence = 0;
    std::map<int, ClusterCounts> by_object;
    for (const io::RunRecord* r : runs) {
      if (static_cast<std::size_t>(k) >= r->steps.size()) continue;
      const io::RunStepRecord& s = r->steps[static_cast<std::size_t>(k)];
      if (col >= s.values.size() || std::isnan(s.values[col])) continue;   // not evaluated
      const bool w = s.values[col] == 1.0;
      ++n;
      wins += w ? 1 : 0;
      right += s.correct ? 1 : 0;
      if (!s.correct) (w ? search : evidence) += 1;
      ClusterCounts& c = by_object[r->object];
      ++c.trials;
      c.successes += w ? 1 : 0;
    }
    evaluated_any += n;
    J row;
    row["step"] = k + 1;
    row["runs"] = n;
    row["correct"] = right;
    row["truth_pose_wins"] = wins;
    row["truth_pose_rate"] = n ? J(double(wins) / double(n)) : J(nullptr);
    if (n) {
      const Interval i = wilson_interval(wins, n);
      row["truth_pose_rate_ci95"] = J::array({i.lo, i.hi});
    } else {
      row["truth_pose_rate_ci95"] = nullptr;
    }
    if (clustered && n) {
      std::vector<ClusterCounts> c;
      for (const auto& [object, counts] : by_object) c.push_back(counts);
      const Interval i = cluster_bootstrap_interval(c);
      row["truth_pose_rate_cluster_ci95"] = J::array({i.lo, i.hi});
    } else {
      row["truth_pose_rate_cluster_ci95"] = nullptr;
    }
    row["misses_lost_by_search"] = search;
    row["misses_lost_by_evidence"] = evidence;
    rows.push_back(row);
  }
  if (evaluated_any == 0) return nullptr;
  return rows;
}

struct VariantJson {
  J per_step, per_object, summary, confidence, open_set, truth_pose, stages, confusions;
};

/// What the misses named instead, at the last step: per (explored object, named object) the runs,
/// most frequent first; "named": null where the step named nothing. `congruent`: the two are in
/// one congruent class (the class-aware rate counts such a miss as right). Hidden objects' runs
/// are left out (open_set judges them).
J confusions_json(const io::RunStoreHeader& h, const std::vector<const io::RunRecord*>& runs, const ClassMap& classes) {
  std::map<std::pair<int, int>, std::size_t> counts;   // (explored, named or -1) -> runs
  std::map<int, std::size_t> misses_of;
  std::size_t misses = 0;
  const auto last = static_cast<std::size_t>(std::max(0, h.steps - 1));
  for (const io::RunRecord* r : runs) {
    if (r->steps.size() <= last || r->steps[last].correct) continue;
    const io::RunStepRecord& s = r->steps[last];
    const bool named = s.best_object >= 0 && static_cast<std::size_t>(s.best_object) < h.database_objects.size();
    ++counts[{r->object, named ? s.best_object : -1}];
    ++misses_of[r->object];
    ++misses;
  }
  std::vector<std::pair<std::pair<int, int>, std::size_t>> rows(counts.begin(), counts.end());
  std::stable_sort(rows.begin(), rows.end(), [](const auto& a, const auto& b) { return a.second > b.second; });
  J pairs = J::array();
  for (const auto& [key, n] : rows) {
    const std::string& object = h.objects.at(static_cast<std::size_t>(key.first));
    J row;
    row["object"] = object;
    row["named"] = key.second < 0 ? J(nullptr) : J(h.database_objects[static_cast<std::size_t>(key.second)]);
    row["runs"] = n;
    row["share_of_object_misses"] = double(n) / double(misses_of[key.first]);
    bool congruent = false;
    if (key.second >= 0) {
      const auto a = classes.find(object), b = classes.find(h.database_objects[static_cast<std::size_t>(key.second)]);
      congruent = a != classes.end() && b != classes.end() && a->second == b->second;
    }
    row["congruent"] = congruent;
    pairs.push_back(row);
  }
  J out;
  out["step"] = h.steps;
  out["misses"] = misses;
  out["pairs"] = pairs;
  return out;
}

/// The store's ran.<stage> values (RecognitionEngine): per stage of the method's pipeline, the
/// steps that recorded it and the share of them that left it out (their scene did not need it).
/// Null when the store has no such values (a store written before they were recorded).
J stages_json(const io::RunStoreHeader& h, const std::vector<const io::RunRecord*>& runs) {
  J out = J::array();
  for (std::size_t col = 0; col < h.step_values.size(); ++col) {
    const std::string& name = h.step_values[col];
    if (!name.starts_with("ran.")) continue;
    std::size_t n = 0, skipped = 0;
    for (const io::RunRecord* r : runs)
      for (const io::RunStepRecord& s : r->steps) {
        if (col >= s.values.size() || std::isnan(s.values[col])) continue;   // not in the method
        ++n;
        skipped += s.values[col] == 0.0 ? 1 : 0;
      }
    if (n > 0) out.push_back({{"stage", name.substr(4)}, {"steps", n}, {"skipped_share", double(skipped) / double(n)}});
  }
  return out.empty() ? J(nullptr) : out;
}


J bins_json(const ConfidenceCalibration& c) {
  J out = J::array();
  for (const ReliabilityBin& b : c.bins)
    out.push_back({{"lo", b.lo}, {"hi", b.hi}, {"n", b.n}, {"mean_confidence", b.mean_confidence},
                   {"accuracy", b.accuracy}});
  return out;
}

/// Calibration of the confidences per step (ECE, Brier, reliability): those the store recorded,
/// or recomputed from its features with `calibration`. Null when there are none.
/// A step's confidences (object, pose): those the store recorded, or recomputed from its features
/// with the report's calibration; NaN when there are none.
class ConfidenceSource {
 public:
  ConfidenceSource(const io::RunStoreHeader& h, const ReportSettings& settings) : settings_(settings) {
    auto column = [&](const std::string& name) {
      const auto it = std::find(h.step_values.begin(), h.step_values.end(), name);
      return it == h.step_values.end() ? -1 : static_cast<int>(it - h.step_values.begin());
    };
    object_col_ = column("confidence_object");
    pose_col_ = column("confidence_pose");
    if (settings.calibration)
      for (const std::string& f : settings.calibration->features) {
        feature_cols_.push_back(column("feature." + f));
        if (feature_cols_.back() < 0)
          throw Error("the run store has no feature '" + f + "' to apply the calibration to",
                      settings.calibration_path, "features");
      }
  }
  bool available() const { return settings_.calibration || (object_col_ >= 0 && pose_col_ >= 0); }
  std::pair<double, double> at(const io::RunStepRecord& s, int step) const {
    if (settings_.calibration) {
      const std::vector<double> f = features(s);
      return {settings_.calibration->object_confidence(step, f), settings_.calibration->pose_confidence(step, f)};
    }
    return {s.values.at(static_cast<std::size_t>(object_col_)), s.values.at(static_cast<std::size_t>(pose_col_))};
  }
  /// The open-set score of the report's calibration (which must have one).
  double in_database(const io::RunStepRecord& s, int step) const {
    return settings_.calibration->in_database(step, features(s)).value();
  }

 private:
  std::vector<double> features(const io::RunStepRecord& s) const {
    std::vector<double> f;
    for (int c : feature_cols_) f.push_back(s.values.at(static_cast<std::size_t>(c)));
    return f;
  }

  const ReportSettings& settings_;
  int object_col_ = -1, pose_col_ = -1;
  std::vector<int> feature_cols_;
};

J confidence_json(const io::RunStoreHeader& h, const std::vector<const io::RunRecord*>& runs,
                  const ReportSettings& settings) {
  const ConfidenceSource source(h, settings);
  if (!source.available() || runs.empty()) return nullptr;
  const int steps = h.steps;
  std::vector<double> all_object, all_pose;
  std::vector<int> all_object_right, all_pose_right;
  J rows = J::array();
  J at20 = nullptr;
  for (int k = 0; k < steps; ++k) {
    std::vector<double> obj, pose;
    std::vector<int> obj_right, pose_right;
    for (const io::RunRecord* r : runs) {
      const io::RunStepRecord& s = r->steps[static_cast<std::size_t>(k)];
      const auto [co, cp] = source.at(s, k + 1);
      if (!std::isfinite(co) || !std::isfinite(cp)) continue;  // recorded without a calibration
      obj.push_back(co);
      pose.push_back(cp);
      obj_right.push_back(s.correct ? 1 : 0);
      pose_right.push_back(s.correct && s.position_error_m < 0.01 ? 1 : 0);
    }
    if (obj.empty()) return nullptr;
    const ConfidenceCalibration a = confidence_calibration(obj, obj_right);
    const ConfidenceCalibration b = confidence_calibration(pose, pose_right);
    J row;
    row["step"] = k + 1;
    row["n"] = a.n;
    row["object_confidence_mean"] = a.mean_confidence;
    row["object_accuracy"] = a.accuracy;
    row["object_ece"] = a.ece;
    const EceNoise noise = ece_sampling_noise(obj);   // an exact model's ECE at these answers
    row["object_ece_noise_mean"] = noise.mean;
    row["object_ece_noise_p95"] = noise.p95;
    row["object_brier"] = a.brier;
    row["pose_confidence_mean"] = b.mean_confidence;
    row["pose_accuracy"] = b.accuracy;
    row["pose_ece"] = b.ece;
    row["pose_brier"] = b.brier;
    rows.push_back(row);
    if (k + 1 == std::min(20, steps)) at20 = J{{"object", bins_json(a)}, {"pose", bins_json(b)}};
    all_object.insert(all_object.end(), obj.begin(), obj.end());
    all_pose.insert(all_pose.end(), pose.begin(), pose.end());
    all_object_right.insert(all_object_right.end(), obj_right.begin(), obj_right.end());
    all_pose_right.insert(all_pose_right.end(), pose_right.begin(), pose_right.end());
  }
  const ConfidenceCalibration a = confidence_calibration(all_object, all_object_right);
  const ConfidenceCalibration b = confidence_calibration(all_pose, all_pose_right);
  J out;
  out["source"] = settings.calibration ? "recomputed from the stored features with " + settings.calibration_path
                                       : std::string("recorded by the experiment");
  out["object_outcome"] = "the named object is the explored object (strict)";
  out["pose_outcome"] = "the named object is right and its position error is below 1 cm";
  out["bins"] = a.bins.size();
  out["per_step"] = rows;
  out["all_steps"] = {{"n", a.n}, {"object_ece", a.ece}, {"object_brier", a.brier}, {"pose_ece", b.ece},
                      {"pose_brier", b.brier}, {"object_reliability", bins_json(a)},
                      {"pose_reliability", bins_json(b)}};
  out["step20_reliability"] = at20;
  return out;
}

/// Open set (config `hidden`): runs of objects the recognizer did not know, against runs of known
/// ones, with the calibration's open-set threshold t: an answer with in-database score < t is
/// "not in the database". Per step: the false-accept rate (hidden runs that name an object; null
/// without hidden runs) and the known objects' recognition with and without the threshold. Null
/// without a threshold.
J open_set_json(const io::RunStoreHeader& h, const std::vector<const io::RunRecord*>& known,
                const std::vector<const io::RunRecord*>& hidden, const ReportSettings& settings,
                const ClassMap& classes) {
  if (!settings.calibration || !settings.calibration->open_set_threshold) return nullptr;
  const double t = *settings.calibration->open_set_threshold;
  const ConfidenceSource source(h, settings);
  J rows = J::array();
  for (int k = 0; k < h.steps; ++k) {
    const auto step = static_cast<std::size_t>(k);
    std::size_t accepts = 0, accepts_class = 0, right_closed = 0, right_open = 0;
    for (const io::RunRecord* r : hidden) {
      const io::RunStepRecord& s = r->steps[step];
      const bool accepted = s.best_object >= 0 && source.in_database(s, k + 1) >= t;
      accepts += accepted ? 1 : 0;
      // Class-aware: naming an object congruent with the hidden one names the same solid (a
      // copy of it is in the database), which is not a false accept.
      accepts_class += accepted && !correct_in_class(h, *r, s, classes) ? 1 : 0;
    }
    for (const io::RunRecord* r : known) {
      const io::RunStepRecord& s = r->steps[step];
      right_closed += s.correct ? 1 : 0;
      right_open += s.correct && source.in_database(s, k + 1) >= t ? 1 : 0;
    }
    const Interval fa = wilson_interval(accepts, hidden.size());
    J row;
    row["step"] = k + 1;
    row["hidden_runs"] = hidden.size();
    row["false_accepts"] = accepts;
    row["false_accepts_class"] = accepts_class;
    if (hidden.empty()) {   // no hidden objects: only the known objects' side
      row["false_accept_rate"] = row["false_accept_rate_ci95"] = nullptr;
      row["false_accept_rate_class"] = row["false_accept_rate_class_ci95"] = nullptr;
    } else {
      const double n = static_cast<double>(hidden.size());
      row["false_accept_rate"] = static_cast<double>(accepts) / n;
      row["false_accept_rate_ci95"] = J::array({fa.lo, fa.hi});
      const Interval fc = wilson_interval(accepts_class, hidden.size());
      row["false_accept_rate_class"] = static_cast<double>(accepts_class) / n;
      row["false_accept_rate_class_ci95"] = J::array({fc.lo, fc.hi});
    }
    row["known_runs"] = known.size();
    if (known.empty()) {
      row["known_rate_closed"] = row["known_rate_open"] = row["known_drop"] = nullptr;
    } else {
      const double n = static_cast<double>(known.size());
      row["known_rate_closed"] = static_cast<double>(right_closed) / n;
      row["known_rate_open"] = static_cast<double>(right_open) / n;
      row["known_drop"] = static_cast<double>(right_closed - right_open) / n;
    }
    rows.push_back(row);
  }
  J out;
  out["threshold"] = t;
  out["source"] = settings.calibration_path;
  out["per_step"] = rows;
  return out;
}

/// Explored objects hidden from the recognizer (config `hidden`; "each": all of them).
std::set<int> hidden_objects(const io::RunStoreHeader& h) {
  std::set<int> out;
  const J config = J::parse(h.config_json, nullptr, false);
  if (!config.is_object() || !config.contains("hidden") || !config["hidden"].is_array()) return out;
  std::set<std::string> names;
  for (const auto& n : config["hidden"])
    if (n.is_string()) names.insert(n.get<std::string>());
  for (std::size_t o = 0; o < h.objects.size(); ++o)
    if (names.count("each") || names.count(h.objects[o])) out.insert(static_cast<int>(o));
  return out;
}

VariantJson variant_json(const io::RunStoreContents& store, int variant, const ReportSettings& settings) {
  const ErrorBounds& bounds = settings.bounds;
  const auto& h = store.header;
  std::vector<const io::RunRecord*> all;
  std::vector<std::vector<const io::RunRecord*>> by_object(h.objects.size());
  for (const auto& r : store.runs)
    if (r.variant == variant) {
      all.push_back(&r);
      by_object[static_cast<std::size_t>(r.object)].push_back(&r);
    }
  const ClassMap classes = class_map(h);
  // Open set: the recognition rates are over the known objects' runs (all runs when every
  // explored object was hidden); the hidden objects' runs are judged in open_set.
  const std::set<int> hidden_set = hidden_objects(h);
  std::vector<const io::RunRecord*> known, hidden;
  for (const io::RunRecord* r : all) (hidden_set.count(r->object) ? hidden : known).push_back(r);
  if (!hidden.empty() && !known.empty()) all = known;
  VariantJson v;
  v.open_set = open_set_json(h, known, hidden, settings, classes);
  std::set<int> objects;
  for (const io::RunRecord* r : all) objects.insert(r->object);
  v.per_step = per_step_json(h, all, h.steps, bounds, classes, objects.size() > 1);
  v.summary = summary_json(v.per_step, all);
  v.confidence = confidence_json(h, all, settings);
  v.truth_pose = truth_pose_json(h, all, objects.size() > 1);
  v.stages = stages_json(h, all);
  v.confusions = confusions_json(h, all, classes);
  v.per_object = J::array();
  for (std::size_t o = 0; o < h.objects.size(); ++o) {
    if (by_object[o].empty()) continue;
    J obj;
    obj["object"] = h.objects[o];
    obj["runs"] = by_object[o].size();
    obj["per_step"] = per_step_json(h, by_object[o], h.steps, bounds, classes, false);
    obj["summary"] = summary_json(obj["per_step"], by_object[o]);
    obj["confusions"] = confusions_json(h, by_object[o], classes);
    v.per_object.push_back(obj);
  }
  return v;
}

J parse_or_text(const std::string& text) {
  try {
    return J::parse(text);
  } catch (const std::exception&) {
    return J(text);
  }
}

}  // namespace

nlohmann::ordered_json report_json(const io::RunStoreContents& store, const ReportSettings& settings,
                                   const std::string& store_path) {
  const auto& h = store.header;
  J config = parse_or_text(h.config_json);
  J versions = parse_or_text(h.versions_json);
  const std::size_t variants = h.variant_labels.size();
  int runs_per = 0;
  if (config.is_object() && config.contains("runs") && config["runs"].is_number_integer())
    runs_per = config["runs"].get<int>();

  J out;
  out["config"] = config;
  J st;
  st["path"] = store_path;
  st["complete"] = store.complete;
  st["runs_done"] = store.runs.size();
  st["runs_planned"] = variants * h.objects.size() * static_cast<std::size_t>(runs_per);
  st["objects"] = h.objects;
  st["stages"] = h.stages;
  st["database"] = parse_or_text(h.database_json);
  st["versions"] = versions;
  out["store"] = st;
  // The classes the class-aware rates count with (null: the store's database recorded none, so
  // the class-aware rates equal the strict ones).
  {
    const J& db = st["database"];
    out["congruent_classes"] = db.is_object() && db.contains("congruent_classes") ? db["congruent_classes"] : J(nullptr);
  }

  // What the runs share and what each interval assumes (stores written before the protocol key
  // were made with the shared pool, the only protocol then).
  const std::string protocol = config.is_object() && config.contains("protocol") && config["protocol"].is_string()
                                   ? config["protocol"].get<std::string>()
                                   : "shared_pool";
  {
    J iv;
    iv["protocol"] = protocol;
    iv["runs_share"] = protocol == "shared_pool"
                           ? "the runs of an object share its object pose and grasp pool (the paper's "
                             "protocol) and differ only in the order grasps are drawn"
                           : "nothing but the object: each run has its own object pose and grasp pool";
    iv["wilson"] = "recognition_rate_ci95 and recognition_rate_class_ci95: Wilson score 95 %, assumes "
                   "every run independent; too narrow when runs of an object are correlated (always "
                   "under shared_pool, and across objects of unequal difficulty)";
    iv["cluster_bootstrap"] = "recognition_rate_cluster_ci95 and recognition_rate_class_cluster_ci95: "
                              "percentile bootstrap over explored objects (" +
                              std::to_string(kBootstrapResamples) +
                              " resamples, fixed seed), assumes only that objects are independent "
                              "(null for a single object)";
    iv["bootstrap_resamples"] = kBootstrapResamples;
    out["intervals"] = iv;
  }

  std::vector<VariantJson> vj;
  for (std::size_t v = 0; v < variants; ++v) {
    bool any = false;
    for (const auto& r : store.runs) any = any || r.variant == static_cast<int>(v);
    if (!any) {
      vj.push_back({J::array(), J::array(), nullptr, nullptr, nullptr, nullptr, nullptr, nullptr});
      continue;
    }
    vj.push_back(variant_json(store, static_cast<int>(v), settings));
  }
  out["per_step"] = vj.empty() ? J::array() : vj[0].per_step;
  out["per_object"] = vj.empty() ? J::array() : vj[0].per_object;
  out["summary"] = vj.empty() ? J(nullptr) : vj[0].summary;
  out["confidence"] = vj.empty() ? J(nullptr) : vj[0].confidence;
  out["open_set"] = vj.empty() ? J(nullptr) : vj[0].open_set;
  out["truth_pose"] = vj.empty() ? J(nullptr) : vj[0].truth_pose;
  out["stages"] = vj.empty() ? J(nullptr) : vj[0].stages;
  out["confusions"] = vj.empty() ? J(nullptr) : vj[0].confusions;

  if (variants > 1) {
    J list = J::array();
    std::vector<double> cost, rate, neg_error;
    std::vector<std::size_t> index;
    for (std::size_t v = 0; v < variants; ++v) {
      J item;
      item["label"] = h.variant_labels[v];
      item["config"] = parse_or_text(h.variant_configs[v]);
      item["summary"] = vj[v].summary;
      item["per_step"] = vj[v].per_step;
      item["per_object"] = vj[v].per_object;
      item["truth_pose"] = vj[v].truth_pose;
      item["stages"] = vj[v].stages;
      item["confusions"] = vj[v].confusions;
      list.push_back(item);
      const J& s = vj[v].summary;
      if (s.is_null() || s["time_s_per_step_mean"].is_null()) continue;
      index.push_back(v);
      cost.push_back(s["time_s_per_step_mean"].get<double>());
      rate.push_back(s["recognition_rate_final"].get<double>());
      // A variant that never recognizes gets the bound as its error.
      const J& e = s["position_error_m_median_final"];
      neg_error.push_back(-(e.is_null() ? settings.bounds.position_m : e.get<double>()));
    }
    out["variants"] = list;
    J pareto;
    J by_rate = J::array(), by_error = J::array();
    for (std::size_t i : pareto_front(cost, rate)) by_rate.push_back(h.variant_labels[index[i]]);
    for (std::size_t i : pareto_front(cost, neg_error)) by_error.push_back(h.variant_labels[index[i]]);
    pareto["cost"] = "time_s_per_step_mean";
    pareto["recognition_rate_final"] = by_rate;
    pareto["position_error_m_median_final"] = by_error;
    out["pareto"] = pareto;
  }
  out["threads"] = settings.threads > 0 ? J(settings.threads)
                   : versions.is_object() && versions.contains("threads") ? versions["threads"]
                                                                          : J(nullptr);
  out["machine"] = settings.machine.empty() ? J(h.machine) : J(settings.machine);
  return out;
}

namespace {

std::string fmt(const J& v, double scale, int precision, const char* missing = "-") {
  if (v.is_null()) return missing;
  std::ostringstream s;
  s << std::fixed << std::setprecision(precision) << v.get<double>() * scale;
  return s.str();
}

std::string pct(const J& v) { return fmt(v, 100.0, 0); }

/// An interval [lo, hi] of shares as "lo-hi" percent ("-" when absent).
std::string pct_range(const J& ci) { return ci.is_array() ? pct(ci[0]) + "-" + pct(ci[1]) : std::string("-"); }

/// The steps the per-step tables print: `first`, 5, every tenth and the last row.
bool table_step(const J& rows, std::size_t i, int first = 1) {
  const int step = rows[i]["step"].get<int>();
  return step == first || step == 5 || step % 10 == 0 || i + 1 == rows.size();
}

void print_steps(const J& per_step, std::ostream& out) {
  out << "  step   rate  Wilson   obj-boot  class  pos med  pos p95  ori med  sym-ori  time med  time p95\n"
         "         (%)   (%)      (%)       (%)    (mm)     (mm)     (deg)    med(deg) (s)       (s)\n";
  for (const auto& r : per_step) {
    out << "  " << std::setw(4) << r["step"].get<int>() << "  " << std::setw(5)
        << pct(r["recognition_rate"]) << "  " << std::left << std::setw(7)
        << pct_range(r["recognition_rate_ci95"]) << "  " << std::setw(8)
        << pct_range(r.value("recognition_rate_cluster_ci95", J(nullptr)))
        << std::right << "  " << std::setw(5) << pct(r.value("recognition_rate_class", J(nullptr)))
        << "  " << std::setw(7) << fmt(r["position_error_m_median"], 1000, 1)
        << "  " << std::setw(7) << fmt(r["position_error_m_p95"], 1000, 1) << "  "
        << std::setw(7) << fmt(r["orientation_error_deg_median"], 1, 1) << "  " << std::setw(7)
        << fmt(r["symmetric_orientation_error_deg_median"], 1, 1) << "  " << std::setw(8)
        << fmt(r["time_s_median"], 1, 3) << "  " << std::setw(8) << fmt(r["time_s_p95"], 1, 3)
        << "\n";
  }
}

/// The misses' answers at the last step, most frequent first (at most `most` rows).
void print_confusions(const J& c, const std::string& label, std::ostream& out, std::size_t most = 10) {
  if (c.is_null() || c["misses"].get<std::size_t>() == 0) return;
  out << "\nMisses at step " << c["step"].get<int>() << label << " (" << c["misses"].get<std::size_t>()
      << " runs), what they named instead (most frequent first; (=): congruent with the explored object):\n";
  std::size_t width = 6;
  for (const auto& p : c["pairs"]) width = std::max(width, p["object"].get<std::string>().size());
  std::size_t shown = 0;
  for (const auto& p : c["pairs"]) {
    if (shown++ == most) {
      out << "  ... " << c["pairs"].size() - most << " more (the report's JSON: confusions)\n";
      break;
    }
    out << "  " << std::left << std::setw(static_cast<int>(width)) << p["object"].get<std::string>()
        << std::right << "  -> " << (p["named"].is_null() ? std::string("(nothing)") : p["named"].get<std::string>())
        << (p["congruent"].get<bool>() ? " (=)" : "") << "  " << p["runs"].get<std::size_t>() << " run"
        << (p["runs"].get<std::size_t>() == 1 ? "" : "s") << "\n";
  }
}

void print_objects(const J& per_object, std::ostream& out) {
  if (per_object.empty()) return;
  const std::size_t steps = per_object[0]["per_step"].size();
  std::vector<std::size_t> cols;
  for (std::size_t s : {1, 5, 10, 20, 40})
    if (s <= steps) cols.push_back(s);
  if (cols.empty() || cols.back() != steps) cols.push_back(steps);
  std::size_t width = 6;
  for (const auto& o : per_object) width = std::max(width, o["object"].get<std::string>().size());
  out << "  " << std::left << std::setw(static_cast<int>(width)) << "object" << std::right
      << "  runs";
  for (std::size_t c : cols) {
    std::string head(1, '@');  // not "@" + ...: GCC 12 -Wrestrict false positive
    head += std::to_string(c);
    out << std::setw(8) << head;
  }
  out << "  pos med  sym-ori  (rate % at step; errors at the last step, mm / deg)\n";
  for (const auto& o : per_object) {
    out << "  " << std::left << std::setw(static_cast<int>(width)) << o["object"].get<std::string>()
        << std::right << std::setw(6) << o["runs"].get<int>();
    for (std::size_t c : cols) out << std::setw(8) << pct(o["per_step"][c - 1]["recognition_rate"]);
    const J& last = o["per_step"][steps - 1];
    out << "  " << std::setw(7) << fmt(last["position_error_m_median"], 1000, 1) << "  "
        << std::setw(7) << fmt(last["symmetric_orientation_error_deg_median"], 1, 1) << "\n";
  }
}

void print_classes(const J& report, std::ostream& out) {
  const J& c = report.value("congruent_classes", J(nullptr));
  if (!c.is_array()) {
    out << "  congruent classes of the database: not known (the class rate is the strict one)\n";
    return;
  }
  // A large database has hundreds of classes: beyond 10, only those of the explored objects are
  // listed (the class-aware rate counts with them), the rest are in the JSON.
  constexpr std::size_t kListed = 10;
  std::set<std::string> explored;
  if (report.contains("store") && report["store"].contains("objects"))
    for (const auto& o : report["store"]["objects"]) explored.insert(o.get<std::string>());
  std::size_t objects = 0;
  for (const auto& cls : c) objects += cls.size();
  const bool all = c.size() <= kListed;
  out << "  congruent classes of the database: " << (c.empty() ? "none" : "");
  if (!all)
    out << c.size() << " classes of " << objects << " objects (all in the JSON's congruent_classes); "
        << "those of the explored objects: ";
  std::size_t shown = 0;
  for (std::size_t k = 0; k < c.size(); ++k) {
    bool relevant = all;
    for (const auto& name : c[k]) relevant = relevant || explored.count(name.get<std::string>()) > 0;
    if (!relevant) continue;
    out << (shown++ ? "; " : "");
    for (std::size_t i = 0; i < c[k].size(); ++i) out << (i ? " = " : "") << c[k][i].get<std::string>();
  }
  if (!all && shown == 0) out << "none";
  out << "\n";
}

void print_intervals(const J& report, std::ostream& out) {
  const J& iv = report.value("intervals", J(nullptr));
  if (!iv.is_object()) return;
  const bool shared = iv.value("protocol", std::string()) == "shared_pool";
  out << "  runs: protocol " << iv.value("protocol", std::string("?"))
      << (shared ? " (the runs of an object share its pose and grasp pool)"
                 : " (each run its own object pose and grasp pool)")
      << "\n  intervals (95 %): Wilson assumes every run independent"
      << (shared ? " (they are not: too narrow)" : "")
      << ";\n    obj-boot resamples the explored objects (" << iv.value("bootstrap_resamples", 0)
      << " resamples), assuming only objects independent\n";
}

void print_open_set(const J& report, std::ostream& out) {
  const J& o = report.value("open_set", J(nullptr));
  if (!o.is_object()) return;
  out << "\nOpen set (threshold " << fmt(o["threshold"], 1, 3) << " on the in-database score, from "
      << o["source"].get<std::string>() << "): hidden objects named as a database object, and the "
      << "known objects' recognition without / with the threshold (strict; class-aware: naming an "
         "object congruent with the hidden one is not a false accept)\n"
         "  step  hidden  false accepts (%)  Wilson (%)  class-aware (%)  known  closed (%)  open (%)  drop (points)\n";
  const J& rows = o["per_step"];
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const J& r = rows[i];
    const int step = r["step"].get<int>();
    if (!table_step(rows, i)) continue;
    out << "  " << std::setw(4) << step << "  " << std::setw(6) << r["hidden_runs"].get<std::size_t>() << "  "
        << std::setw(17) << fmt(r["false_accept_rate"], 100, 1) << "  " << std::setw(10) << pct_range(r["false_accept_rate_ci95"]) << "  "
        << std::setw(15) << fmt(r.value("false_accept_rate_class", J(nullptr)), 100, 1) << "  "
        << std::setw(5) << r["known_runs"].get<std::size_t>() << "  " << std::setw(10)
        << fmt(r["known_rate_closed"], 100, 1) << "  " << std::setw(8) << fmt(r["known_rate_open"], 100, 1)
        << "  " << std::setw(13) << fmt(r["known_drop"], 100, 1) << "\n";
  }
}

void print_stages(const J& rows, const std::string& label, std::ostream& out) {
  if (!rows.is_array()) return;
  out << "\nStages left out" << label << " (share of steps whose scene did not need them):";
  for (const auto& r : rows) out << " " << r["stage"].get<std::string>() << " " << pct(r["skipped_share"]) << " %;";
  out << "\n";
}

void print_answer_sets(const J& rows, const std::string& label, std::ostream& out) {
  if (!rows.is_array() || rows.empty() || rows[0].value("set_coverage", J(nullptr)).is_null()) return;
  out << "\nSet answers" << label
      << " (the calibration's conformal sets of classes): the share of runs whose set held the truth, and "
         "the sets' sizes (an uninformative set counts as every class)\n"
         "  step  runs  right (%)  coverage (%)  Wilson (%)  obj-boot (%)  size median  mean   p90  informative (%)\n";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const J& r = rows[i];
    const int step = r["step"].get<int>();
    if (!table_step(rows, i)) continue;
    out << "  " << std::setw(4) << step << "  " << std::setw(4) << r["runs"].get<std::size_t>() << "  " << std::setw(9)
        << fmt(r["recognition_rate"], 100, 1) << "  " << std::setw(12) << fmt(r["set_coverage"], 100, 1) << "  "
        << std::setw(10) << pct_range(r["set_coverage_ci95"]) << "  " << std::setw(12)
        << pct_range(r["set_coverage_cluster_ci95"]) << "  " << std::setw(11) << fmt(r["set_size_median"], 1, 1) << "  "
        << std::setw(5) << fmt(r["set_size_mean"], 1, 1) << "  " << std::setw(4) << fmt(r["set_size_p90"], 1, 0)
        << "  " << std::setw(15) << fmt(r["set_informative_share"], 100, 1) << "\n";
  }
}

void print_planner(const J& rows, const std::string& label, std::ostream& out) {
  if (!rows.is_array() ||
      std::none_of(rows.begin(), rows.end(), [](const J& r) { return r.value("plan_expected_object_information_median", J(nullptr)).is_number(); }))
    return;
  out << "\nActive touch" << label
      << ": the information about the object the planner expected of the grasps it chose, and the drop of "
         "the posterior's entropy over objects those steps gave (nats, medians)\n"
         "  step  expected  realized\n";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const J& r = rows[i];
    const int step = r["step"].get<int>();
    if (!table_step(rows, i, 2)) continue;
    out << "  " << std::setw(4) << step << "  " << std::setw(8) << fmt(r["plan_expected_object_information_median"], 1, 3)
        << "  " << std::setw(8) << fmt(r["plan_entropy_drop_median"], 1, 3) << "\n";
  }
}

void print_truth_pose(const J& rows, const std::string& label, std::ostream& out) {
  if (!rows.is_array()) return;
  out << "\nThe true object at its true pose" << label
      << " (diagnostics.truth_pose): would the step's answer rule name it? (the rate a perfect "
         "search reaches with this evidence and rule); the misses lost by the search (it would) "
         "and by the evidence (another object beats even the true pose)\n"
         "  step  runs  right (%)  at the true pose (%)  Wilson (%)  obj-boot (%)  misses: search  evidence\n";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const J& r = rows[i];
    const int step = r["step"].get<int>();
    if (!table_step(rows, i)) continue;
    const std::size_t n = r["runs"].get<std::size_t>();
    out << "  " << std::setw(4) << step << "  " << std::setw(4) << n << "  " << std::setw(9)
        << (n ? fmt(J(r["correct"].get<double>() / double(n)), 100, 1) : std::string("-")) << "  "
        << std::setw(19) << fmt(r["truth_pose_rate"], 100, 1) << "  " << std::setw(10)
        << pct_range(r["truth_pose_rate_ci95"]) << "  " << std::setw(12) << pct_range(r["truth_pose_rate_cluster_ci95"])
        << "  " << std::setw(14) << r["misses_lost_by_search"].get<std::size_t>() << "  " << std::setw(8)
        << r["misses_lost_by_evidence"].get<std::size_t>() << "\n";
  }
}

void print_confidence(const J& report, std::ostream& out) {
  const J& c = report.value("confidence", J(nullptr));
  if (!c.is_object()) {
    out << "  confidence: not calibrated (experiment or report with a calibration file: "
           "`touchstone calibrate`)\n";
    return;
  }
  out << "\nConfidence (" << c["source"].get<std::string>()
      << "): calibration against the outcomes, per step\n"
         "  step     n  object: mean  right  ECE    (exact model: mean, p95)  Brier   pose (< 1 cm): mean  right  ECE    Brier\n";
  const J& rows = c["per_step"];
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const int step = rows[i]["step"].get<int>();
    if (!table_step(rows, i)) continue;
    const J& r = rows[i];
    std::ostringstream noise;
    noise << fmt(r["object_ece_noise_mean"], 1, 3) << ", " << fmt(r["object_ece_noise_p95"], 1, 3);
    out << "  " << std::setw(4) << step << "  " << std::setw(4) << r["n"].get<std::size_t>() << "  "
        << std::setw(12) << fmt(r["object_confidence_mean"], 1, 3)
        << "  " << std::setw(5) << fmt(r["object_accuracy"], 1, 3) << "  " << std::setw(5)
        << fmt(r["object_ece"], 1, 3) << "  " << std::setw(24) << noise.str() << "  " << std::setw(6)
        << fmt(r["object_brier"], 1, 3) << "  "
        << std::setw(19) << fmt(r["pose_confidence_mean"], 1, 3) << "  " << std::setw(5)
        << fmt(r["pose_accuracy"], 1, 3) << "  " << std::setw(5) << fmt(r["pose_ece"], 1, 3) << "  "
        << std::setw(6) << fmt(r["pose_brier"], 1, 3) << "\n";
  }
  const J& a = c["all_steps"];
  out << "  all steps (" << a["n"].get<std::size_t>() << " step answers): object ECE "
      << fmt(a["object_ece"], 1, 3) << ", Brier " << fmt(a["object_brier"], 1, 3) << "; pose ECE "
      << fmt(a["pose_ece"], 1, 3) << ", Brier " << fmt(a["pose_brier"], 1, 3) << " ("
      << c["bins"].get<std::size_t>() << " equal-width bins)\n";
}

}  // namespace

std::set<int> hidden_explored_objects(const io::RunStoreHeader& header) { return hidden_objects(header); }

/// "@20", or "@K" when the runs have fewer than 20 steps (the summary's step-20 column).
static std::string step20_label(const J& report) {
  std::size_t steps = 20;
  for (const auto& v : report["variants"])
    if (!v["per_step"].empty()) steps = std::min<std::size_t>(20, v["per_step"].size());
  std::string s(1, '@');
  s += std::to_string(steps);
  return s;
}

void print_report(const nlohmann::ordered_json& report, std::ostream& out) {
  const J& cfg = report["config"];
  const J& st = report["store"];
  out << "Experiment";
  if (cfg.is_object() && cfg.contains("name")) out << " '" << cfg["name"].get<std::string>() << "'";
  out << ": " << st["runs_done"].get<std::size_t>() << " of " << st["runs_planned"].get<std::size_t>()
      << " runs" << (st["complete"].get<bool>() ? "" : " (incomplete)");
  if (cfg.is_object())
    out << ", method " << cfg.value("method", std::string("?")) << ", noise "
        << cfg.value("noise", std::string("?")) << ", sensors " << cfg.value("sensors", 0) << ", "
        << st["objects"].size() << " objects";
  out << "\n";
  if (!report["threads"].is_null())
    out << "Machine: " << report["machine"].get<std::string>() << ", " << report["threads"] << " threads\n";
  const bool sweep = report.contains("variants");
  if (!sweep) {
    if (report["per_step"].empty()) {
      out << "No completed runs yet.\n";
      return;
    }
    out << "\nAll objects, per step (errors over runs that recognized the object; class: the rate when an "
           "answer congruent with the true object counts as right):\n";
    print_steps(report["per_step"], out);
    print_classes(report, out);
    print_intervals(report, out);
    print_confidence(report, out);
    print_open_set(report, out);
    print_answer_sets(report["per_step"], "", out);
    print_planner(report["per_step"], "", out);
    print_truth_pose(report.value("truth_pose", J(nullptr)), "", out);
    print_stages(report.value("stages", J(nullptr)), "", out);
    print_confusions(report.value("confusions", J(nullptr)), "", out);
    out << "\nPer object:\n";
    print_objects(report["per_object"], out);
    return;
  }
  out << "\nSweep variants (rates at the last step; time per step over all steps):\n";
  std::size_t width = 7;
  for (const auto& v : report["variants"]) width = std::max(width, v["label"].get<std::string>().size());
  out << "  " << std::left << std::setw(static_cast<int>(width)) << "variant" << std::right
      << "  runs   rate  " << std::left << std::setw(4) << step20_label(report) << std::right
      << "  pos med  sym-ori  time/step  p95     pareto\n";
  auto on_front = [&](const std::string& label, const char* key) {
    for (const auto& l : report["pareto"][key])
      if (l == label) return true;
    return false;
  };
  for (const auto& v : report["variants"]) {
    const std::string label = v["label"].get<std::string>();
    const J& s = v["summary"];
    out << "  " << std::left << std::setw(static_cast<int>(width)) << label << std::right;
    if (s.is_null()) {
      out << "     0  (no runs yet)\n";
      continue;
    }
    std::string front;
    if (on_front(label, "recognition_rate_final")) front += "R";
    if (on_front(label, "position_error_m_median_final")) front += "E";
    out << std::setw(6) << s["runs"].get<int>() << "  " << std::setw(5)
        << pct(s["recognition_rate_final"]) << "  " << std::setw(3) << pct(s["recognition_rate_step20"])
        << "  " << std::setw(7) << fmt(s["position_error_m_median_final"], 1000, 1) << "  "
        << std::setw(7) << fmt(s["symmetric_orientation_error_deg_median_final"], 1, 1) << "  "
        << std::setw(9) << fmt(s["time_s_per_step_mean"], 1, 3) << "  " << std::setw(6)
        << fmt(s["time_s_per_step_p95"], 1, 3) << "  " << front << "\n";
  }
  out << "  pareto: R = on the front of recognition rate vs time per step, E = of position error "
         "vs time per step\n";
  for (const auto& v : report["variants"])
    print_answer_sets(v.value("per_step", J(nullptr)), ", variant " + v["label"].get<std::string>(), out);
  for (const auto& v : report["variants"])
    print_planner(v.value("per_step", J(nullptr)), ", variant " + v["label"].get<std::string>(), out);
  for (const auto& v : report["variants"])
    print_truth_pose(v.value("truth_pose", J(nullptr)), ", variant " + v["label"].get<std::string>(), out);
  for (const auto& v : report["variants"])
    print_stages(v.value("stages", J(nullptr)), ", variant " + v["label"].get<std::string>(), out);
  for (const auto& v : report["variants"])
    print_confusions(v.value("confusions", J(nullptr)), ", variant " + v["label"].get<std::string>(), out);
}

std::filesystem::path plot_script() {
  namespace fs = std::filesystem;
  if (const char* env = std::getenv("TOUCHSTONE_PLOT_SCRIPT"); env && *env) return env;
  const fs::path rel = fs::path("scripts") / "plots" / "touchstone_plots.py";
  // An installed command: PREFIX/bin/touchstone, the script in PREFIX/share/touchstone.
  const fs::path installed = fs::path("share") / "touchstone" / "touchstone_plots.py";
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec)
    for (fs::path dir = exe.parent_path(); !dir.empty() && dir != dir.root_path(); dir = dir.parent_path()) {
      if (fs::is_regular_file(dir / rel, ec)) return dir / rel;
      if (fs::is_regular_file(dir / installed, ec)) return dir / installed;
    }
  const fs::path src = fs::path(TS_SOURCE_DIR) / rel;
  if (!std::string(TS_SOURCE_DIR).empty() && fs::is_regular_file(src, ec)) return src;
  throw Error("cannot find the plot script scripts/plots/touchstone_plots.py (set "
              "TOUCHSTONE_PLOT_SCRIPT)", rel.string());
}

std::vector<std::filesystem::path> write_plots(const nlohmann::ordered_json& report,
                                               const std::filesystem::path& dir, const std::string& json_name) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw Error("cannot create the plot folder: " + ec.message(), dir.string());
  const fs::path json_path = dir / json_name;
  {
    io::AtomicOutput out(json_path);
    std::ofstream f(out.temp_path());
    f << report.dump(1) << "\n";
    f.close();
    if (!f) throw Error("cannot write the report", json_path.string());
    out.commit();
  }
  const fs::path script = plot_script();
  const char* env_python = std::getenv("TOUCHSTONE_PYTHON");
  const std::string python = env_python && *env_python ? env_python : "/usr/bin/python3";
  const std::string list_path = (dir / ".plots-written").string();
  // Arguments prepared before spawning (nothing but the exec happens in the child).
  std::vector<std::string> args{python, script.string(), json_path.string(), "--out", dir.string(),
                                "--list", list_path};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (posix_spawn(&pid, python.c_str(), nullptr, nullptr, argv.data(), environ) != 0)
    throw Error("cannot run " + python + " for the plot script", script.string());
  int status = 0;
  while (waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) throw Error("lost the plot script process", script.string());
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw Error("the plot script failed (exit " +
                    std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + "; it needs " +
                    python + " with matplotlib and numpy)", script.string());
  std::vector<fs::path> files;
  std::ifstream list(list_path);
  for (std::string line; std::getline(list, line);)
    if (!line.empty()) files.emplace_back(line);
  fs::remove(list_path, ec);
  return files;
}

}  // namespace ts::experiments
