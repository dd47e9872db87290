#include "engine/database/symmetry_cache.hpp"
#include "engine/geometry/kabsch.hpp"
#include "engine/geometry/pose_error.hpp"
#include "engine/geometry/symmetry.hpp"
#include "engine/recognition/ransac.hpp"
#include "recognition_fixture.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

using namespace ts;

namespace {

RansacSettings quick() {
  RansacSettings s;
  s.triplets = 10;
  s.registrations = 100;
  s.prune_w = 1500;
  s.normal_tolerance_deg = 15.0;
  return s;
}

struct Fixture {
  std::shared_ptr<test::TestSource> src = test::make_source();
  Database db{src};
  FeatureSearch index{FeatureTable::shared(db), nullptr};
  Scene scene(std::size_t obj, const Pose& T, int patches, std::uint64_t seed = 3) {
    return prepare_scene(test::touch(src->fines[obj], T, patches, seed), {}, db.settings().fpfh, {}, 1, 1);
  }
};

}  // namespace

TEST_CASE("Batch RANSAC: some registration of the true object lands near the truth") {
  Fixture f;
  for (std::size_t obj : {1u, 4u}) {
    const Pose T = test::random_pose(50 + obj, Vec3(0.5, 0.5, 0.5));
    const Scene sc = f.scene(obj, T, 8);
    RansacStats st;
    const auto cands = ransac_candidates(sc, f.db, f.index, objects_spanning(sc, f.db, 0.02), quick(), 1, 1, &st);
    CHECK(st.triplets == 10);
    CHECK(cands.size() > 100);
    double best_pos = 1e9, best_ori = 1e9;
    SymmetryCache symmetries;
    const SymmetryGroup& sym = symmetries.get(f.db, obj);
    for (const Candidate& c : cands) {
      if (c.object != obj) continue;
      const PoseError e = pose_error(sc.to_world(c.T_scene_object), T, &sym);
      if (e.symmetric_position_m < 0.01) best_ori = std::min(best_ori, e.symmetric_orientation_deg);
      best_pos = std::min(best_pos, e.symmetric_position_m);
    }
    // Triplet registrations are coarse (5 mm database voxels); they must land in ICP's basin.
    INFO("object " << f.db.info(obj).name << " best position " << best_pos << " orientation " << best_ori);
    CHECK(best_pos < 0.01);
    CHECK(best_ori < 15.0);
  }
}

TEST_CASE("Batch RANSAC: identical candidates for 1 and 2 threads and for the same seed") {
  Fixture f;
  const Scene sc = f.scene(1, test::random_pose(7, Vec3(0, 0, 0)), 6);
  const auto allowed = objects_spanning(sc, f.db, 0.02);
  std::vector<Candidate> a, b, c;
  tbb::task_arena one(1), two(2);
  one.execute([&] { a = ransac_candidates(sc, f.db, f.index, allowed, quick(), 9, 4); });
  two.execute([&] { b = ransac_candidates(sc, f.db, f.index, allowed, quick(), 9, 4); });
  two.execute([&] { c = ransac_candidates(sc, f.db, f.index, allowed, quick(), 10, 4); });
  REQUIRE(a.size() == b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].object == b[i].object);
    CHECK(a[i].slot == b[i].slot);
    CHECK(a[i].T_scene_object.matrix() == b[i].T_scene_object.matrix());
  }
  bool differs = a.size() != c.size();
  for (std::size_t i = 0; !differs && i < a.size(); ++i)
    differs = a[i].T_scene_object.matrix() != c[i].T_scene_object.matrix();
  CHECK(differs);  // another seed draws other triplets
}

TEST_CASE("Batch RANSAC: objects too small to span the contacts are excluded before matching") {
  Fixture f;
  const Pose T = test::random_pose(8, Vec3(0, 0, 0));
  const Scene sc = f.scene(0, T, 14);  // the 12 x 8 x 5 cm box, touched all over
  const auto allowed = objects_spanning(sc, f.db, 0.0);
  for (std::size_t o = 0; o < f.db.size(); ++o)
    CHECK(bool(allowed[o]) == (f.db.info(o).extent.norm() >= sc.diameter));
  CHECK(allowed[0]);
  std::size_t excluded = 0;
  for (auto a : allowed) excluded += a ? 0 : 1;
  CHECK(excluded > 0);
  const auto cands = ransac_candidates(sc, f.db, f.index, allowed, quick(), 1, 1);
  for (const Candidate& c : cands) CHECK(allowed[c.object]);
}

TEST_CASE("Batch RANSAC: degenerate clouds give no candidates and no NaN") {
  Fixture f;
  SUBCASE("collinear contacts") {
    PointCloud line;
    for (int i = 0; i < 60; ++i) line.points.emplace_back(0.001 * i, 0.0, 0.0);
    const Scene sc = prepare_scene(line, {}, f.db.settings().fpfh, {}, 1, 1);
    CHECK(ransac_candidates(sc, f.db, f.index, objects_spanning(sc, f.db, 0.02), quick(), 1, 1).empty());
  }
  SUBCASE("identical contacts") {
    PointCloud same;
    same.points.assign(40, Vec3(1, 2, 3));
    const Scene sc = prepare_scene(same, {}, f.db.settings().fpfh, {}, 1, 1);
    CHECK(ransac_candidates(sc, f.db, f.index, objects_spanning(sc, f.db, 0.02), quick(), 1, 1).empty());
  }
  SUBCASE("empty") {
    const Scene sc = prepare_scene({}, {}, f.db.settings().fpfh, {}, 1, 1);
    CHECK(ransac_candidates(sc, f.db, f.index, objects_spanning(sc, f.db, 0.02), quick(), 1, 1).empty());
  }
}

TEST_CASE("Batch RANSAC: every candidate is a proper rigid transform") {
  Fixture f;
  const Scene sc = f.scene(3, test::random_pose(9, Vec3(1, 1, 1)), 5);
  for (const Candidate& c : ransac_candidates(sc, f.db, f.index, objects_spanning(sc, f.db, 0.02), quick(), 1, 1)) {
    const Mat3 R = c.T_scene_object.linear();
    CHECK(R.allFinite());
    CHECK(R.determinant() == doctest::Approx(1.0).epsilon(1e-9));
    CHECK((R * R.transpose() - Mat3::Identity()).norm() < 1e-9);
  }
}

TEST_CASE("FeatureTable: the W nearest equal a brute-force oracle, for any thread count") {
  // Random FPFH-like features in 3 objects; queries perturbed copies of some rows.
  auto src = std::make_shared<test::TestSource>();
  Rng rng(4);
  for (int o = 0; o < 3; ++o) {
    ObjectInfo info;
    info.name = "o";
    info.name += std::to_string(o);  // (GCC 12 warns falsely on "o" + to_string: -Wrestrict)
    ObjectFeatures f;
    for (int i = 0; i < 3000 + 500 * o; ++i) {
      Feature x;
      for (auto& v : x) v = static_cast<float>(rng.uniform(0, 10));
      if (i % 7 == 0 && i > 0) x = f.features.fpfh(static_cast<std::size_t>(i - 1));  // exact ties
      f.features.push_back(x);
      f.coarse.points.push_back(Vec3::Zero());
    }
    src->infos.push_back(info);
    src->feats.push_back(f);
    src->fines.emplace_back();
  }
  Database db(src);
  FeatureRows queries;
  std::size_t total = 0;
  for (std::uint32_t o = 0; o < 3; ++o) total += db.load_features(o).features.size();
  for (int q = 0; q < 20; ++q) {
    Feature x = db.load_features(static_cast<std::size_t>(q % 3)).features.fpfh(static_cast<std::size_t>(q * 37));
    for (auto& v : x) v += static_cast<float>(rng.uniform(-0.5, 0.5));
    queries.push_back(x);
  }
  const FeatureTable table(db);
  REQUIRE(table.features() == total);
  REQUIRE(table.size() >= total);
  // Every (object, point) appears once among the table's rows (the rest is padding).
  std::vector<std::pair<std::uint32_t, std::uint32_t>> rows;  // table row -> (object, point)
  std::vector<std::uint32_t> real;                            // rows that hold a feature
  for (std::size_t r = 0; r < table.size(); ++r) {
    rows.emplace_back(table.ref(r).object, table.ref(r).point);
    if (table.ref(r).object != 0xffffffffu) real.push_back(static_cast<std::uint32_t>(r));
  }
  REQUIRE(real.size() == total);
  {
    std::vector<std::pair<std::uint32_t, std::uint32_t>> sorted;
    for (std::uint32_t r : real) sorted.push_back(rows[r]);
    std::sort(sorted.begin(), sorted.end());
    CHECK(std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end());
  }
  // The oracle: per query, every real row by (squared distance, row), computed once (each
  // object's features loaded once: the sanitizer builds run this test too).
  std::vector<FeatureRows> features_of;
  for (std::uint32_t o = 0; o < 3; ++o) features_of.push_back(db.load_features(o).features);
  std::vector<std::vector<std::pair<float, std::uint32_t>>> sorted_rows(queries.size());
  for (std::size_t q = 0; q < queries.size(); ++q) {
    for (std::uint32_t r : real) {
      const float* f = features_of[rows[r].first].row(rows[r].second);
      float d = 0.0f;
      for (int k = 0; k < kFeatureDim; ++k) {
        const float e = f[k] - queries.row(q)[k];
        d += e * e;
      }
      sorted_rows[q].emplace_back(d, r);
    }
    std::sort(sorted_rows[q].begin(), sorted_rows[q].end());
  }
  // The oracle of knn_per_object: each object's w nearest rows, objects ascending (an empty
  // mask: every object).
  auto per_object_oracle = [&](std::size_t q, std::size_t w, const std::vector<std::uint8_t>& mask) {
    std::vector<Neighbour> expect;
    for (std::uint32_t o = 0; o < 3; ++o) {
      if (!mask.empty() && !mask[o]) continue;
      std::size_t taken = 0;
      for (auto it = sorted_rows[q].begin(); it != sorted_rows[q].end() && taken < w; ++it)
        if (rows[it->second].first == o) {
          expect.push_back({it->second, static_cast<double>(it->first)});
          ++taken;
        }
    }
    return expect;
  };
  // knn_per_object with 1 thread (one) and 2 threads (two) against that oracle, query by query.
  auto check_per_object = [&](const std::vector<std::vector<Neighbour>>& one,
                              const std::vector<std::vector<Neighbour>>& two, std::size_t w,
                              const std::vector<std::vector<std::uint8_t>>& masks) {
    for (std::size_t q = 0; q < queries.size(); ++q) {
      const std::vector<Neighbour> expect = per_object_oracle(q, w, masks.empty() ? std::vector<std::uint8_t>{} : masks[q]);
      CAPTURE(q);
      REQUIRE(one[q].size() == expect.size());
      REQUIRE(two[q].size() == expect.size());
      for (std::size_t i = 0; i < expect.size(); ++i) {
        CHECK(one[q][i].index == expect[i].index);
        CHECK(one[q][i].sq_distance == expect[i].sq_distance);
        CHECK(two[q][i].index == one[q][i].index);
      }
    }
  };
  for (std::size_t w : {1u, 50u, 700u, 20000u}) {
    std::vector<std::vector<Neighbour>> one, two;
    tbb::task_arena a1(1), a2(2);
    a1.execute([&] { one = table.knn(queries, w); });
    a2.execute([&] { two = table.knn(queries, w); });
    for (std::size_t q = 0; q < queries.size(); ++q) {
      const auto& oracle = sorted_rows[q];
      const std::size_t k = std::min(w, real.size());
      REQUIRE(one[q].size() == k);
      for (std::size_t i = 0; i < k; ++i) {
        CHECK(one[q][i].index == oracle[i].second);
        CHECK(one[q][i].sq_distance == static_cast<double>(oracle[i].first));
        CHECK(two[q][i].index == one[q][i].index);
      }
      CHECK(table.ref(one[q][0].index).object == rows[one[q][0].index].first);
    }
  }
  // Per object: the w nearest of each object, objects ascending, the same for any thread count.
  for (std::size_t w : {1u, 64u, 3200u}) {
    std::vector<std::vector<Neighbour>> one, two;
    tbb::task_arena a1(1), a2(2);
    a1.execute([&] { one = table.knn_per_object(queries, w); });
    a2.execute([&] { two = table.knn_per_object(queries, w); });
    check_per_object(one, two, w, {});
  }
  // A mask per query (searched object-major): each query gets exactly its own objects' w
  // nearest, objects ascending; an empty mask means every object.
  {
    std::vector<std::vector<std::uint8_t>> masks(queries.size());
    for (std::size_t q = 0; q < queries.size(); ++q)
      if (q % 4 != 3) masks[q] = {std::uint8_t(q % 2), std::uint8_t(q % 3 == 0), 1};
    const std::size_t w = 90;
    std::vector<std::vector<Neighbour>> one, two;
    tbb::task_arena a1(1), a2(2);
    a1.execute([&] { one = table.knn_per_object(queries, w, masks); });
    a2.execute([&] { two = table.knn_per_object(queries, w, masks); });
    check_per_object(one, two, w, masks);
  }
  CHECK(FeatureTable::shared(db).get() == FeatureTable::shared(db).get());
}
