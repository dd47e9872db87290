// KdTree3 and FeatureIndex against brute force: random clouds, duplicates and exact ties
// (integer grids, where every distance is exact), parallel queries, and the approximate
// forest's reproducibility.
#include "engine/geometry/search.hpp"
#include "engine/recognition/ransac.hpp"

#include <doctest/doctest.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>

using namespace ts;

namespace {

// Brute-force oracles. Distances use the formulas documented in engine/geometry/search.hpp.
double sq3(const Vec3& q, const Vec3& p) {
  const double dx = q[0] - p[0], dy = q[1] - p[1], dz = q[2] - p[2];
  double s = 0.0;
  s += dx * dx;
  s += dy * dy;
  s += dz * dz;
  return s;
}

double sqf(const Feature& a, const Feature& b) {
  double s = 0.0;
  for (int i = 0; i < kFeatureDim; ++i) {
    const double d = double(a[i]) - double(b[i]);
    s += d * d;
  }
  return s;
}

template <class Dist>
std::vector<Neighbour> brute_all(std::size_t n, Dist dist) {
  std::vector<Neighbour> all(n);
  for (std::size_t i = 0; i < n; ++i) all[i] = {static_cast<std::uint32_t>(i), dist(i)};
  std::sort(all.begin(), all.end(), [](const Neighbour& a, const Neighbour& b) {
    return a.sq_distance < b.sq_distance || (a.sq_distance == b.sq_distance && a.index < b.index);
  });
  return all;
}

std::vector<Neighbour> brute_knn(const std::vector<Vec3>& pts, const Vec3& q, std::size_t k) {
  auto all = brute_all(pts.size(), [&](std::size_t i) { return sq3(q, pts[i]); });
  all.resize(std::min(k, all.size()));
  return all;
}

std::vector<Neighbour> brute_radius(const std::vector<Vec3>& pts, const Vec3& q, double r) {
  auto all = brute_all(pts.size(), [&](std::size_t i) { return sq3(q, pts[i]); });
  std::vector<Neighbour> out;
  for (const auto& n : all)
    if (n.sq_distance <= r * r) out.push_back(n);
  return out;
}

std::vector<Neighbour> brute_features(const std::vector<Feature>& f, const Feature& q, std::size_t k) {
  auto all = brute_all(f.size(), [&](std::size_t i) { return sqf(q, f[i]); });
  all.resize(std::min(k, all.size()));
  return all;
}

void check_same(const std::vector<Neighbour>& got, const std::vector<Neighbour>& want) {
  REQUIRE(got.size() == want.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    CHECK(got[i].index == want[i].index);
    CHECK(got[i].sq_distance == want[i].sq_distance);
  }
}

std::vector<Vec3> random_cloud(Rng& rng, std::size_t n, double scale) {
  std::vector<Vec3> pts(n);
  for (auto& p : pts) p = Vec3(rng.uniform(-scale, scale), rng.uniform(-scale, scale), rng.uniform(-scale, scale));
  return pts;
}

/// Integer grid with every point present twice (exact ties everywhere).
std::vector<Vec3> grid_with_duplicates(int n) {
  std::vector<Vec3> pts;
  for (int rep = 0; rep < 2; ++rep)
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        for (int k = 0; k < n; ++k) pts.emplace_back(i, j, k);
  return pts;
}

/// Features in a few clusters with some exact duplicates, like FPFH of flat faces.
std::vector<Feature> random_features(Rng& rng, std::size_t n) {
  std::vector<Feature> centres(8);
  for (auto& c : centres)
    for (auto& v : c) v = static_cast<float>(rng.uniform(0.0, 30.0));
  std::vector<Feature> f(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (i > 0 && rng.uniform() < 0.15) {
      f[i] = f[rng.index(i)];   // exact duplicate of an earlier feature
      continue;
    }
    const auto& c = centres[rng.index(centres.size())];
    for (int d = 0; d < kFeatureDim; ++d) f[i][d] = c[d] + static_cast<float>(3.0 * rng.normal());
  }
  return f;
}

}  // namespace

TEST_CASE("KdTree3 knn and radius match brute force on random clouds") {
  Rng rng(11);
  for (std::size_t n : {1u, 7u, 100u, 2000u}) {
    const auto pts = random_cloud(rng, n, 0.1);
    const KdTree3 tree(pts);
    REQUIRE(tree.size() == n);
    for (int q = 0; q < 50; ++q) {
      const Vec3 query(rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12));
      for (std::size_t k : {1u, 5u, 32u, 5000u}) check_same(tree.knn(query, k), brute_knn(pts, query, k));
      for (double r : {0.0, 0.01, 0.05, 1.0}) {
        const auto want = brute_radius(pts, query, r);
        check_same(tree.radius(query, r), want);
        std::vector<Neighbour> buffer(3, Neighbour{99, 1.0});   // cleared by the call
        tree.radius(query, r, buffer, true);
        check_same(buffer, want);
        tree.radius(query, r, buffer, false);   // same set, traversal order
        std::sort(buffer.begin(), buffer.end(), [](const Neighbour& a, const Neighbour& b) {
          return a.sq_distance < b.sq_distance || (a.sq_distance == b.sq_distance && a.index < b.index);
        });
        check_same(buffer, want);
      }
      const auto nn = tree.nearest(query);
      const auto b = brute_knn(pts, query, 1);
      CHECK(nn.index == b[0].index);
      CHECK(nn.sq_distance == b[0].sq_distance);
    }
  }
}

TEST_CASE("KdTree3 breaks ties by the smaller index and includes the radius boundary") {
  const auto pts = grid_with_duplicates(6);   // 432 points, each position twice
  const KdTree3 tree(pts);
  Rng rng(3);
  for (int q = 0; q < 200; ++q) {
    // Grid points and half-integer points: many neighbours at exactly equal distances.
    const double h = (q % 2) ? 0.5 : 0.0;
    const Vec3 query(double(rng.index(6)) + h, double(rng.index(6)), double(rng.index(6)) - h);
    for (std::size_t k : {1u, 2u, 3u, 7u, 13u, 27u, 64u}) check_same(tree.knn(query, k), brute_knn(pts, query, k));
    for (double r : {1.0, 1.5, 2.0}) {
      const auto got = tree.radius(query, r);
      check_same(got, brute_radius(pts, query, r));
    }
  }
  // The boundary is inclusive: a grid point's radius-1 ball holds its 6 axis neighbours.
  const auto ball = tree.radius(Vec3(2, 2, 2), 1.0);
  CHECK(ball.size() == 2 * 7);
  // Nearest of a duplicated point is its first copy.
  CHECK(tree.nearest(pts[300]).index == 300 - 216);
}

TEST_CASE("KdTree3::nearest_within is nearest() when the nearest is within reach, none when nothing is") {
  Rng rng(17);
  std::vector<Vec3> pts(2000);
  for (auto& p : pts) p = Vec3(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.1, 0.1));
  const KdTree3 tree(pts);
  const auto grid = grid_with_duplicates(6);   // exact ties: the smaller index must win alike
  const KdTree3 tied(grid);
  std::size_t within = 0, beyond = 0;
  for (int q = 0; q < 3000; ++q) {
    const Vec3 query(rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5), rng.uniform(-0.6, 0.6));
    const Neighbour exact = brute_knn(pts, query, 1).front();
    REQUIRE(tree.nearest(query).index == exact.index);
    for (double r : {0.0, 0.01, 0.05, 0.2, 1.0}) {
      const Neighbour got = tree.nearest_within(query, r);
      if (exact.sq_distance <= r * r) {
        ++within;
        CHECK(got.index == exact.index);
        CHECK(got.sq_distance == exact.sq_distance);
      } else {
        ++beyond;
        // none, or some point a few ulps beyond the reach
        CHECK((got.sq_distance == std::numeric_limits<double>::infinity() ||
               (got.sq_distance >= exact.sq_distance && got.sq_distance <= r * r * (1.0 + 1e-9))));
      }
    }
    const Vec3 g(double(rng.index(6)) + 0.5 * double(q % 2), double(rng.index(6)), double(rng.index(6)));
    const Neighbour t = brute_knn(grid, g, 1).front();
    const Neighbour got = tied.nearest_within(g, 1.0);
    CHECK(got.index == t.index);
    CHECK(got.sq_distance == t.sq_distance);
  }
  CHECK(within > 1000);   // both branches exercised
  CHECK(beyond > 1000);
  CHECK(KdTree3().nearest_within(Vec3::Zero(), 1.0).sq_distance == std::numeric_limits<double>::infinity());
  CHECK(tree.nearest_within(Vec3::Zero(), -1.0).sq_distance == std::numeric_limits<double>::infinity());
  CHECK(tree.nearest_within(pts[5], 0.0).index == 5);   // a point is within reach 0 of itself
  // The reach is inclusive: on the grid, a point exactly 1 from its nearest (every distance is
  // exact) is found with reach 1 and not with a reach just short of it.
  const Vec3 off(2.0, 2.0, 6.0);   // nearest: the grid point (2, 2, 5), at distance 1
  const Neighbour exact = brute_knn(grid, off, 1).front();
  REQUIRE(exact.sq_distance == 1.0);
  const Neighbour at = tied.nearest_within(off, 1.0);
  CHECK(at.index == exact.index);
  CHECK(at.sq_distance == 1.0);
  CHECK(tied.nearest_within(off, 0.999).sq_distance == std::numeric_limits<double>::infinity());
}

TEST_CASE("KdTree3 handles empty trees, k = 0 and all-identical points") {
  const KdTree3 empty;
  CHECK(empty.size() == 0);
  CHECK(std::isinf(empty.nearest(Vec3::Zero()).sq_distance));
  CHECK(empty.knn(Vec3::Zero(), 3).empty());
  CHECK(empty.radius(Vec3::Zero(), 1.0).empty());

  const std::vector<Vec3> same(50, Vec3(1, 2, 3));
  const KdTree3 tree(same);
  CHECK(tree.knn(Vec3(1, 2, 3), 0).empty());
  const auto r = tree.knn(Vec3(0, 0, 0), 10);
  REQUIRE(r.size() == 10);
  for (std::uint32_t i = 0; i < 10; ++i) CHECK(r[i].index == i);
  CHECK(tree.radius(Vec3(1, 2, 3), 0.0).size() == 50);

  KdTree3 moved = KdTree3(same);
  KdTree3 other;
  other = std::move(moved);
  CHECK(other.size() == 50);
  CHECK(other.points()[49] == Vec3(1, 2, 3));
}

TEST_CASE("KdTree3::over searches its owner's points without a copy, and survives moving them") {
  Rng rng(12);
  std::vector<Vec3> pts = random_cloud(rng, 3000, 0.1);
  const std::vector<Vec3> copy = pts;
  const Vec3* buffer = pts.data();
  struct Held {   // a cloud and its tree held together, as a database object holds them
    std::vector<Vec3> points;
    KdTree3 tree;
  };
  Held held{std::move(pts), KdTree3()};
  held.tree = KdTree3::over(held.points);
  Held moved = std::move(held);   // the buffer moves with the vector
  REQUIRE(moved.points.data() == buffer);
  CHECK(moved.tree.points().data() == buffer);
  CHECK(moved.tree.size() == copy.size());
  const KdTree3 own(copy);
  CHECK(moved.tree.memory_bytes() + copy.size() * sizeof(Vec3) == own.memory_bytes());
  for (int q = 0; q < 200; ++q) {
    const Vec3 query(rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12));
    check_same(moved.tree.knn(query, 7), brute_knn(copy, query, 7));
    check_same(moved.tree.radius(query, 0.02), brute_radius(copy, query, 0.02));
  }
}

TEST_CASE("KdTree3 parallel queries equal serial queries") {
  Rng rng(5);
  const auto pts = random_cloud(rng, 5000, 0.1);
  const KdTree3 tree(pts);
  const auto queries = random_cloud(rng, 2000, 0.1);
  std::vector<std::vector<Neighbour>> serial(queries.size()), parallel(queries.size());
  for (std::size_t i = 0; i < queries.size(); ++i) serial[i] = tree.knn(queries[i], 8);
  tbb::task_arena arena(2);
  arena.execute([&] {
    tbb::parallel_for(std::size_t(0), queries.size(), [&](std::size_t i) { parallel[i] = tree.knn(queries[i], 8); });
  });
  for (std::size_t i = 0; i < queries.size(); ++i) check_same(parallel[i], serial[i]);
}

TEST_CASE("FeatureIndex exact mode matches brute force, ties included") {
  Rng rng(21);
  const auto feats = random_features(rng, 3000);
  std::vector<FeatureRef> refs(feats.size());
  for (std::size_t i = 0; i < refs.size(); ++i) refs[i] = {static_cast<std::uint32_t>(i % 7), static_cast<std::uint32_t>(i)};
  FeatureIndexSettings s;
  s.exact = true;
  const FeatureIndex index(FeatureRows(feats), refs, s);
  REQUIRE(index.size() == feats.size());
  CHECK(index.ref(10).object == 3);
  for (int q = 0; q < 40; ++q) {
    // Half the queries are database features themselves (exact duplicates exist).
    Feature query = feats[rng.index(feats.size())];
    if (q % 2)
      for (auto& v : query) v += static_cast<float>(rng.normal());
    for (std::size_t w : {1u, 10u, 100u, 3000u, 5000u}) check_same(index.knn(query.data(), w), brute_features(feats, query, w));
  }
  // FLANN's search is const with per-call state only: parallel queries equal serial ones.
  std::vector<Feature> queries(64);
  for (auto& q : queries) {
    q = feats[rng.index(feats.size())];
    for (auto& v : q) v += static_cast<float>(rng.normal());
  }
  std::vector<std::vector<Neighbour>> par(queries.size());
  tbb::task_arena arena(2);
  arena.execute([&] {
    tbb::parallel_for(std::size_t(0), queries.size(), [&](std::size_t i) { par[i] = index.knn(queries[i].data(), 200); });
  });
  for (std::size_t i = 0; i < queries.size(); ++i) check_same(par[i], brute_features(feats, queries[i], 200));
}

TEST_CASE("FeatureIndex ties: among identical features the smaller indices win") {
  // 12 distinct features, each repeated 250 times in shuffled positions (flat faces give exactly
  // this: many identical histograms).
  Rng rng(23);
  std::vector<Feature> distinct(12);
  for (auto& f : distinct)
    for (auto& v : f) v = static_cast<float>(rng.index(20));
  std::vector<Feature> feats;
  for (int rep = 0; rep < 250; ++rep)
    for (const auto& f : distinct) feats.push_back(f);
  for (std::size_t i = feats.size(); i > 1; --i) std::swap(feats[i - 1], feats[rng.index(i)]);
  const std::vector<FeatureRef> refs(feats.size());
  FeatureIndexSettings exact;
  exact.exact = true;
  FeatureIndexSettings approx;
  approx.exact = false;
  approx.checks = 1000;
  const FeatureIndex a(FeatureRows(feats), refs, exact), b(FeatureRows(feats), refs, approx);
  for (int q = 0; q < 12; ++q) {
    Feature query = distinct[q];
    query[q] += 0.25f;
    for (std::size_t w : {1u, 100u, 250u, 400u, 777u}) {
      const auto want = brute_features(feats, query, w);
      check_same(a.knn(query.data(), w), want);
      // Approximate: whatever it returns is sorted by (distance, index) with true distances.
      const auto got = b.knn(query.data(), w);
      REQUIRE(got.size() == w);
      for (std::size_t i = 0; i < got.size(); ++i) {
        CHECK(got[i].sq_distance == sqf(query, feats[got[i].index]));
        if (i > 0)
          CHECK((got[i - 1].sq_distance < got[i].sq_distance ||
                 (got[i - 1].sq_distance == got[i].sq_distance && got[i - 1].index < got[i].index)));
      }
    }
  }
}

TEST_CASE("FeatureIndex approximate mode is reproducible, seeded, and near-exact with a full budget") {
  Rng rng(22);
  const auto feats = random_features(rng, 4000);
  std::vector<FeatureRef> refs(feats.size());
  FeatureIndexSettings s;
  s.exact = false;
  s.trees = 4;
  s.checks = 128;
  const FeatureIndex a(FeatureRows(feats), refs, s), b(FeatureRows(feats), refs, s);
  FeatureIndexSettings all = s;
  all.checks = static_cast<int>(feats.size());
  const FeatureIndex full(FeatureRows(feats), refs, all);
  FeatureIndexSettings other_seed = s;
  other_seed.seed = 2;
  const FeatureIndex c(FeatureRows(feats), refs, other_seed);

  double recall_sum = 0.0;
  bool seed_matters = false;
  const int nq = 30;
  std::vector<Feature> queries(nq);
  for (auto& q : queries) {
    q = feats[rng.index(feats.size())];
    for (auto& v : q) v += static_cast<float>(2.0 * rng.normal());
  }
  for (const auto& q : queries) {
    const auto ra = a.knn(q.data(), 50);
    check_same(ra, b.knn(q.data(), 50));               // same settings, same answers
    const auto truth = brute_features(feats, q, 50);
    // A budget of every feature: (nearly) exhaustive. The forest's branch bound is FLANN's
    // heuristic, not a true lower bound, so exactness is not promised; recall must be ~1.
    const auto rf = full.knn(q.data(), 50);
    std::size_t full_hit = 0;
    for (const auto& n : rf)
      full_hit += std::count_if(truth.begin(), truth.end(), [&](const Neighbour& t) { return t.index == n.index; });
    CHECK(full_hit >= 49);
    REQUIRE(ra.size() == 50);
    for (std::size_t i = 1; i < ra.size(); ++i)
      CHECK((ra[i - 1].sq_distance < ra[i].sq_distance ||
             (ra[i - 1].sq_distance == ra[i].sq_distance && ra[i - 1].index < ra[i].index)));
    std::size_t hit = 0;
    for (const auto& n : ra)
      hit += std::count_if(truth.begin(), truth.end(), [&](const Neighbour& t) { return t.index == n.index; });
    recall_sum += double(hit) / 50.0;
    const auto rc = c.knn(q.data(), 50);
    for (std::size_t i = 0; i < rc.size(); ++i) seed_matters |= rc[i].index != ra[i].index;
  }
  CHECK(recall_sum / nq > 0.5);   // approximate but useful (the benchmark measures it properly)
  CHECK(seed_matters);            // the seed really drives the trees

  // Parallel queries equal serial ones.
  std::vector<std::vector<Neighbour>> par(queries.size());
  tbb::task_arena arena(2);
  arena.execute([&] {
    tbb::parallel_for(std::size_t(0), queries.size(), [&](std::size_t i) { par[i] = a.knn(queries[i].data(), 50); });
  });
  for (std::size_t i = 0; i < queries.size(); ++i) check_same(par[i], a.knn(queries[i].data(), 50));
}

TEST_CASE("FeatureIndex rejects bad input and handles the empty index") {
  std::vector<Feature> f(3);
  CHECK_THROWS_AS(FeatureIndex(FeatureRows(f), std::vector<FeatureRef>(2), {}), Error);
  f[1][4] = std::nanf("");
  CHECK_THROWS_AS(FeatureIndex(FeatureRows(f), std::vector<FeatureRef>(3), {}), Error);
  FeatureIndexSettings bad;
  bad.exact = false;
  bad.checks = 0;
  CHECK_THROWS_AS(FeatureIndex(FeatureRows(std::vector<Feature>(2)), std::vector<FeatureRef>(2), bad), Error);
  const FeatureIndex empty;
  CHECK(empty.size() == 0);
  CHECK(empty.knn(Feature{}.data(), 5).empty());
  const FeatureIndex none(FeatureRows(std::vector<Feature>{}), {}, {});
  CHECK(none.knn(Feature{}.data(), 5).empty());
}

TEST_CASE("FeatureIndex at every descriptor's dimension: exact search is the brute force; queries of another dimension are refused") {
  for (const int dim : {125, 352, 153}) {
    CAPTURE(dim);
    std::mt19937 gen(static_cast<unsigned>(dim));
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    const std::size_t n = 400;
    FeatureRows rows(dim, n);
    for (float& v : rows.values()) v = u(gen);
    std::vector<FeatureRef> refs(n);
    for (std::size_t i = 0; i < n; ++i) refs[i] = {static_cast<std::uint32_t>(i % 7), static_cast<std::uint32_t>(i)};
    const auto index = std::make_shared<const FeatureIndex>(rows, refs, FeatureIndexSettings{});
    CHECK(index->dim() == dim);
    FeatureRows queries(dim, 5);
    for (float& v : queries.values()) v = u(gen);
    for (std::size_t q = 0; q < queries.size(); ++q) {
      std::vector<std::pair<double, std::uint32_t>> all;
      for (std::size_t i = 0; i < n; ++i) {
        double d = 0.0;
        for (int k = 0; k < dim; ++k) {
          const double e = double(rows.row(i)[k]) - double(queries.row(q)[k]);
          d += e * e;
        }
        all.emplace_back(d, static_cast<std::uint32_t>(i));
      }
      std::sort(all.begin(), all.end());
      const auto got = index->knn(queries.row(q), 10);
      REQUIRE(got.size() == 10);
      for (std::size_t k = 0; k < 10; ++k) {
        CHECK(got[k].index == all[k].second);
        CHECK(std::abs(got[k].sq_distance - all[k].first) <= 1e-4 * all[k].first);
      }
    }
    FeatureSearch search;
    search.index = index;
    CHECK(search.knn(queries, 3).size() == 5);
    FeatureRows fpfh(kFeatureDim, 2);
    CHECK_THROWS_WITH_AS(search.knn(fpfh, 3), doctest::Contains("another descriptor"), Error);
  }
}
