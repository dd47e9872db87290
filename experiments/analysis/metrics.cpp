#include "experiments/analysis/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace ts::experiments {

Interval wilson_interval(std::size_t successes, std::size_t trials, double z) {
  if (trials == 0) return {0.0, 1.0};
  if (successes > trials) throw Error("more successes than trials", {}, "wilson_interval");
  const double n = static_cast<double>(trials);
  const double p = static_cast<double>(successes) / n;
  const double z2 = z * z;
  const double denom = 1.0 + z2 / n;
  const double centre = (p + z2 / (2.0 * n)) / denom;
  const double half = z / denom * std::sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n));
  // At p = 0 or 1 the exact bound is 0 or 1; clamp away the rounding.
  double lo = successes == 0 ? 0.0 : std::max(0.0, centre - half);
  double hi = successes == trials ? 1.0 : std::min(1.0, centre + half);
  return {lo, hi};
}

Interval cluster_bootstrap_interval(std::span<const ClusterCounts> clusters, std::size_t resamples,
                                    std::uint64_t seed, double level) {
  if (resamples == 0) throw Error("a bootstrap needs at least one resample", {}, "resamples");
  if (!(level > 0.0 && level < 1.0)) throw Error("confidence level outside (0, 1)", {}, "level");
  std::vector<ClusterCounts> used;
  for (const ClusterCounts& c : clusters) {
    if (c.successes > c.trials) throw Error("more successes than trials", {}, "cluster_bootstrap");
    if (c.trials > 0) used.push_back(c);
  }
  if (used.empty()) return {0.0, 1.0};
  Rng rng(seed);
  std::vector<double> rates(resamples);
  for (double& rate : rates) {
    std::size_t successes = 0, trials = 0;
    for (std::size_t k = 0; k < used.size(); ++k) {
      const ClusterCounts& c = used[rng.index(used.size())];
      successes += c.successes;
      trials += c.trials;
    }
    rate = static_cast<double>(successes) / static_cast<double>(trials);
  }
  return {*quantile(rates, 0.5 * (1.0 - level)), *quantile(rates, 0.5 * (1.0 + level))};
}

ConfidenceCalibration confidence_calibration(std::span<const double> confidence,
                                             std::span<const int> outcome, std::size_t bins) {
  if (confidence.size() != outcome.size())
    throw Error("confidences and outcomes differ in number", {}, "confidence");
  if (bins == 0) throw Error("a reliability diagram needs at least one bin", {}, "bins");
  ConfidenceCalibration out;
  out.bins.resize(bins);
  for (std::size_t b = 0; b < bins; ++b) {
    out.bins[b].lo = static_cast<double>(b) / static_cast<double>(bins);
    out.bins[b].hi = static_cast<double>(b + 1) / static_cast<double>(bins);
  }
  out.n = confidence.size();
  if (out.n == 0) return out;
  std::vector<double> sum_conf(bins, 0.0), sum_right(bins, 0.0);
  for (std::size_t i = 0; i < out.n; ++i) {
    const double c = confidence[i];
    if (!(c >= 0.0 && c <= 1.0)) throw Error("a confidence outside [0, 1]", {}, "confidence");
    const double y = outcome[i] != 0 ? 1.0 : 0.0;
    const std::size_t b = std::min(bins - 1, static_cast<std::size_t>(c * static_cast<double>(bins)));
    ++out.bins[b].n;
    sum_conf[b] += c;
    sum_right[b] += y;
    out.brier += (c - y) * (c - y);
    out.mean_confidence += c;
    out.accuracy += y;
  }
  const double n = static_cast<double>(out.n);
  out.brier /= n;
  out.mean_confidence /= n;
  out.accuracy /= n;
  for (std::size_t b = 0; b < bins; ++b) {
    ReliabilityBin& r = out.bins[b];
    if (r.n == 0) continue;
    r.mean_confidence = sum_conf[b] / static_cast<double>(r.n);
    r.accuracy = sum_right[b] / static_cast<double>(r.n);
    out.ece += static_cast<double>(r.n) / n * std::abs(r.accuracy - r.mean_confidence);
  }
  return out;
}

EceNoise ece_sampling_noise(std::span<const double> confidence, std::size_t bins, std::size_t replicates,
                            std::uint64_t seed) {
  EceNoise out;
  if (confidence.empty() || replicates == 0) return out;
  Rng rng(seed);
  std::vector<int> y(confidence.size());
  std::vector<double> e(replicates);
  for (std::size_t k = 0; k < replicates; ++k) {
    for (std::size_t i = 0; i < y.size(); ++i) y[i] = rng.uniform() < confidence[i] ? 1 : 0;
    e[k] = confidence_calibration(confidence, y, bins).ece;
  }
  out.mean = std::accumulate(e.begin(), e.end(), 0.0) / static_cast<double>(e.size());
  out.p95 = *quantile(e, 0.95);
  return out;
}

std::optional<double> quantile(std::span<const double> values, double p) {
  if (values.empty()) return std::nullopt;
  if (!(p >= 0.0 && p <= 1.0)) throw Error("quantile level outside [0, 1]", {}, "p");
  std::vector<double> v(values.begin(), values.end());
  for (double x : v)
    if (!std::isfinite(x)) throw Error("non-finite value in a quantile", {}, "values");
  std::sort(v.begin(), v.end());
  const double h = p * static_cast<double>(v.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(h));
  const std::size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (h - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

std::optional<double> median(std::span<const double> values) { return quantile(values, 0.5); }

namespace {
// Continued fraction of the incomplete beta function (modified Lentz), Numerical Recipes 6.4.
double beta_continued_fraction(double a, double b, double x) {
  constexpr double tiny = 1e-300;
  constexpr double eps = 1e-15;
  const double qab = a + b, qap = a + 1.0, qam = a - 1.0;
  double c = 1.0;
  double d = 1.0 - qab * x / qap;
  if (std::abs(d) < tiny) d = tiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m <= 10000; ++m) {
    const double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((qam + m2) * (a + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    h *= d * c;
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1.0) < eps) break;
  }
  return h;
}
}  // namespace

double incomplete_beta(double x, double a, double b) {
  if (!(a > 0.0 && b > 0.0)) throw Error("incomplete beta needs a, b > 0", {}, "a, b");
  if (!(x >= 0.0 && x <= 1.0)) throw Error("incomplete beta needs x in [0, 1]", {}, "x");
  if (x == 0.0 || x == 1.0) return x;
  const double log_front = std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) +
                           a * std::log(x) + b * std::log1p(-x);
  const double front = std::exp(log_front);
  if (x < (a + 1.0) / (a + b + 2.0)) return front * beta_continued_fraction(a, b, x) / a;
  return 1.0 - front * beta_continued_fraction(b, a, 1.0 - x) / b;
}

double student_t_cdf(double t, double dof) {
  if (!(dof > 0.0)) throw Error("Student t needs dof > 0", {}, "dof");
  if (std::isinf(t)) return t > 0 ? 1.0 : 0.0;
  const double x = dof / (dof + t * t);
  const double tail = 0.5 * incomplete_beta(x, 0.5 * dof, 0.5);  // P(T > |t|)
  return t > 0.0 ? 1.0 - tail : tail;
}

double student_t_quantile(double p, double dof) {
  if (!(p > 0.0 && p < 1.0)) throw Error("Student t quantile needs p in (0, 1)", {}, "p");
  if (p < 0.5) return -student_t_quantile(1.0 - p, dof);
  if (p == 0.5) return 0.0;
  double lo = 0.0, hi = 1.0;
  while (student_t_cdf(hi, dof) < p) {
    lo = hi;
    hi *= 2.0;
    if (hi > 1e12) return hi;  // p within rounding of 1
  }
  for (int i = 0; i < 200 && hi - lo > 1e-13 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (student_t_cdf(mid, dof) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

MeanInterval mean_t_interval(std::span<const double> values, double level) {
  if (!(level > 0.0 && level < 1.0)) throw Error("confidence level outside (0, 1)", {}, "level");
  MeanInterval out;
  out.n = values.size();
  if (values.empty()) return out;
  // Fixed-order sums: the same values give the same bits.
  double sum = 0.0;
  for (double v : values) sum += v;
  out.mean = sum / static_cast<double>(out.n);
  if (out.n < 2) return out;
  double ss = 0.0;
  for (double v : values) ss += (v - out.mean) * (v - out.mean);
  const double sd = std::sqrt(ss / static_cast<double>(out.n - 1));
  const double t = student_t_quantile(0.5 * (1.0 + level), static_cast<double>(out.n - 1));
  const double half = t * sd / std::sqrt(static_cast<double>(out.n));
  out.ci = Interval{out.mean - half, out.mean + half};
  return out;
}

double mssd(const Pose& estimate, const Pose& truth, std::span<const Pose> symmetries,
            std::span<const Vec3> model_points) {
  if (model_points.empty()) return 0.0;
  auto max_distance = [&](const Pose& valid_truth) {
    double worst = 0.0;
    for (const Vec3& x : model_points)
      worst = std::max(worst, (estimate * x - valid_truth * x).squaredNorm());
    return std::sqrt(worst);
  };
  double best = max_distance(truth);
  for (const Pose& s : symmetries) best = std::min(best, max_distance(truth * s));
  return best;
}

ErrorSummary summarize_errors(std::span<const double> errors, double bound) {
  ErrorSummary out;
  out.n = errors.size();
  out.median = median(errors);
  out.p95 = quantile(errors, 0.95);
  if (errors.empty()) {
    out.bounded_mean = bound;
    return out;
  }
  std::vector<double> bounded(errors.begin(), errors.end());
  for (double& e : bounded) e = std::min(e, bound);
  const MeanInterval m = mean_t_interval(bounded);
  out.bounded_mean = m.mean;
  out.bounded_mean_ci95 = m.ci;
  return out;
}

StepSummary summarize_step(int step, std::span<const StepSample> samples,
                           const ErrorBounds& bounds) {
  StepSummary out;
  out.step = step;
  out.runs = samples.size();
  std::vector<double> pos, ori, sym, ms, times;
  for (const StepSample& s : samples) {
    times.push_back(s.time_s);
    if (s.correct || s.correct_class) ++out.correct_class;
    if (!s.correct) continue;
    ++out.correct;
    pos.push_back(s.position_error_m);
    ori.push_back(s.orientation_error_rad);
    sym.push_back(s.symmetric_orientation_error_rad);
    ms.push_back(s.mssd_m);
  }
  out.recognition_rate =
      out.runs == 0 ? 0.0 : static_cast<double>(out.correct) / static_cast<double>(out.runs);
  out.recognition_rate_ci95 = wilson_interval(out.correct, out.runs);
  out.recognition_rate_class =
      out.runs == 0 ? 0.0 : static_cast<double>(out.correct_class) / static_cast<double>(out.runs);
  out.recognition_rate_class_ci95 = wilson_interval(out.correct_class, out.runs);
  out.position_m = summarize_errors(pos, bounds.position_m);
  out.orientation_rad = summarize_errors(ori, bounds.orientation_rad);
  out.symmetric_orientation_rad = summarize_errors(sym, bounds.orientation_rad);
  out.mssd_m = summarize_errors(ms, bounds.mssd_m);
  out.time_s_median = median(times);
  out.time_s_p95 = quantile(times, 0.95);
  if (!times.empty()) out.time_s_mean = mean_t_interval(times).mean;
  return out;
}

std::vector<std::size_t> pareto_front(std::span<const double> cost, std::span<const double> benefit) {
  if (cost.size() != benefit.size()) throw Error("cost and benefit differ in size", {}, "pareto");
  std::vector<std::size_t> order(cost.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    if (cost[a] != cost[b]) return cost[a] < cost[b];
    if (benefit[a] != benefit[b]) return benefit[a] > benefit[b];
    return a < b;
  });
  // Sweep by increasing cost: a point is on the front when its benefit beats every cheaper
  // point's. Equal points (same cost and benefit) are all kept.
  std::vector<std::size_t> front;
  double best = -std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < order.size(); ++k) {
    const std::size_t i = order[k];
    const bool same_as_last = !front.empty() && cost[front.back()] == cost[i] &&
                              benefit[front.back()] == benefit[i];
    if (benefit[i] > best || same_as_last) {
      front.push_back(i);
      best = std::max(best, benefit[i]);
    }
  }
  return front;
}

}  // namespace ts::experiments
