// Metrics of an exploration experiment (paper Section 5.2): recognition rate with its Wilson
// score interval, the BOP MSSD (the position and orientation errors, symmetry-aware too, are the
// engine's pose_error()), and the errors' summaries per step: median, 95th percentile, and the mean bounded by the
// paper's limits (4 cm, 1 rad) with a Student-t 95 % confidence interval.
//
// Conventions: poses are T_world_object (object frame -> world). A symmetry S is a rigid
// transform of the object frame that maps the object onto itself, so T_truth * S is an equally
// valid ground truth. Errors are in metres and radians here; the JSON layer converts to degrees.
#pragma once

#include "engine/core.hpp"

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

namespace ts::experiments {

/// Two-sided standard normal quantile for 95 %: Phi^-1(0.975).
constexpr double kZ95 = 1.959963984540054;

struct Interval {
  double lo = 0.0;
  double hi = 0.0;
};

// --- Recognition rate --------------------------------------------------------------------------

/// Wilson score interval for `successes` out of `trials` at normal quantile z (default 95 %).
/// trials == 0 gives [0, 1] (nothing is known). Always inside [0, 1].
Interval wilson_interval(std::size_t successes, std::size_t trials, double z = kZ95);

/// Successes and trials of one cluster of runs (the runs of one explored object).
struct ClusterCounts {
  std::size_t successes = 0;
  std::size_t trials = 0;
};

/// Resamples of the cluster bootstrap in reports (a fixed seed: the same store gives the same
/// interval).
constexpr std::size_t kBootstrapResamples = 2000;
constexpr std::uint64_t kBootstrapSeed = 0x626f6f74ULL;  // "boot"

/// Percentile cluster bootstrap of a pooled rate (sum of successes / sum of trials): `resamples`
/// times, draw as many clusters as there are, with replacement, from Rng(seed); the interval is
/// the (1 - level) / 2 and (1 + level) / 2 quantiles (type 7) of the resampled rates. Runs of one
/// cluster may be correlated (they share an object; under the shared-pool protocol also its pose
/// and grasps); clusters are assumed independent. Clusters without trials are ignored; none
/// left gives [0, 1]. Deterministic for a given seed. Throws ts::Error when a cluster has more
/// successes than trials or resamples is 0.
Interval cluster_bootstrap_interval(std::span<const ClusterCounts> clusters,
                                    std::size_t resamples = kBootstrapResamples,
                                    std::uint64_t seed = kBootstrapSeed, double level = 0.95);

// --- Calibration of a confidence -------------------------------------------------------------------

struct ReliabilityBin {
  double lo = 0.0, hi = 0.0;         ///< confidence range [lo, hi) (the last bin includes 1)
  std::size_t n = 0;                 ///< predictions in the bin
  double mean_confidence = 0.0;      ///< 0 when n == 0
  double accuracy = 0.0;             ///< share right; 0 when n == 0
};

struct ConfidenceCalibration {
  std::size_t n = 0;
  double ece = 0.0;                  ///< expected calibration error: sum_b n_b / n |acc_b - conf_b|
  double brier = 0.0;                ///< mean (confidence - outcome)^2
  double mean_confidence = 0.0, accuracy = 0.0;
  std::vector<ReliabilityBin> bins;  ///< equal-width bins over [0, 1] (the reliability diagram)
};

/// ECE, Brier score and reliability diagram of confidences in [0, 1] against 0/1 outcomes.
/// Empty input gives n = 0 and zeros. Throws ts::Error for sizes that differ, a confidence
/// outside [0, 1] or non-finite, or bins == 0.
ConfidenceCalibration confidence_calibration(std::span<const double> confidence,
                                             std::span<const int> outcome, std::size_t bins = 10);

/// What sampling alone gives: the ECE of an exactly calibrated model at these confidences, its
/// outcomes drawn as Bernoulli(confidence), over `replicates` draws (fixed seed: deterministic).
struct EceNoise {
  double mean = 0.0;                 ///< mean ECE over the draws
  double p95 = 0.0;                  ///< its 95th percentile
};
EceNoise ece_sampling_noise(std::span<const double> confidence, std::size_t bins = 10,
                            std::size_t replicates = 400, std::uint64_t seed = 14);

// --- Order statistics and means ------------------------------------------------------------------

/// Quantile p in [0, 1] by linear interpolation between order statistics (Hyndman & Fan type 7,
/// the default of R and NumPy). Empty input gives nullopt. Non-finite values are a programming
/// error (ts::Error).
std::optional<double> quantile(std::span<const double> values, double p);
std::optional<double> median(std::span<const double> values);

/// Regularized incomplete beta function I_x(a, b), a, b > 0, x in [0, 1] (continued fraction,
/// Numerical Recipes 6.4); accurate to ~1e-12.
double incomplete_beta(double x, double a, double b);
/// CDF of Student's t with `dof` > 0 degrees of freedom.
double student_t_cdf(double t, double dof);
/// Quantile of Student's t (p in (0, 1)), by bisection on the CDF.
double student_t_quantile(double p, double dof);

struct MeanInterval {
  std::size_t n = 0;
  double mean = 0.0;
  std::optional<Interval> ci;   ///< nullopt when n < 2 (the spread is unknown)
};

/// Mean with a two-sided Student-t confidence interval at `level`:
/// mean ± t_{(1+level)/2, n-1} · s / sqrt(n), s the sample standard deviation.
MeanInterval mean_t_interval(std::span<const double> values, double level = 0.95);

// --- Pose errors ---------------------------------------------------------------------------------

// The position and orientation errors (Section 5.2, Eq. 10; symmetry-aware too) are the
// engine's: pose_error() in engine/geometry/pose_error.hpp.
/// BOP Maximum Symmetry-aware Surface Distance (Hodan et al. 2020):
/// min_S max_x || T_est x - T_truth S x || over model points x (object frame). The identity is
/// always considered. No points gives 0.
double mssd(const Pose& estimate, const Pose& truth, std::span<const Pose> symmetries,
            std::span<const Vec3> model_points);

// --- Per-step summaries --------------------------------------------------------------------------

/// The paper's bounds when averaging errors (Section 5.2): 4 cm and 1 rad.
struct ErrorBounds {
  double position_m = 0.04;      ///< m
  double orientation_rad = 1.0;  ///< rad (also for the symmetric orientation error)
  double mssd_m = 0.04;          ///< m (same bound as position)
};

/// One exploration run observed at one step.
struct StepSample {
  bool correct = false;                       ///< the best hypothesis is the true object
  double position_error_m = 0.0;
  double orientation_error_rad = 0.0;
  double symmetric_orientation_error_rad = 0.0;
  double mssd_m = 0.0;
  double time_s = 0.0;                        ///< wall time of the step
  /// The best hypothesis is congruent with the true object (in its class of congruent objects,
  /// which no touch can tell apart); a correct sample counts as such whatever this says.
  bool correct_class = false;
};

/// Summary of one error over the runs that recognized the right object (as in the paper,
/// errors are only defined for those).
struct ErrorSummary {
  std::size_t n = 0;                          ///< runs with the correct object
  std::optional<double> median;               ///< of the raw errors; nullopt when n == 0
  std::optional<double> p95;                  ///< 95th percentile of the raw errors
  /// Mean of min(error, bound); equals the bound when no run recognized the object (the
  /// paper's convention for Figures 15, 16, 21).
  double bounded_mean = 0.0;
  std::optional<Interval> bounded_mean_ci95;  ///< Student-t, n >= 2 only
};

struct StepSummary {
  int step = 0;
  std::size_t runs = 0;
  std::size_t correct = 0;
  double recognition_rate = 0.0;              ///< correct / runs (0 when runs == 0)
  Interval recognition_rate_ci95;             ///< Wilson
  std::size_t correct_class = 0;              ///< runs right within the true object's class
  double recognition_rate_class = 0.0;        ///< correct_class / runs (class-aware; >= the strict rate)
  Interval recognition_rate_class_ci95;       ///< Wilson
  ErrorSummary position_m, orientation_rad, symmetric_orientation_rad, mssd_m;
  std::optional<double> time_s_median, time_s_p95, time_s_mean;  ///< over all runs
};

ErrorSummary summarize_errors(std::span<const double> errors_of_correct_runs, double bound);
StepSummary summarize_step(int step, std::span<const StepSample> samples,
                           const ErrorBounds& bounds = {});

/// Indices of the Pareto-optimal points when minimizing cost[i] and maximizing benefit[i]
/// (a point is dominated when another is no worse in both and better in one). Sorted by cost,
/// ties by index.
std::vector<std::size_t> pareto_front(std::span<const double> cost, std::span<const double> benefit);

}  // namespace ts::experiments
