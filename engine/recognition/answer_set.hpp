// Set answers with a coverage guarantee (issue 56): split-conformal sets over the database's
// classes of congruent objects.
//
// The nonconformity score of a class at a step is its log-weight gap to the answer: ln w of the
// hypothesis the answer rule chose minus the best ln w among the class's own hypotheses, floored at
// 0 (Eq. 5-6; 0 for the answer's class and for any class weighted above it). The answer's class is
// therefore in every set. A class without hypotheses in the state scores after every class with
// some: kOutsideState plus its shape-prior gap (the best class's shape-prior score minus its own,
// engine/recognition/shape_prior.hpp: the step's pose-free ranking of every object, which runs on
// large databases; all tied at kOutsideState when the step has none or it scored no class), or
// +inf when the class alone has none (objects too small to span the contacts). Without a prior
// the sets are the same as with +inf for every such class, as before it: the tied classes come
// into a set together, and then with every class (the set says "any object"). On a database of
// thousands, the truth is outside the state in more than alpha of the runs until late steps, and
// with +inf for all of those no class could be excluded: the set said "any object" (4 500
// catalogue objects: through step 20). Ranked by the prior instead, the set is
// the state's classes and the prior's best. Any fixed score keeps the guarantee below. Scoring
// against the ln w leader instead left the truth out whenever the near-twin verification chose it
// over a heavier twin (9 of 96 right answers at step 40 of study7_cat450_sets). Calibration runs
// (simulated runs of the database, experiments/analysis/calibration.hpp) give the gaps of the
// true class at each step; a class's conformal p-value is (1 + #{calibration gaps >= its gap}) /
// (n + 1), and the set at level alpha is the classes whose p-value exceeds alpha. When the run is
// drawn as the calibration runs were (exchangeable with them: the same database, noise and
// sensing, the object and its pose drawn alike), the set holds the true class with probability at
// least
// 1 - alpha (Vovk et al. 2005; Angelopoulos & Bates 2021, Section 1). Runs of one object share
// its shape, so calibration runs are not independent of each other; the guarantee is marginal
// over objects and is checked on held-out runs (experiments report set_coverage).
#pragma once

#include "engine/recognition/step_result.hpp"

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace ts {
inline namespace recognition {

/// The score of a class outside the state: kOutsideState plus its shape-prior gap (>= 0). Gaps
/// in the state are capped below it (at kOutsideState / 2; ln w's gaps are a few nats at most).
inline constexpr double kOutsideState = 1e6;
/// Whether a score is a class outside the state's (kOutsideState + its prior gap, or +inf).
inline bool outside_state(double score) { return score >= kOutsideState; }

/// Per class (class_of[object] < classes): `answer_log_weight` (the ln w of the answer rule's
/// choice, one of the state's) minus the best ln w of the class's hypotheses, floored at 0. A class
/// with none scores kOutsideState plus (the best class's prior minus its own), its prior the best
/// of its objects' `object_prior` (the shape prior's scores, one per object); kOutsideState when
/// no class has a finite prior (`object_prior` empty: no shape prior, or it scored nothing): all
/// tied, so that a calibration fitted with priors leaves none of them out on a step without; +inf
/// when its prior is -inf while another's is finite (it cannot span the contacts). An empty state
/// gives +inf for every class; a NaN answer_log_weight is replaced by the state's largest ln w. Throws ts::Error when a
/// hypothesis names an object outside class_of, a class_of entry is not below `classes`, or
/// `object_prior` is neither empty nor one per object.
std::vector<double> class_log_weight_gaps(std::span<const Hypothesis> state, double answer_log_weight,
                                          std::span<const std::uint32_t> class_of, std::size_t classes,
                                          std::span<const double> object_prior = {});
/// The same for a step: its state, its answer (r.best) and its shape prior (r.prior_scores); every
/// gap +inf when the step is not valid.
std::vector<double> class_log_weight_gaps(const StepResult& r, std::span<const std::uint32_t> class_of, std::size_t classes);

/// Classes of a database's objects as class_of indices: `members` (each class's objects, e.g. a
/// congruence record's classes) numbered in order, every object not in one its own class after
/// them. Returns the class of each of `objects` objects and sets `classes` to their count.
/// Throws ts::Error for an object index >= objects or an object in two classes.
std::vector<std::uint32_t> class_indices(std::size_t objects, const std::vector<std::vector<std::size_t>>& members,
                                         std::size_t& classes);

/// The calibration scores of one step: the true class's gap on each of n calibration runs.
class ConformalScores {
 public:
  ConformalScores() = default;
  /// Throws ts::Error for a NaN or negative gap (an infinite one is a run whose true class had
  /// no hypothesis).
  explicit ConformalScores(std::vector<double> gaps);
  /// The same from the finite gaps and a count of infinite ones (a count read from a file is
  /// never materialized).
  ConformalScores(std::vector<double> finite_gaps, std::size_t infinite);
  std::size_t size() const { return finite_.size() + infinite_; }
  const std::vector<double>& finite() const { return finite_; }   ///< ascending
  std::size_t infinite() const { return infinite_; }
  /// Near-ties: a gap below `nats` scores 0, as the answer's own class does (near-twins whose
  /// weights differ by less than the evaluation can tell: their gaps are 1e-6 to 1e-2 nats while a
  /// mostly right calibration admits no gap above 0). The score is a fixed function of the gap,
  /// used alike on the calibration runs and the step, so the guarantee holds as before. Throws
  /// ts::Error (key "answer_sets.tie_nats") for a value that is not finite and >= 0.
  ConformalScores& set_tie(double nats);
  double tie() const { return tie_; }
  /// (1 + #{calibration scores >= the gap's score}) / (n + 1); 1 for a gap below the tie.
  double p_value(double gap) const;
  /// The largest score a set at level alpha admits: the ceil((n + 1)(1 - alpha))-th smallest
  /// calibration score (0 when that gap is below the tie), +inf when that rank exceeds n or
  /// falls on an infinite gap. Throws ts::Error for alpha outside (0, 1).
  double threshold(double alpha) const;

 private:
  std::vector<double> finite_;   ///< the gaps themselves, ascending (the tie applies when scored)
  std::size_t infinite_ = 0;
  double tie_ = 0.0;
};

struct AnswerSetMember {
  std::uint32_t cls = 0;   ///< class index (class_indices)
  double gap = 0.0;        ///< its log-weight gap (0: the leading class), or outside the state
                           ///< kOutsideState + its shape-prior gap (outside_state(gap))
  double p_value = 1.0;    ///< its conformal p-value: the set at level a holds it for a < p_value
};

struct AnswerSet {
  double alpha = 0.05;
  /// false: no class can be excluded at this alpha (the calibration's gaps at this step reach
  /// +inf within the 1 - alpha quantile, or the state is empty, or every class is in the set):
  /// the answer is "any object", `members` is empty and `size` the number of classes.
  bool informative = true;
  std::size_t size = 0;
  std::vector<AnswerSetMember> members;   ///< by gap ascending, then class (the leading class first)
};

/// The classes whose p-value exceeds alpha. Throws ts::Error for alpha outside (0, 1) (key
/// "answer_set.alpha") or calibration scores without runs.
AnswerSet conformal_set(std::span<const double> gaps, const ConformalScores& scores, double alpha);

}  // namespace recognition
}  // namespace ts
