// Set answers (issue 56): the classes' log-weight gaps, the conformal p-values and thresholds
// against their definitions, and the coverage of the sets against its exact finite-sample value.
#include "engine/recognition/answer_set.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

using namespace ts;

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();

Hypothesis hyp(std::uint32_t object, double log_weight) {
  Hypothesis h;
  h.object = object;
  h.log_weight = log_weight;
  h.weight = std::exp(log_weight);
  return h;
}
}  // namespace

TEST_CASE("Classes' log-weight gaps: the answer's ln w minus each class's best, floored at 0, tied after them without hypotheses") {
  std::size_t classes = 0;
  // Objects 1 and 3 congruent: classes {1, 3} -> 0, then 0 -> 1, 2 -> 2, 4 -> 3.
  const std::vector<std::uint32_t> of = class_indices(5, {{1, 3}}, classes);
  REQUIRE(classes == 4);
  CHECK(of == std::vector<std::uint32_t>{1, 0, 2, 0, 3});
  const std::vector<Hypothesis> state{hyp(2, -0.5), hyp(3, -0.01), hyp(0, -0.25), hyp(1, -0.04), hyp(2, -0.75)};
  // The answer is the ln w leader (object 3).
  std::vector<double> gaps = class_log_weight_gaps(state, -0.01, of, classes);
  REQUIRE(gaps.size() == 4);
  CHECK(gaps[0] == 0.0);                              // object 3 leads; its class holds object 1 too
  CHECK(gaps[1] == doctest::Approx(0.24).epsilon(1e-12));
  CHECK(gaps[2] == doctest::Approx(0.49).epsilon(1e-12));   // object 2's best, not its worse one
  CHECK(gaps[3] == kOutsideState);                    // no hypothesis of object 4 (no prior: tied)
  // NaN: the leader stands in for the answer.
  CHECK(class_log_weight_gaps(state, std::nan(""), of, classes) == gaps);
  // The answer rule chose object 0 (ln w -0.25) over the heavier class {1, 3}: object 0's class
  // scores 0, the heavier class 0 too (floored), object 2 its distance below the answer.
  gaps = class_log_weight_gaps(state, -0.25, of, classes);
  CHECK(gaps[0] == 0.0);
  CHECK(gaps[1] == 0.0);
  CHECK(gaps[2] == doctest::Approx(0.25).epsilon(1e-12));
  CHECK(gaps[3] == kOutsideState);
  // The same through a step: its answer is r.best; a step without hypotheses has no evidence.
  StepResult r;
  r.valid = true;
  r.hypotheses = state;
  r.best = state[2];
  CHECK(class_log_weight_gaps(r, of, classes) == gaps);
  r.valid = false;
  for (double g : class_log_weight_gaps(r, of, classes)) CHECK(g == kInf);
  // An empty state: no class has evidence.
  for (double g : class_log_weight_gaps({}, 0.0, of, classes)) CHECK(g == kInf);
  // A hypothesis outside the database, a class index out of range, an object in two classes.
  CHECK_THROWS_AS(class_log_weight_gaps(std::vector<Hypothesis>{hyp(7, 0.0)}, 0.0, of, classes), Error);
  CHECK_THROWS_AS(class_log_weight_gaps(state, -0.01, of, 2), Error);
  CHECK_THROWS_AS(class_indices(5, {{1, 3}, {3, 4}}, classes), Error);
  CHECK_THROWS_AS(class_indices(5, {{1, 5}}, classes), Error);
}

TEST_CASE("Conformal p-values and thresholds against their definitions, ties and infinite gaps included") {
  Rng rng(7);
  for (int trial = 0; trial < 300; ++trial) {
    const std::size_t n = 1 + rng.index(40);
    std::vector<double> gaps(n);
    for (double& g : gaps) {
      const double u = rng.uniform();
      g = u < 0.1 ? kInf : u < 0.3 ? 0.0 : std::round(rng.uniform() * 8.0) / 4.0;   // ties and zeros
    }
    const ConformalScores s(gaps);
    REQUIRE(s.size() == n);
    for (double g : {0.0, 0.25, 0.6, 1.0, 2.0, kInf}) {
      const auto at_least = std::count_if(gaps.begin(), gaps.end(), [&](double x) { return x >= g; });
      CHECK(s.p_value(g) == doctest::Approx(double(1 + at_least) / double(n + 1)).epsilon(1e-15));
    }
    for (double alpha : {0.05, 0.1, 0.2, 0.5}) {
      std::vector<double> sorted = gaps;
      std::sort(sorted.begin(), sorted.end());
      const auto k = static_cast<std::size_t>(std::ceil((double(n) + 1) * (1 - alpha) - 1e-9));
      const double expected = k == 0 ? 0.0 : k > n ? kInf : sorted[k - 1];
      CHECK(s.threshold(alpha) == expected);
      // The set {p > alpha} is the set {gap <= threshold}.
      for (double g : {0.0, 0.25, 0.6, 1.0, 2.0, kInf})
        CHECK((s.p_value(g) > alpha) == (g <= s.threshold(alpha)));
    }
  }
  // (19 + 1) * 0.95 is 19 in exact arithmetic: the 19th of 19 scores, not "beyond n".
  std::vector<double> nineteen(19);
  for (std::size_t i = 0; i < 19; ++i) nineteen[i] = double(i);
  CHECK(ConformalScores(nineteen).threshold(0.05) == 18.0);
  CHECK(ConformalScores(std::vector<double>(18, 1.0)).threshold(0.05) == kInf);   // 18 runs: too few
  // From finite gaps and a count of infinite ones: the same scores.
  const ConformalScores counted({0.25, 0.5}, 2), listed({0.5, kInf, 0.25, kInf});
  CHECK(counted.size() == listed.size());
  for (double g : {0.0, 0.25, 0.4, 0.5, 1.0, kInf}) CHECK(counted.p_value(g) == listed.p_value(g));
  CHECK_THROWS_AS(ConformalScores({0.5, kInf}, 1), Error);
  CHECK_THROWS_AS(ConformalScores({0.5, std::nan("")}), Error);
  CHECK_THROWS_AS(ConformalScores({-0.5}), Error);
  for (double alpha : {0.0, 1.0, -0.1, 1.5, std::nan("")}) {
    CHECK_THROWS_AS(ConformalScores({0.5}).threshold(alpha), Error);
    CHECK_THROWS_AS(conformal_set(std::vector<double>{0.0}, ConformalScores({0.5}), alpha), Error);
  }
  CHECK_THROWS_AS(conformal_set(std::vector<double>{0.0}, ConformalScores(), 0.1), Error);
}

TEST_CASE("Conformal sets: the leader always, classes by gap, and an explicit 'any object' when none can be excluded") {
  // 20 calibration gaps 0, 0.1, ..., 1.9: at alpha 0.1 the threshold is the ceil(21 * 0.9) = 19th, 1.8.
  std::vector<double> cal(20);
  for (std::size_t i = 0; i < cal.size(); ++i) cal[i] = 0.1 * double(i);
  const ConformalScores s(cal);
  CHECK(s.threshold(0.1) == doctest::Approx(1.8).epsilon(1e-12));
  const std::vector<double> gaps{0.5, 0.0, 1.85, 1.75, kInf};
  const AnswerSet set = conformal_set(gaps, s, 0.1);
  REQUIRE(set.informative);
  REQUIRE(set.size == 3);
  CHECK(set.members[0].cls == 1);   // the leader
  CHECK(set.members[0].p_value == 1.0);
  CHECK(set.members[1].cls == 0);
  CHECK(set.members[2].cls == 3);
  CHECK(set.members[2].p_value == doctest::Approx(3.0 / 21.0));   // gaps 1.8, 1.9 and itself
  // A larger alpha keeps fewer: class 0's p-value is 16 / 21, the leader's 1.
  CHECK(conformal_set(gaps, s, 0.5).size == 2);
  CHECK(conformal_set(gaps, s, 0.9).size == 1);
  // Calibration runs without a hypothesis of their class at the quantile: every class.
  std::vector<double> blind = cal;
  blind[19] = blind[18] = kInf;
  const AnswerSet any = conformal_set(gaps, ConformalScores(blind), 0.1);
  CHECK_FALSE(any.informative);
  CHECK(any.members.empty());
  CHECK(any.size == gaps.size());
  // An empty state: no evidence, "any object", never an empty set.
  const AnswerSet none = conformal_set(std::vector<double>(4, kInf), s, 0.1);
  CHECK_FALSE(none.informative);
  CHECK(none.size == 4);
}

TEST_CASE("Coverage of conformal sets: the exact finite-sample rate k / (n + 1) on exchangeable runs") {
  // Runs with 6 classes, the truth's gap drawn from one continuous law for every run (the runs
  // exchangeable, no ties), another class leading. With n calibration runs the set at level alpha
  // holds the truth with probability exactly k / (n + 1), k = ceil((n + 1)(1 - alpha)), over the
  // draws of the calibration and the run: averaged over many calibrations the coverage must land
  // there (a rank off by one, e.g. ceil(n (1 - alpha)), moves it by 1 / (n + 1) >= 0.01).
  Rng rng(11);
  for (const auto& [n, alpha] : {std::pair{10, 0.2}, {30, 0.1}, {99, 0.05}}) {
    const int calibrations = 400, tests = 200;
    double covered = 0.0, size = 0.0;
    for (int c = 0; c < calibrations; ++c) {
      std::vector<double> cal;
      for (int i = 0; i < n; ++i) cal.push_back(-std::log(1.0 - rng.uniform()));
      const ConformalScores s(cal);
      for (int t = 0; t < tests; ++t) {
        std::vector<double> gaps(6);
        gaps[0] = -std::log(1.0 - rng.uniform());
        for (std::size_t k = 1; k < 6; ++k) gaps[k] = 3.0 * rng.uniform();
        gaps[1 + rng.index(5)] = 0.0;   // the leader
        const AnswerSet set = conformal_set(gaps, s, alpha);
        // Every class (not informative) holds the truth too.
        covered += !set.informative || std::any_of(set.members.begin(), set.members.end(),
                                                   [](const AnswerSetMember& m) { return m.cls == 0; }) ? 1.0 : 0.0;
        size += double(set.size);
      }
    }
    const double total = double(calibrations) * tests;
    const double exact = std::ceil((n + 1) * (1 - alpha) - 1e-9) / (n + 1);
    INFO("n " << n << ", alpha " << alpha << ": coverage " << covered / total << ", exact " << exact);
    // Standard error about 0.0015 (the calibrations' spread dominates): 0.006 is 4 of them.
    CHECK(std::abs(covered / total - exact) < 0.006);
    CHECK(size / total < 6.0);   // the sets exclude classes
  }
}

TEST_CASE("Conformal sets with a tie: gaps below it score as the answer's class, on both sides alike") {
  // 20 calibration runs, 19 of them right (gap 0) and one a near-twin miss (gap 1e-6): without a
  // tie the 95 % threshold is the 20th smallest, 1e-6, and a step's near-twin at 1e-5 is left out.
  std::vector<double> cal(20, 0.0);
  cal[7] = 1e-6;
  const ConformalScores plain(cal);
  CHECK(plain.threshold(0.05) == 1e-6);
  const std::vector<double> gaps{0.0, 1e-5, 0.3, kInf};   // the answer, a near-twin, a rival, none
  const AnswerSet without = conformal_set(gaps, plain, 0.05);
  REQUIRE(without.informative);
  CHECK(without.size == 1);
  // With a tie of 0.01 nats the near-twin scores 0: in the set, its p-value 1; the rival at 0.3
  // (above the tie, scored as its gap) stays out; the reported gap stays the gap.
  ConformalScores tied(cal);
  tied.set_tie(0.01);
  CHECK(tied.tie() == 0.01);
  CHECK(tied.threshold(0.05) == 0.0);   // every calibration score is 0
  CHECK(tied.p_value(1e-5) == 1.0);
  CHECK(tied.p_value(0.3) == doctest::Approx(1.0 / 21.0));
  const AnswerSet with = conformal_set(gaps, tied, 0.05);
  REQUIRE(with.informative);
  REQUIRE(with.size == 2);
  CHECK(with.members[1].cls == 1);
  CHECK(with.members[1].gap == 1e-5);
  // Calibration gaps above the tie keep their scores: a threshold between them is unchanged.
  std::vector<double> spread(20);
  for (std::size_t i = 0; i < spread.size(); ++i) spread[i] = 0.1 * double(i);
  ConformalScores s(spread);
  const double before = s.threshold(0.1);
  s.set_tie(0.05);
  CHECK(s.threshold(0.1) == before);
  CHECK(s.p_value(0.04) == 1.0);
  CHECK(s.p_value(0.15) == doctest::Approx(19.0 / 21.0));   // 1 + the 18 gaps 0.2 ... 1.9
  for (double bad : {-0.1, kInf, std::nan("")}) CHECK_THROWS_AS(s.set_tie(bad), Error);
}

TEST_CASE("Classes without hypotheses ranked by the shape prior: after every class of the state, a finite score") {
  std::size_t classes = 0;
  // Objects 1 and 3 congruent: classes {1, 3} -> 0, then 0 -> 1, 2 -> 2, 4 -> 3, 5 -> 4.
  const std::vector<std::uint32_t> of = class_indices(6, {{1, 3}}, classes);
  REQUIRE(classes == 5);
  const std::vector<Hypothesis> state{hyp(0, -0.1), hyp(2, -0.6)};
  // Prior scores per object: class {1, 3} takes its best (-2.0), object 4's is the best of all
  // (-1.5), object 5 was not allowed (-inf).
  const std::vector<double> prior{-3.0, -2.5, -4.0, -2.0, -1.5, -kInf};
  const std::vector<double> gaps = class_log_weight_gaps(state, -0.1, of, classes, prior);
  REQUIRE(gaps.size() == 5);
  CHECK(gaps[1] == 0.0);                                     // object 0: the answer
  CHECK(gaps[2] == doctest::Approx(0.5).epsilon(1e-12));     // object 2: in the state, by ln w
  CHECK(gaps[0] == doctest::Approx(kOutsideState + 0.5).scale(0).epsilon(1e-12));   // class {1, 3}: -1.5 - (-2.0)
  CHECK(gaps[3] == kOutsideState);                           // object 4: the prior's best
  CHECK(gaps[4] == kInf);                                    // object 5: no prior score
  CHECK_FALSE(outside_state(gaps[2]));
  CHECK(outside_state(gaps[0]));
  CHECK(outside_state(gaps[4]));
  // The prior of a class in the state does not matter: object 0's -3.0 is the worst, its gap 0.
  // Without a prior, or a prior that scored no class, the classes outside are tied.
  const std::vector<double> plain = class_log_weight_gaps(state, -0.1, of, classes);
  CHECK(plain[0] == kOutsideState);
  CHECK(plain[3] == kOutsideState);
  CHECK(plain[4] == kOutsideState);
  CHECK(plain[2] == gaps[2]);
  CHECK(class_log_weight_gaps(state, -0.1, of, classes, std::vector<double>(6, -kInf)) == plain);
  // Through a step: r.prior_scores; an empty state stays "no evidence" whatever the prior.
  StepResult r;
  r.valid = true;
  r.hypotheses = state;
  r.best = state[0];
  r.prior_scores = prior;
  CHECK(class_log_weight_gaps(r, of, classes) == gaps);
  for (double g : class_log_weight_gaps({}, 0.0, of, classes, prior)) CHECK(g == kInf);
  // A prior of the wrong length.
  CHECK_THROWS_AS(class_log_weight_gaps(state, -0.1, of, classes, std::vector<double>(5, 0.0)), Error);

  // Calibration: 20 runs, 16 with the truth in the state (gaps 0) and 4 outside it with prior
  // gaps 0.2, 0.4, 0.6, 0.8. At alpha 0.1 the threshold is the 19th smallest score, 1e6 + 0.6:
  // the set is the state's classes and the outside classes within 0.6 of the prior's best.
  std::vector<double> cal(16, 0.0);
  for (double p : {0.2, 0.4, 0.6, 0.8}) cal.push_back(kOutsideState + p);
  const ConformalScores s(cal);
  CHECK(s.threshold(0.1) == doctest::Approx(kOutsideState + 0.6).scale(0).epsilon(1e-9));
  const AnswerSet set = conformal_set(gaps, s, 0.1);
  REQUIRE(set.informative);
  REQUIRE(set.size == 4);                                    // all but object 5's class
  CHECK(set.members[0].cls == 1);                            // the answer first
  CHECK(set.members[1].cls == 2);                            // then the state, by ln w
  CHECK(set.members[2].cls == 3);                            // then the prior's best
  CHECK(set.members[3].cls == 0);
  CHECK(set.members[3].p_value == doctest::Approx(3.0 / 21.0));   // 1 + the scores >= 1e6 + 0.5 (0.6, 0.8)
  // At alpha 0.2 the threshold is the 17th smallest score, 1e6 + 0.2: of the classes outside,
  // the prior's best (prior gap 0) only.
  const AnswerSet tighter = conformal_set(gaps, s, 0.2);
  REQUIRE(tighter.informative);
  CHECK(tighter.size == 3);
  // The same calibration scored +inf outside (a version 6 file) gives the sets it gave: "any object".
  std::vector<double> old(16, 0.0);
  old.insert(old.end(), 4, kInf);
  CHECK_FALSE(conformal_set(gaps, ConformalScores(old), 0.1).informative);
  CHECK_FALSE(conformal_set(plain, ConformalScores(old), 0.1).informative);
  // A step without a prior under a calibration with priors: the classes outside tie at 1e6, whose
  // p-value counts every calibration run outside the state (5 / 21 > 0.1): all of them come in,
  // so every class: "any object", never a set that leaves them out unseen.
  CHECK(s.p_value(plain[0]) == doctest::Approx(5.0 / 21.0));
  CHECK_FALSE(conformal_set(plain, s, 0.1).informative);
  // Without priors on either side (a small database) the ties act as +inf did: left out while
  // few calibration runs lie outside the state (1 of 20: p 2 / 21), then every class (3 of 20).
  std::vector<double> plain_inf = plain;
  for (double& g : plain_inf)
    if (outside_state(g)) g = kInf;
  for (const int outside : {1, 3}) {
    std::vector<double> tied(20 - outside, 0.0), tied_inf = tied;
    tied.insert(tied.end(), outside, kOutsideState);
    tied_inf.insert(tied_inf.end(), outside, kInf);
    const AnswerSet now = conformal_set(plain, ConformalScores(tied), 0.1);
    const AnswerSet before = conformal_set(plain_inf, ConformalScores(tied_inf), 0.1);
    CHECK(now.informative == (outside == 1));
    CHECK(now.informative == before.informative);
    CHECK(now.size == before.size);
    CHECK(now.size == (outside == 1 ? 1 : 5));   // the answer alone (the rival at 0.5: p 2 / 21)
  }
}
