#include "engine/recognition/ransac.hpp"
#include "engine/detail.hpp"

#include "engine/geometry/kabsch.hpp"
#include "engine/target_clones.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <numeric>
#include <chrono>
#include <cmath>
#include <numbers>
#include <optional>

namespace ts {
inline namespace recognition {

namespace {
using detail::seconds_since;

constexpr std::uint64_t kTagTriplet = 0x7121;
constexpr std::uint64_t kTagRegistration = 0x7e61;
constexpr std::uint64_t kTagObjects = 0x0b1e;

using Clock = std::chrono::steady_clock;

/// One pruned feature: which object, which coarse point.
struct Pruned {
  std::uint32_t object;
  std::uint32_t point;
};

/// Pruned features of one triplet point, grouped by object (ascending), nearest first within.
struct PrunedSet {
  std::vector<Pruned> items;
  std::vector<float> x, y, z;    ///< the items' coarse points (object frame), for fast scans
  std::vector<std::array<std::uint32_t, 3>> ranges;  ///< (object, begin, end)

  std::pair<std::uint32_t, std::uint32_t> range_of(std::uint32_t object) const {
    auto it = std::lower_bound(ranges.begin(), ranges.end(), object,
                               [](const auto& r, std::uint32_t o) { return r[0] < o; });
    if (it == ranges.end() || (*it)[0] != object) return {0, 0};
    return {(*it)[1], (*it)[2]};
  }
};

/// in[j] = 1 when the squared distance of item j to c lies in [lo, hi] (vectorized scan).
TS_TARGET_CLONES
void shell_mask(const float* __restrict x, const float* __restrict y, const float* __restrict z,
                std::uint32_t n, float cx, float cy, float cz, float lo, float hi,
                std::uint8_t* __restrict in) {
  for (std::uint32_t j = 0; j < n; ++j) {
    const float dx = x[j] - cx, dy = y[j] - cy, dz = z[j] - cz;
    const float d2 = dx * dx + dy * dy + dz * dz;
    in[j] = static_cast<std::uint8_t>((d2 >= lo) & (d2 <= hi));
  }
}

/// As shell_mask with two shells: in[j] = 1 for the items inside both, around c and around e.
TS_TARGET_CLONES
void shell_mask2(const float* __restrict x, const float* __restrict y, const float* __restrict z,
                 std::uint32_t n, float cx, float cy, float cz, float lo, float hi,
                 float ex, float ey, float ez, float lo2, float hi2, std::uint8_t* __restrict in) {
  for (std::uint32_t j = 0; j < n; ++j) {
    const float dx = x[j] - cx, dy = y[j] - cy, dz = z[j] - cz;
    const float d2 = dx * dx + dy * dy + dz * dz;
    const float fx = x[j] - ex, fy = y[j] - ey, fz = z[j] - ez;
    const float f2 = fx * fx + fy * fy + fz * fz;
    in[j] = static_cast<std::uint8_t>((d2 >= lo) & (d2 <= hi) & (f2 >= lo2) & (f2 <= hi2));
  }
}

/// The indices j < n with in[j] = 1, ascending, into out (room for n); returns how many.
/// Branch-free: every index is written and the count advances past the selected ones (a branch
/// per item mispredicts about as often as an item is inside the shell).
inline std::uint32_t selected(const std::uint8_t* __restrict in, std::uint32_t n, std::uint32_t* __restrict out) {
  std::uint32_t m = 0;
  for (std::uint32_t j = 0; j < n; ++j) {
    out[m] = j;
    m += in[j];
  }
  return m;
}

/// Sign-free angles of a point pair with normals: |n_a . n_b|, |n_a . u|, |n_b . u| (u the unit
/// chord), as cosines. Invariant to rigid motions and to flipped normals.
struct PairSignature {
  double nn = 0, na = 0, nb = 0;
};
inline PairSignature signature(const Vec3& pa, const Vec3& na, const Vec3& pb, const Vec3& nb) {
  const Vec3 u = (pb - pa).normalized();
  return {std::abs(na.dot(nb)), std::abs(na.dot(u)), std::abs(nb.dot(u))};
}
inline bool similar(const PairSignature& a, const PairSignature& b, double tol) {
  return std::abs(a.nn - b.nn) <= tol && std::abs(a.na - b.na) <= tol && std::abs(a.nb - b.nb) <= tol;
}

struct Triplet {
  bool valid = false;
  std::array<std::uint32_t, 3> point{};   ///< contact indices
  std::array<Vec3, 3> p;                  ///< scene frame
  KabschTarget target;                    ///< p, prepared for the registrations against it
  std::array<Vec3, 3> n;                  ///< scene normals
  PairSignature s12, s13, s23;
  double d12 = 0, d13 = 0, d23 = 0;
  std::array<PrunedSet, 3> pruned;
  std::vector<std::uint32_t> first;   ///< items of pruned[0] whose object is in all three sets
  bool from_boundary = false;   ///< drawn from all points, the interior gave no valid triplet
};

PrunedSet prune(const Database& db, const FeatureSearch& search, const std::vector<Neighbour>& nn,
                const std::vector<std::uint8_t>& allowed) {
  PrunedSet set;
  set.items.reserve(nn.size());
  for (const Neighbour& nb : nn) {
    const FeatureRef& r = search.ref(nb.index);
    if (r.object < allowed.size() && allowed[r.object]) set.items.push_back({r.object, r.point});
  }
  // Group by object, keeping the nearest-first order inside each group (per-object pruning
  // delivers them grouped already).
  const auto by_object = [](const Pruned& a, const Pruned& b) { return a.object < b.object; };
  if (!std::is_sorted(set.items.begin(), set.items.end(), by_object))
    std::stable_sort(set.items.begin(), set.items.end(), by_object);
  for (std::uint32_t i = 0; i < set.items.size();) {
    std::uint32_t j = i;
    while (j < set.items.size() && set.items[j].object == set.items[i].object) ++j;
    set.ranges.push_back({set.items[i].object, i, j});
    i = j;
  }
  const std::size_t n = set.items.size();
  set.x.resize(n);
  set.y.resize(n);
  set.z.resize(n);
  for (const auto& [object, b, e] : set.ranges) {
    const std::vector<Vec3>& points = db.keypoints(object).coarse.points;
    for (std::uint32_t i = b; i < e; ++i) {
      const Vec3& p = points[set.items[i].point];
      set.x[i] = static_cast<float>(p.x());
      set.y[i] = static_cast<float>(p.y());
      set.z[i] = static_cast<float>(p.z());
    }
  }
  return set;
}

std::optional<Candidate> register_once(const Triplet& t, const Database& db,
                                       const RansacSettings& s, Rng& rng,
                                       std::vector<std::uint32_t>& buf2,
                                       std::vector<std::uint32_t>& buf3,
                                       std::vector<std::uint8_t>& mask,
                                       std::vector<std::uint32_t>& inside) {
  const PrunedSet& F1 = t.pruned[0];
  const PrunedSet& F2 = t.pruned[1];
  const PrunedSet& F3 = t.pruned[2];
  if (F1.items.empty() || F2.items.empty() || F3.items.empty()) return std::nullopt;
  const double tol = s.distance_tolerance;
  const bool use_normals = s.normal_tolerance_deg > 0.0;
  const double ntol = std::sin(std::min(90.0, s.normal_tolerance_deg) * std::numbers::pi / 180.0);
  if (t.first.empty()) return std::nullopt;
  for (int attempt = 0; attempt < s.registration_attempts; ++attempt) {
    const Pruned& a = F1.items[t.first[rng.index(t.first.size())]];
    const PointCloud& coarse = db.keypoints(a.object).coarse;
    const std::vector<Vec3>& pts = coarse.points;
    const bool normals = use_normals && coarse.has_normals();
    const Vec3& q1 = pts[a.point];
    // Second point: same object, distance to the first matching the input's (and, as an
    // extension, the same angles between normals and chord). Squared distances against a
    // squared window, vectorized over the object's pruned items; the hits gathered branch-free.
    auto window = [&](double d) {
      const double lo = std::max(0.0, d - tol), hi = d + tol;
      return std::pair(static_cast<float>(lo * lo), static_cast<float>(hi * hi));
    };
    const auto [lo12, hi12] = window(t.d12);
    const auto [b2, e2] = F2.range_of(a.object);
    mask.resize(std::max(e2 - b2, 1u));
    inside.resize(mask.size());
    shell_mask(&F2.x[b2], &F2.y[b2], &F2.z[b2], e2 - b2, float(q1.x()), float(q1.y()), float(q1.z()), lo12, hi12,
               mask.data());
    const std::uint32_t n2 = selected(mask.data(), e2 - b2, inside.data());
    buf2.clear();
    for (std::uint32_t m = 0; m < n2; ++m) {
      const std::uint32_t k = F2.items[b2 + inside[m]].point;
      if (normals && !similar(signature(q1, coarse.normals[a.point], pts[k], coarse.normals[k]), t.s12, ntol))
        continue;
      buf2.push_back(k);
    }
    if (buf2.empty()) continue;
    const std::uint32_t k2 = buf2[rng.index(buf2.size())];
    const Vec3& q2 = pts[k2];
    const auto [lo13, hi13] = window(t.d13);
    const auto [lo23, hi23] = window(t.d23);
    const auto [b3, e3] = F3.range_of(a.object);
    mask.resize(std::max(e3 - b3, 1u));
    inside.resize(mask.size());
    shell_mask2(&F3.x[b3], &F3.y[b3], &F3.z[b3], e3 - b3, float(q1.x()), float(q1.y()), float(q1.z()), lo13, hi13,
                float(q2.x()), float(q2.y()), float(q2.z()), lo23, hi23, mask.data());
    const std::uint32_t n3 = selected(mask.data(), e3 - b3, inside.data());
    buf3.clear();
    for (std::uint32_t m = 0; m < n3; ++m) {
      const std::uint32_t k = F3.items[b3 + inside[m]].point;
      const Vec3& q = pts[k];
      if (normals &&
          (!similar(signature(q1, coarse.normals[a.point], q, coarse.normals[k]), t.s13, ntol) ||
           !similar(signature(q2, coarse.normals[k2], q, coarse.normals[k]), t.s23, ntol)))
        continue;
      buf3.push_back(k);
    }
    if (buf3.empty()) continue;
    const Vec3& q3 = pts[buf3[rng.index(buf3.size())]];
    if (!triangle_well_conditioned(q1, q2, q3, s.min_sv_ratio)) continue;
    const std::array<Vec3, 3> src{q1, q2, q3};
    const RigidFit fit = kabsch(src, t.target);
    if (!fit.valid) continue;
    Candidate c;
    c.object = a.object;
    c.T_scene_object = fit.T_target_source;
    return c;
  }
  return std::nullopt;
}

}  // namespace

std::vector<std::uint8_t> objects_spanning(const Scene& scene, const Database& db, double slack) {
  std::vector<std::uint8_t> allowed(db.size(), 1);
  for (std::size_t o = 0; o < db.size(); ++o)
    allowed[o] = db.info(o).extent.norm() + slack >= scene.diameter ? 1 : 0;
  return allowed;
}

FeatureIndex build_feature_index(const Database& db, const FeatureIndexSettings& settings,
                                 const std::vector<std::uint8_t>& objects) {
  FeatureRows features(descriptor_dim(db.settings().descriptor));
  std::vector<FeatureRef> refs;
  for (std::size_t o = 0; o < db.size(); ++o) {
    if (!objects.empty() && (o >= objects.size() || !objects[o])) continue;
    const ObjectFeatures f = db.load_features(o);
    if (!f.features.empty() && f.features.dim() != features.dim())
      throw Error("object '" + db.info(o).name + "' has features of " + std::to_string(f.features.dim()) +
                      " values, its database's descriptor (" + descriptor_name(db.settings().descriptor) + ") " +
                      std::to_string(features.dim()),
                  {}, "features");
    for (std::size_t i = 0; i < f.features.size(); ++i) {
      features.push_back(f.features.row(i));
      refs.push_back({static_cast<std::uint32_t>(o), static_cast<std::uint32_t>(i)});
    }
  }
  return FeatureIndex(std::move(features), std::move(refs), settings);
}

std::size_t FeatureSearch::size() const {
  return table ? table->features() : index ? index->size() : 0;
}

std::vector<std::vector<Neighbour>> FeatureSearch::knn_per_object(const FeatureRows& queries,
                                                                  std::size_t w,
                                                                  const std::vector<std::vector<std::uint8_t>>& masks,
                                                                  std::size_t max_blocks) const {
  if (!table) throw Error("per-object feature pruning needs the exact feature table", {}, "prune_per_object");
  return table->knn_per_object(queries, w, masks, max_blocks);
}

const FeatureRef& FeatureSearch::ref(std::size_t i) const {
  return table ? table->ref(i) : index->ref(i);
}

std::vector<std::vector<Neighbour>> FeatureSearch::knn(const FeatureRows& queries,
                                                       std::size_t w) const {
  if (table) return table->knn(queries, w);
  std::vector<std::vector<Neighbour>> out(queries.size());
  if (!index) return out;
  if (!queries.empty() && index->size() > 0 && queries.dim() != index->dim())
    throw Error("the query features have " + std::to_string(queries.dim()) + " values, the feature index " +
                    std::to_string(index->dim()) + " (another descriptor)",
                {}, "descriptor");
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, queries.size(), 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t q = r.begin(); q != r.end(); ++q) out[q] = index->knn(queries.row(q), w);
                    });
  return out;
}

namespace {

/// N triplets (one slot each), from the interior points with a feature first, all points with
/// a feature when no valid triplet can be drawn from the interior (small or narrow patches).
std::vector<Triplet> sample_triplets(const Scene& scene, const RansacSettings& s, int N, std::uint64_t seed,
                                     std::uint64_t step, const std::vector<std::uint32_t>& interior,
                                     const std::vector<std::uint32_t>& valid, double spacing) {
  std::vector<Triplet> trip(static_cast<std::size_t>(N));
  tbb::parallel_for(tbb::blocked_range<int>(0, N, 1), [&](const tbb::blocked_range<int>& r) {
    for (int i = r.begin(); i != r.end(); ++i) {
      Triplet& t = trip[static_cast<std::size_t>(i)];
      Rng rng(seed, step, kTagTriplet, static_cast<std::uint64_t>(i));
      for (int a = 0; a < 2 * s.triplet_attempts && !t.valid; ++a) {
        const bool inner = a < s.triplet_attempts && interior.size() >= 3;
        if (!inner && a < s.triplet_attempts) continue;
        const std::vector<std::uint32_t>& pool = inner ? interior : valid;
        t.from_boundary = !inner;
        std::array<std::uint32_t, 3> k{};
        for (auto& x : k) x = pool[rng.index(pool.size())];
        const Vec3 &p1 = scene.contacts.points[k[0]], &p2 = scene.contacts.points[k[1]],
                   &p3 = scene.contacts.points[k[2]];
        const double d12 = (p2 - p1).norm(), d13 = (p3 - p1).norm(), d23 = (p3 - p2).norm();
        if (d12 < spacing || d13 < spacing || d23 < spacing) continue;
        if (!triangle_well_conditioned(p1, p2, p3, s.min_sv_ratio)) continue;
        t.valid = true;
        t.point = k;
        t.p = {p1, p2, p3};
        t.target = KabschTarget(t.p);
        t.n = {scene.contacts.normals[k[0]], scene.contacts.normals[k[1]], scene.contacts.normals[k[2]]};
        t.s12 = signature(p1, t.n[0], p2, t.n[1]);
        t.s13 = signature(p1, t.n[0], p3, t.n[2]);
        t.s23 = signature(p2, t.n[1], p3, t.n[2]);
        t.d12 = d12;
        t.d13 = d13;
        t.d23 = d23;
      }
    }
  });
  return trip;
}

/// The objects each triplet's pruning searches (object draws). Without draws (or with no more
/// allowed objects than draws): every allowed object. With them: consecutive slices of one
/// shuffled order of the database (the same for every step of a run), each triplet D =
/// object_draws objects on from where the previous one stopped, each step on from where the
/// previous step stopped: every allowed object is searched once before any is searched twice.
/// With a shape prior, the first prior_draws of the draws are the same best objects for every
/// triplet, and the slices (of the other objects) are that much shorter.
class ObjectDraws {
 public:
  ObjectDraws(const std::vector<std::uint8_t>& allowed, const RansacSettings& s, std::uint64_t seed,
              std::uint64_t step, std::size_t triplets, const std::vector<std::uint32_t>& preferred)
      : allowed_(allowed), slice_(s.object_draws) {
    std::size_t n_allowed = 0;
    for (std::uint8_t a : allowed) n_allowed += a ? 1 : 0;
    draw_ = s.object_draws > 0 && n_allowed > s.object_draws;
    if (!draw_) return;
    common_.assign(allowed.size(), 0);
    if (s.prior_draws > 0) {
      std::size_t taken = 0;
      for (std::uint32_t o : preferred) {
        if (taken == std::min(s.prior_draws, s.object_draws)) break;
        if (o < allowed.size() && allowed[o] && !common_[o]) {
          common_[o] = 1;
          ++taken;
        }
      }
      slice_ -= taken;
    }
    std::vector<std::uint32_t> all(allowed.size());
    std::iota(all.begin(), all.end(), 0u);
    Rng rng(seed, 0, kTagObjects, 0);
    for (std::size_t k = all.size(); k > 1; --k) std::swap(all[k - 1], all[rng.index(k)]);
    for (std::uint32_t o : all)
      if (allowed[o] && !common_[o]) order_.push_back(o);
    if (!order_.empty())
      offset_ = (static_cast<std::size_t>(step > 0 ? step - 1 : 0) * triplets * slice_) % order_.size();
  }

  /// The objects triplet i searches.
  std::vector<std::uint8_t> mask(std::size_t i) const {
    if (!draw_) return allowed_;
    std::vector<std::uint8_t> m = common_;   // the common objects and this triplet's slice
    if (!order_.empty())
      for (std::size_t d = 0; d < std::min(slice_, order_.size()); ++d)
        m[order_[(offset_ + i * slice_ + d) % order_.size()]] = 1;
    return m;
  }

 private:
  const std::vector<std::uint8_t>& allowed_;
  bool draw_ = false;
  std::vector<std::uint8_t> common_;
  std::size_t slice_;
  std::vector<std::uint32_t> order_;
  std::size_t offset_ = 0;
};

/// Feature-based database pruning: the W nearest database features of every valid triplet's
/// points (all queries of the step in one batch), then each point's pruned set and the first
/// features registration may draw (among objects that all three sets reach).
void prune_triplets(std::vector<Triplet>& trip, const Scene& scene, const Database& db, const FeatureSearch& search,
                    const std::vector<std::uint8_t>& allowed, const RansacSettings& s, const ObjectDraws& draws,
                    RansacStats& st) {
  FeatureRows queries(scene.features.dim());
  std::vector<std::vector<std::uint8_t>> masks;  // per-object pruning: the objects searched
  for (std::size_t i = 0; i < trip.size(); ++i) {
    const Triplet& t = trip[i];
    if (!t.valid) continue;
    const std::vector<std::uint8_t> mask = draws.mask(i);
    st.objects_searched += static_cast<std::size_t>(std::count(mask.begin(), mask.end(), 1));
    st.searched.resize(mask.size(), 0);
    for (std::size_t o = 0; o < mask.size(); ++o) st.searched[o] |= mask[o];
    for (int j = 0; j < 3; ++j) {
      queries.push_back(scene.features.row(t.point[j]));
      masks.push_back(mask);
    }
  }
  const std::size_t blocks = db.size() > s.prune_blocks_min_database ? s.prune_blocks : 0;
  const auto nearest = s.prune_per_object > 0 ? search.knn_per_object(queries, s.prune_per_object, masks, blocks)
                                               : search.knn(queries, s.prune_w);
  std::vector<std::array<std::size_t, 2>> jobs;  // (triplet, first query)
  std::size_t q = 0;
  for (std::size_t i = 0; i < trip.size(); ++i)
    if (trip[i].valid) {
      jobs.push_back({i, q});
      q += 3;
    }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, jobs.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t k = r.begin(); k != r.end(); ++k) {
      Triplet& t = trip[jobs[k][0]];
      for (int j = 0; j < 3; ++j) t.pruned[j] = prune(db, search, nearest[jobs[k][1] + j], allowed);
      for (const auto& [o, b, e] : t.pruned[0].ranges) {
        const auto r2 = t.pruned[1].range_of(o), r3 = t.pruned[2].range_of(o);
        if (r2.second > r2.first && r3.second > r3.first)
          for (std::uint32_t i = b; i < e; ++i) t.first.push_back(i);
      }
    }
  });
}

/// Triplet registration, one slot per (triplet, registration); the valid ones in slot order.
std::vector<std::optional<Candidate>> register_triplets(const std::vector<Triplet>& trip, const Database& db,
                                                        const RansacSettings& s, std::size_t R,
                                                        std::uint64_t seed, std::uint64_t step) {
  const std::size_t slots = trip.size() * R;
  std::vector<std::optional<Candidate>> cand(slots);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, slots, 16), [&](const tbb::blocked_range<std::size_t>& r) {
    std::vector<std::uint32_t> buf2, buf3;
    std::vector<std::uint8_t> mask;
    std::vector<std::uint32_t> inside;
    for (std::size_t k = r.begin(); k != r.end(); ++k) {
      const std::size_t i = k / R;
      if (!trip[i].valid) continue;
      Rng rng(seed, step, kTagRegistration, k);
      cand[k] = register_once(trip[i], db, s, rng, buf2, buf3, mask, inside);
      if (cand[k]) cand[k]->slot = static_cast<std::uint32_t>(k);
    }
  });
  return cand;
}

}  // namespace

std::vector<Candidate> ransac_candidates(const Scene& scene, const Database& db,
                                         const FeatureSearch& search,
                                         const std::vector<std::uint8_t>& allowed,
                                         const RansacSettings& s, std::uint64_t seed,
                                         std::uint64_t step, RansacStats* stats,
                                         const std::vector<std::uint32_t>& preferred) {
  RansacStats st;
  for (std::uint8_t a : allowed) st.objects_allowed += a;
  std::vector<Candidate> out;
  const int N = std::max(0, s.triplets), R = std::max(0, s.registrations);
  std::vector<std::uint32_t> interior, valid;   // the sampling pools
  for (std::uint32_t i = 0; i < scene.contacts.size(); ++i) {
    if (!scene.feature_valid[i]) continue;
    valid.push_back(i);
    if (scene.interior[i]) interior.push_back(i);
  }
  if (valid.size() < 3 || N == 0 || R == 0 || search.size() == 0 || st.objects_allowed == 0) {
    if (stats) *stats = st;
    return out;
  }
  const double spacing = std::min(s.min_spacing > 0.0 ? s.min_spacing : scene.feature_radius,
                                  0.3 * scene.diameter);

  auto t0 = Clock::now();
  std::vector<Triplet> trip = sample_triplets(scene, s, N, seed, step, interior, valid, spacing);
  const ObjectDraws draws(allowed, s, seed, step, trip.size(), preferred);
  prune_triplets(trip, scene, db, search, allowed, s, draws, st);
  st.time_prune_s = seconds_since(t0);
  for (const Triplet& t : trip) {
    st.triplets += t.valid;
    if (t.valid && t.from_boundary) st.boundary_fallback = true;
    if (t.valid)
      for (const PrunedSet& ps : t.pruned) st.pruned += ps.items.size();
  }

  t0 = Clock::now();
  const std::vector<std::optional<Candidate>> cand =
      register_triplets(trip, db, s, static_cast<std::size_t>(R), seed, step);
  st.time_register_s = seconds_since(t0);
  std::vector<std::uint8_t> reached(db.size(), 0);
  for (const auto& c : cand) {
    if (!c) continue;
    reached[c->object] = 1;
    out.push_back(*c);
  }
  st.registrations = out.size();
  for (std::uint8_t r : reached) st.objects_reached += r;
  if (stats) *stats = st;
  return out;
}

}  // namespace recognition
}  // namespace ts
