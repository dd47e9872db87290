// Feature-free hypotheses for sparse contacts (engine/recognition/sparse_hypotheses): the pair tables against
// brute force, when the source runs, the true pose among the candidates (asymmetric, symmetric,
// coplanar, 1 mm quantized contacts), degenerate sets, determinism, and the recognizer with
// isolated contacts alone.
#include "engine/database/symmetry_cache.hpp"
#include "engine/detail.hpp"
#include "engine/geometry/pose_error.hpp"
#include "engine/geometry/symmetry.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/recognition/sparse_hypotheses.hpp"
#include "recognition_fixture.hpp"

#include <doctest/doctest.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numbers>
#include <numeric>

using namespace ts;

namespace {

using ts::detail::kRadPerDeg;

/// `n` isolated contacts of object `obj` at T (world), at least `spacing` apart, with outward
/// normals tilted by up to `tilt_deg`, noise `noise` per axis, rounded to `quantum` (0: not).
PointCloud isolated(const test::TestSource& src, std::size_t obj, const Pose& T, std::size_t n,
                    std::uint64_t seed, double spacing = 0.02, double tilt_deg = 10.0,
                    double noise = 0.0, double quantum = 0.0) {
  const PointCloud& fine = src.fines[obj];
  Rng rng(seed);
  PointCloud out;
  for (int attempt = 0; attempt < 100000 && out.size() < n; ++attempt) {
    const std::size_t i = rng.index(fine.size());
    const Vec3 p = T * fine.points[i];
    bool far = true;
    for (const Vec3& q : out.points) far = far && (q - p).norm() >= spacing;
    if (!far) continue;
    Vec3 w = p + noise * Vec3(rng.normal(), rng.normal(), rng.normal());
    if (quantum > 0)
      for (int k = 0; k < 3; ++k) w[k] = quantum * std::round(w[k] / quantum);
    const Vec3 nrm = T.linear() * fine.normals[i];
    const Vec3 axis = nrm.cross(rng.unit_vector()).normalized();
    out.points.push_back(w);
    out.normals.push_back(Eigen::AngleAxisd(tilt_deg * kRadPerDeg * rng.uniform(), axis) * nrm);
  }
  return out;
}

Scene scene_of(const Database& db, const PointCloud& contacts) {
  return prepare_scene(contacts, {}, db.settings().fpfh, SceneSettings{}, 1, 1);
}

/// The smallest (position, orientation) error of the object's candidates to the truth, up to
/// the object's symmetries.
std::pair<double, double> closest(const Scene& scene, const std::vector<Candidate>& cands, std::uint32_t obj,
                                  const Pose& T, const SymmetryGroup* sym) {
  double best_p = 1e9, best_r = 1e9, best = 1e9;
  for (const Candidate& c : cands) {
    if (c.object != obj) continue;
    const PoseError e = pose_error(scene.to_world(c.T_scene_object), T, sym);
    const double score = e.symmetric_position_m / 0.005 + e.symmetric_orientation_deg / 5.0;
    if (score < best) best = score, best_p = e.symmetric_position_m, best_r = e.symmetric_orientation_deg;
  }
  return {best_p, best_r};
}

}  // namespace

namespace {

/// Entries of a table that differ from the plain way of computing them (std::atan2, rounded;
/// the distance from Eigen's norm), after checking each row's order and indices; `angles`
/// counts the angles compared.
std::size_t table_mismatches(const ObjectPairs& t, std::size_t& angles) {
  auto units = [](const Vec3& a, const Vec3& b) {
    const double rad = std::atan2(a.cross(b).norm(), a.dot(b));
    return static_cast<int>(std::lround(std::clamp(rad, 0.0, std::numbers::pi) * 255.0 / std::numbers::pi));
  };
  const std::size_t n = t.points.size();
  REQUIRE(t.near.size() == n * (n - 1));
  std::size_t mismatched = 0;
  for (std::size_t i = 0; i < n; ++i) {
    std::vector<std::uint8_t> seen(n, 0);
    for (std::size_t k = 0; k < n - 1; ++k) {
      const ObjectPairs::Near& e = t.near[i * (n - 1) + k];
      if (k > 0) {
        const ObjectPairs::Near& f = t.near[i * (n - 1) + k - 1];
        CHECK((f.distance < e.distance || (f.distance == e.distance && f.index < e.index)));
      }
      REQUIRE(e.index < n);
      CHECK(e.index != i);
      CHECK_FALSE(seen[e.index]);
      seen[e.index] = 1;
      const Vec3 d = t.points[e.index] - t.points[i];
      mismatched += e.distance != std::lround(std::min((t.points[i] - t.points[e.index]).norm() / t.unit, 65535.0));
      mismatched += e.a_i != units(t.normals[i], d);
      mismatched += e.a_j != units(t.normals[e.index], d);
      mismatched += e.a_ij != units(t.normals[i], t.normals[e.index]);
      angles += 3;
    }
  }
  return mismatched;
}

}  // namespace

TEST_CASE("Pair tables: every other point per point, sorted by distance, with the pair's angles") {
  // The oracle: each entry's distance and angles in the table's units, computed the plain way
  // (std::atan2, rounded), equal bit for bit: the table's fast angles fall back to std::atan2
  // near a rounding boundary and must never round otherwise. Every object of the fixture, up to
  // 250 points each: about 480 000 angles.
  auto src = test::make_source();
  Database db(src);
  SparseSettings s;
  s.max_model_points = 250;
  std::size_t angles = 0, mismatched = 0;
  for (std::size_t o = 0; o < db.size(); ++o) {
    CAPTURE(o);
    const ObjectPairs t = build_object_pairs(db.keypoints(o), s);
    const std::size_t n = t.points.size();
    REQUIRE(n >= 20);
    CHECK(n <= 250);
    mismatched += table_mismatches(t, angles);
    for (const Vec3& v : t.normals) CHECK(std::abs(v.norm() - 1.0) < 1e-6);
  }
  CHECK(angles > 400000);
  CHECK(mismatched == 0);
}

TEST_CASE("Pair tables: the cases the fast path leaves to the exact one") {
  // Points on a grid with axis-aligned normals (dot products of exactly +0 and -0, angles of
  // exactly pi / 2), points without normals (atan2(0, +-0): 0 or 255 by the sign of zero) and
  // normals exactly opposite each other: the table equals the plain
  // computation entry for entry.
  ObjectKeypoints grid, bare;
  for (int x = 0; x < 5; ++x)
    for (int y = 0; y < 5; ++y)
      for (int z = 0; z < 3; ++z) {
        const Vec3 p(0.01 * x, 0.01 * y, 0.01 * z);
        grid.coarse.points.push_back(p);
        grid.coarse.normals.push_back(z == 0 ? Vec3(0, 0, -1) : (x == 0 ? Vec3(-1, 0, 0) : Vec3(0, 0, 1)));
        bare.coarse.points.push_back(p + Vec3(0.003 * y, 0.0, 0.001 * x));
      }
  grid.coarse.normals[7] = Vec3(1, 1, 0).normalized();
  SparseSettings s;
  s.model_spacing = 1e-4;   // keep every point
  std::size_t angles = 0;
  const ObjectPairs g = build_object_pairs(grid, s);
  REQUIRE(g.points.size() == 75);
  CHECK(table_mismatches(g, angles) == 0);
  const ObjectPairs b = build_object_pairs(bare, s);
  REQUIRE(b.points.size() == 75);
  for (const Vec3& v : b.normals) CHECK(v == Vec3::Zero());
  CHECK(table_mismatches(b, angles) == 0);
  // Without normals every a_i is 0 or 255 (atan2(0, +-0)), and both occur.
  std::size_t zero = 0, full = 0;
  for (const ObjectPairs::Near& e : b.near) zero += e.a_i == 0, full += e.a_i == 255;
  CHECK(zero > 0);
  CHECK(full > 0);
  CHECK(zero + full == b.near.size());
  CHECK(angles == 3 * 2 * 75 * 74);
}

TEST_CASE("The source runs on isolated contacts, not on tactile patches") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(5, Vec3(0.3, 0.1, -0.2));
  const SparseSettings s;
  const Scene dense = scene_of(db, test::touch(src->fines[4], T, 6, 3));
  CHECK(dense.contacts.size() > 50);
  CHECK_FALSE(sparse_active(dense, s));
  const Scene sparse = scene_of(db, isolated(*src, 4, T, 12, 3));
  CHECK(sparse.contacts.size() == 12);
  CHECK(isolated_contacts(sparse) == 12);
  CHECK(sparse_active(sparse, s));
  SparseSettings off = s;
  off.mode = kSparseNever;
  CHECK_FALSE(sparse_active(sparse, off));
  SparseSettings always = s;
  always.mode = kSparseAlways;
  CHECK(sparse_active(dense, always));   // patches too
  CHECK(sparse_active(sparse, always));
  CHECK_FALSE(sparse_active(scene_of(db, isolated(*src, 4, T, 2, 3)), always));
  // Two contacts are no triplet.
  CHECK_FALSE(sparse_active(scene_of(db, isolated(*src, 4, T, 2, 3)), s));
}

TEST_CASE("Always: on tactile patches without sensor normals, the scene's normals find the true pose") {
  auto src = test::make_source();
  Database db(src);
  SymmetryCache symmetries;
  SparseSettings s;
  s.mode = kSparseAlways;
  SparseTables tables(db, s);
  const std::vector<std::uint8_t> all(db.size(), 1);
  for (std::size_t obj : {std::size_t{4}, std::size_t{0}}) {
    CAPTURE(obj);
    const Pose T = test::random_pose(70 + obj, Vec3(0.1, -0.3, 0.2));
    const PointCloud patches = test::touch(src->fines[obj], T, 6, 11 + obj);   // points, no normals
    REQUIRE_FALSE(patches.has_normals());
    const Scene scene = scene_of(db, patches);
    // The scene's own normals stand in for the sensor's, under `always` only.
    CHECK(scene_contact_normals(scene, patches).empty());
    CHECK(sparse_contact_normals(scene, patches, SparseSettings{}).empty());
    const std::vector<Vec3> normals = sparse_contact_normals(scene, patches, s);
    REQUIRE(normals.size() == scene.contacts.size());
    std::size_t defined = 0;
    for (const Vec3& n : normals) defined += n.squaredNorm() > 0.5;
    CHECK(defined > scene.contacts.size() / 2);
    SparseStats st;
    const auto cands = sparse_candidates(scene, tables, normals, all, s, 5, 1, &st);
    CHECK(st.active);
    CHECK(st.isolated == 0);   // patches: the automatic mode would not have run
    REQUIRE(!cands.empty());
    const auto [dp, dr] = closest(scene, cands, static_cast<std::uint32_t>(obj), T, &symmetries.get(db, obj));
    CHECK(dp < 0.012);
    CHECK(dr < 12.0);
    // The automatic mode leaves these scenes to Batch RANSAC.
    CHECK(sparse_candidates(scene, tables, normals, all, SparseSettings{}, 5, 1).empty());
  }
}

TEST_CASE("The true pose is among the candidates: asymmetric, symmetric, noisy, quantized") {
  auto src = test::make_source();
  Database db(src);
  SymmetryCache symmetries;
  SparseTables tables(db, SparseSettings{});
  const std::vector<std::uint8_t> all(db.size(), 1);
  struct Case {
    std::size_t obj;
    double noise, quantum, tilt;
    bool normals;
  };
  for (const Case& k : {Case{4, 0.0, 0.0, 10.0, true},      // wedge, exact contacts
                        Case{4, 0.001, 0.0, 20.0, true},    // 1 mm noise, rough normals
                        Case{4, 0.0, 0.001, 10.0, true},    // 1 mm quantization
                        Case{4, 0.0, 0.0, 0.0, false},      // no normals known
                        Case{1, 0.0005, 0.001, 10.0, true}, // nut (5-fold symmetric)
                        Case{5, 0.0005, 0.0, 10.0, true}}) { // cube (24 rotations)
    INFO("object " << db.info(k.obj).name << " noise " << k.noise << " quantum " << k.quantum
                   << " normals " << k.normals);
    const Pose T = test::random_pose(60 + k.obj, Vec3(-0.2, 0.4, 0.1));
    PointCloud c = isolated(*src, k.obj, T, 15, 7 + k.obj, 0.02, k.tilt, k.noise, k.quantum);
    if (!k.normals) c.normals.clear();
    const Scene scene = scene_of(db, c);
    SparseStats st;
    const auto cands = sparse_candidates(scene, tables, scene_contact_normals(scene, c), all, SparseSettings{},
                                         9, 1, &st);
    CHECK(st.active);
    CHECK(st.triplets > 0);
    REQUIRE(!cands.empty());
    for (const Candidate& cd : cands) {
      REQUIRE(cd.T_scene_object.matrix().allFinite());
      CHECK(std::abs(cd.T_scene_object.linear().determinant() - 1.0) < 1e-9);
      CHECK(cd.slot >= kSparseSlot);
    }
    const auto [dp, dr] = closest(scene, cands, static_cast<std::uint32_t>(k.obj), T,
                                  &symmetries.get(db, k.obj));
    CHECK(dp < 0.012);
    CHECK(dr < 12.0);
  }
}

TEST_CASE("Degenerate contacts: collinear sets give no triplet, coplanar ones stay finite") {
  auto src = test::make_source();
  Database db(src);
  SparseTables tables(db, SparseSettings{});
  const std::vector<std::uint8_t> all(db.size(), 1);
  // Nine points on one line (an edge of the box), 15 mm apart (isolated: the feature radius is
  // 12 mm): no well-conditioned triangle.
  PointCloud line;
  for (int i = 0; i < 9; ++i) line.points.push_back(Vec3(-0.06 + 0.015 * i, -0.04, -0.025) + Vec3(1.0, 2.0, 3.0));
  const Scene s1 = scene_of(db, line);
  SparseStats st;
  CHECK(sparse_candidates(s1, tables, {}, all, SparseSettings{}, 1, 1, &st).empty());
  CHECK(st.active);
  CHECK(st.triplets == 0);
  // Nearly collinear (1e-5 m off the line) is refused the same way.
  line.points[4].y() += 1e-5;
  CHECK(sparse_candidates(scene_of(db, line), tables, {}, all, SparseSettings{}, 1, 1, &st).empty());
  // Every contact on the box's largest face: a plane; candidates exist, the truth up to the
  // face's in-plane ambiguity is among them, every pose finite and proper.
  const Pose T = test::random_pose(8, Vec3(0.1, 0.2, 0.3));
  PointCloud face;
  Rng rng(4);
  for (int i = 0; i < 10; ++i)
    face.points.push_back(T * Vec3(rng.uniform(-0.055, 0.055), rng.uniform(-0.035, 0.035), 0.025));
  const Scene s2 = scene_of(db, face);
  const auto cands = sparse_candidates(s2, tables, {}, all, SparseSettings{}, 1, 1, &st);
  REQUIRE(!cands.empty());
  bool on_face = false;
  for (const Candidate& c : cands) {
    REQUIRE(c.T_scene_object.matrix().allFinite());
    if (c.object != 0) continue;
    // The contacts should lie within the tolerance of the box's surface under the candidate.
    double worst = 0.0;
    const Pose Tw = s2.to_world(c.T_scene_object).inverse();
    for (const Vec3& p : face.points) {
      const Vec3 q = Tw * p;
      const Vec3 h(0.06, 0.04, 0.025);
      const Vec3 out = (q.cwiseAbs() - h);
      worst = std::max(worst, out.maxCoeff() > 0 ? out.cwiseMax(0.0).norm() : -out.maxCoeff());
    }
    on_face = on_face || worst < 0.008;
  }
  CHECK(on_face);
}

TEST_CASE("Sparse candidates: the same for 1 and 2 threads") {
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(12, Vec3(0.0, 0.0, 0.5));
  const PointCloud c = isolated(*src, 1, T, 20, 5, 0.02, 15.0, 0.001);
  const std::vector<std::uint8_t> all(db.size(), 1);
  auto run = [&](int threads) {
    tbb::task_arena arena(threads);
    std::vector<Candidate> out;
    arena.execute([&] {
      SparseTables tables(db, SparseSettings{});
      const Scene scene = scene_of(db, c);
      out = sparse_candidates(scene, tables, scene_contact_normals(scene, c), all, SparseSettings{}, 3, 2);
    });
    return out;
  };
  const auto a = run(1), b = run(2);
  REQUIRE(a.size() == b.size());
  REQUIRE(!a.empty());
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].object == b[i].object);
    CHECK(a[i].slot == b[i].slot);
    CHECK(a[i].T_scene_object.matrix() == b[i].T_scene_object.matrix());
  }
}

TEST_CASE("The recognizer recognizes and localizes from isolated contacts alone") {
  auto src = test::make_source();
  Database db(src);
  SymmetryCache symmetries;
  RecognizerSettings rs = test::fast_settings();
  rs.evaluate.free_inside_penalty = true;
  rs.refine_new = true;
  rs.refine_pool = 40;
  for (std::size_t obj : {4u, 1u}) {
    INFO("object " << db.info(obj).name);
    const Pose T = test::random_pose(80 + obj, Vec3(0.2, -0.1, 0.3));
    const PointCloud all = isolated(*src, obj, T, 25, 21 + obj, 0.015, 15.0, 0.0005);
    Recognizer rec(db, rs);
    StepResult last;
    for (std::size_t k = 3; k <= all.size(); k += 2) {
      PointCloud c;
      c.points.assign(all.points.begin(), all.points.begin() + static_cast<std::ptrdiff_t>(k));
      c.normals.assign(all.normals.begin(), all.normals.begin() + static_cast<std::ptrdiff_t>(k));
      last = rec.step(c, {});
      CHECK(last.sparse_active);
    }
    REQUIRE(last.valid);
    CHECK(last.best.object == obj);
    const PoseError e = pose_error(last.best.pose, T, &symmetries.get(db, obj));
    CHECK(e.symmetric_position_m < 0.004);
    CHECK(e.symmetric_orientation_deg < 4.0);
    // The mean contact-to-model distance at the answer: about the contact noise.
    const double d = mean_contact_distance(*db.geometry(last.best.object), last.best.pose, all.points);
    CHECK(d < 0.0015);
    const double wrong = mean_contact_distance(*db.geometry(last.best.object),
                                               Pose(Eigen::Translation3d(0.01, 0, 0)) * last.best.pose, all.points);
    CHECK(wrong > d);
  }
}

TEST_CASE("Pair tables beyond the budget: the least recently wanted idle ones go, and come back alike") {
  auto src = test::make_source();
  Database db(src);
  auto only = [&](std::size_t o) {
    std::vector<std::uint8_t> w(db.size(), 0);
    w[o] = 1;
    return w;
  };
  // The tables' sizes, from a cache without a budget problem.
  SparseTables keeping(db, SparseSettings{});
  std::vector<std::size_t> bytes(db.size());
  for (std::size_t o = 0; o < db.size(); ++o) bytes[o] = keeping.prepare(only(o))[o]->memory_bytes();
  CHECK(keeping.held_bytes() == std::accumulate(bytes.begin(), bytes.end(), std::size_t{0}));   // all kept
  // Objects a, b, c with c's table no larger than b's: a budget of a + b holds a and c after
  // the LRU drops b.
  std::vector<std::size_t> order(db.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) { return bytes[x] > bytes[y]; });
  REQUIRE(order.size() >= 3);
  const std::size_t a = order[1], b = order[0], c = order[2];
  REQUIRE(bytes[c] <= bytes[b]);
  SparseSettings tight;
  tight.table_budget_mb = static_cast<double>(bytes[a] + bytes[b]) / (1024.0 * 1024.0);
  SparseTables lru(db, tight);
  SparseTables::View first_a = lru.prepare(only(a));
  REQUIRE(first_a[a]);
  CHECK_FALSE(first_a[b]);   // not wanted: not in the view
  lru.prepare(only(b));
  CHECK(lru.held_bytes() == bytes[a] + bytes[b]);   // within the budget: both kept
  lru.prepare(only(a));                             // a is now wanted more recently than b
  first_a = {};
  lru.prepare(only(c));   // over the budget: b, the least recently wanted, goes
  CHECK(lru.held_bytes() == bytes[a] + bytes[c]);
  // A table some caller still uses is not dropped (it would stay in memory anyway).
  SparseSettings none;
  none.table_budget_mb = 0.0;
  SparseTables dropping(db, none);
  const SparseTables::View held_a = dropping.prepare(only(a));
  dropping.prepare(only(b));
  CHECK(dropping.held_bytes() == bytes[a] + bytes[b]);   // a is in held_a
  dropping.prepare(only(c));
  CHECK(dropping.held_bytes() == bytes[a] + bytes[c]);   // b was idle: gone
  // Rebuilt when wanted again: the same table as one never dropped.
  const SparseTables::View again = dropping.prepare(only(b));
  const SparseTables::View kept = keeping.prepare(only(b));
  REQUIRE(again[b]);
  REQUIRE(kept[b]);
  const ObjectPairs &x = *again[b], &y = *kept[b];
  REQUIRE(x.near.size() == y.near.size());
  CHECK(x.points == y.points);
  CHECK(x.unit == y.unit);
  CHECK(std::equal(x.near.begin(), x.near.end(), y.near.begin(), [](const ObjectPairs::Near& u, const ObjectPairs::Near& v) {
    return u.distance == v.distance && u.index == v.index && u.a_i == v.a_i && u.a_j == v.a_j && u.a_ij == v.a_ij;
  }));
}

TEST_CASE("Pair tables shared by concurrent callers: every view holds every table it wanted") {
  // Callers on several threads with no budget at all: each one's prepare() drops whatever it
  // does not want and nobody uses, while others build; no view may miss a table it asked for.
  auto src = test::make_source();
  Database db(src);
  SparseSettings none;
  none.table_budget_mb = 0.0;
  SparseTables tables(db, none), reference(db, SparseSettings{});
  const SparseTables::View all = reference.prepare({});
  std::atomic<int> wrong{0};
  tbb::task_arena arena(4);
  arena.execute([&] {
    tbb::parallel_for(0, 48, [&](int call) {
      std::vector<std::uint8_t> w(db.size(), 0);
      w[static_cast<std::size_t>(call) % db.size()] = 1;
      w[static_cast<std::size_t>(call * 7 + 3) % db.size()] = 1;
      const SparseTables::View v = tables.prepare(w);
      for (std::size_t o = 0; o < db.size(); ++o)
        if (w[o] && (!v[o] || v[o]->near.size() != all[o]->near.size() || v[o]->points != all[o]->points)) ++wrong;
    });
  });
  CHECK(wrong == 0);
}

TEST_CASE("Pair tables are shared per database and table settings, while held") {
  auto src = test::make_source();
  Database db(src), other_db(src);
  SparseSettings s;
  auto a = SparseTables::shared(db, s);
  SparseSettings matching = s;   // settings the tables do not depend on: the same cache
  matching.triplets = 3;
  matching.mode = kSparseAlways;
  CHECK(SparseTables::shared(db, matching) == a);
  SparseSettings coarser = s;
  coarser.max_model_points = 100;
  CHECK(SparseTables::shared(db, coarser) != a);
  CHECK(SparseTables::shared(other_db, s) != a);
  // A table built through one holder is found by the next.
  const std::vector<std::uint8_t> all;
  a->prepare(all);
  const std::size_t held = a->held_bytes();
  CHECK(held > 0);
  CHECK(SparseTables::shared(db, s)->held_bytes() == held);
  // Released by everyone: gone, and a new cache starts empty.
  a.reset();
  CHECK(SparseTables::shared(db, s)->held_bytes() == 0);
  // The recognizer's: none when the source is off; otherwise the shared cache, which a
  // recognizer's step on isolated contacts fills.
  RecognizerSettings rs = test::fast_settings();
  rs.sparse.mode = kSparseNever;
  CHECK(Recognizer::sparse_tables(db, rs) == nullptr);
  rs.sparse.mode = kSparseAuto;
  const auto held_by_test = Recognizer::sparse_tables(db, rs);
  REQUIRE(held_by_test);
  CHECK(held_by_test->held_bytes() == 0);
  Recognizer rec(db, rs);
  const StepResult r = rec.step(isolated(*src, 4, test::random_pose(5, Vec3(0.1, 0.0, 0.3)), 12, 8), {});
  CHECK(r.sparse_active);
  CHECK(held_by_test->held_bytes() > 0);
}

namespace {

/// FNV-1a over the candidates' objects, slots and pose bits.
std::uint64_t candidates_hash(const std::vector<Candidate>& cands) {
  std::uint64_t h = 1469598103934665603ull;
  auto mix = [&](const void* p, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  for (const Candidate& c : cands) {
    mix(&c.object, sizeof c.object);
    mix(&c.slot, sizeof c.slot);
    const Eigen::Matrix4d m = c.T_scene_object.matrix();
    mix(m.data(), sizeof(double) * 16);
  }
  return h;
}

}  // namespace

TEST_CASE("Sparse candidates: the same as the per-(triplet, object) matcher they replaced") {
  // The expected counts and hashes were printed by the matcher of commit d6f182e (one task per
  // (triplet, object), its own binary searches, real-valued bounds) on these inputs; the
  // per-object sweep with integer bounds must give the same candidates bit for bit.
  auto src = test::make_source();
  Database db(src);
  const Pose T = test::random_pose(12, Vec3(0.0, 0.0, 0.5));
  const PointCloud c = isolated(*src, 1, T, 20, 5, 0.02, 15.0, 0.001);
  const Scene scene = scene_of(db, c);
  const std::vector<std::uint8_t> all(db.size(), 1);
  std::vector<std::uint8_t> one(db.size(), 0);
  one[1] = 1;
  SparseSettings wide;
  wide.distance_tolerance = 0.02;   // wide bands (and bounds beyond the small objects' tables)
  struct Case {
    const char* name;
    SparseSettings s;
    bool normals;
    const std::vector<std::uint8_t>* allowed;
  };
  const Case cases[] = {{"normals, all objects", SparseSettings{}, true, &all},
                        {"distances only, all objects", SparseSettings{}, false, &all},
                        {"normals, one object", SparseSettings{}, true, &one},
                        {"wide bands, distances only", wide, false, &all}};
  std::vector<std::pair<std::size_t, std::uint64_t>> got;
  for (const Case& k : cases) {
    SparseTables tables(db, k.s);
    const auto cands = sparse_candidates(scene, tables, k.normals ? scene_contact_normals(scene, c) : std::vector<Vec3>{},
                                         *k.allowed, k.s, 3, 2);
    got.emplace_back(cands.size(), candidates_hash(cands));
    MESSAGE(std::string(k.name) << ": " << cands.size() << " candidates, hash " << got.back().second);
  }
  const std::pair<std::size_t, std::uint64_t> expected[] = {{1247, 10388630797745070833ull}, {2269, 1882848317045372430ull}, {309, 8675346054493745836ull}, {2304, 15144142114756254813ull}};
  for (std::size_t i = 0; i < got.size(); ++i) {
    CAPTURE(cases[i].name);
    CHECK(got[i].second == expected[i].second);
    CHECK(got[i].first == expected[i].first);
  }
}
