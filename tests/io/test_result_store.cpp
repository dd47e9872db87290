#include "io/result_store.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <string>

using namespace ts;
using ts::test::TempDir;

namespace {

Pose pose_of(double angle, const Vec3& t) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(angle, Vec3(1, -2, 0.5).normalized()).toRotationMatrix();
  T.translation() = t;
  return T;
}

io::ResultHeader header() {
  io::ResultHeader h;
  h.method = "bricpsf";
  h.seed = 18446744073709551615ull;  // the largest seed survives
  h.database = "db.h5";
  h.input = "log.h5";
  h.objects = {"cube", "nut", "pitcher"};
  h.truth_object = "nut";
  h.truth_pose = pose_of(0.3, Vec3(1e5, -2e4, 3.0));
  h.params = {{"n_p", 100}, {"psi", 0.8}, {"d_outlier", 0.2}};
  return h;
}

std::vector<io::ResultStep> steps() {
  std::vector<io::ResultStep> out;
  for (int k = 1; k <= 3; ++k) {
    StepResult r;
    r.step = k;
    r.valid = k > 1;
    r.contacts = 10 * k;
    r.free_points = 100 * k;
    r.candidates = 7;
    r.unobservable_dof = k == 2 ? 3 : 0;
    r.posteriors = {0.1, 0.7, 0.2};
    for (int j = 0; j < (r.valid ? 4 : 0); ++j) {
      Hypothesis hyp;
      hyp.object = static_cast<std::uint32_t>(j % 3);
      hyp.pose = pose_of(0.1 * j, Vec3(1e5 + 0.001 * j, -2e4, 3.0));
      hyp.log_weight = -0.01 * j;
      hyp.weight = std::exp(hyp.log_weight);
      hyp.born = j;
      hyp.slot = 1000u + static_cast<std::uint32_t>(j);
      hyp.icp_iterations = j;
      hyp.icp_converged = j % 2 == 0;
      r.hypotheses.push_back(hyp);
    }
    if (r.valid) {
      r.best = r.hypotheses.front();
      r.posterior = r.posteriors[r.best.object];
    }
    out.push_back(io::to_result_step(r, std::size_t{1}, header().truth_pose, nullptr));
  }
  return out;
}

}  // namespace

TEST_CASE("result store: round trip of header, steps and every hypothesis") {
  TempDir dir("result");
  const auto p = dir / "r.h5";
  const auto h = header();
  const auto s = steps();
  io::write_result(p, h, s);
  const io::ResultData d = io::read_result(p);
  CHECK(d.header.method == h.method);
  CHECK(d.header.seed == h.seed);
  CHECK(d.header.objects == h.objects);
  CHECK(d.header.truth_object == "nut");
  REQUIRE(d.header.truth_pose);
  CHECK((d.header.truth_pose->matrix() - h.truth_pose->matrix()).norm() < 1e-9);
  CHECK(d.header.params.size() == 3);
  REQUIRE(d.steps.size() == 3);
  for (std::size_t k = 0; k < 3; ++k) {
    const auto &a = s[k], &b = d.steps[k];
    CHECK(a.step == b.step);
    CHECK(a.valid == b.valid);
    CHECK(a.contacts == b.contacts);
    CHECK(a.unobservable_dof == b.unobservable_dof);
    CHECK(a.best_object == b.best_object);
    CHECK(a.posterior == b.posterior);
    CHECK(a.correct == b.correct);
    CHECK(a.error.has_value() == b.error.has_value());
    if (a.error) CHECK(a.error->position_m == b.error->position_m);
    REQUIRE(a.hypotheses.size() == b.hypotheses.size());
    for (std::size_t j = 0; j < a.hypotheses.size(); ++j) {
      CHECK(a.hypotheses[j].object == b.hypotheses[j].object);
      CHECK(a.hypotheses[j].log_weight == b.hypotheses[j].log_weight);
      CHECK(a.hypotheses[j].slot == b.hypotheses[j].slot);
      CHECK((a.hypotheses[j].pose.matrix() - b.hypotheses[j].pose.matrix()).norm() < 1e-9);
    }
  }
  CHECK_FALSE(d.steps[0].error.has_value());  // step 1 found nothing: no error to report
  CHECK(d.steps[1].correct == std::optional<bool>(false));
}

TEST_CASE("result store: identical bytes for identical content; bad files give clear errors") {
  TempDir dir("result");
  io::write_result(dir / "a.h5", header(), steps());
  io::write_result(dir / "b.h5", header(), steps());
  CHECK(test::read_bytes(dir / "a.h5") == test::read_bytes(dir / "b.h5"));
  // empty results are fine
  io::ResultHeader h = header();
  h.truth_pose.reset();
  io::write_result(dir / "e.h5", h, {});
  CHECK(io::read_result(dir / "e.h5").steps.empty());
  test::write_text(dir / "x.h5", "not hdf5");
  CHECK_THROWS_AS(io::read_result(dir / "x.h5"), Error);
  CHECK_THROWS_AS(io::read_result(dir / "missing.h5"), Error);
  // a posterior of the wrong size is refused and leaves nothing behind
  auto bad = steps();
  bad[0].posterior.pop_back();
  CHECK_THROWS_AS(io::write_result(dir / "bad.h5", header(), bad), Error);
  CHECK_FALSE(std::filesystem::exists(dir / "bad.h5"));
}

TEST_CASE("result store: answer sets round trip, and a file's bad sets are refused naming the field") {
  TempDir dir("result");
  io::ResultHeader h = header();
  h.answer_set_alpha = 0.1;
  h.calibration = "cal.json";
  auto s = steps();
  const double inf = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < s.size(); ++k) {
    io::ResultAnswerSet a;
    a.informative = k > 0;
    a.size = k > 0 ? 2 : 3;
    a.calibrated_step = static_cast<int>(k) + 1;
    a.p_value = {1.0, 0.45, 1.0 / 11.0};
    a.log_weight_gap = {0.0, 0.25, inf};
    a.in_set = k > 0 ? std::vector<std::uint8_t>{1, 1, 0} : std::vector<std::uint8_t>{1, 1, 1};
    s[k].answer_set = a;
  }
  io::write_result(dir / "s.h5", h, s);
  const io::ResultData d = io::read_result(dir / "s.h5");
  REQUIRE(d.header.answer_set_alpha);
  CHECK(*d.header.answer_set_alpha == 0.1);
  CHECK(d.header.calibration == "cal.json");
  for (std::size_t k = 0; k < s.size(); ++k) {
    REQUIRE(d.steps[k].answer_set);
    const auto &a = *s[k].answer_set, &b = *d.steps[k].answer_set;
    CHECK(a.informative == b.informative);
    CHECK(a.size == b.size);
    CHECK(a.calibrated_step == b.calibrated_step);
    CHECK(a.p_value == b.p_value);
    CHECK(a.log_weight_gap == b.log_weight_gap);   // +inf survives
    CHECK(a.in_set == b.in_set);
  }
  // Without a level no step may carry a set; with one every step must, over every object.
  io::ResultHeader none = header();
  CHECK_THROWS_AS(io::write_result(dir / "n.h5", none, s), Error);
  auto missing = s;
  missing[1].answer_set.reset();
  CHECK_THROWS_AS(io::write_result(dir / "m.h5", h, missing), Error);
  auto short_set = s;
  short_set[2].answer_set->in_set.pop_back();
  CHECK_THROWS_AS(io::write_result(dir / "t.h5", h, short_set), Error);
  for (const char* f : {"n.h5", "m.h5", "t.h5"}) CHECK_FALSE(std::filesystem::exists(dir / f));

  // Bad values in a file: one error naming /answer_sets/<field>.
  struct Bad {
    const char* field;
    void (*edit)(std::vector<io::ResultStep>&, io::ResultHeader&);
  };
  const Bad bad[] = {
      {"/answer_sets/p_value", [](auto& st, auto&) { st[1].answer_set->p_value[0] = 0.0; }},
      {"/answer_sets/p_value", [](auto& st, auto&) { st[1].answer_set->p_value[2] = std::nan(""); }},
      {"/answer_sets/log_weight_gap", [](auto& st, auto&) { st[2].answer_set->log_weight_gap[1] = -0.5; }},
      {"/answer_sets/in_set", [](auto& st, auto&) { st[1].answer_set->in_set[2] = 2; }},
      {"/answer_sets/in_set", [](auto& st, auto&) { st[0].answer_set->in_set[0] = 0; }},   // uninformative: all in
      {"/answer_sets/in_set", [](auto& st, auto&) { st[1].answer_set->in_set[1] = 0; }},   // 1 object, 2 classes
      {"/answer_sets/size", [](auto& st, auto&) { st[1].answer_set->size = 4; }},
      {"/answer_sets/calibrated_step", [](auto& st, auto&) { st[1].answer_set->calibrated_step = 0; }},
  };
  for (const Bad& b : bad) {
    CAPTURE(b.field);
    auto st = s;
    io::ResultHeader hh = h;
    b.edit(st, hh);
    const auto p = dir / "bad.h5";
    io::write_result(p, hh, st);   // the writer checks shapes; values are the reader's to refuse
    try {
      (void)io::read_result(p);
      FAIL("accepted");
    } catch (const Error& e) {
      CHECK(e.field() == b.field);
      CHECK(e.file() == p.string());
    }
  }
  io::ResultHeader bad_alpha = h;
  bad_alpha.answer_set_alpha = 1.0;
  CHECK_THROWS_AS(io::write_result(dir / "a.h5", bad_alpha, s), Error);
  CHECK_FALSE(std::filesystem::exists(dir / "a.h5"));
}
