#include "engine/recognition/sparse_hypotheses.hpp"
#include "engine/detail.hpp"

#include "engine/geometry/cloud.hpp"
#include "engine/geometry/kabsch.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <tuple>
#include <numbers>

namespace ts {
inline namespace recognition {

namespace {

constexpr std::uint64_t kSparseStream = 0x5350415253450000ull;  // "SPARSE"

double angle_between(const Vec3& a, const Vec3& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

/// The invariant angles of an oriented point pair (Drost et al. 2010): angle(n_a, d),
/// angle(n_b, d), angle(n_a, n_b), d = b - a.
struct PairAngles {
  double a = 0.0, b = 0.0, ab = 0.0;
};
PairAngles pair_angles(const Vec3& pa, const Vec3& na, const Vec3& pb, const Vec3& nb) {
  const Vec3 d = pb - pa;
  return {angle_between(na, d), angle_between(nb, d), angle_between(na, nb)};
}

/// Angles in the table's units (pi / 255).
int angle_units(double rad) {
  return static_cast<int>(std::lround(std::clamp(rad, 0.0, std::numbers::pi) * 255.0 / std::numbers::pi));
}

/// angle_units(std::atan2(y, x)) for y >= 0, bit for bit, at a fraction of its cost: a table of
/// 600 points takes 359 400 pairs and three angles a pair, and std::atan2 was a third of a
/// one-shot recognition's time. The angle comes from Abramowitz and Stegun's 4.4.49 polynomial
/// (|error| <= 2e-8 rad, 1.6e-6 of a unit); where the scaled angle lies within 1e-4 of a unit
/// of a rounding boundary, which that error could cross, it is computed exactly instead (about
/// 2 angles in 10 000).
/// angle_units of an angle `rad` known within 2e-8 rad of atan2(y, x); std::atan2 itself where
/// that error could change the rounding.
[[gnu::always_inline]] inline std::uint8_t rounded_units(double rad, double y, double x) {
  const double v = rad * 255.0 / std::numbers::pi;   // >= 0
  const int whole = static_cast<int>(v);
  const double part = v - whole;
  if (std::abs(part - 0.5) < 1e-4) [[unlikely]]
    return static_cast<std::uint8_t>(angle_units(std::atan2(y, x)));
  return static_cast<std::uint8_t>(std::min(whole + (part > 0.5 ? 1 : 0), 255));
}

/// angle_units(std::atan2(y, x)) and angle_units(std::atan2(y, -x)) for y >= 0 and x != 0 (a
/// pair's angle from either end), bit for bit, at a fraction of std::atan2's cost.
[[gnu::always_inline]] inline void angle_units_both(double y, double x, std::uint8_t& plus, std::uint8_t& minus) {
  const double ax = std::abs(x);
  const double hi = std::max(ax, y), lo = std::min(ax, y);
  if (!(hi > 0.0 && hi <= std::numeric_limits<double>::max())) {
    plus = static_cast<std::uint8_t>(angle_units(std::atan2(y, x)));
    minus = static_cast<std::uint8_t>(angle_units(std::atan2(y, -x)));
    return;
  }
  // atan(z), z in [0, 1]; the polynomial in z^2 evaluated by Estrin's scheme (short dependency
  // chains, so the angles of several pairs overlap).
  const double z = lo / hi, z2 = z * z, z4 = z2 * z2, z8 = z4 * z4;
  const double p01 = 1.0 + z2 * -0.3333314528, p23 = 0.1999355085 + z2 * -0.1420889944;
  const double p45 = 0.1065626393 + z2 * -0.0752896400, p67 = 0.0429096138 + z2 * -0.0161657367;
  const double p = (p01 + z4 * p23) + z8 * ((p45 + z4 * p67) + z8 * 0.0028662257);
  double a = z * p;                                  // the angle of (y, |x|), in [0, pi/2]
  if (y > ax) a = std::numbers::pi / 2 - a;
  const double obtuse = std::numbers::pi - a;
  plus = rounded_units(x < 0.0 ? obtuse : a, y, x);
  minus = rounded_units(x < 0.0 ? a : obtuse, y, -x);
}

struct ContactTriplet {
  std::uint32_t k[3] = {0, 0, 0};
};

/// A well-conditioned triplet of contacts with sides >= min_side, or none.
bool draw_triplet(const std::vector<Vec3>& pts, double min_side, const SparseSettings& s, Rng& rng,
                  ContactTriplet& out) {
  const std::size_t n = pts.size();
  if (n < 3) return false;
  for (int attempt = 0; attempt < s.triplet_attempts; ++attempt) {
    const std::size_t a = rng.index(n), b = rng.index(n), c = rng.index(n);
    if (a == b || b == c || a == c) continue;
    if ((pts[a] - pts[b]).norm() < min_side || (pts[b] - pts[c]).norm() < min_side ||
        (pts[a] - pts[c]).norm() < min_side)
      continue;
    if (!triangle_well_conditioned(pts[a], pts[b], pts[c], s.min_sv_ratio)) continue;
    // The longest side first: its distance is the most selective in the pair table.
    std::uint32_t k[3] = {static_cast<std::uint32_t>(a), static_cast<std::uint32_t>(b),
                          static_cast<std::uint32_t>(c)};
    const double dab = (pts[a] - pts[b]).squaredNorm(), dbc = (pts[b] - pts[c]).squaredNorm(),
                 dca = (pts[c] - pts[a]).squaredNorm();
    if (dbc >= dab && dbc >= dca) k[0] = b, k[1] = c, k[2] = a;
    else if (dca >= dab && dca >= dbc) k[0] = c, k[1] = a, k[2] = b;
    std::copy(k, k + 3, out.k);
    return true;
  }
  return false;
}



/// One contact triplet against one object's table: its sides in the table's distance units
/// (integer bounds: a stored distance u matches a side d when d - tol <= u * unit <= d + tol)
/// and its point-pair angles in the table's angle units.
struct TripletQuery {
  Vec3 p[3], n[3];
  bool normals = false;
  int lo01 = 0, hi01 = -1, lo02 = 0, hi02 = -1;
  double d12 = 0.0;
  int sa = 0, sb = 0, sab = 0, ta = 0, tb = 0, tab = 0;
};

TripletQuery make_query(const ObjectPairs& T, const Vec3 (&p)[3], const Vec3 (&n)[3], bool normals,
                        const SparseSettings& s) {
  TripletQuery q;
  std::copy(p, p + 3, q.p);
  std::copy(n, n + 3, q.n);
  q.normals = normals;
  const double tol = s.distance_tolerance;
  const double d01 = (p[1] - p[0]).norm(), d02 = (p[2] - p[0]).norm();
  q.d12 = (p[2] - p[1]).norm();
  auto units = [&](double d) { return std::clamp(d / T.unit, 0.0, 65535.0); };
  // u >= lo (real) is u >= ceil(lo); u <= hi is u <= floor(hi): the same pairs, in integers.
  // A side that is not a number matches nothing.
  auto bounds = [&](double d, int& lo, int& hi) {
    const double l = units(d - tol), h = units(d + tol);
    if (!(l <= h)) return;   // NaN (or a negative tolerance): lo 0 > hi -1
    lo = static_cast<int>(std::ceil(l)), hi = static_cast<int>(std::floor(h));
  };
  bounds(d01, q.lo01, q.hi01);
  bounds(d02, q.lo02, q.hi02);
  if (normals) {
    const PairAngles a = pair_angles(p[0], n[0], p[1], n[1]);
    q.sa = angle_units(a.a), q.sb = angle_units(a.b), q.sab = angle_units(a.ab);
    const PairAngles c = pair_angles(p[0], n[0], p[2], n[2]);   // the third side, from contact 0
    q.ta = angle_units(c.a), q.tb = angle_units(c.b), q.tab = angle_units(c.ab);
  }
  return q;
}

using Row = std::vector<ObjectPairs::Near>::const_iterator;
Row first_at_least(Row row, Row end, int v) {
  return std::lower_bound(row, end, v, [](const ObjectPairs::Near& x, int w) { return x.distance < w; });
}

/// The oriented model pairs (i on contact 0, j on contact 1) that agree with each query's
/// longest side (distance, and the point-pair angles where the contacts have normals), in row
/// order. One sweep over the rows serves all the queries: each row is read from memory once a
/// step and searched once a query while it is in cache (the searches, one row fetched from
/// memory each, were most of the source's time).
std::vector<std::vector<std::pair<std::uint16_t, std::uint16_t>>> matched_pairs(
    const ObjectPairs& T, const std::vector<TripletQuery>& queries, int utol) {
  std::vector<std::vector<std::pair<std::uint16_t, std::uint16_t>>> matched(queries.size());
  const std::size_t m = T.points.size();
  for (std::size_t i = 0; i < m; ++i) {
    const Row row = T.near.begin() + static_cast<std::ptrdiff_t>(i * (m - 1));
    const Row end = row + static_cast<std::ptrdiff_t>(m - 1);
    for (std::size_t k = 0; k < queries.size(); ++k) {
      const TripletQuery& q = queries[k];
      for (Row it = first_at_least(row, end, q.lo01); it != end && it->distance <= q.hi01; ++it) {
        if (q.normals && (std::abs(q.sab - it->a_ij) > utol || std::abs(q.sa - it->a_i) > utol ||
                          std::abs(q.sb - it->a_j) > utol))
          continue;
        matched[k].emplace_back(static_cast<std::uint16_t>(i), it->index);
      }
    }
  }
  return matched;
}

/// Candidates of one (triplet, object): a deterministic random subset of its matched pairs, then
/// the model points closing the triangle (from the first point's sorted row), registered by
/// Kabsch and checked on the normals.
void close_triangles(const ObjectPairs& T, const TripletQuery& q,
                     std::vector<std::pair<std::uint16_t, std::uint16_t>>& matched, int utol,
                     const SparseSettings& s, Rng& rng, std::vector<Pose>& out) {
  const std::size_t m = T.points.size();
  const double tol = s.distance_tolerance;
  const double cos_ntol = std::cos(s.normal_tolerance_deg * std::numbers::pi / 180.0);
  // A deterministic random subset of them (partial Fisher-Yates).
  const std::size_t take = std::min(matched.size(), s.pairs_per_triplet);
  for (std::size_t k = 0; k < take; ++k) std::swap(matched[k], matched[k + rng.index(matched.size() - k)]);
  KabschSettings ks;
  ks.min_sv_ratio = s.min_sv_ratio;
  for (std::size_t k = 0; k < take && out.size() < s.per_object; ++k) {
    const auto [i, j] = matched[k];
    const Row row = T.near.begin() + static_cast<std::ptrdiff_t>(std::size_t{i} * (m - 1));
    const Row end = row + static_cast<std::ptrdiff_t>(m - 1);
    for (Row it = first_at_least(row, end, q.lo02); it != end && it->distance <= q.hi02 && out.size() < s.per_object; ++it) {
      const std::size_t r = it->index;
      if (r == j) continue;
      if (q.normals && (std::abs(q.tab - it->a_ij) > utol || std::abs(q.ta - it->a_i) > utol || std::abs(q.tb - it->a_j) > utol))
        continue;
      if (std::abs((T.points[r] - T.points[j]).norm() - q.d12) > tol) continue;
      const Vec3 src[3] = {T.points[i], T.points[j], T.points[r]};
      const RigidFit fit = kabsch(std::span<const Vec3>(src, 3), std::span<const Vec3>(q.p, 3), {}, ks);
      if (!fit.valid) continue;
      if (q.normals) {
        const Mat3 R = fit.T_target_source.linear();
        const std::size_t idx[3] = {i, j, r};
        bool ok = true;
        for (int c = 0; c < 3 && ok; ++c) ok = (R * T.normals[idx[c]]).dot(q.n[c]) >= cos_ntol;
        if (!ok) continue;
      }
      out.push_back(fit.T_target_source);
    }
  }
}

}  // namespace

ObjectPairs build_object_pairs(const ObjectKeypoints& keypoints, const SparseSettings& s) {
  ObjectPairs out;
  const std::size_t cap = std::min<std::size_t>(s.max_model_points, 65535);
  PointCloud thin;
  for (double voxel = s.model_spacing; ; voxel *= 1.5) {
    thin = voxel_filter(keypoints.coarse, voxel);
    if (thin.size() <= cap) break;
  }
  out.points = thin.points;
  out.normals = thin.has_normals() ? thin.normals : std::vector<Vec3>(thin.size(), Vec3::Zero());
  const std::size_t n = out.points.size();
  if (n < 2) return out;
  double largest = 0.0;
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j) largest = std::max(largest, (out.points[i] - out.points[j]).norm());
  out.unit = std::max(largest, 1e-9) / 65535.0;
  out.near.reserve(n * (n - 1));
  // Row i: every j != i sorted by (distance, index), each with angle(n_i, d), angle(n_j, d) and
  // angle(n_i, n_j) of d = p_j - p_i (pair_angles, in units). Each unordered pair is measured
  // once, for both rows: from j's end, d is exactly -d (its norm and cross products' norms the
  // same, its dot products negated), so angle(n_j, -d) and angle(n_i, -d) are atan2 of the same
  // numbers with x negated. A dot product of exactly 0 (its sign is then not the negation's) and
  // a cross product whose norm differs either way round (fused multiply-adds) are measured
  // again as the row's own. Then each row is sorted as 32-bit keys (distance, index).
  std::vector<std::uint16_t> distance(n * n);
  std::vector<std::array<std::uint8_t, 3>> angles(n * n);
  auto measure = [&](std::size_t i, std::size_t j) {   // row i's entry j, as pair_angles would
    const Vec3 d = out.points[j] - out.points[i];
    const Vec3& ni = out.normals[i];
    const Vec3& nj = out.normals[j];
    std::uint8_t ignored = 0;
    auto& e = angles[i * n + j];
    angle_units_both(ni.cross(d).norm(), ni.dot(d), e[0], ignored);
    angle_units_both(nj.cross(d).norm(), nj.dot(d), e[1], ignored);
    angle_units_both(ni.cross(nj).norm(), ni.dot(nj), e[2], ignored);
  };
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3& p_i = out.points[i];
    const Vec3& ni = out.normals[i];
    for (std::size_t j = i + 1; j < n; ++j) {
      const Vec3 d = out.points[j] - p_i;
      const Vec3& nj = out.normals[j];
      const auto units = static_cast<std::uint16_t>(std::lround(std::min((p_i - out.points[j]).norm() / out.unit, 65535.0)));
      distance[i * n + j] = distance[j * n + i] = units;
      const double si = ni.dot(d), sj = nj.dot(d), sij = ni.dot(nj);
      if (si == 0.0 || sj == 0.0 || sij == 0.0) {
        measure(i, j);
        measure(j, i);
        continue;
      }
      const double ci = ni.cross(d).norm(), cj = nj.cross(d).norm(), cij = ni.cross(nj).norm();
      auto& row_i = angles[i * n + j];
      auto& row_j = angles[j * n + i];
      angle_units_both(ci, si, row_i[0], row_j[1]);   // angle(n_i, d); from j: angle(n_i, -d)
      angle_units_both(cj, sj, row_i[1], row_j[0]);   // angle(n_j, d); from j: angle(n_j, -d)
      std::uint8_t ignored = 0;
      angle_units_both(cij, sij, row_i[2], ignored);
      if (nj.cross(ni).norm() == cij)
        row_j[2] = row_i[2];
      else
        angle_units_both(nj.cross(ni).norm(), nj.dot(ni), row_j[2], ignored);
    }
  }
  // Each row sorted by (distance, index): j taken in increasing order, then a stable radix sort
  // on the distance's low byte and on its high byte.
  std::vector<std::uint16_t> order(n - 1), by_low(n - 1);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint16_t* row = distance.data() + i * n;
    std::size_t k = 0;
    for (std::size_t j = 0; j < n; ++j)
      if (j != i) order[k++] = static_cast<std::uint16_t>(j);
    for (const int shift : {0, 8}) {
      std::array<std::uint32_t, 257> start{};
      for (const std::uint16_t j : order) ++start[((row[j] >> shift) & 0xffu) + 1];
      for (std::size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
      for (const std::uint16_t j : order) by_low[start[(row[j] >> shift) & 0xffu]++] = j;
      order.swap(by_low);
    }
    for (const std::uint16_t j : order) {
      const auto& a = angles[i * n + j];
      out.near.push_back({row[j], j, a[0], a[1], a[2], 0});
    }
  }
  return out;
}

std::size_t ObjectPairs::memory_bytes() const {
  return points.size() * 2 * sizeof(Vec3) + near.size() * sizeof(Near);
}

SparseTables::SparseTables(const Database& db, SparseSettings settings)
    : db_(db), s_(settings), tables_(db.size()), last_wanted_(db.size(), 0) {}

std::shared_ptr<SparseTables> SparseTables::shared(const Database& db, const SparseSettings& s) {
  // Keyed by the database's address and what a table or the cache depends on; weak, so the
  // tables live only while used (as ShapePrior::shared).
  using Key = std::tuple<const Database*, double, std::size_t, double>;
  static std::mutex mutex;
  static std::map<Key, std::weak_ptr<SparseTables>> cache;
  std::lock_guard<std::mutex> lock(mutex);
  for (auto it = cache.begin(); it != cache.end();) it = it->second.expired() ? cache.erase(it) : std::next(it);
  auto& slot = cache[Key{&db, s.model_spacing, s.max_model_points, s.table_budget_mb}];
  if (auto p = slot.lock()) return p;
  auto p = std::make_shared<SparseTables>(db, s);
  slot = p;
  return p;
}

std::size_t SparseTables::held_bytes() const {
  std::lock_guard lock(mutex_);
  return held_;
}

SparseTables::View SparseTables::prepare(const std::vector<std::uint8_t>& wanted) {
  auto is_wanted = [&](std::size_t o) { return wanted.empty() || (o < wanted.size() && wanted[o]); };
  // The wanted tables held now go into the view at once: held by it, another caller's
  // prepare() cannot drop them while this one builds the missing.
  View view(tables_.size());
  std::vector<std::size_t> missing;
  {
    std::lock_guard lock(mutex_);
    ++calls_;
    for (std::size_t o = 0; o < tables_.size(); ++o) {
      if (!is_wanted(o)) continue;
      last_wanted_[o] = calls_;
      if (tables_[o]) view[o] = tables_[o];
      else missing.push_back(o);
    }
  }
  // Built outside the lock. A table is a function of the object's keypoints alone, so two
  // callers that build the same one build the same table; the first installed is kept.
  std::vector<std::shared_ptr<const ObjectPairs>> built(missing.size());
  detail::parallel_each(missing.size(), 1, [&](std::size_t k) {
    built[k] = std::make_shared<const ObjectPairs>(build_object_pairs(db_.keypoints(missing[k]), s_));
  });
  std::lock_guard lock(mutex_);
  for (std::size_t k = 0; k < missing.size(); ++k) {
    auto& table = tables_[missing[k]];
    if (!table) table = std::move(built[k]);
    view[missing[k]] = table;
  }
  held_ = 0;
  for (const auto& t : tables_)
    if (t) held_ += t->memory_bytes();
  // Large databases (the shape prior's best objects change from step to step): beyond the
  // budget, the least recently wanted tables nobody uses are dropped until the rest fit, so the
  // cache holds at most the budget plus what its callers use at once. A dropped table comes
  // back bit for bit.
  const double budget = s_.table_budget_mb * 1024.0 * 1024.0;
  if (static_cast<double>(held_) > budget) {
    std::vector<std::size_t> idle;
    for (std::size_t o = 0; o < tables_.size(); ++o)
      if (tables_[o] && !is_wanted(o) && tables_[o].use_count() == 1) idle.push_back(o);
    std::sort(idle.begin(), idle.end(), [&](std::size_t a, std::size_t b) {
      return last_wanted_[a] != last_wanted_[b] ? last_wanted_[a] < last_wanted_[b] : a < b;
    });
    for (std::size_t k = 0; k < idle.size() && static_cast<double>(held_) > budget; ++k) {
      held_ -= tables_[idle[k]]->memory_bytes();
      tables_[idle[k]].reset();
    }
  }
  return view;
}

std::size_t isolated_contacts(const Scene& scene) {
  std::size_t n = 0;
  std::vector<Neighbour> near;
  for (std::size_t i = 0; i < scene.contacts.size(); ++i) {
    if (i < scene.feature_valid.size() && scene.feature_valid[i]) continue;
    scene.tree.radius(scene.contacts.points[i], scene.feature_radius, near, false);
    n += near.size() <= 1;   // itself alone
  }
  return n;
}

namespace {
/// sparse_active with the scene's isolated contacts already counted.
bool active_with(const Scene& scene, const SparseSettings& s, std::size_t iso) {
  if (s.mode == kSparseNever || scene.contacts.size() < 3) return false;
  if (s.mode == kSparseAlways) return true;
  return iso >= s.min_isolated && static_cast<double>(iso) >= s.min_isolated_share * static_cast<double>(scene.contacts.size());
}
}  // namespace

bool sparse_active(const Scene& scene, const SparseSettings& s) {
  return active_with(scene, s, s.mode == kSparseAuto ? isolated_contacts(scene) : 0);
}

std::vector<Vec3> scene_contact_normals(const Scene& scene, const PointCloud& contacts_world) {
  if (!contacts_world.has_normals()) return {};
  std::vector<Vec3> local;
  std::vector<std::size_t> index;
  for (std::size_t i = 0; i < contacts_world.size(); ++i)
    if (contacts_world.points[i].allFinite()) {
      local.push_back(contacts_world.points[i] - scene.origin);
      index.push_back(i);
    }
  if (local.empty()) return {};
  const KdTree3 tree(local);
  std::vector<Vec3> out(scene.contacts.size(), Vec3::Zero());
  for (std::size_t k = 0; k < scene.contacts.size(); ++k) {
    const Neighbour nb = tree.nearest(scene.contacts.points[k]);
    if (nb.sq_distance > 1e-12) continue;   // the scene moved or merged it: unknown
    const Vec3& nw = contacts_world.normals[index[nb.index]];
    const double len = nw.norm();
    if (std::isfinite(len) && len > 0.5) out[k] = nw / len;
  }
  return out;
}

std::vector<Vec3> sparse_contact_normals(const Scene& scene, const PointCloud& contacts_world,
                                         const SparseSettings& s) {
  std::vector<Vec3> n = scene_contact_normals(scene, contacts_world);
  if (n.empty() && s.mode == kSparseAlways) n = scene.contacts.normals;
  return n;
}

std::vector<Candidate> sparse_candidates(const Scene& scene, SparseTables& tables,
                                         const std::vector<Vec3>& contact_normals,
                                         const std::vector<std::uint8_t>& allowed,
                                         const SparseSettings& s, std::uint64_t seed,
                                         std::uint64_t step, SparseStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  SparseStats st;
  st.isolated = isolated_contacts(scene);
  std::vector<Candidate> out;
  auto finish = [&] {
    st.candidates = out.size();
    st.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (stats) *stats = st;
    return out;
  };
  if (!active_with(scene, s, st.isolated)) return finish();
  st.active = true;
  const std::vector<Vec3>& pts = scene.contacts.points;
  const bool with_normals = contact_normals.size() == pts.size();

  // Triplets (serial: few draws, one stream).
  Rng rng(seed, step, kSparseStream);
  const double min_side = std::max(2.0 * s.distance_tolerance, s.min_side_share * scene.diameter);
  std::vector<ContactTriplet> triplets;
  for (int t = 0; t < s.triplets; ++t) {
    ContactTriplet tr;
    if (draw_triplet(pts, min_side, s, rng, tr)) triplets.push_back(tr);
  }
  st.triplets = triplets.size();
  std::vector<std::uint32_t> objects;
  for (std::uint32_t o = 0; o < allowed.size(); ++o)
    if (allowed[o]) objects.push_back(o);
  if (triplets.empty() || objects.empty()) return finish();
  const SparseTables::View view = tables.prepare(allowed);

  // Each task sweeps one object's table once for a group of the triplets (all of them when
  // there are enough objects to keep the threads busy; a few objects split them, so that
  // `--only NAME` is not left to one thread). Each (triplet, object) draws from its own stream
  // and fills its own slot, so the candidates depend on neither the grouping nor the order.
  const std::size_t tasks = triplets.size() * objects.size();
  std::vector<std::vector<Pose>> slots(tasks);
  const int utol = angle_units(s.normal_tolerance_deg * std::numbers::pi / 180.0);
  const std::size_t groups = std::clamp<std::size_t>((16 + objects.size() - 1) / objects.size(), 1, triplets.size());
  detail::parallel_each(objects.size() * groups, 1, [&](std::size_t job) {
    const std::size_t k = job / groups, g = job % groups;
    const std::size_t t0 = g * triplets.size() / groups, t1 = (g + 1) * triplets.size() / groups;
    const ObjectPairs& T = *view[objects[k]];
    if (T.points.size() < 3 || !(T.unit > 0.0)) return;
    std::vector<TripletQuery> queries;
    for (std::size_t t = t0; t < t1; ++t) {
      Vec3 p[3], n[3];
      bool normals = with_normals;
      for (int q = 0; q < 3; ++q) {
        p[q] = pts[triplets[t].k[q]];
        n[q] = with_normals ? contact_normals[triplets[t].k[q]] : Vec3::Zero();
        normals = normals && n[q].squaredNorm() > 0.0;
      }
      queries.push_back(make_query(T, p, n, normals, s));
    }
    auto matched = matched_pairs(T, queries, utol);
    for (std::size_t t = t0; t < t1; ++t) {
      const std::size_t task = t * objects.size() + k;
      Rng r(seed, step, kSparseStream + 1, task);
      close_triangles(T, queries[t - t0], matched[t - t0], utol, s, r, slots[task]);
    }
  });
  std::uint32_t slot = kSparseSlot;
  for (std::size_t task = 0; task < tasks; ++task)
    for (const Pose& T : slots[task]) {
      Candidate c;
      c.object = objects[task % objects.size()];
      c.T_scene_object = T;
      c.slot = slot++;
      out.push_back(c);
    }
  return finish();
}

double mean_contact_distance(const ObjectGeometry& geometry, const Pose& T_world_object,
                             const std::vector<Vec3>& contacts_world) {
  if (contacts_world.empty()) return std::numeric_limits<double>::quiet_NaN();
  const Pose T_object_world = T_world_object.inverse();
  double sum = 0.0;
  for (const Vec3& c : contacts_world) sum += std::abs(geometry.field.distance(T_object_world * c));
  return sum / static_cast<double>(contacts_world.size());
}

}  // namespace recognition
}  // namespace ts
