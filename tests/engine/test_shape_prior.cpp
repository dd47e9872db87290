// The shape prior against oracles: its score equals the log-likelihood computed by a direct
// formulation (a map of pair bins, no flat histogram), it names the sampled object first
// among shapes that differ in form and in size whatever the pose, it is the same for 1 and 2
// threads, and feature pruning with prior_draws searches the prior's best objects from every
// triplet.
#include "engine/recognition/ransac.hpp"
#include "engine/recognition/shape_prior.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <map>
#include <tuple>

using namespace ts;

namespace {

/// Keypoints only: objects given as points with unit normals.
class KeypointSource final : public ObjectSource {
 public:
  std::vector<ObjectInfo> infos;
  std::vector<PointCloud> clouds;
  DatabaseSettings db_settings;
  void add(const std::string& name, PointCloud c) {
    ObjectInfo info;
    info.name = name;
    Vec3 lo = c.points.front(), hi = c.points.front();
    for (const Vec3& p : c.points) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    info.extent = hi - lo;
    info.coarse_points = c.points.size();
    infos.push_back(info);
    clouds.push_back(std::move(c));
  }
  std::size_t size() const override { return infos.size(); }
  const ObjectInfo& info(std::size_t i) const override { return infos.at(i); }
  const DatabaseSettings& settings() const override { return db_settings; }
  ObjectFeatures load_features(std::size_t i) const override {
    ObjectFeatures f;
    f.coarse = clouds.at(i);
    f.features.assign(f.coarse.points.size(), Feature{});
    return f;
  }
  PointCloud load_fine(std::size_t) const override { return {}; }
  DistanceField load_field(std::size_t) const override { return {}; }
};

// Surface samples with outward normals.
PointCloud box(Vec3 size, std::size_t n, Rng& rng) {
  PointCloud c;
  const double area[3] = {size.y() * size.z(), size.x() * size.z(), size.x() * size.y()};
  const double total = area[0] + area[1] + area[2];
  for (std::size_t i = 0; i < n; ++i) {
    const double u = rng.uniform() * total;
    const int axis = u < area[0] ? 0 : (u < area[0] + area[1] ? 1 : 2);
    Vec3 p(rng.uniform(-0.5, 0.5) * size.x(), rng.uniform(-0.5, 0.5) * size.y(), rng.uniform(-0.5, 0.5) * size.z());
    const double side = rng.uniform() < 0.5 ? -1.0 : 1.0;
    p[axis] = side * 0.5 * size[axis];
    Vec3 nv = Vec3::Zero();
    nv[axis] = side;
    c.points.push_back(p);
    c.normals.push_back(nv);
  }
  return c;
}
PointCloud sphere(double r, std::size_t n, Rng& rng) {
  PointCloud c;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 u = rng.unit_vector();
    c.points.push_back(r * u);
    c.normals.push_back(u);
  }
  return c;
}
PointCloud cylinder(double r, double h, std::size_t n, Rng& rng) {  // mantle only (a pipe)
  PointCloud c;
  for (std::size_t i = 0; i < n; ++i) {
    const double a = rng.uniform(0.0, 2.0 * M_PI);
    const Vec3 u(std::cos(a), std::sin(a), 0.0);
    c.points.push_back(r * u + Vec3(0, 0, rng.uniform(-0.5, 0.5) * h));
    c.normals.push_back(u);
  }
  return c;
}

std::shared_ptr<KeypointSource> shapes() {
  auto src = std::make_shared<KeypointSource>();
  Rng rng(11);
  src->add("cube10", box({0.10, 0.10, 0.10}, 400, rng));
  src->add("plate", box({0.20, 0.15, 0.02}, 400, rng));
  src->add("bar", box({0.30, 0.04, 0.04}, 400, rng));
  src->add("sphere5", sphere(0.05, 400, rng));
  src->add("sphere10", sphere(0.10, 400, rng));
  src->add("pipe", cylinder(0.03, 0.25, 400, rng));
  src->add("cube20", box({0.20, 0.20, 0.20}, 400, rng));
  return src;
}

Scene scene_of(const PointCloud& c, const Pose& T) {
  Scene s;
  for (std::size_t i = 0; i < c.points.size(); ++i) {
    s.contacts.points.push_back(T * c.points[i]);
    s.contacts.normals.push_back(T.linear() * c.normals[i]);
  }
  return s;
}

/// The score by a direct formulation: a map from (distance bin, x, y, z bins) to weight.
double oracle_score(const PointCloud& object, const Scene& scene, const ShapePriorSettings& s, double diag) {
  using Bin = std::tuple<long, int, int, int>;
  auto bins = [&](const Vec3& pa, const Vec3& na, const Vec3& pb, const Vec3& nb, double& d) {
    d = (pb - pa).norm();
    const Vec3 u = (pb - pa) / d;
    const double ca = std::abs(na.dot(u)), cb = std::abs(nb.dot(u));
    auto q = [&](double c) { return std::min(s.angle_bins - 1, static_cast<int>(c * s.angle_bins)); };
    return std::make_tuple(q(std::min(ca, cb)), q(std::max(ca, cb)), q(std::abs(na.dot(nb))));
  };
  const long max_bin = static_cast<long>(std::floor(diag / s.distance_bin));
  std::map<Bin, double> h;
  double total = 0.0;
  for (std::size_t a = 0; a < object.points.size(); ++a)
    for (std::size_t b = a + 1; b < object.points.size(); ++b) {
      double d = 0.0;
      const auto [x, y, z] = bins(object.points[a], object.normals[a], object.points[b], object.normals[b], d);
      if (d < s.min_pair_distance) continue;
      // distance split between the two bins whose centres bracket d
      const double f = d / s.distance_bin - 0.5;
      const long k = static_cast<long>(std::floor(f));
      const double w = f - double(k);
      if (k >= 0 && k <= max_bin) { h[{k, x, y, z}] += 1.0 - w; total += 1.0 - w; }
      if (k + 1 >= 0 && k + 1 <= max_bin) { h[{k + 1, x, y, z}] += w; total += w; }
    }
  double sum = 0.0;
  int pairs = 0;
  const auto& P = scene.contacts.points;
  const auto& N = scene.contacts.normals;
  for (std::size_t a = 0; a < P.size(); ++a)
    for (std::size_t b = a + 1; b < P.size(); ++b) {
      double d = 0.0;
      const auto [x, y, z] = bins(P[a], N[a], P[b], N[b], d);
      if (d < s.min_pair_distance) continue;
      const long k = static_cast<long>(std::floor(d / s.distance_bin));
      const auto it = h.find({k, x, y, z});
      sum += std::log((it == h.end() ? 0.0 : it->second / total) + s.floor);
      ++pairs;
    }
  return sum / pairs;
}

Pose some_pose(std::uint64_t seed) {
  Rng rng(seed);
  Pose T = Pose::Identity();
  T.linear() = rng.rotation().toRotationMatrix();
  T.translation() = Vec3(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-5, 5));
  return T;
}

}  // namespace

TEST_CASE("Shape prior: the score is the pairs' mean log-likelihood under each object's histogram") {
  auto src = shapes();
  Database db(src);
  ShapePriorSettings s;
  s.object_points = 1000;  // every keypoint: the oracle uses them all
  s.scene_pairs = 100000;  // every contact pair
  const ShapePrior prior(db, s);
  Rng rng(3);
  for (std::size_t truth : {std::size_t(0), std::size_t(2), std::size_t(5)}) {
    // 40 contacts of one object's surface, elsewhere than its keypoints, moved far away
    const PointCloud sample = truth == 5 ? cylinder(0.03, 0.25, 40, rng) : box(truth == 0 ? Vec3(0.1, 0.1, 0.1)
                                                                                         : Vec3(0.3, 0.04, 0.04), 40, rng);
    const Scene scene = scene_of(sample, some_pose(truth));
    const std::vector<double> score = prior.score(scene, {}, 1, 1);
    REQUIRE(score.size() == db.size());
    for (std::size_t o = 0; o < db.size(); ++o) {
      const double expect = oracle_score(src->clouds[o], scene, s, src->infos[o].extent.norm());
      // the histogram stores ln p in 255 steps of ln(floor): at most half a step off per pair
      CHECK(std::abs(score[o] - expect) <= 0.5 * std::abs(std::log(s.floor)) / 255.0 + 1e-9);
    }
  }
}

TEST_CASE("Shape prior: the sampled object ranks first, by form and by size, whatever the pose") {
  auto src = shapes();
  Database db(src);
  const ShapePriorSettings s;  // defaults: 500 keypoints, 1000 pairs
  const ShapePrior prior(db, s);
  Rng rng(21);
  const std::vector<PointCloud> samples = {
      box({0.10, 0.10, 0.10}, 60, rng), box({0.20, 0.15, 0.02}, 60, rng), box({0.30, 0.04, 0.04}, 60, rng),
      sphere(0.05, 60, rng),            sphere(0.10, 60, rng),            cylinder(0.03, 0.25, 60, rng),
      box({0.20, 0.20, 0.20}, 60, rng)};
  for (std::size_t truth = 0; truth < samples.size(); ++truth) {
    CAPTURE(src->infos[truth].name);
    const Scene scene = scene_of(samples[truth], some_pose(100 + truth));
    const std::vector<std::uint32_t> ranked = rank_by_prior(prior.score(scene, {}, 7, 3));
    REQUIRE(ranked.size() == db.size());
    CHECK(ranked.front() == truth);
  }
  // Objects not allowed get no score and no rank.
  const Scene scene = scene_of(samples[3], some_pose(9));
  std::vector<std::uint8_t> allowed(db.size(), 1);
  allowed[3] = 0;
  const std::vector<double> score = prior.score(scene, allowed, 7, 3);
  CHECK(std::isinf(score[3]));
  const std::vector<std::uint32_t> ranked = rank_by_prior(score);
  CHECK(ranked.size() == db.size() - 1);
  CHECK(std::find(ranked.begin(), ranked.end(), 3u) == ranked.end());
}

TEST_CASE("Shape prior without normals: the distances' marginal, by an oracle; size and form still rank") {
  auto src = shapes();
  Database db(src);
  ShapePriorSettings s;
  s.object_points = 1000;  // every keypoint: the oracle uses them all
  s.scene_pairs = 100000;  // every contact pair
  const ShapePrior prior(db, s);
  // The oracle: each object's pair distances (pairs of keypoints with normals, split between
  // the two bins whose centres bracket d), the contacts' pairs scored by distance alone.
  auto oracle = [&](std::size_t o, const Scene& scene) {
    const PointCloud& obj = src->clouds[o];
    const long max_bin = static_cast<long>(std::floor(src->infos[o].extent.norm() / s.distance_bin));
    std::map<long, double> h;
    double total = 0.0;
    for (std::size_t a = 0; a < obj.points.size(); ++a)
      for (std::size_t b = a + 1; b < obj.points.size(); ++b) {
        const double d = (obj.points[b] - obj.points[a]).norm();
        if (d < s.min_pair_distance) continue;
        const double f = d / s.distance_bin - 0.5;
        const long k = static_cast<long>(std::floor(f));
        const double w = f - double(k);
        if (k >= 0 && k <= max_bin) { h[k] += 1.0 - w; total += 1.0 - w; }
        if (k + 1 >= 0 && k + 1 <= max_bin) { h[k + 1] += w; total += w; }
      }
    double sum = 0.0;
    int pairs = 0;
    const auto& P = scene.contacts.points;
    for (std::size_t a = 0; a < P.size(); ++a)
      for (std::size_t b = a + 1; b < P.size(); ++b) {
        const double d = (P[b] - P[a]).norm();
        if (d < s.min_pair_distance) continue;
        const auto it = h.find(static_cast<long>(std::floor(d / s.distance_bin)));
        sum += std::log((it == h.end() ? 0.0 : it->second / total) + s.floor);
        ++pairs;
      }
    return sum / pairs;
  };
  Rng rng(5);
  const std::vector<PointCloud> samples = {box({0.10, 0.10, 0.10}, 40, rng), box({0.30, 0.04, 0.04}, 40, rng),
                                           sphere(0.10, 40, rng), box({0.20, 0.20, 0.20}, 40, rng)};
  const std::size_t truths[] = {0, 2, 4, 6};
  std::size_t first = 0;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    Scene scene = scene_of(samples[k], some_pose(40 + k));
    // Fingertip-like: most contacts without a normal (zero), a few with one; below half, the
    // prior scores every contact by distance alone.
    for (std::size_t i = 0; i < scene.contacts.normals.size(); ++i)
      if (i % 3 != 0) scene.contacts.normals[i] = Vec3::Zero();
    const std::vector<double> score = prior.score(scene, {}, 1, 1);
    for (std::size_t o = 0; o < db.size(); ++o) {
      CAPTURE(o);
      REQUIRE(std::isfinite(score[o]));
      CHECK(std::abs(score[o] - oracle(o, scene)) <= 0.5 * std::abs(std::log(s.floor)) / 255.0 + 1e-9);
    }
    const std::vector<std::uint32_t> ranked = rank_by_prior(score);
    CAPTURE(src->infos[truths[k]].name);
    const auto at = std::find(ranked.begin(), ranked.end(), static_cast<std::uint32_t>(truths[k]));
    CHECK(at - ranked.begin() < 3);   // distances alone: near the top (form is weaker than with angles)
    first += ranked.front() == truths[k];
  }
  CHECK(first >= 3);
  // With at least half the contacts carrying a normal the angles are used, as before: the
  // score differs from the distances' one.
  Scene half = scene_of(samples[0], some_pose(7));
  for (std::size_t i = 0; i < half.contacts.normals.size(); i += 2) half.contacts.normals[i] = Vec3::Zero();
  const std::vector<double> with_angles = prior.score(half, {}, 1, 1);
  CHECK(std::isfinite(with_angles[0]));
  for (auto& n : half.contacts.normals) n = Vec3::Zero();
  CHECK(prior.score(half, {}, 1, 1)[0] != with_angles[0]);
}

TEST_CASE("Shape prior: the same histograms and scores for 1 and 2 threads; sampled scene pairs") {
  auto src = shapes();
  Database db(src);
  ShapePriorSettings s;
  s.object_points = 150;  // a sample of the keypoints
  s.scene_pairs = 300;    // fewer than the 60 x 59 / 2 pairs: drawn at random
  Rng rng(4);
  const Scene scene = scene_of(box({0.2, 0.15, 0.02}, 60, rng), some_pose(4));
  std::vector<double> one, two;
  tbb::task_arena(1).execute([&] { one = ShapePrior(db, s).score(scene, {}, 5, 2); });
  tbb::task_arena(2).execute([&] { two = ShapePrior(db, s).score(scene, {}, 5, 2); });
  CHECK(one == two);
  CHECK(rank_by_prior(one).front() == 1);  // the plate
  // Another draw of pairs changes the scores (the draw depends on the step).
  const std::vector<double> other = ShapePrior(db, s).score(scene, {}, 5, 3);
  CHECK(other != one);
}

TEST_CASE("Shape prior: settings out of range are refused naming the key") {
  auto src = shapes();
  Database db(src);
  auto refused = [&](ShapePriorSettings s, const std::string& field) {
    try {
      ShapePrior p(db, s);
    } catch (const Error& e) {
      CHECK(e.field() == field);
      return true;
    }
    return false;
  };
  ShapePriorSettings s;
  s.distance_bin = 0.0;
  CHECK(refused(s, "prior.distance_bin"));
  s = {};
  s.angle_bins = 0;
  CHECK(refused(s, "prior.angle_bins"));
  s = {};
  s.floor = 0.0;
  CHECK(refused(s, "prior.floor"));
  s = {};
  s.object_points = 1;
  CHECK(refused(s, "prior.object_points"));
}

TEST_CASE("Feature pruning with prior_draws: every triplet searches the preferred objects") {
  auto src = shapes();
  Database db(src);
  Rng rng(8);
  const PointCloud sample = box({0.2, 0.15, 0.02}, 80, rng);
  Scene scene = scene_of(sample, Pose::Identity());
  // Every point interior and a feature each: enough for triplets.
  scene.features.assign(scene.contacts.points.size(), Feature{});
  scene.feature_valid.assign(scene.contacts.points.size(), 1);
  scene.interior.assign(scene.contacts.points.size(), 1);
  scene.tree = KdTree3(scene.contacts.points);
  scene.diameter = 0.25;
  FeatureSearch search;
  search.table = FeatureTable::shared(db);
  RansacSettings rs;
  rs.triplets = 6;
  rs.registrations = 4;
  rs.prune_per_object = 5;
  rs.object_draws = 2;
  rs.min_spacing = 0.01;
  const std::vector<std::uint8_t> allowed(db.size(), 1);
  const std::vector<std::uint32_t> preferred = {4, 1, 0, 2, 3, 5, 6};
  rs.prior_draws = 1;
  RansacStats st;
  ransac_candidates(scene, db, search, allowed, rs, 1, 1, &st, preferred);
  REQUIRE(st.triplets == 6);
  // each triplet: object 4 and one object of its slice
  CHECK(st.objects_searched == 12);
  CHECK(st.searched[4] == 1);
  rs.prior_draws = 2;   // both draws: the two best, nothing else
  ransac_candidates(scene, db, search, allowed, rs, 1, 1, &st, preferred);
  CHECK(st.objects_searched == 12);
  for (std::uint32_t o = 0; o < db.size(); ++o) CHECK(st.searched[o] == (o == 4 || o == 1));
  rs.prior_draws = 0;   // no prior: slices of the shuffled order, every object once first
  ransac_candidates(scene, db, search, allowed, rs, 1, 1, &st, preferred);
  CHECK(std::count(st.searched.begin(), st.searched.end(), 1) == 7);
}
