// Calibrated confidence of a recognition step (issue 14): the probability that the named object
// is right, and separately that its pose is within 1 cm, from small logistic models (one per
// range of steps) over features of the step's evidence (posterior mass of the winner, its margin
// to the runner-up, the Eq. 5-6 evidence of the best hypothesis, how many hypotheses agree with
// it, contacts, and how well the answer explains the contacts and free space in absolute terms).
// Apart from these, the open-set score: the probability that the explored object is in the
// database at all, fitted on runs of known objects against runs of objects hidden from the
// recognizer (leave-one-out); the open-set threshold applies to it.
//
// The model is fitted on simulated runs (the run store records every step's features and truth:
// `touchstone calibrate STORE... --out FILE`) and shipped as a versioned JSON file that records
// the database fingerprint it was fitted for; applying it to another database or version is one
// clear error naming the file and the key. The raw posterior of the improved preset (0.02-0.07
// when right) and of the paper preset (0.85-0.98) are not probabilities; this is.
#pragma once

#include "engine/recognition/answer_set.hpp"
#include "engine/recognition/recognizer.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace ts::experiments {

/// Names of the features confidence_features() computes, in order.
const std::vector<std::string>& confidence_feature_names();

/// The features of one step (confidence_feature_names() order); a step without hypotheses gives
/// the values of "no evidence" (posterior 0, evidence at its floor).
std::vector<double> confidence_features(const StepResult& r);

/// Entropy (nats) of a posterior over objects (zeros skipped).
double posterior_entropy(std::span<const double> posteriors);

/// The step a feature vector of confidence_features() was computed at (its "log_step").
int feature_step(std::span<const double> features);

/// Logistic regression p = 1 / (1 + exp(-(b + w . z))), z the standardized terms: the features
/// themselves (linear), or the features and then their squares (quadratic).
struct LogisticModel {
  std::vector<double> mean, scale;   ///< standardization of each term
  std::vector<double> coef;          ///< b, then one weight per term
  bool quadratic = false;            ///< the terms are the features and their squares
  /// Standardized terms are clamped to [-clamp, clamp] in the fit and in predict (0: not
  /// clamped, as in version 2 files): a term that is nearly always the same (the free-space
  /// conflict is 0 in 99.9 % of answers) has a tiny scale, and its rare large values would
  /// otherwise sit hundreds of scales out and swing the logit without bound.
  double clamp = 0.0;
  double predict(std::span<const double> features) const;
};

/// The clamp of standardized terms fit_step_models uses (and version 3 files record).
inline constexpr double kTermClamp = 4.0;

/// The terms of a quadratic model: the features, then their squares.
std::vector<double> quadratic_terms(std::span<const double> features);

/// Fit by Newton's method (IRLS) with an L2 penalty `l2` on the weights (not the bias) over the
/// standardized features, each clamped to [-clamp, clamp] when clamp > 0. rows[i] has one value
/// per feature; labels are 0 or 1. Throws ts::Error for empty or ragged input or non-finite values.
LogisticModel fit_logistic(const std::vector<std::vector<double>>& rows, const std::vector<int>& labels,
                           double l2 = 1e-3, double clamp = 0.0);

/// The models of one range of steps.
struct StepModels {
  int first_step = 1;                 ///< the range runs from here to the next range's first step
  LogisticModel object;               ///< P(the named object is right | it is in the database)
  LogisticModel pose;                 ///< P(right object and position error < 1 cm | ...)
  /// Open set: P(the explored object is in the database), fitted on runs of known objects
  /// against runs of hidden ones (unset: the calibration has no open-set score).
  std::optional<LogisticModel> in_database;
  /// The L2 penalties the fit chose for object, pose, in_database (cross-validation over the
  /// explored objects; informational, 0 when not recorded).
  std::array<double, 3> l2{};
};

/// Set answers (engine/recognition/answer_set.hpp): the true class's log-weight gap on each
/// calibration run at each step, and what the runs were simulated with (the guarantee holds for
/// runs drawn alike).
struct AnswerSetCalibration {
  double alpha = 0.05;                     ///< the level sets are answered at by default
  double tie_nats = 0.0;                   ///< gaps below this score 0 (ConformalScores::set_tie)
  nlohmann::ordered_json simulation;       ///< simulation_of the runs' configuration
  std::vector<ConformalScores> steps;      ///< step k at [k - 1]
  /// The scores of a step (1-based); steps past the last calibrated one use the last.
  const ConformalScores& at(int step) const;
  /// The step whose scores at(step) uses.
  int calibrated_step(int step) const;
};

/// The simulation settings an answer-set calibration records, from an experiment configuration's
/// JSON (touchstone's config_json): noise, noise.*, sensing, sensors, scene, scene.*, probe.*,
/// fingertips.*, sorted by key; unset overrides (null), scene "none" and noise.arm_scale 1 left
/// out.
nlohmann::ordered_json simulation_of(const nlohmann::ordered_json& config);

/// The calibration file (JSON, "format": "touchstone-calibration", version 7; versions 2 (all
/// models linear), 3 (no answer sets), 4 (answer sets scored against the ln w leader: refused,
/// refit), 5 (the answer sets of one simulation, an object) and 6 (a class without hypotheses
/// scored +inf, not by the shape prior: the same sets) are read as well; version 7 is new so that
/// earlier builds, which would score such classes +inf against gaps that rank them, refuse it): one set of
/// models per range of steps (how far an exploration is changes what the features mean), and the
/// answer sets' scores, one entry per simulation the calibration runs were drawn with.
struct Calibration {
  static constexpr int kVersion = 7;
  static constexpr int kOldestVersion = 2;
  std::string database_fingerprint;   ///< of the database the runs explored
  std::vector<std::string> features;  ///< confidence_feature_names() when fitted
  std::vector<StepModels> ranges;     ///< first_step ascending, the first 1
  /// Open set: an answer whose in-database score is below this is "not in the database"
  /// (unset: every answer names an object). Chosen on calibration runs by
  /// choose_open_set_threshold; needs in_database in every range.
  std::optional<double> open_set_threshold;
  /// Set answers, one entry per simulation the calibration runs were drawn with (a sweep of noise
  /// settings gives one per variant); empty: fitted without them, or before version 5.
  std::vector<AnswerSetCalibration> answer_sets;
  nlohmann::ordered_json provenance;  ///< what it was fitted on (stores, runs, steps, seeds)

  /// The answer sets calibrated on runs simulated as `simulation` (simulation_of); nullptr: none.
  const AnswerSetCalibration* answer_sets_for(const nlohmann::ordered_json& simulation) const;
  /// The answer sets of a calibration of one simulation (data without a simulation to match:
  /// `recognize`, Python). Throws ts::Error naming `file` and the key when it holds several.
  const AnswerSetCalibration& single_answer_sets(const std::string& file) const;
  /// The simulations the answer sets hold for, for messages: "{...}, {...}".
  std::string answer_set_simulations() const;

  /// The range of a step (1-based; steps past the last range's first use the last).
  const StepModels& at(int step) const;
  /// The same, the step read off the features' own ln(step) (confidence_feature_names()).
  double object_confidence(std::span<const double> f) const { return object_confidence(feature_step(f), f); }
  double pose_confidence(std::span<const double> f) const { return pose_confidence(feature_step(f), f); }
  double object_confidence(int step, std::span<const double> f) const { return at(step).object.predict(f); }
  double pose_confidence(int step, std::span<const double> f) const { return at(step).pose.predict(f); }
  /// The open-set score; nullopt without an in-database model.
  std::optional<double> in_database(int step, std::span<const double> f) const {
    const StepModels& m = at(step);
    return m.in_database ? std::optional(m.in_database->predict(f)) : std::nullopt;
  }
};

/// The default ranges of steps (their first steps): 1, 2, 3-4, 5-6, 7-8, 9-11, 12-15, 16 on.
const std::vector<int>& default_step_ranges();

/// One step answer to fit on: its features, its step, whether the explored object was hidden from
/// the recognizer (open-set run), and its outcomes.
struct CalibrationRow {
  std::vector<double> features;
  int step = 1;
  int group = 0;                      ///< the explored object (cross-validation folds by it)
  bool hidden = false;
  /// Hidden, but the answer names an object congruent with it (the database's classes): a copy
  /// of the explored solid is in the database, so the open-set score counts it as known.
  bool copy_in_database = false;
  bool right = false;                 ///< the named object is the explored one
  bool pose_right = false;            ///< ... and its position error is below 1 cm
};

/// The in-database score's outcome of a row: 1 for a known object or a hidden one whose
/// congruent copy was named, 0 otherwise.
inline int in_database_label(const CalibrationRow& r) { return !r.hidden || r.copy_in_database ? 1 : 0; }

/// The L2 penalty of fit_logistic, among `grid`, with the least log loss on held-out groups
/// (`folds`-fold cross-validation, group g in fold g mod folds): answers of one explored object
/// are not independent, so they are held out together. The first of the grid when fewer than
/// two folds have rows.
double choose_l2(const std::vector<std::vector<double>>& rows, const std::vector<int>& labels,
                 const std::vector<int>& groups, const std::vector<double>& grid, int folds = 5,
                 double clamp = 0.0);

/// Out-of-fold in-database scores of the rows at `step`: each row scored by the model of its
/// step's range fitted (L2 penalty `l2`) without its group's fold (group g in fold g mod folds),
/// so that a threshold chosen on them is not chosen on the model's own training answers; the
/// terms clamped as fit_step_models clamps them (kTermClamp by default).
/// Returns one score per row at that step (NaN for rows at other steps).
std::vector<double> out_of_fold_in_database(const std::vector<CalibrationRow>& rows, const std::vector<int>& first_steps,
                                            int step, double l2, int folds = 5, double clamp = kTermClamp);

/// The default grid of choose_l2.
const std::vector<double>& default_l2_grid();

/// The models of each range of steps (`first_steps` ascending from 1): object and pose on the
/// rows of known objects, in_database on all rows (known 1, hidden 0) when some row is hidden;
/// each with the L2 penalty choose_l2 picks from `l2_grid` (one value: that one). Object and
/// pose are quadratic (cross-validated on the 45-object runs: a lower log loss and ECE than
/// linear); the in-database score, which is only thresholded, stays linear.
/// Throws ts::Error (key "--step-ranges") for a range without rows of known objects, or without
/// hidden rows when other ranges have some.
std::vector<StepModels> fit_step_models(const std::vector<CalibrationRow>& rows, const std::vector<int>& first_steps,
                                        const std::vector<double>& l2_grid = default_l2_grid());

/// The open-set threshold: the largest confidence t such that refusing the answers below t
/// costs at most `max_drop` of the runs at that step their right answer, i.e. t is the
/// (floor(max_drop * runs) + 1)-th smallest confidence of the right answers (1 when there are
/// no more right answers than that). `right_confidences`: the object confidences of the right
/// answers at one step; `runs`: all answers at that step. Throws for max_drop outside [0, 1).
double choose_open_set_threshold(std::vector<double> right_confidences, std::size_t runs, double max_drop);

/// One known object's answer at the open-set step: its explored object (the cluster), whether it
/// was right, and its in-database score.
struct KnownAnswer {
  int group = 0;
  bool right = false;
  double score = 0.0;
};

/// The open-set threshold with the explored objects' clustering taken into account. The runs of
/// one object fail together (they share its shape, and its low scores), so the share of right
/// answers a threshold costs varies far more between samples of objects than a count of runs
/// suggests, and a threshold that costs exactly `max_drop` on the calibration runs costs new
/// runs more about half the time. This draws `resamples` samples of the objects with replacement
/// (each drawn object with all its answers; ts::Rng(seed)), takes choose_open_set_threshold on
/// each, and returns the (1 - confidence) quantile of those thresholds (the
/// (floor((1 - confidence) * resamples) + 1)-th smallest): in at least `confidence` of the resamples the
/// threshold costs at most `max_drop`. confidence 0 gives choose_open_set_threshold on all
/// answers. Deterministic; the order of `answers` does not matter. Throws ts::Error for
/// max_drop outside [0, 1) (key "--open-set-drop"), confidence outside [0, 1)
/// ("--open-set-confidence"), or no resamples.
double choose_open_set_threshold_clustered(std::vector<KnownAnswer> answers, double max_drop, double confidence,
                                           int resamples = 2000, std::uint64_t seed = 1);

nlohmann::ordered_json to_json(const Calibration& c);
/// Write atomically (a temporary file renamed).
void write_calibration(const std::filesystem::path& file, const Calibration& c);
/// Read and check a calibration file: format, version, features of this build, model sizes,
/// finite numbers, and (when `database_fingerprint` is not empty) the database it was fitted for.
/// Every problem is one ts::Error naming the file and the key.
Calibration read_calibration(const std::filesystem::path& file, const std::string& database_fingerprint);

}  // namespace ts::experiments
