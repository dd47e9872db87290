// Large-database machinery against oracles: the FeatureTable's masked per-object search
// against brute force, the object shortlist's screening against the true pose, the Database's
// memory budget (LRU eviction, pinned objects kept, reloads equal), and the recognizer with a
// shortlist (right object, fewer objects loaded, same result for 1 and 2 threads).
#include "engine/database/feature_table.hpp"
#include "engine/recognition/ransac.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/recognition/shortlist.hpp"
#include "recognition_fixture.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <map>
#include <set>

using namespace ts;

namespace {

/// Features only: objects of random features, some clustered (flat-like duplicates).
class FeatureSource final : public ObjectSource {
 public:
  std::vector<ObjectInfo> infos;
  std::vector<ObjectFeatures> feats;
  DatabaseSettings db_settings;
  std::size_t size() const override { return infos.size(); }
  const ObjectInfo& info(std::size_t i) const override { return infos.at(i); }
  const DatabaseSettings& settings() const override { return db_settings; }
  ObjectFeatures load_features(std::size_t i) const override { return feats.at(i); }
  PointCloud load_fine(std::size_t) const override { return {}; }
  DistanceField load_field(std::size_t) const override { return {}; }
};

Feature random_feature(Rng& rng, const Feature* around = nullptr, float spread = 1.0f) {
  Feature f{};
  for (int d = 0; d < kFeatureDim; ++d)
    f[d] = around ? (*around)[d] + spread * static_cast<float>(rng.uniform() - 0.5)
                  : static_cast<float>(100.0 * rng.uniform());
  return f;
}

std::shared_ptr<FeatureSource> feature_source() {
  auto src = std::make_shared<FeatureSource>();
  Rng rng(5, 0, 0, 0);
  const std::size_t counts[] = {300, 40, 129, 1, 700, 256, 90, 500};
  for (std::size_t o = 0; o < std::size(counts); ++o) {
    ObjectInfo info;
    info.name = 'o' + std::to_string(o);
    ObjectFeatures f;
    const Feature centre = random_feature(rng);
    for (std::size_t i = 0; i < counts[o]; ++i)  // odd objects: one tight cluster
      f.features.push_back(o % 2 ? random_feature(rng, &centre, 2.0f) : random_feature(rng));
    f.coarse.points.assign(counts[o], Vec3::Zero());
    src->infos.push_back(info);
    src->feats.push_back(std::move(f));
  }
  return src;
}

double feature_sq(const Feature& a, const Feature& b) {
  double s = 0.0;
  for (int i = 0; i < kFeatureDim; ++i) s += (double(a[i]) - double(b[i])) * (double(a[i]) - double(b[i]));
  return s;
}

/// Per-object pruning, smaller numbers (unit tests must be fast).
/// n queries near random database features (with `anywhere`, every fourth one anywhere).
FeatureRows random_queries(const FeatureSource& src, int n, std::uint64_t seed, bool anywhere) {
  Rng rng(seed, 0, 0, 0);
  FeatureRows queries;
  for (int i = 0; i < n; ++i) {
    const auto& fs = src.feats[rng.index(src.size())].features;
    const Feature near = fs.fpfh(rng.index(fs.size()));
    queries.push_back(anywhere && i % 4 == 0 ? random_feature(rng) : random_feature(rng, &near, 6.0f));
  }
  return queries;
}

RecognizerSettings shortlist_settings() {
  RecognizerSettings s = test::fast_settings();
  s.ransac.prune_per_object = 100;
  return s;
}

/// A skewed wedge (no symmetry) and its twin 5 mm taller, among other shapes.
std::shared_ptr<test::TestSource> lookalike_source() {
  auto src = std::make_shared<test::TestSource>();
  src->add("wedge", test::prism_mesh(3, 0.07, 0.05, 0.25), 1);
  src->add("wedge_tall", test::prism_mesh(3, 0.07, 0.055, 0.25), 2);
  src->add("nut", test::prism_mesh(5, 0.06, 0.04), 3);
  src->add("box", test::box_mesh(Vec3(0.12, 0.08, 0.05)), 4);
  src->add("hexbar", test::prism_mesh(6, 0.03, 0.14), 5);
  return src;
}

}  // namespace

TEST_CASE("FeatureTable: per-object search restricted to a mask equals brute force") {
  auto src = feature_source();
  Database db(src);
  const FeatureTable table(db);
  const FeatureRows queries = random_queries(*src, 40, 9, true);
  for (const std::vector<std::uint8_t>& mask :
       {std::vector<std::uint8_t>{}, std::vector<std::uint8_t>{1, 0, 1, 1, 0, 1, 1, 0}}) {
    const auto per = table.knn_per_object(queries, 7, mask);
    for (std::size_t q = 0; q < queries.size(); ++q) {
      std::map<std::uint32_t, std::vector<double>> by_object;
      for (const Neighbour& n : per[q]) by_object[table.ref(n.index).object].push_back(n.sq_distance);
      for (std::uint32_t o = 0; o < src->size(); ++o) {
        const bool in = mask.empty() || mask[o];
        CHECK(by_object.count(o) == (in ? 1u : 0u));
        if (!in) continue;
        std::vector<double> d;
        const FeatureRows& fo = src->feats[o].features;
        for (std::size_t i = 0; i < fo.size(); ++i) d.push_back(feature_sq(queries.fpfh(q), fo.fpfh(i)));
        std::sort(d.begin(), d.end());
        const auto& mine = by_object[o];
        REQUIRE(mine.size() == std::min<std::size_t>(7, d.size()));
        for (std::size_t j = 0; j < mine.size(); ++j) CHECK(mine[j] == doctest::Approx(d[j]).epsilon(1e-5).scale(0));
      }
    }
  }
}

TEST_CASE("Shortlist: screening ranks the true pose first; the state's objects are kept; off when small") {
  auto src = test::make_source();
  Database db(src);
  ShortlistSettings s;
  s.objects = 1;
  for (std::size_t obj : {0u, 1u, 4u}) {  // box, nut, wedge
    INFO("object " << db.info(obj).name);
    const Pose T = test::random_pose(70 + obj, Vec3(0.1, 0.2, -0.3));
    const PointCloud c = test::touch(src->fines[obj], T, 6, 3 + obj, 0.0, 0.0);
    const Scene scene = prepare_scene(c, {}, db.settings().fpfh, SceneSettings{}, 1, 1);
    // candidates: the truth, the truth moved, and every other object at the true pose
    std::vector<Candidate> cands;
    Candidate truth;
    truth.object = static_cast<std::uint32_t>(obj);
    truth.T_scene_object = scene.to_scene(T);
    cands.push_back(truth);
    Candidate moved = truth;
    moved.T_scene_object.translation() += Vec3(0.02, 0.02, 0.02);  // off every face by 2 cm
    cands.push_back(moved);
    for (std::uint32_t o = 0; o < db.size(); ++o)
      if (o != obj) {
        Candidate other = truth;
        other.object = o;
        cands.push_back(other);
      }
    const std::vector<double> score = screen_candidates(scene, db, cands, s);
    // the contacts lie on the surface: only the coarse sampling's curvature error remains
    CHECK(score[0] < 0.05);
    CHECK(score[1] > 0.5);
    for (std::size_t i = 2; i < cands.size(); ++i) CHECK(score[i] > score[0]);
    const Shortlist sl = shortlist_objects(scene, db, cands, {}, s);
    REQUIRE(sl.active);
    CHECK(sl.kept == 1);
    CHECK(sl.mask[obj] == 1);
    CHECK(sl.ranked.front() == obj);
    CHECK(sl.best[obj] == score[0]);
    CHECK(sl.ranked.size() == db.size());
    // an object held by the state goes on whatever its score
    const std::uint32_t last = sl.ranked.back();
    const Shortlist held = shortlist_objects(scene, db, cands, {last}, s);
    CHECK(held.mask[last] == 1);
    CHECK(held.kept == 2);
    // as many objects as have candidates: nothing left out
    ShortlistSettings all = s;
    all.objects = db.size();
    const Shortlist off = shortlist_objects(scene, db, cands, {}, all);
    CHECK_FALSE(off.active);
    CHECK(off.kept == db.size());
  }
  // no geometry was needed
  for (std::size_t o = 0; o < db.size(); ++o) CHECK_FALSE(db.geometry_loaded(o));
}

TEST_CASE("Database memory budget: least recently used geometry evicted, pinned kept, reloads equal") {
  auto src = test::make_source();
  Database db(src);
  std::vector<std::size_t> bytes;
  for (std::size_t o = 0; o < 3; ++o) bytes.push_back(memory_bytes(*db.geometry(o)));
  CHECK(db.geometry_bytes() == bytes[0] + bytes[1] + bytes[2]);
  CHECK(db.geometry_resident() == 3);
  for (std::size_t b : bytes) CHECK(b > src->fines[0].size() * sizeof(Vec3));  // at least the cloud
  // Budget for the two most recently used (1, 2): object 0 goes.
  db.set_memory_budget(bytes[1] + bytes[2]);
  CHECK_FALSE(db.geometry_loaded(0));
  CHECK(db.geometry_loaded(1));
  CHECK(db.geometry_loaded(2));
  CHECK(db.geometry_evictions() == 1);
  // Touch 1, load 3: the least recently used is now 2.
  (void)db.geometry(1);
  const GeometryRef pinned = db.geometry(1);
  const GeometryRef g3 = db.geometry(3);
  CHECK(db.geometry_loaded(3));
  CHECK_FALSE(db.geometry_loaded(2));
  CHECK(db.geometry_loaded(1));
  // Everything pinned survives a budget of one byte; the reference stays valid.
  const std::size_t loads = db.geometry_loads();
  db.set_memory_budget(1);
  CHECK(db.geometry_loaded(1));
  CHECK(db.geometry_loaded(3));
  CHECK(pinned->fine.points == src->fines[1].points);
  // A reload equals the original.
  const GeometryRef again = db.geometry(0);
  CHECK(db.geometry_loads() == loads + 1);
  CHECK(again->fine.points == src->fines[0].points);
  CHECK(std::abs(again->field.distance(src->fines[0].points[0])) < 0.002);
  CHECK(db.geometry_peak_bytes() >= db.geometry_bytes());
  // No budget: nothing is evicted any more.
  db.set_memory_budget(0);
  for (std::size_t o = 0; o < db.size(); ++o) (void)db.geometry(o);
  CHECK(db.geometry_resident() == db.size());
}

TEST_CASE("Recognizer with a shortlist: right object, fewer objects loaded, same for any thread count") {
  // 6 objects, 2 shortlisted per step (and the state's): the right object still wins.
  auto src = test::make_source();
  for (std::size_t obj : {1u, 4u}) {  // nut, wedge
    INFO("object " << src->infos[obj].name);
    const Pose T = test::random_pose(90 + obj, Vec3(-0.2, 0.1, 0.3));
    auto run = [&](int threads, std::size_t shortlist, std::size_t min_database = 0) {
      Database db(src);
      RecognizerSettings s = shortlist_settings();
      s.shortlist.objects = shortlist;
      s.shortlist.min_database = min_database;
      Recognizer rec(db, s);
      tbb::task_arena arena(threads);
      std::vector<StepResult> out;
      for (int k = 1; k <= 6; ++k) {
        const PointCloud c = test::touch(src->fines[obj], T, k, 21 + obj, 0.0005, 0.0002);
        out.push_back(arena.execute([&] { return rec.step(c, {}); }));
      }
      return std::pair(out, db.geometry_loads());
    };
    const auto [with, loads_with] = run(2, 2);
    const auto [with1, loads_with1] = run(1, 2);
    const auto [without, loads_without] = run(2, 0);
    const auto [small_db, loads_small] = run(2, 2, src->size());  // a database this small: off
    CHECK(loads_small == loads_without);
    for (std::size_t k = 0; k < small_db.size(); ++k) {
      CHECK(small_db[k].shortlist.empty());
      CHECK(small_db[k].best.object == without[k].best.object);
      CHECK(small_db[k].best.pose.matrix() == without[k].best.pose.matrix());
    }
    REQUIRE(with.back().valid);
    CHECK(with.back().best.object == obj);
    CHECK(without.back().best.object == obj);
    CHECK(loads_with < loads_without);
    std::set<std::uint32_t> held;  // the state's objects before each step
    for (const StepResult& r : with) {
      if (!r.shortlist.empty()) {  // active: the 2 best screened and the state's objects
        CHECK(r.shortlist.size() <= 2 + held.size());
        for (std::uint32_t o : held) CHECK(std::find(r.shortlist.begin(), r.shortlist.end(), o) != r.shortlist.end());
      }
      held.clear();
      for (const Hypothesis& h : r.hypotheses) {
        held.insert(h.object);
        CHECK((r.shortlist.empty() || std::find(r.shortlist.begin(), r.shortlist.end(), h.object) != r.shortlist.end() ||
               h.born < r.step));  // new hypotheses only of shortlisted objects
      }
    }
    CHECK(std::count_if(with.begin(), with.end(), [](const StepResult& r) { return !r.shortlist.empty(); }) > 0);
    for (std::size_t k = 0; k < with.size(); ++k) {
      CHECK(with[k].shortlist == with1[k].shortlist);
      REQUIRE(with[k].hypotheses.size() == with1[k].hypotheses.size());
      for (std::size_t i = 0; i < with[k].hypotheses.size(); ++i) {
        CHECK(with[k].hypotheses[i].object == with1[k].hypotheses[i].object);
        CHECK(with[k].hypotheses[i].pose.matrix() == with1[k].hypotheses[i].pose.matrix());
      }
    }
  }
}

TEST_CASE("Object draws: each triplet searches the objects its draws reach; all of them when few") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(31, Vec3(0.0, 0.1, 0.2));
  const PointCloud c = test::touch(src->fines[1], T, 6, 8, 0.0005, 0.0002);
  const Scene scene = prepare_scene(c, {}, db.settings().fpfh, SceneSettings{}, 1, 1);
  FeatureSearch search;
  search.table = FeatureTable::shared(db);
  const std::vector<std::uint8_t> allowed(db.size(), 1);
  RansacSettings s = shortlist_settings().ransac;
  auto run = [&](std::size_t draws, int threads) {
    RansacSettings x = s;
    x.object_draws = draws;
    RansacStats st;
    tbb::task_arena arena(threads);
    auto cands = arena.execute([&] { return ransac_candidates(scene, db, search, allowed, x, 3, 1, &st); });
    return std::pair(cands, st);
  };
  const auto [all, st_all] = run(0, 2);
  const auto [many, st_many] = run(db.size(), 2);  // no more objects than draws: all searched
  REQUIRE(st_all.triplets > 0);
  CHECK(st_all.objects_searched == st_all.triplets * db.size());
  CHECK(st_many.objects_searched == st_all.objects_searched);
  REQUIRE(all.size() == many.size());
  for (std::size_t i = 0; i < all.size(); ++i) {
    CHECK(all[i].object == many[i].object);
    CHECK(all[i].T_scene_object.matrix() == many[i].T_scene_object.matrix());
  }
  const auto [two, st_two] = run(2, 2);  // at most 2 objects per triplet
  const auto [two1, st_two1] = run(2, 1);
  CHECK(st_two.objects_searched == 2 * st_two.triplets);   // 2 distinct objects per triplet
  CHECK(st_two.objects_reached <= st_two.objects_searched);
  CHECK(two.size() < all.size());
  // per triplet (slot / R), candidates of at most 2 objects
  std::map<std::uint32_t, std::set<std::uint32_t>> per_triplet;
  for (const Candidate& cd : two) per_triplet[cd.slot / static_cast<std::uint32_t>(s.registrations)].insert(cd.object);
  for (const auto& [t, objects] : per_triplet) CHECK(objects.size() <= 2);
  REQUIRE(two.size() == two1.size());
  for (std::size_t i = 0; i < two.size(); ++i) {
    CHECK(two[i].slot == two1[i].slot);
    CHECK(two[i].T_scene_object.matrix() == two1[i].T_scene_object.matrix());
  }
}

TEST_CASE("Object draws rotate: every allowed object is searched once before any is searched twice") {
  auto src = test::make_source();
  Database db(src);
  const std::size_t A = db.size();
  REQUIRE(A >= 5);
  const Pose T = test::random_pose(32, Vec3(0.0, 0.1, 0.2));
  const PointCloud c = test::touch(src->fines[1], T, 6, 8, 0.0005, 0.0002);
  const Scene scene = prepare_scene(c, {}, db.settings().fpfh, SceneSettings{}, 1, 1);
  FeatureSearch search;
  search.table = FeatureTable::shared(db);
  std::vector<std::uint8_t> allowed(A, 1);
  allowed[2] = 0;   // never searched
  const std::size_t allowed_n = A - 1;
  RansacSettings x = shortlist_settings().ransac;
  x.triplets = 2;
  x.object_draws = 1;   // each step searches 2 objects
  std::vector<int> count(A, 0);
  std::size_t searched = 0;
  for (std::uint64_t step = 1; searched < allowed_n; ++step) {
    REQUIRE(step <= allowed_n);
    RansacStats st;
    (void)ransac_candidates(scene, db, search, allowed, x, 3, step, &st);
    REQUIRE(st.triplets == 2);
    CHECK(st.objects_searched == 2);
    for (std::size_t o = 0; o < A; ++o)
      if (o < st.searched.size() && st.searched[o]) ++count[o];
    searched += 2;
    CHECK(count[2] == 0);
    // once before twice: while fewer than allowed_n searches were made, no object twice
    if (searched <= allowed_n)
      for (std::size_t o = 0; o < A; ++o) CHECK(count[o] <= 1);
  }
  for (std::size_t o = 0; o < A; ++o)
    if (o != 2) CHECK(count[o] >= 1);
  // Another seed, another order (the first step's two objects differ for some seed).
  bool differs = false;
  RansacStats first;
  (void)ransac_candidates(scene, db, search, allowed, x, 3, 1, &first);
  for (std::uint64_t seed = 4; seed < 12 && !differs; ++seed) {
    RansacStats st;
    (void)ransac_candidates(scene, db, search, allowed, x, seed, 1, &st);
    differs = st.searched != first.searched;
  }
  CHECK(differs);
}

TEST_CASE("Approximate pruning by block: the exact search's neighbours when every block is read") {
  auto src = feature_source();
  Database db(src);
  const FeatureTable table(db);
  const FeatureRows queries = random_queries(*src, 20, 4, false);
  const auto exact = table.knn_per_object(queries, 9, std::vector<std::uint8_t>{});
  const auto wide = table.knn_per_object(queries, 9, std::vector<std::uint8_t>{}, 1000);  // every block
  const auto one = table.knn_per_object(queries, 9, std::vector<std::uint8_t>{}, 1);      // the nearest block
  std::size_t found = 0, total = 0;
  for (std::size_t q = 0; q < queries.size(); ++q) {
    REQUIRE(wide[q].size() == exact[q].size());
    for (std::size_t j = 0; j < exact[q].size(); ++j) CHECK(wide[q][j].index == exact[q][j].index);
    // one block of 128 rows per object: w rows of each object, all from that block
    for (const Neighbour& n : one[q]) {
      ++total;
      found += std::any_of(exact[q].begin(), exact[q].end(), [&](const Neighbour& e) { return e.index == n.index; });
    }
  }
  std::size_t total_exact = 0;
  for (const auto& v : exact) total_exact += v.size();
  CHECK(total == total_exact);  // w of every object still (each block holds >= 9 rows)
  CHECK(found > total / 2);  // the nearest block by mean holds most of the exact neighbours
}

TEST_CASE("Shortlist: each object's best score, cut short where a candidate cannot win, equals the full minimum") {
  auto src = test::make_source();
  Database db(src);
  ShortlistSettings s;
  const Pose T = test::random_pose(90, Vec3(0.1, -0.2, 0.3));
  const PointCloud c = test::touch(src->fines[1], T, 6, 9, 0.0005, 0.0002);
  const Scene scene = prepare_scene(c, {}, db.settings().fpfh, SceneSettings{}, 1, 1);
  // Candidates of every object, near and far from the truth, interleaved in a random order.
  Rng rng(91);
  std::vector<Candidate> cands;
  for (int n = 0; n < 400; ++n) {
    Candidate x;
    x.object = static_cast<std::uint32_t>(rng.index(db.size()));
    x.T_scene_object = scene.to_scene(T);
    x.T_scene_object.translation() += rng.uniform(0.0, 0.03) * rng.unit_vector();
    x.T_scene_object.linear() = x.T_scene_object.linear() * Eigen::AngleAxisd(rng.uniform(0.0, 0.3), rng.unit_vector()).toRotationMatrix();
    cands.push_back(x);
  }
  const std::vector<double> score = screen_candidates(scene, db, cands, s);
  std::vector<double> want(db.size(), 1.0);
  for (std::size_t i = 0; i < cands.size(); ++i) want[cands[i].object] = std::min(want[cands[i].object], score[i]);
  std::vector<double> one, two;
  tbb::task_arena(1).execute([&] { one = screen_objects(scene, db, cands, s); });
  tbb::task_arena(2).execute([&] { two = screen_objects(scene, db, cands, s); });
  CHECK(one == want);   // bit for bit
  CHECK(two == want);
  // Only the K best needed: they are exact and the same; the others report 1.
  std::vector<std::uint32_t> order;
  for (std::uint32_t o = 0; o < db.size(); ++o) order.push_back(o);
  std::sort(order.begin(), order.end(),
            [&](std::uint32_t x, std::uint32_t y) { return want[x] != want[y] ? want[x] < want[y] : x < y; });
  for (std::size_t K : {1u, 2u, 3u}) {
    std::vector<double> k1, k2;
    tbb::task_arena(1).execute([&] { k1 = screen_objects(scene, db, cands, s, K); });
    tbb::task_arena(2).execute([&] { k2 = screen_objects(scene, db, cands, s, K); });
    CHECK(k1 == k2);
    for (std::size_t r = 0; r < order.size(); ++r) CHECK(k1[order[r]] == (r < K ? want[order[r]] : 1.0));
  }
  CHECK(*std::min_element(want.begin(), want.end()) < 0.5);   // some candidate is good
}

TEST_CASE("Pose transfer: the leader's pose tried on its look-alikes, at that pose; off on small databases") {
  // The wedge, its taller twin and three other shapes (lookalike_source); the scene touches the
  // twin.
  const auto src = lookalike_source();
  const std::uint32_t truth = 1;
  const Pose T = test::random_pose(77, Vec3(0.1, -0.2, 0.3));
  auto run = [&](int threads, std::size_t transfer, std::size_t min_database) {
    Database db(src);
    RecognizerSettings s = shortlist_settings();
    s.n_p = 20;
    s.twins.transfer = transfer;
    s.twins.transfer_min_database = min_database;
    Recognizer rec(db, s);
    tbb::task_arena arena(threads);
    std::vector<StepResult> out;
    for (int k = 1; k <= 8; ++k) {
      const PointCloud c = test::touch(src->fines[truth], T, k, 31, 0.0003, 0.0001);
      out.push_back(arena.execute([&] { return rec.step(c, {}); }));
    }
    return out;
  };
  const auto with = run(2, 2, 0), with1 = run(1, 2, 0), off = run(2, 0, 0), gated = run(2, 2, src->size());
  std::size_t transferred = 0, near_truth = 0;
  for (const StepResult& r : with)
    for (const Hypothesis& h : r.hypotheses) {
      if (h.slot < kTransferSlot) continue;
      ++transferred;
      CHECK(h.slot - kTransferSlot == h.object);   // the slot names the object it was moved to
      // The wedges share their frame (bounding-box centred): once the leader stands on the
      // truth, its pose carried to the other wedge is the truth's within the height change.
      if (h.object <= 1 && r.step == with.back().step) {
        const double dt = (h.pose.translation() - T.translation()).norm();
        const double da = Eigen::AngleAxisd(h.pose.linear().transpose() * T.linear()).angle();
        near_truth += dt < 0.01 && da < 0.1;
      }
    }
  CHECK(transferred > 0);
  REQUIRE(with.back().valid);
  CHECK(with.back().best.object <= 1);   // one of the wedges (they are look-alikes by design)
  CHECK(near_truth > 0);
  for (const auto* other : {&off, &gated})
    for (const StepResult& r : *other)
      for (const Hypothesis& h : r.hypotheses) CHECK(h.slot < kTransferSlot);
  // Gated off by the database size: the same results as transfer off.
  for (std::size_t k = 0; k < off.size(); ++k) {
    REQUIRE(gated[k].hypotheses.size() == off[k].hypotheses.size());
    CHECK(gated[k].best.pose.matrix() == off[k].best.pose.matrix());
  }
  // Any thread count: the same state.
  for (std::size_t k = 0; k < with.size(); ++k) {
    REQUIRE(with[k].hypotheses.size() == with1[k].hypotheses.size());
    for (std::size_t i = 0; i < with[k].hypotheses.size(); ++i) {
      CHECK(with[k].hypotheses[i].object == with1[k].hypotheses[i].object);
      CHECK(with[k].hypotheses[i].slot == with1[k].hypotheses[i].slot);
      CHECK(with[k].hypotheses[i].pose.matrix() == with1[k].hypotheses[i].pose.matrix());
    }
  }
}

TEST_CASE("Pose transfer's pool: with the shape prior, only the prior's best objects are screened") {
  // The database of the test above; the shape prior on (any database size), each object
  // watched in turn. An object the prior ranks below the pool is never screened for the
  // transfer (no transfer rank) nor moved to; a pool as large as the database changes nothing.
  const auto src = lookalike_source();
  const std::uint32_t truth = 1;
  const Pose T = test::random_pose(77, Vec3(0.1, -0.2, 0.3));
  auto run = [&](std::size_t pool, std::optional<std::uint32_t> watch) {
    Database db(src);
    RecognizerSettings s = shortlist_settings();
    s.n_p = 20;
    s.twins.transfer = 2;
    s.twins.transfer_min_database = 0;
    s.twins.transfer_pool = pool;
    s.ransac.object_draws = 3;
    s.ransac.prior_draws = 2;
    s.prior_min_database = 0;
    Recognizer rec(db, s);
    rec.watch(watch);
    std::vector<StepResult> out;
    for (int k = 1; k <= 8; ++k) out.push_back(rec.step(test::touch(src->fines[truth], T, k, 31, 0.0003, 0.0001), {}));
    return out;
  };
  const auto all = run(0, std::nullopt), wide = run(src->size(), std::nullopt);
  for (std::size_t k = 0; k < all.size(); ++k) {   // the pool holds every object: no change
    REQUIRE(all[k].hypotheses.size() == wide[k].hypotheses.size());
    for (std::size_t i = 0; i < all[k].hypotheses.size(); ++i) {
      CHECK(all[k].hypotheses[i].object == wide[k].hypotheses[i].object);
      CHECK(all[k].hypotheses[i].pose.matrix() == wide[k].hypotheses[i].pose.matrix());
    }
  }
  const std::size_t pool = 2;
  std::size_t outside = 0, inside_ranked = 0;
  for (std::uint32_t o = 0; o < src->size(); ++o) {
    for (const StepResult& r : run(pool, o)) {
      REQUIRE(r.watched.has_value());
      const Funnel& f = *r.watched;
      if (f.prior_rank == 0) continue;   // no prior this step (too few contacts)
      // The step keeps the scores it ranked by (set answers rank classes without hypotheses by them).
      REQUIRE(r.prior_scores.size() == src->size());
      CHECK(rank_by_prior(r.prior_scores).at(f.prior_rank - 1) == o);
      if (f.prior_rank > pool) {
        ++outside;
        CHECK(f.transfer_rank == 0);
        CHECK_FALSE(f.transferred);
        for (const Hypothesis& h : r.hypotheses)   // none moved to it this step
          if (h.slot >= kTransferSlot && h.born == r.step) CHECK(h.object != o);
      } else if (f.transfer_rank > 0) {
        ++inside_ranked;
      }
    }
  }
  CHECK(outside > 0);         // the case arose
  CHECK(inside_ranked > 0);   // and objects within the pool were screened
}
