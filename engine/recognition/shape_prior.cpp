#include "engine/recognition/shape_prior.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <numeric>
#include <tuple>

namespace ts {
inline namespace recognition {

namespace {

constexpr std::uint64_t kTagPrior = 0x7072696f72ULL;  // "prior"
constexpr std::uint8_t kEmpty = 255;                   // code of an empty bin: ln(floor)

bool has_normal(const Vec3& n) { return n.squaredNorm() > 0.5; }

/// Angle bin of a pair (x, y, z as in the header), or -1 for coincident points.
int angle_bin(const Vec3& pa, const Vec3& na, const Vec3& pb, const Vec3& nb, int bins, double& d) {
  const Vec3 v = pb - pa;
  d = v.norm();
  if (!(d > 0.0)) return -1;
  const Vec3 u = v / d;
  const double ca = std::abs(na.dot(u)), cb = std::abs(nb.dot(u)), cn = std::abs(na.dot(nb));
  auto q = [bins](double c) { return std::clamp(static_cast<int>(c * bins), 0, bins - 1); };
  return (q(std::min(ca, cb)) * bins + q(std::max(ca, cb))) * bins + q(cn);
}

void prior_check_settings(const ShapePriorSettings& settings, std::size_t mask, std::size_t objects) {
  if (!(settings.distance_bin > 0.0) || !std::isfinite(settings.distance_bin))
    throw Error("shape prior: distance_bin must be positive", {}, "prior.distance_bin");
  if (settings.angle_bins < 1 || settings.angle_bins > 64)
    throw Error("shape prior: angle_bins must be in [1, 64]", {}, "prior.angle_bins");
  if (!(settings.floor > 0.0 && settings.floor < 1.0))
    throw Error("shape prior: floor must be in (0, 1)", {}, "prior.floor");
  if (settings.object_points < 2)
    throw Error("shape prior: object_points must be at least 2", {}, "prior.object_points");
  if (mask != 0 && mask != objects)
    throw Error("shape prior: object mask has " + std::to_string(mask) + " entries, the database " +
                std::to_string(objects) + " objects", {}, "objects");
}

/// Object o's pair histogram into h (D distance bins x `angles`, each pair split linearly
/// between the two distance bins whose centres bracket it) over at most object_points of its
/// coarse points with normals (a uniform sample, the same on every run); its total weight, 0
/// without a pair. `pick` is scratch.
double prior_object_histogram(const PointCloud& coarse, std::size_t o, std::size_t D, std::size_t angles,
                              const ShapePriorSettings& settings, std::vector<double>& h,
                              std::vector<std::uint32_t>& pick) {
  pick.clear();
  for (std::uint32_t i = 0; i < coarse.points.size(); ++i)
    if (i < coarse.normals.size() && has_normal(coarse.normals[i])) pick.push_back(i);
  if (pick.size() > settings.object_points) {
    Rng rng(kTagPrior, o);
    for (std::size_t k = 0; k < settings.object_points; ++k)
      std::swap(pick[k], pick[k + rng.index(pick.size() - k)]);
    pick.resize(settings.object_points);
    std::sort(pick.begin(), pick.end());
  }
  h.assign(D * angles, 0.0);
  double total = 0.0;
  for (std::size_t a = 0; a < pick.size(); ++a)
    for (std::size_t b = a + 1; b < pick.size(); ++b) {
      double d = 0.0;
      const int ab = angle_bin(coarse.points[pick[a]], coarse.normals[pick[a]], coarse.points[pick[b]],
                               coarse.normals[pick[b]], settings.angle_bins, d);
      if (ab < 0 || d < settings.min_pair_distance) continue;
      // Linear split between the bins whose centres ((k + 1/2) bin) bracket d.
      const double f = d / settings.distance_bin - 0.5;
      const double k0 = std::floor(f), w1 = f - k0;
      for (int j = 0; j < 2; ++j) {
        const double k = k0 + j;
        const double w = j == 0 ? 1.0 - w1 : w1;
        if (k < 0.0 || k >= static_cast<double>(D) || w <= 0.0) continue;
        h[static_cast<std::size_t>(k) * angles + static_cast<std::size_t>(ab)] += w;
        total += w;
      }
    }
  return total;
}

}  // namespace

struct ShapePrior::Impl {
  ShapePriorSettings s;
  std::size_t angles = 0;                 // angle_bins^3
  std::vector<std::uint32_t> dbins;       // per object: distance bins of its histogram (0: none)
  std::vector<std::size_t> offset;        // per object: first code
  std::vector<std::uint8_t> codes;        // round(255 ln(p + floor) / ln(floor)), bin-major
  // The distances' marginal (the angles summed out), for contacts without normals: per object
  // dbins codes from dist_offset (the D2 shape distribution of Osada et al. 2002).
  std::vector<std::size_t> dist_offset;
  std::vector<std::uint8_t> dist_codes;
};

ShapePrior::ShapePrior(const Database& db, const ShapePriorSettings& settings,
                       const std::vector<std::uint8_t>& objects)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.s = settings;
  prior_check_settings(settings, objects.size(), db.size());
  const auto A = static_cast<std::size_t>(settings.angle_bins);
  m.angles = A * A * A;
  const std::size_t n = db.size();
  m.dbins.assign(n, 0);
  for (std::size_t o = 0; o < n; ++o) {
    if (!objects.empty() && !objects[o]) continue;
    const double diag = db.info(o).extent.norm();
    // Bins up to the object's diagonal (with the linear split, a pair of length diag reaches
    // bin floor(diag / bin)); a coarse cloud wider than its box extent is clamped below.
    m.dbins[o] = static_cast<std::uint32_t>(std::min(1.0e6, std::floor(diag / settings.distance_bin))) + 1;
  }
  m.offset.assign(n + 1, 0);
  for (std::size_t o = 0; o < n; ++o) m.offset[o + 1] = m.offset[o] + m.dbins[o] * m.angles;
  m.codes.assign(m.offset[n], kEmpty);
  m.dist_offset.assign(n + 1, 0);
  for (std::size_t o = 0; o < n; ++o) m.dist_offset[o + 1] = m.dist_offset[o] + m.dbins[o];
  m.dist_codes.assign(m.dist_offset[n], kEmpty);
  const double ln_floor = std::log(settings.floor);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1), [&](const tbb::blocked_range<std::size_t>& r) {
    std::vector<double> h;
    std::vector<std::uint32_t> pick;
    for (std::size_t o = r.begin(); o != r.end(); ++o) {
      const std::size_t D = m.dbins[o];
      if (D == 0) continue;
      const double total = prior_object_histogram(db.keypoints(o).coarse, o, D, m.angles, settings, h, pick);
      if (!(total > 0.0)) continue;  // no pair: every bin stays empty
      std::uint8_t* out = &m.codes[m.offset[o]];
      auto code = [&](double p) {
        const double c = 255.0 * std::log(p + settings.floor) / ln_floor;
        return static_cast<std::uint8_t>(std::clamp(std::lround(c), 0L, 255L));
      };
      for (std::size_t i = 0; i < h.size(); ++i) out[i] = code(h[i] / total);
      std::uint8_t* dist = &m.dist_codes[m.dist_offset[o]];
      for (std::size_t k = 0; k < D; ++k) {
        double sum = 0.0;
        for (std::size_t a = 0; a < m.angles; ++a) sum += h[k * m.angles + a];
        dist[k] = code(sum / total);
      }
    }
  });
}

ShapePrior::~ShapePrior() = default;
ShapePrior::ShapePrior(ShapePrior&&) noexcept = default;
ShapePrior& ShapePrior::operator=(ShapePrior&&) noexcept = default;

std::size_t ShapePrior::size() const { return impl_->dbins.size(); }

std::vector<double> ShapePrior::score(const Scene& scene, const std::vector<std::uint8_t>& allowed,
                                      std::uint64_t seed, std::uint64_t step) const {
  const Impl& m = *impl_;
  const std::size_t n = m.dbins.size();
  constexpr double kNone = -std::numeric_limits<double>::infinity();
  std::vector<double> out(n, kNone);
  // The contact pairs: every pair when there are few, else scene_pairs drawn at random. When
  // fewer than half the contacts have a normal (isolated points: fingertips, a probe, a
  // points-only cloud), every contact, scored on the distances alone.
  std::vector<std::uint32_t> with;
  for (std::uint32_t i = 0; i < scene.contacts.points.size(); ++i)
    if (i < scene.contacts.normals.size() && has_normal(scene.contacts.normals[i])) with.push_back(i);
  const bool distances_only = 2 * with.size() < scene.contacts.points.size();
  if (distances_only) {
    with.resize(scene.contacts.points.size());
    std::iota(with.begin(), with.end(), 0u);
  }
  std::vector<std::pair<std::uint32_t, std::uint32_t>> pairs;  // (distance bin, angle bin)
  auto add = [&](std::uint32_t a, std::uint32_t b) {
    double d = 0.0;
    const int ab = distances_only ? ((d = (scene.contacts.points[b] - scene.contacts.points[a]).norm()) > 0.0 ? 0 : -1)
                                  : angle_bin(scene.contacts.points[a], scene.contacts.normals[a],
                                              scene.contacts.points[b], scene.contacts.normals[b], m.s.angle_bins, d);
    if (ab < 0 || d < m.s.min_pair_distance) return false;
    pairs.emplace_back(static_cast<std::uint32_t>(std::min(4.0e9, std::floor(d / m.s.distance_bin))),
                       static_cast<std::uint32_t>(ab));
    return true;
  };
  const std::size_t w = with.size();
  if (w < 2 || m.s.scene_pairs == 0) return out;
  if (w * (w - 1) / 2 <= m.s.scene_pairs) {
    for (std::size_t a = 0; a < w; ++a)
      for (std::size_t b = a + 1; b < w; ++b) add(with[a], with[b]);
  } else {
    Rng rng(seed, step, kTagPrior);
    for (std::size_t tries = 0; pairs.size() < m.s.scene_pairs && tries < 20 * m.s.scene_pairs; ++tries) {
      const std::size_t a = rng.index(w), b = rng.index(w);
      if (a != b) add(with[a], with[b]);
    }
  }
  if (pairs.empty()) return out;
  const double per_code = std::log(m.s.floor) / 255.0 / static_cast<double>(pairs.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 16), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t o = r.begin(); o != r.end(); ++o) {
      if (m.dbins[o] == 0 || (!allowed.empty() && !allowed[o])) continue;
      std::uint64_t sum = 0;
      if (distances_only) {
        const std::uint8_t* h = &m.dist_codes[m.dist_offset[o]];
        for (const auto& [db, ab] : pairs) sum += db < m.dbins[o] ? h[db] : kEmpty;
      } else {
        const std::uint8_t* h = &m.codes[m.offset[o]];
        for (const auto& [db, ab] : pairs)
          sum += db < m.dbins[o] ? h[static_cast<std::size_t>(db) * m.angles + ab] : kEmpty;
      }
      out[o] = per_code * static_cast<double>(sum);
    }
  });
  return out;
}

std::shared_ptr<const ShapePrior> ShapePrior::shared(const Database& db, const ShapePriorSettings& s,
                                                     const std::vector<std::uint8_t>& objects) {
  // Keyed by the database's address, the settings and the mask; weak, so a prior lives only
  // while used (as FeatureTable::shared).
  using Key = std::tuple<const Database*, double, int, std::size_t, std::size_t, double, double,
                         std::vector<std::uint8_t>>;
  static std::mutex mutex;
  static std::map<Key, std::weak_ptr<const ShapePrior>> cache;
  std::lock_guard<std::mutex> lock(mutex);
  auto& slot = cache[Key{&db, s.distance_bin, s.angle_bins, s.object_points, s.scene_pairs, s.min_pair_distance,
                         s.floor, objects}];
  if (auto p = slot.lock()) return p;
  auto p = std::make_shared<const ShapePrior>(db, s, objects);
  slot = p;
  return p;
}

std::vector<std::uint32_t> rank_by_prior(const std::vector<double>& score) {
  std::vector<std::uint32_t> order;
  for (std::uint32_t o = 0; o < score.size(); ++o)
    if (std::isfinite(score[o])) order.push_back(o);
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return score[a] != score[b] ? score[a] > score[b] : a < b;
  });
  return order;
}

}  // namespace recognition
}  // namespace ts
