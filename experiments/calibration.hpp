// Calibrated confidence of a recognition step (issue 14): the probability that the named object
// is right, and separately that its pose is within 1 cm, from a small logistic model over
// features of the step's evidence (posterior mass of the winner, its margin to the runner-up, the
// Eq. 5-6 evidence of the best hypothesis, how many hypotheses agree with it, contacts).
//
// The model is fitted on simulated runs (the run store records every step's features and truth:
// `touchstone calibrate STORE... --out FILE`) and shipped as a versioned JSON file that records
// the database fingerprint it was fitted for; applying it to another database or version is one
// clear error naming the file and the key. The raw posterior of the improved preset (0.02-0.07
// when right) and of the paper preset (0.85-0.98) are not probabilities; this is.
#pragma once

#include "engine/recognizer.hpp"

#include <nlohmann/json.hpp>

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

/// Logistic regression p = 1 / (1 + exp(-(b + w . z))), z the standardized features.
struct LogisticModel {
  std::vector<double> mean, scale;   ///< standardization of each feature
  std::vector<double> coef;          ///< b, then one weight per feature
  double predict(std::span<const double> features) const;
};

/// Fit by Newton's method (IRLS) with an L2 penalty `l2` on the weights (not the bias) over the
/// standardized features. rows[i] has one value per feature; labels are 0 or 1. Throws ts::Error
/// for empty or ragged input or non-finite values.
LogisticModel fit_logistic(const std::vector<std::vector<double>>& rows, const std::vector<int>& labels,
                           double l2 = 1e-3);

/// The calibration file (JSON, "format": "touchstone-calibration").
struct Calibration {
  static constexpr int kVersion = 1;
  std::string database_fingerprint;   ///< of the database the runs explored
  std::vector<std::string> features;  ///< confidence_feature_names() when fitted
  LogisticModel object;               ///< P(the named object is right)
  LogisticModel pose;                 ///< P(right object and position error < 1 cm)
  /// Open set: an answer whose object confidence is below this is "not in the database"
  /// (unset: every answer names an object). Chosen on calibration runs by
  /// choose_open_set_threshold.
  std::optional<double> open_set_threshold;
  nlohmann::ordered_json provenance;  ///< what it was fitted on (stores, runs, steps, seeds)

  double object_confidence(std::span<const double> f) const { return object.predict(f); }
  double pose_confidence(std::span<const double> f) const { return pose.predict(f); }
};

/// The open-set threshold: the largest confidence t such that refusing the answers below t
/// costs at most `max_drop` of the runs at that step their right answer, i.e. t is the
/// (floor(max_drop * runs) + 1)-th smallest confidence of the right answers (1 when there are
/// no more right answers than that). `right_confidences`: the object confidences of the right
/// answers at one step; `runs`: all answers at that step. Throws for max_drop outside [0, 1).
double choose_open_set_threshold(std::vector<double> right_confidences, std::size_t runs, double max_drop);

nlohmann::ordered_json to_json(const Calibration& c);
/// Write atomically (a temporary file renamed).
void write_calibration(const std::filesystem::path& file, const Calibration& c);
/// Read and check a calibration file: format, version, features of this build, model sizes,
/// finite numbers, and (when `database_fingerprint` is not empty) the database it was fitted for.
/// Every problem is one ts::Error naming the file and the key.
Calibration read_calibration(const std::filesystem::path& file, const std::string& database_fingerprint);

}  // namespace ts::experiments
