#include "engine/recognition/answer_set.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

namespace ts {
inline namespace recognition {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}

std::vector<double> class_log_weight_gaps(std::span<const Hypothesis> state, double answer_log_weight,
                                          std::span<const std::uint32_t> class_of, std::size_t classes,
                                          std::span<const double> object_prior) {
  if (!object_prior.empty() && object_prior.size() != class_of.size())
    throw Error("the shape prior has " + std::to_string(object_prior.size()) + " scores for a database of " +
                std::to_string(class_of.size()), {}, "answer_set");
  for (const std::uint32_t c : class_of)
    if (c >= classes) throw Error("class index " + std::to_string(c) + " out of " + std::to_string(classes), {}, "answer_set");
  std::vector<double> best(classes, -kInf);
  double top = -kInf;
  for (const Hypothesis& h : state) {
    if (h.object >= class_of.size())
      throw Error("a hypothesis names object " + std::to_string(h.object) + " of a database of " +
                  std::to_string(class_of.size()), {}, "answer_set");
    const std::uint32_t c = class_of[h.object];
    if (std::isnan(h.log_weight)) continue;
    best[c] = std::max(best[c], h.log_weight);
    top = std::max(top, h.log_weight);
  }
  std::vector<double> gaps(classes, kInf);
  if (top == -kInf) return gaps;
  const double ref = std::isnan(answer_log_weight) ? top : answer_log_weight;
  for (std::size_t c = 0; c < classes; ++c) {
    if (best[c] == -kInf) continue;
    if (ref == kInf)
      gaps[c] = best[c] == kInf ? 0.0 : 0.5 * kOutsideState;
    else   // a class weighted at or above the answer: 0
      gaps[c] = std::min(std::max(0.0, ref - best[c]), 0.5 * kOutsideState);
  }
  // Outside the state: after every class in it, by the shape prior; all tied when there is none
  // or it scored no class (no contact pair far enough apart).
  std::vector<double> prior(classes, -kInf);
  for (std::size_t i = 0; i < object_prior.size(); ++i)
    if (!std::isnan(object_prior[i])) prior[class_of[i]] = std::max(prior[class_of[i]], object_prior[i]);
  const double top_prior = *std::max_element(prior.begin(), prior.end());
  for (std::size_t c = 0; c < classes; ++c) {
    if (best[c] != -kInf) continue;
    if (!std::isfinite(top_prior))
      gaps[c] = kOutsideState;
    else if (std::isfinite(prior[c]))
      gaps[c] = kOutsideState + (top_prior - prior[c]);   // else +inf: it cannot span the contacts
  }
  return gaps;
}

std::vector<double> class_log_weight_gaps(const StepResult& r, std::span<const std::uint32_t> class_of, std::size_t classes) {
  if (!r.valid) return class_log_weight_gaps({}, 0.0, class_of, classes);
  return class_log_weight_gaps(r.hypotheses, r.best.log_weight, class_of, classes, r.prior_scores);
}

std::vector<std::uint32_t> class_indices(std::size_t objects, const std::vector<std::vector<std::size_t>>& members,
                                         std::size_t& classes) {
  constexpr auto kNone = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> of(objects, kNone);
  std::uint32_t next = 0;
  for (const auto& m : members) {
    if (m.empty()) continue;
    for (std::size_t i : m) {
      if (i >= objects)
        throw Error("a class names object " + std::to_string(i) + " of a database of " + std::to_string(objects), {},
                    "congruent_classes");
      if (of[i] != kNone) throw Error("object " + std::to_string(i) + " is in two classes", {}, "congruent_classes");
      of[i] = next;
    }
    ++next;
  }
  for (auto& c : of)
    if (c == kNone) c = next++;
  classes = next;
  return of;
}

ConformalScores::ConformalScores(std::vector<double> gaps) {
  for (double g : gaps) {
    if (std::isnan(g) || g < 0.0) throw Error("a calibration gap must be a number >= 0 (or +inf)", {}, "answer_sets");
    if (std::isinf(g))
      ++infinite_;
    else
      finite_.push_back(g);
  }
  std::sort(finite_.begin(), finite_.end());
}

ConformalScores::ConformalScores(std::vector<double> finite_gaps, std::size_t infinite) : ConformalScores(std::move(finite_gaps)) {
  if (infinite_ != 0) throw Error("an infinite gap among the finite ones", {}, "answer_sets");
  infinite_ = infinite;
}

ConformalScores& ConformalScores::set_tie(double nats) {
  if (!(std::isfinite(nats) && nats >= 0.0)) throw Error("the tie must be a finite number >= 0", {}, "answer_sets.tie_nats");
  tie_ = nats;
  return *this;
}

double ConformalScores::p_value(double gap) const {
  // Scored 0 below the tie: every calibration score is >= 0.
  if (gap < tie_) return 1.0;
  // Calibration scores >= gap (>= the tie, so a score is its gap): every infinite one, and the
  // finite ones from the first >= gap.
  const std::size_t at_least =
      infinite_ + (std::isinf(gap) ? 0 : static_cast<std::size_t>(finite_.end() - std::lower_bound(finite_.begin(), finite_.end(), gap)));
  return static_cast<double>(1 + at_least) / static_cast<double>(size() + 1);
}

double ConformalScores::threshold(double alpha) const {
  if (!(alpha > 0.0 && alpha < 1.0)) throw Error("alpha must lie in (0, 1)", {}, "answer_set.alpha");
  const double n = static_cast<double>(size());
  // The rank k = ceil((n + 1)(1 - alpha)), computed with a small allowance so that e.g.
  // (19 + 1) * 0.95 = 19 is not rounded up to 20 by binary arithmetic.
  const double exact = (n + 1.0) * (1.0 - alpha);
  const auto k = static_cast<std::size_t>(std::ceil(exact - 1e-9 * (n + 1.0)));
  if (k == 0) return 0.0;
  if (k > finite_.size()) return kInf;   // beyond n, or on an infinite gap
  return finite_[k - 1] < tie_ ? 0.0 : finite_[k - 1];
}

AnswerSet conformal_set(std::span<const double> gaps, const ConformalScores& scores, double alpha) {
  if (!(alpha > 0.0 && alpha < 1.0)) throw Error("alpha must lie in (0, 1)", {}, "answer_set.alpha");
  if (scores.size() == 0) throw Error("the calibration has no runs at this step", {}, "answer_sets");
  AnswerSet out;
  out.alpha = alpha;
  for (std::size_t c = 0; c < gaps.size(); ++c) {
    const double p = scores.p_value(gaps[c]);
    if (p > alpha) out.members.push_back({static_cast<std::uint32_t>(c), gaps[c], p});
  }
  const bool any_evidence = std::any_of(gaps.begin(), gaps.end(), [](double g) { return std::isfinite(g); });
  if (!any_evidence || out.members.empty() || out.members.size() == gaps.size() ||
      std::any_of(out.members.begin(), out.members.end(), [](const AnswerSetMember& m) { return std::isinf(m.gap); })) {
    // Every class (a class without hypotheses is in the set only when all of those are): say so.
    out.informative = false;
    out.members.clear();
    out.size = gaps.size();
    return out;
  }
  std::sort(out.members.begin(), out.members.end(), [](const AnswerSetMember& a, const AnswerSetMember& b) {
    return a.gap != b.gap ? a.gap < b.gap : a.cls < b.cls;
  });
  out.size = out.members.size();
  return out;
}

}  // namespace recognition
}  // namespace ts
