// The recognizer's step as a pipeline of stages (engine/recognition/pipeline/): each method's
// composition, what a step leaves out and why, and the errors of a bad composition or a
// throwing observer.
#include "engine/recognition/pipeline/compose.hpp"
#include "engine/recognition/recognizer.hpp"
#include "recognition_fixture.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <string>

using namespace ts;

namespace {

const StageRun& stage_of(const StepResult& r, std::string_view name) {
  const auto it = std::find_if(r.stages.begin(), r.stages.end(), [&](const StageRun& g) { return g.name == name; });
  REQUIRE(it != r.stages.end());
  return *it;
}

std::vector<std::string> stage_names(const StepResult& r) {
  std::vector<std::string> out;
  for (const StageRun& g : r.stages) out.push_back(g.name);
  return out;
}

}  // namespace

TEST_CASE("Pipeline: each method's stages in Algorithm 1's order, and a small database leaves out the large-database stages") {
  auto src = test::make_source();
  Database db(src);
  REQUIRE(db.size() < 48);
  RecognizerSettings s = test::fast_settings(Method::bricpsf);
  s.shortlist.objects = 16;            // the large-database extensions, as the improved preset has them
  s.shortlist.min_database = 48;
  s.twins.transfer = 2;
  s.twins.transfer_min_database = 48;
  s.ransac.prior_draws = 60;
  s.ransac.object_draws = 100;
  s.prior_min_database = 48;
  s.sparse.mode = kSparseNever;
  Recognizer rec(db, s);
  const Pose T = test::random_pose(7, Vec3(0.1, 0.0, 0.0));
  const StepResult r1 = rec.step(test::touch(src->fines[4], T, 1, 5), {});
  const StepResult r2 = rec.step(test::touch(src->fines[4], T, 2, 5), {});
  const std::vector<std::string> bricpsf = {"support", "scene",     "shape_prior",   "survivors",         "early_stop",
                                            "ransac",    "sparse",        "shortlist",         "sequential_filter",
                                            "pose_transfer", "posteriors", "answer_rule",      "state",
                                            "observability", "attribution"};
  CHECK(stage_names(r1) == bricpsf);
  CHECK(stage_names(r2) == bricpsf);
  const std::string small = "database of " + std::to_string(db.size()) + " objects";
  for (const StepResult* r : {&r1, &r2}) {
    REQUIRE(r->valid);
    CHECK_FALSE(stage_of(*r, "shape_prior").ran);
    CHECK(stage_of(*r, "shape_prior").reason.starts_with(small));
    CHECK(r->prior_scores.empty());   // set answers then score classes without hypotheses +inf
    CHECK_FALSE(stage_of(*r, "shortlist").ran);
    CHECK(stage_of(*r, "shortlist").reason == small + " (the shortlist acts above 48)");
    CHECK_FALSE(stage_of(*r, "attribution").ran);   // no support looked for, no background term
    CHECK(stage_of(*r, "attribution").reason == "support.mode off, evaluate.outlier_m 0");
    CHECK_FALSE(stage_of(*r, "pose_transfer").ran);
    CHECK(stage_of(*r, "sparse").reason == "sparse.mode = never");
    CHECK(stage_of(*r, "early_stop").reason == "early_stop off");
    CHECK(stage_of(*r, "support").reason == "support.mode off");
    CHECK_FALSE(r->sparse_active);
    CHECK(r->shortlist.empty());
    for (const char* always : {"scene", "ransac", "sequential_filter", "posteriors", "answer_rule", "state"}) {
      CHECK(stage_of(*r, always).ran);
      CHECK(stage_of(*r, always).reason.empty());
    }
    for (const StageRun& g : r->stages) CHECK((g.ran ? g.seconds >= 0.0 : g.seconds == 0.0));
  }
  // The survivors: none before the first step, the first step's state in the second.
  CHECK_FALSE(stage_of(r1, "survivors").ran);
  CHECK(stage_of(r1, "survivors").reason == "no hypotheses from an earlier step");
  CHECK(stage_of(r2, "survivors").ran);
  std::size_t old = 0;
  for (const Hypothesis& h : r2.hypotheses) old += h.born == 1 ? 1 : 0;
  CHECK(old > 0);   // the survivors' hypotheses are in the new state

  // The other methods' selections.
  for (Method m : {Method::batch_ransac, Method::ransac_icp, Method::ransac_icp_fs}) {
    Recognizer other(db, test::fast_settings(m));
    const StepResult r = other.step(test::touch(src->fines[4], T, 1, 5), {});
    const std::vector<std::string> names = stage_names(r);
    const std::string selection = m == Method::batch_ransac ? "select" : "icp_each";
    CHECK(std::find(names.begin(), names.end(), selection) != names.end());
    CHECK(std::find(names.begin(), names.end(), "survivors") == names.end());
    CHECK(std::find(names.begin(), names.end(), "sequential_filter") == names.end());
    CHECK(std::find(names.begin(), names.end(), "early_stop") == names.end());
    CHECK(names.size() == bricpsf.size() - 2);
  }
}

TEST_CASE("Pipeline: early stop leaves out the sources while the leading survivor alone explains every contact") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(7, Vec3(0.1, 0.0, 0.0));
  RecognizerSettings s = test::fast_settings(Method::bricpsf);
  s.sparse.mode = kSparseAlways;
  s.early_stop = true;
  Recognizer rec(db, s);
  const StepResult r1 = rec.step(test::touch(src->fines[4], T, 4, 5), {});
  REQUIRE(r1.valid);
  REQUIRE(r1.best.object == 4);   // the premise: the first step found the object
  CHECK(stage_of(r1, "early_stop").reason == "no hypotheses from an earlier step");
  CHECK(stage_of(r1, "ransac").ran);

  // More contacts on the same object: the evolved leader explains them all, no other object does.
  const PointCloud more = test::touch(src->fines[4], T, 6, 5);
  const StepResult r2 = rec.step(more, {});
  REQUIRE(r2.valid);
  CHECK(stage_of(r2, "early_stop").ran);
  for (const char* left_out : {"ransac", "sparse", "shortlist"}) {
    CAPTURE(left_out);
    CHECK_FALSE(stage_of(r2, left_out).ran);
    CHECK(stage_of(r2, left_out).reason.starts_with("early stop: the leading survivor explains every contact"));
  }
  CHECK(r2.candidates == 0);
  CHECK(r2.sparse_candidates == 0);
  CHECK(stage_of(r2, "sequential_filter").ran);
  CHECK(r2.best.object == 4);
  CHECK(r2.hypotheses.size() == r1.hypotheses.size());   // the survivors, all kept
  for (const Hypothesis& h : r2.hypotheses) CHECK(h.born == 1);

  // A contact 3 cm beyond the object's bounding box: the leader no longer explains the step, the
  // sources run.
  Eigen::AlignedBox3d box;
  for (const Vec3& p : src->fines[4].points) box.extend(p);
  PointCloud off = more;
  off.points.push_back(T * Vec3(box.max().x() + 0.03, box.center().y(), box.center().z()));
  if (off.has_normals()) off.normals.push_back(Vec3::UnitZ());
  const StepResult r3 = rec.step(off, {});
  CHECK(stage_of(r3, "early_stop").ran);
  CHECK(stage_of(r3, "ransac").ran);
  CHECK(stage_of(r3, "ransac").reason.empty());
}

TEST_CASE("Pipeline: the sparse source runs exactly when its stage says so, the shortlist when the database is large enough") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(9, Vec3(0.0, 0.1, 0.0));
  RecognizerSettings s = test::fast_settings(Method::bricpsf);
  s.sparse.mode = kSparseAlways;
  s.shortlist.objects = 2;             // keep 2 objects' candidates ...
  s.shortlist.min_database = 0;        // ... on any database
  Recognizer rec(db, s);
  const StepResult r = rec.step(test::touch(src->fines[1], T, 1, 3), {});
  REQUIRE(r.contacts >= 3);
  CHECK(stage_of(r, "sparse").ran);
  CHECK(r.sparse_active);
  CHECK(stage_of(r, "shortlist").ran);
  CHECK(r.shortlist.size() <= 2);      // no earlier state holds other objects
  s.sparse.mode = kSparseAuto;         // pad-like patches: no isolated contacts
  Recognizer automatic(db, s);
  const StepResult a = automatic.step(test::touch(src->fines[1], T, 1, 3), {});
  CHECK_FALSE(stage_of(a, "sparse").ran);
  CHECK(stage_of(a, "sparse").reason == "too few isolated contacts (sparse.mode = auto)");
  CHECK_FALSE(a.sparse_active);
}

TEST_CASE("Pipeline: no contacts leaves every later stage out and keeps the state") {
  auto src = test::make_source();
  Database db(src);
  Recognizer rec(db, test::fast_settings());
  const Pose T = test::random_pose(3, Vec3::Zero());
  const StepResult first = rec.step(test::touch(src->fines[2], T, 1, 1), {});
  REQUIRE(first.valid);
  const StepResult empty = rec.step(PointCloud{}, {});
  CHECK(empty.step == 2);
  CHECK(rec.steps_done() == 2);
  CHECK_FALSE(empty.valid);
  REQUIRE(empty.stages.size() == first.stages.size());
  CHECK(empty.stages[0].reason == "support.mode off");
  CHECK(empty.stages[1].ran);          // the scene found nothing to match
  for (std::size_t k = 2; k < empty.stages.size(); ++k) {
    CHECK_FALSE(empty.stages[k].ran);
    CHECK(empty.stages[k].reason == "no contacts");
  }
  CHECK(rec.hypotheses().size() == first.hypotheses.size());
}

TEST_CASE("Pipeline: an unknown stage and a throwing observer are errors naming the stage") {
  try {
    (void)pipeline::compose({"scene", "ransac", "magic"});
    FAIL("an unknown stage was accepted");
  } catch (const Error& e) {
    CHECK(e.field() == "pipeline.stages");
    CHECK(std::string(e.what()).find("unknown stage 'magic'") != std::string::npos);
    CHECK(std::string(e.what()).find("sequential_filter") != std::string::npos);   // the known ones
  }
  for (std::string_view name : pipeline::known_stages())
    CHECK(pipeline::compose({name}).front()->name() == name);
  CHECK(pipeline_stage_names().size() == pipeline::known_stages().size());

  struct Throws final : pipeline::StepObserver {
    void after(std::string_view stage, bool, pipeline::StepContext&) override {
      if (stage == "ransac") throw std::runtime_error("observer broke");
    }
  };
  auto src = test::make_source();
  Database db(src);
  const RecognizerSettings s = test::fast_settings();
  FeatureSearch search;
  search.table = FeatureTable::shared(db, {});
  std::shared_ptr<SparseTables> tables;
  const std::vector<Hypothesis> previous;
  const PointCloud contacts = test::touch(src->fines[1], test::random_pose(2, Vec3::Zero()), 1, 2);
  const std::vector<Vec3> free;
  const GraspGroups grasps;
  StepResult res;
  res.posteriors.assign(db.size(), 0.0);
  pipeline::StepContext c{.db = db, .s = s, .search = search, .prior = nullptr, .sparse_tables = tables,
                          .previous = previous, .contacts_world = contacts, .free_world = free,
                          .grasps = grasps, .step = 1, .res = res};
  Throws observer;
  std::vector<pipeline::StepObserver*> observers{&observer};
  const pipeline::Pipeline stages = pipeline::compose(pipeline::method_stages(Method::bricpsf));
  try {
    pipeline::run_pipeline(stages, c, observers);
    FAIL("the observer's exception was lost");
  } catch (const Error& e) {
    CHECK(e.field() == "stage.ransac");
    CHECK(std::string(e.what()).find("stage 'ransac': an observer after it failed: observer broke") != std::string::npos);
  }
  CHECK(res.hypotheses.empty());       // the state stage never ran
  CHECK(res.stages.size() == 5);       // support, scene, shape_prior, survivors, early_stop recorded
                                       // (support off; the last two left out: no earlier step);
                                       // ransac's not complete
}

namespace {

/// `n` points of the object's fine cloud at least `spacing` apart (isolated: no normals can be
/// estimated from them), placed at T, without normals.
PointCloud isolated_points(const PointCloud& fine, const Pose& T, std::size_t n, double spacing, std::uint64_t seed) {
  Rng rng(seed);
  std::vector<Vec3> kept;
  for (int tries = 0; tries < 20000 && kept.size() < n; ++tries) {
    const Vec3& p = fine.points[rng.index(fine.size())];
    bool far = true;
    for (const Vec3& q : kept) far = far && (p - q).norm() >= spacing;
    if (far) kept.push_back(p);
  }
  PointCloud out;
  for (const Vec3& p : kept) out.points.push_back(T * p);
  return out;
}

}  // namespace

TEST_CASE("Pipeline: attribution labels the answer's contacts, one 5 mm off it too, one 5 cm off it unexplained") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(13, Vec3(0.3, -0.2, 0.1));
  PointCloud pts = test::touch(src->fines[0], T, 5, 3);   // the box, five patches
  const std::size_t n = pts.size();
  // Beside the top face's centre (the box is centred on its frame's origin): 5 mm and 5 cm out.
  const double top = 0.5 * db.info(0).extent.z();
  for (double off : {0.005, 0.05}) {
    pts.points.push_back(T * Vec3(0.0, 0.0, top + off));
    if (pts.has_normals() || !pts.normals.empty()) pts.normals.push_back(T.linear() * Vec3::UnitZ());
  }
  RecognizerSettings s = test::fast_settings(Method::bricpsf);
  Recognizer plain(db, s);
  const StepResult r0 = plain.step(pts, {});
  CHECK_FALSE(stage_of(r0, "attribution").ran);
  CHECK(r0.attribution.empty());
  s.evaluate.outlier_m = 0.015;
  Recognizer rec(db, s);
  const StepResult r = rec.step(pts, {});
  REQUIRE(r.valid);
  REQUIRE(r.best.object == 0);
  CHECK(stage_of(r, "attribution").ran);
  REQUIRE(r.attribution.size() == n + 2);
  std::size_t object = 0;
  for (std::size_t i = 0; i < n; ++i) object += r.attribution[i] == ContactLabel::object;
  CHECK(20 * object >= 19 * n);   // 95 % of the box's own contacts: the right answer, within a few mm
  CHECK(r.attribution[n] == ContactLabel::object);
  CHECK(r.attribution[n + 1] == ContactLabel::unexplained);
  // A tighter attribution: the 5 mm contact is no longer the object's.
  s.support.attribution = 0.003;
  Recognizer tight(db, s);
  const StepResult t = tight.step(pts, {});
  REQUIRE(t.attribution.size() == n + 2);
  CHECK(t.attribution[n] == ContactLabel::unexplained);
}

TEST_CASE("Recognizer: with the background term on, ICP's pair gate is twice its distance unless set") {
  // (What the gate does to a fit: test_icp.cpp; what it does to recognition among neighbours:
  // study15_cluttered, paired against the commit before.)
  auto src = test::make_source();
  Database db(src);
  RecognizerSettings s = test::fast_settings(Method::bricpsf);
  CHECK(Recognizer(db, s).settings().icp.max_correspondence == 0.0);   // no term, no gate
  s.evaluate.outlier_m = 0.015;
  CHECK(Recognizer(db, s).settings().icp.max_correspondence == 0.03);
  s.icp.max_correspondence = 0.1;   // an explicit gate is kept
  CHECK(Recognizer(db, s).settings().icp.max_correspondence == 0.1);
  // Scaled settings (objects of another size): the gate follows the scaled distance.
  s.icp.max_correspondence = 0.0;
  CHECK(Recognizer(db, s.scaled(2.0)).settings().icp.max_correspondence == doctest::Approx(0.06).scale(0).epsilon(1e-12));
}

TEST_CASE("Scaled settings scale the support's and the background term's lengths (objects of another size)") {
  RecognizerSettings s;
  s.evaluate.outlier_m = 0.015;
  s.support.free_margin = 0.01;
  const RecognizerSettings t = s.scaled(10.0);
  CHECK(t.evaluate.outlier_m == doctest::Approx(0.15).scale(0).epsilon(1e-12));
  CHECK(t.support.tolerance == doctest::Approx(10.0 * s.support.tolerance).scale(0).epsilon(1e-12));
  CHECK(t.support.free_margin == doctest::Approx(0.1).scale(0).epsilon(1e-12));
  CHECK(t.support.attribution == doctest::Approx(10.0 * s.support.attribution).scale(0).epsilon(1e-12));
  CHECK(t.support.sink == doctest::Approx(10.0 * s.support.sink).scale(0).epsilon(1e-12));
  CHECK(t.support.sink_cost == s.support.sink_cost);   // nats, not a length
  RecognizerSettings automatic;   // free_margin < 0: automatic, stays so
  CHECK(automatic.scaled(10.0).support.free_margin == automatic.support.free_margin);
}

TEST_CASE("Pipeline: contacts without normals have their free pose DOF judged on the answer's surface") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(11, Vec3(0.2, -0.1, 0.05));
  const double spacing = 1.5 * db.settings().fpfh.normal_radius + 0.01;
  // Each object alone (a known-object localization), the feature-free source on.
  struct Case {
    std::size_t object;
    int free_dof;   // on its surface, with points all over it
  };
  // The surfaces resident (point-to-plane ICP) or not (the default field ICP: the stage reads
  // the answer's surface itself).
  for (const bool resident : {true, false})
  for (const Case& k : {Case{0, 0}, Case{2, 3}, Case{1, 0}}) {   // box, ball (its 3 turns), nut
    CAPTURE(src->infos[k.object].name);
    CAPTURE(resident);
    RecognizerSettings s = test::fast_settings(Method::bricpsf);
    s.sparse.mode = kSparseAlways;
    s.objects.assign(db.size(), 0);
    s.objects[k.object] = 1;
    Recognizer rec(db, s);
    db.set_surface(resident);
    const PointCloud pts = isolated_points(src->fines[k.object], T, 30, spacing, 5 + k.object);
    REQUIRE(pts.size() == 30);
    const StepResult r = rec.step(pts, {});
    REQUIRE(r.valid);
    CHECK(stage_of(r, "scene").ran);
    CHECK(stage_of(r, "observability").ran);   // no normals: the scene could not judge
    CHECK(r.observability_from_model);
    CHECK(r.unobservable_dof == k.free_dof);
    CHECK(r.pose_ambiguous == (k.free_dof > 0));
  }
  // Tactile patches carry normals: the contacts judge, the stage is left out and says why.
  RecognizerSettings s = test::fast_settings(Method::bricpsf);
  Recognizer rec(db, s);
  const StepResult r = rec.step(test::touch(src->fines[0], T, 4, 3), {});
  REQUIRE(r.valid);
  CHECK_FALSE(stage_of(r, "observability").ran);
  CHECK(stage_of(r, "observability").reason == "the contacts' normals judge it");
  CHECK_FALSE(r.observability_from_model);
  // Fewer than 3 distinct contacts: the step stops before matching and says why; a third point
  // lets it go on.
  PointCloud two;
  two.points = {Vec3(0.3, 0.0, 0.0), Vec3(0.32, 0.0, 0.0), Vec3(0.3, 0.0, 0.0)};
  Recognizer few(db, s);
  const StepResult rf = few.step(two, {});
  CHECK_FALSE(rf.valid);
  CHECK(rf.stopped == "fewer than 3 distinct contacts (2)");
  CHECK(stage_of(rf, "scene").ran);
  CHECK(stage_of(rf, "ransac").reason == rf.stopped);
  two.points.push_back(Vec3(0.3, 0.02, 0.0));
  const StepResult r3 = few.step(two, {});
  CHECK(r3.stopped.empty());
  CHECK(stage_of(r3, "ransac").reason != "fewer than 3 distinct contacts (3)");
  // No contacts: nothing to judge on.
  Recognizer empty(db, s);
  const StepResult none = empty.step(PointCloud{}, {});
  CHECK_FALSE(stage_of(none, "observability").ran);
  CHECK(stage_of(none, "observability").reason == "no contacts");
  CHECK(none.stopped == "no contacts");
}
