#include "engine/recognition/sparse_hypotheses.hpp"
#include "engine/detail.hpp"

#include "engine/geometry/cloud.hpp"
#include "engine/geometry/kabsch.hpp"
#include "engine/target_clones.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
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
  KabschTarget target;   ///< p, prepared for the registrations against it
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
  q.target = KabschTarget(std::span<const Vec3>(p, 3));
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
    q.sa = pair_angle_units(a.a), q.sb = pair_angle_units(a.b), q.sab = pair_angle_units(a.ab);
    const PairAngles c = pair_angles(p[0], n[0], p[2], n[2]);   // the third side, from contact 0
    q.ta = pair_angle_units(c.a), q.tb = pair_angle_units(c.b), q.tab = pair_angle_units(c.ab);
  }
  return q;
}

using Row = std::vector<ObjectPairs::Near>::const_iterator;
Row first_at_least(Row row, Row end, int v) {
  return std::lower_bound(row, end, v, [](const ObjectPairs::Near& x, int w) { return x.distance < w; });
}

/// Whether a table entry's point-pair angles agree with a query's (sa, sb, sab) within utol
/// (>= 0): |a - s| <= utol exactly when 0 <= a - s + utol <= 2 utol.
[[gnu::always_inline]] inline bool angles_agree(const ObjectPairs::Near& e, int sa, int sb, int sab, int utol) {
  const auto width = static_cast<unsigned>(2 * utol);
  return (static_cast<unsigned>(e.a_ij - sab + utol) <= width) & (static_cast<unsigned>(e.a_i - sa + utol) <= width) &
         (static_cast<unsigned>(e.a_j - sb + utol) <= width);
}

/// How many of a row's n entries agree with the angles (branch-free: about half of them do, at
/// random).
TS_TARGET_CLONES
std::uint32_t count_agreeing(const ObjectPairs::Near* __restrict row, std::size_t n, int sa, int sb, int sab,
                             int utol) {
  std::uint32_t count = 0;
  for (std::size_t k = 0; k < n; ++k) count += angles_agree(row[k], sa, sb, sab, utol) ? 1u : 0u;
  return count;
}

/// One query's matched model pairs (i on contact 0, j on contact 1: the entries of row i whose
/// distance lies in the query's longest side's band and, where the contacts have normals, whose
/// angles agree), in row order, without listing them: per row, its band [begin, end) and how many
/// pairs the rows before it matched. A (triplet, object) matches thousands of pairs and keeps 48
/// at random; writing them all out was half the source's time.
struct MatchedPairs {
  std::vector<std::uint16_t> begin, end;   ///< per row, the band's entries
  std::vector<std::uint32_t> before;       ///< per row (and one past the last), pairs in rows before
  std::uint32_t size() const { return before.empty() ? 0 : before.back(); }
};

/// Each query's matched pairs. One sweep over the rows serves all the queries: each row is read
/// from memory once a step and searched once a query while it is in cache (the searches, one row
/// fetched from memory each, were most of the source's time).
std::vector<MatchedPairs> matched_pairs(const ObjectPairs& T, const std::vector<TripletQuery>& queries, int utol) {
  const std::size_t m = T.points.size();
  std::vector<MatchedPairs> matched(queries.size());
  for (MatchedPairs& mp : matched) {
    mp.begin.assign(m, 0);
    mp.end.assign(m, 0);
    mp.before.assign(m + 1, 0);
  }
  for (std::size_t i = 0; i < m; ++i) {
    const Row row = T.near.begin() + static_cast<std::ptrdiff_t>(i * (m - 1));
    const Row end = row + static_cast<std::ptrdiff_t>(m - 1);
    for (std::size_t k = 0; k < queries.size(); ++k) {
      const TripletQuery& q = queries[k];
      MatchedPairs& mp = matched[k];
      const Row first = first_at_least(row, end, q.lo01);
      Row last = first;
      while (last != end && last->distance <= q.hi01) ++last;
      const auto n = static_cast<std::size_t>(last - first);
      mp.begin[i] = static_cast<std::uint16_t>(first - row);
      mp.end[i] = static_cast<std::uint16_t>(last - row);
      const std::uint32_t count = q.normals ? count_agreeing(T.near.data() + (first - T.near.begin()), n, q.sa, q.sb, q.sab, utol)
                                            : static_cast<std::uint32_t>(n);
      mp.before[i + 1] = mp.before[i] + count;
    }
  }
  return matched;
}

/// The matched pair at `position` (< mp.size()) of the row-order list.
std::pair<std::uint16_t, std::uint16_t> matched_pair(const ObjectPairs& T, const TripletQuery& q,
                                                     const MatchedPairs& mp, std::uint32_t position, int utol) {
  const std::size_t m = T.points.size();
  // The row: the last whose pairs before it are at most `position` (rows without pairs skipped).
  const auto i = static_cast<std::size_t>(std::upper_bound(mp.before.begin(), mp.before.end(), position) -
                                          mp.before.begin() - 1);
  const ObjectPairs::Near* row = T.near.data() + i * (m - 1);
  std::uint32_t left = position - mp.before[i];
  for (std::size_t x = mp.begin[i]; x < mp.end[i]; ++x) {
    if (q.normals && !angles_agree(row[x], q.sa, q.sb, q.sab, utol)) continue;
    if (left-- == 0) return {static_cast<std::uint16_t>(i), row[x].index};
  }
  throw Error("sparse candidates: a matched pair's position beyond its row (internal)");
}

/// Candidates of one (triplet, object): a deterministic random subset of its matched pairs, then
/// the model points closing the triangle (from the first point's sorted row), registered by
/// Kabsch and checked on the normals.
void close_triangles(const ObjectPairs& T, const TripletQuery& q, const MatchedPairs& mp, int utol,
                     const SparseSettings& s, Rng& rng, std::vector<Pose>& out) {
  const std::size_t m = T.points.size();
  const double tol = s.distance_tolerance;
  const double cos_ntol = std::cos(s.normal_tolerance_deg * std::numbers::pi / 180.0);
  // A deterministic random subset of them: a partial Fisher-Yates shuffle of the positions of the
  // row-order list (the positions it moves kept aside), the pairs then read at the positions
  // drawn.
  const std::uint32_t size = mp.size();
  const std::size_t take = std::min<std::size_t>(size, s.pairs_per_triplet);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> moved;   // (position, what it now holds)
  auto held = [&](std::uint32_t p) {
    for (const auto& [at, v] : moved)
      if (at == p) return v;
    return p;
  };
  auto hold = [&](std::uint32_t p, std::uint32_t v) {
    for (auto& [at, w] : moved)
      if (at == p) {
        w = v;
        return;
      }
    moved.emplace_back(p, v);
  };
  std::vector<std::uint32_t> drawn(take);
  for (std::size_t k = 0; k < take; ++k) {
    const auto r = static_cast<std::uint32_t>(k + rng.index(size - k));
    const std::uint32_t vk = held(static_cast<std::uint32_t>(k)), vr = held(r);
    hold(static_cast<std::uint32_t>(k), vr);
    hold(r, vk);
    drawn[k] = vr;
  }
  KabschSettings ks;
  ks.min_sv_ratio = s.min_sv_ratio;
  for (std::size_t k = 0; k < take && out.size() < s.per_object; ++k) {
    const auto [i, j] = matched_pair(T, q, mp, drawn[k], utol);
    const Row row = T.near.begin() + static_cast<std::ptrdiff_t>(std::size_t{i} * (m - 1));
    const Row end = row + static_cast<std::ptrdiff_t>(m - 1);
    for (Row it = first_at_least(row, end, q.lo02); it != end && it->distance <= q.hi02 && out.size() < s.per_object; ++it) {
      const std::size_t r = it->index;
      if (r == j) continue;
      if (q.normals && (std::abs(q.tab - it->a_ij) > utol || std::abs(q.ta - it->a_i) > utol || std::abs(q.tb - it->a_j) > utol))
        continue;
      if (std::abs((T.points[r] - T.points[j]).norm() - q.d12) > tol) continue;
      const Vec3 src[3] = {T.points[i], T.points[j], T.points[r]};
      const RigidFit fit = kabsch(std::span<const Vec3>(src, 3), q.target, ks);
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
  const int utol = pair_angle_units(s.normal_tolerance_deg * std::numbers::pi / 180.0);
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
