#include "engine/recognition/support.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <utility>
#include <string>

namespace ts::inline recognition {

namespace {

constexpr std::uint64_t kStreamSupport = 0x73757070ULL;   // "supp"

struct Plane {
  Vec3 normal = Vec3::UnitZ();
  Vec3 point = Vec3::Zero();
  double rms = 0.0;   ///< m, RMS distance of the fitted points from it
};

/// The least-squares plane of `points` (PCA); false with fewer than 3 points or no plane.
bool fit_plane(const std::vector<Vec3>& points, Plane& out) {
  if (points.size() < 3) return false;
  Vec3 c = Vec3::Zero();
  for (const Vec3& p : points) c += p;
  c /= static_cast<double>(points.size());
  Mat3 cov = Mat3::Zero();
  for (const Vec3& p : points) cov += (p - c) * (p - c).transpose();
  cov /= static_cast<double>(points.size());
  const Eigen::SelfAdjointEigenSolver<Mat3> eig(cov);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues()[1] > 0.0)) return false;   // a line or a spot
  out.normal = eig.eigenvectors().col(0).normalized();
  out.point = c;
  out.rms = std::sqrt(std::max(0.0, eig.eigenvalues()[0]));
  return true;
}

/// Per grasp, the plane of its patch when flat within half the tolerance (RMS), else a plane
/// with a zero normal.
std::vector<Plane> flat_patches(const GraspGroups& grasps, double tolerance) {
  std::vector<Plane> out(grasps.grasps(), Plane{Vec3::Zero(), Vec3::Zero(), 0.0});
  for (std::size_t g = 0; g < grasps.grasps(); ++g) {
    const std::vector<Vec3> patch(grasps.points.begin() + grasps.first[g], grasps.points.begin() + grasps.first[g + 1]);
    Plane p;
    if (fit_plane(patch, p) && p.rms < 0.5 * tolerance) out[g] = p;
  }
  return out;
}

/// Appends the free points of grasp g's hand (none when unknown) to `out`.
void add_hand_free_points(const GraspGroups& grasps, std::size_t g, std::vector<const Vec3*>& out) {
  if (g + 1 < grasps.free_first.size())
    for (std::uint32_t i = grasps.free_first[g]; i < grasps.free_first[g + 1]; ++i) out.push_back(&grasps.free[i]);
}

void check(const SupportSettings& s) {
  auto require = [](bool ok, const char* key, const char* what) {
    if (!ok) throw Error(std::string(key) + " " + what, {}, key);
  };
  require(std::isfinite(s.tolerance) && s.tolerance > 0 && s.tolerance <= 0.1, "support.tolerance",
          "must lie in (0, 0.1] m");
  require(s.min_contacts >= 3, "support.min_contacts", "must be at least 3");
  require(std::isfinite(s.above_share) && s.above_share > 0.5 && s.above_share <= 1, "support.above_share",
          "must lie in (0.5, 1]");
  require(std::isfinite(s.free_margin) && s.free_margin <= 1, "support.free_margin", "must be at most 1 m");
  require(std::isfinite(s.min_radius) && s.min_radius > 0 && s.min_radius <= 10, "support.min_radius",
          "must lie in (0, 10] m");
  require(std::isfinite(s.attribution) && s.attribution > 0 && s.attribution <= 1, "support.attribution",
          "must lie in (0, 1] m");
  require(std::isfinite(s.sink) && s.sink >= 0 && s.sink <= 1, "support.sink", "must lie in [0, 1] m");
  require(std::isfinite(s.sink_cost) && s.sink_cost >= 0 && s.sink_cost <= 100, "support.sink_cost",
          "must lie in [0, 100]");
}

/// Up for a plane through `centre` with normal `n`: the side of the witnesses (free points of
/// the hands that touched it, or free space near it) farther than `tolerance` from it, by a
/// clear majority (4 to 1); 0 when they do not say.
int free_side(const Vec3& n, const Vec3& centre, const std::vector<const Vec3*>& witnesses, double tolerance) {
  long above = 0, below = 0;
  for (const Vec3* w : witnesses) {   // (those on the plane, e.g. a pad pressed on it, say nothing)
    const double d = n.dot(*w - centre);
    above += d > tolerance;
    below += d < -tolerance;
  }
  if (above + below == 0) return 0;
  if (above >= 4 * below) return 1;
  if (below >= 4 * above) return -1;
  return 0;
}

/// The contacts beyond the tolerance above a candidate support (`height`: signed, up or outside
/// positive), or none when too few lie off it (min_contacts) or too few of those lie above it
/// (above_share): the object rests on its support, while a face of the object has the rest of
/// the object behind it. (Below counts from the tolerance, not from SupportSurface::kBelow
/// tolerances as the contacts it explains do: an object's face would then hide the object's
/// contacts just behind it, and more of them pass for a support.)
template <class Height>
std::optional<std::size_t> rest_above(const PointCloud& contacts, const SupportSettings& s, Height height) {
  std::size_t above = 0, below = 0;
  for (const Vec3& p : contacts.points) {
    const double d = height(p);
    above += d >= s.tolerance;
    below += d <= -s.tolerance;
  }
  if (above + below < s.min_contacts || static_cast<double>(above) < s.above_share * static_cast<double>(above + below))
    return std::nullopt;
  return above;
}

struct Judge {
  const PointCloud& contacts;
  const GraspGroups& grasps;
  const std::vector<Vec3>& free;
  const SupportSettings& s;

  /// The candidate `plane` refitted and judged; found = false when it is not a support.
  SupportSurface operator()(Plane plane) const {
    SupportSurface out;
    out.verdict = SupportVerdict::few_contacts;
    const double tol = s.tolerance;
    auto within = [&](const Plane& q, double band) {
      std::vector<Vec3> near;
      for (const Vec3& p : contacts.points)
        if (std::abs(q.normal.dot(p - q.point)) < band) near.push_back(p);
      return near;
    };
    // Gathered within twice the tolerance first: a patch of a few contacts in a strip (a pad
    // that met the seabed with its edge) gives a normal a few degrees off, which a contact 10 cm
    // away sees as more than the tolerance. Then refitted twice, to those within the tolerance.
    std::vector<Vec3> on = within(plane, 2.0 * tol);
    if (on.size() < s.min_contacts || !fit_plane(on, plane)) return out;
    on = within(plane, tol);
    if (on.size() >= 3 && fit_plane(on, plane)) on = within(plane, tol);   // those of the refitted plane
    out.contacts_on = on.size();
    if (on.size() < s.min_contacts) return out;
    // The disc its contacts span (about their centroid, in the plane).
    Vec3 c = Vec3::Zero();
    for (const Vec3& p : on) c += p;
    c /= static_cast<double>(on.size());
    double radius = 0.0;
    for (const Vec3& p : on) {
      const Vec3 d = p - c;
      radius = std::max(radius, (d - plane.normal.dot(d) * plane.normal).norm());
    }
    // Grasps on it, and the free points of their hands as witnesses of the free side.
    std::vector<const Vec3*> witnesses;
    std::size_t grasps_on = 0;
    for (std::size_t g = 0; g < grasps.grasps(); ++g) {
      const std::uint32_t a = grasps.first[g], b = grasps.first[g + 1];
      if (b - a < 3) continue;
      std::size_t near = 0;
      for (std::uint32_t i = a; i < b; ++i) near += std::abs(plane.normal.dot(grasps.points[i] - c)) < tol;
      if (10 * near < 8 * (b - a)) continue;   // 80 % of the patch on the plane
      ++grasps_on;
      add_hand_free_points(grasps, g, witnesses);
    }
    out.verdict = SupportVerdict::few_grasps;
    if (!grasps.empty() && grasps_on < s.min_grasps) return out;
    out.verdict = SupportVerdict::side_unclear;
    const double reach = radius + 0.05;
    if (witnesses.empty())
      for (const Vec3& q : free)
        if ((q - c).norm() < reach) witnesses.push_back(&q);
    const int side = free_side(plane.normal, c, witnesses, tol);
    if (side == 0) return out;
    const Vec3 n = side * plane.normal;
    // The rest above it, and no free space below it where it was touched.
    out.verdict = SupportVerdict::rest_not_above;
    const std::optional<std::size_t> above = rest_above(contacts, s, [&](const Vec3& p) { return n.dot(p - c); });
    if (!above) return out;
    out.verdict = SupportVerdict::free_behind;
    const double margin = s.free_margin >= 0.0 ? s.free_margin : s.tolerance;
    std::size_t free_near = 0, free_below = 0;
    for (const Vec3& q : free) {
      const Vec3 d = q - c;
      const double h = n.dot(d);
      if ((d - h * n).norm() > radius) continue;
      ++free_near;
      free_below += h < -margin;
    }
    if (free_near > 0 && 50 * free_below > free_near) return out;   // more than 2 % below
    out.found = true;
    out.verdict = SupportVerdict::found;
    out.normal = n;
    out.offset = n.dot(c);
    out.contacts_above = *above;
    out.grasps_on = grasps_on;
    return out;
  }
};


/// Why nothing was found: the verdict of the candidate with the most contacts on it (the first of
/// those), the one most likely the support.
struct Largest {
  SupportVerdict verdict;
  std::size_t contacts = 0;
  explicit Largest(bool none) : verdict(none ? SupportVerdict::no_candidate : SupportVerdict::few_contacts) {}
  void add(const SupportSurface& j) {
    if (j.contacts_on > contacts) contacts = j.contacts_on, verdict = j.verdict;
  }
  /// Into `best` when it was not found: the verdict and the contacts on that candidate.
  void report(SupportSurface& best) const {
    if (best.found) return;   // its judge said found
    best.verdict = verdict;
    best.contacts_on = contacts;
  }
};

// A cylinder: unit axis `a` through `p`, radius `r`.
struct Cylinder {
  Vec3 a = Vec3::UnitX();
  Vec3 p = Vec3::Zero();
  double r = 0.0;
  double distance(const Vec3& x) const {   ///< signed, positive outside
    const Vec3 d = x - p;
    return (d - a.dot(d) * a).norm() - r;
  }
};

/// A unit vector across `a` (any).
Vec3 across(const Vec3& a) { return (std::abs(a.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(a).normalized(); }

/// The cylinder two surface elements (point c, normal n) span, or false: their normals meet at
/// more than 15 degrees, their normal lines meet (within the plane across the axis) and the two
/// radii agree within `agree`.
bool cylinder_through(const Vec3& c1, const Vec3& n1, const Vec3& c2, const Vec3& n2, double agree, Cylinder& out) {
  Vec3 a = n1.cross(n2);
  if (!(a.norm() > std::sin(15.0 * std::numbers::pi / 180.0))) return false;
  a.normalize();
  // In the plane across a: c1 + t n1 = c2 + u n2 (least squares; n1, n2 lie across a).
  const Vec3 d = (c2 - c1) - a.dot(c2 - c1) * a;
  const double k = n1.dot(n2);
  const double det = 1.0 - k * k;
  const double t = (n1.dot(d) - k * n2.dot(d)) / det;
  const double u = (k * n1.dot(d) - n2.dot(d)) / det;
  if (std::abs(std::abs(t) - std::abs(u)) > agree) return false;
  out.a = a;
  out.p = c1 + t * n1;
  out.r = 0.5 * (std::abs(t) + std::abs(u));
  return std::isfinite(out.r);
}

/// The circle (centre, radius) of `q` (2-D points), refined from `c`, `r` by Gauss-Newton on
/// the distances; false when it does not converge (a step under 1e-9 m within 20) to a finite
/// circle, e.g. points all at one place.
bool fit_circle(const std::vector<Eigen::Vector2d>& q, Eigen::Vector2d& c, double& r) {
  for (int it = 0; it < 20; ++it) {
    Mat3 JtJ = Mat3::Zero();
    Vec3 Jtr = Vec3::Zero();
    for (const Eigen::Vector2d& x : q) {
      const Eigen::Vector2d d = x - c;
      const double n = d.norm();
      if (!(n > 0.0)) continue;
      const Vec3 J(-d.x() / n, -d.y() / n, -1.0);   // d(|x - c| - r) / d(cx, cy, r)
      const double res = n - r;
      JtJ += J * J.transpose();
      Jtr += J * res;
    }
    const Eigen::LDLT<Mat3> ldlt(JtJ);
    if (ldlt.info() != Eigen::Success) return false;
    const Vec3 step = ldlt.solve(-Jtr);
    if (!step.allFinite()) return false;
    c += step.head<2>();
    r += step.z();
    if (step.norm() < 1e-9) return std::isfinite(r) && r > 0.0;
  }
  return false;
}

struct CylinderJudge {
  const PointCloud& contacts;
  const GraspGroups& grasps;
  const std::vector<Vec3>& free;
  const SupportSettings& s;
  const std::vector<Plane>& patches;   ///< per grasp (normal zero: no plane)
  static constexpr double kMaxRadius = 10.0;

  bool radius_ok(double r) const { return r >= std::max(s.min_radius, 2.0 * s.tolerance) && r <= kMaxRadius; }

  /// Whether normal `n` at `x` lies across the cylinder's surface (within 25 degrees of its
  /// radial direction there, either way): a face the cylinder merely grazes does not.
  static bool radial(const Cylinder& c, const Vec3& x, const Vec3& n) {
    const Vec3 d = x - c.p;
    const Vec3 r = d - c.a.dot(d) * c.a;
    return std::abs(r.dot(n)) > std::cos(25.0 * std::numbers::pi / 180.0) * r.norm() * n.norm();
  }

  /// The contacts on `c` that decide and fit it: within the tolerance, and with their normals
  /// (when they have them) across it. (Set aside are all within the tolerance, as for a plane.)
  std::vector<std::size_t> on(const Cylinder& c) const {
    std::vector<std::size_t> out;
    for (std::size_t i = 0; i < contacts.points.size(); ++i)
      if (std::abs(c.distance(contacts.points[i])) < s.tolerance &&
          (!contacts.has_normals() || radial(c, contacts.points[i], contacts.normals[i])))
        out.push_back(i);
    return out;
  }

  /// Grasps whose patch lies on `c`: 80 % of its contacts, and its plane (when flat) across it.
  std::vector<std::size_t> grasps_on(const Cylinder& c) const {
    std::vector<std::size_t> out;
    for (std::size_t g = 0; g < grasps.grasps(); ++g) {
      const std::uint32_t a = grasps.first[g], b = grasps.first[g + 1];
      if (b - a < 3) continue;
      if (patches[g].normal.squaredNorm() > 0.0 && !radial(c, patches[g].point, patches[g].normal)) continue;
      std::size_t near = 0;
      for (std::uint32_t i = a; i < b; ++i) near += std::abs(c.distance(grasps.points[i])) < s.tolerance;
      if (10 * near >= 8 * (b - a)) out.push_back(g);
    }
    return out;
  }

  /// `c` refitted to the contacts on it: the axis least along their normals, then their circle.
  bool refit(Cylinder& c) const {
    for (int round = 0; round < 2; ++round) {
      const std::vector<std::size_t> idx = on(c);
      if (idx.size() < s.min_contacts) return false;
      Mat3 nn = Mat3::Zero();
      std::size_t normals = 0;
      for (std::size_t g : grasps_on(c))
        if (patches[g].normal.squaredNorm() > 0.0) nn += patches[g].normal * patches[g].normal.transpose(), ++normals;
      if (normals < 2 && contacts.has_normals())
        for (std::size_t i : idx) nn += contacts.normals[i] * contacts.normals[i].transpose(), ++normals;
      if (normals >= 2) {
        const Eigen::SelfAdjointEigenSolver<Mat3> eig(nn);
        // The normals must span two directions (a patch alone, or one side, leaves the axis open).
        if (eig.info() == Eigen::Success && eig.eigenvalues()[1] > 0.02 * eig.eigenvalues()[2]) {
          Vec3 a = eig.eigenvectors().col(0).normalized();
          if (a.dot(c.a) < 0) a = -a;
          c.a = a;
        }
      }
      const Vec3 u = across(c.a), v = c.a.cross(u);
      std::vector<Eigen::Vector2d> q;
      q.reserve(idx.size());
      for (std::size_t i : idx) {
        const Vec3 d = contacts.points[i] - c.p;
        q.emplace_back(u.dot(d), v.dot(d));
      }
      Eigen::Vector2d centre = Eigen::Vector2d::Zero();
      double r = c.r;
      if (!fit_circle(q, centre, r) || !radius_ok(r)) return false;
      c.p += centre.x() * u + centre.y() * v;
      c.r = r;
    }
    return true;
  }

  SupportSurface operator()(Cylinder c) const {
    SupportSurface out;
    out.verdict = SupportVerdict::few_contacts;
    const double tol = s.tolerance;
    if (!refit(c)) return out;
    const std::vector<std::size_t> idx = on(c);
    out.contacts_on = idx.size();
    if (idx.size() < s.min_contacts) return out;
    // Its contacts' centroid, axial stretch and the axis point nearest them.
    Vec3 centroid = Vec3::Zero();
    for (std::size_t i : idx) centroid += contacts.points[i];
    centroid /= static_cast<double>(idx.size());
    c.p += c.a.dot(centroid - c.p) * c.a;
    double lo = 0.0, hi = 0.0;
    for (std::size_t i : idx) {
      const double t = c.a.dot(contacts.points[i] - c.p);
      lo = std::min(lo, t);
      hi = std::max(hi, t);
    }
    const std::vector<std::size_t> on_grasps = grasps_on(c);
    out.verdict = SupportVerdict::few_grasps;
    if (!grasps.empty() && on_grasps.size() < s.min_grasps) return out;
    out.verdict = SupportVerdict::side_unclear;
    // The free side is outside: the hands that touched it, or the free space near it, with
    // one in 20 inside at most (a cylinder through the object's faces has hands inside it).
    std::vector<const Vec3*> witnesses;
    for (std::size_t g : on_grasps) add_hand_free_points(grasps, g, witnesses);
    if (witnesses.empty())
      for (const Vec3& q : free)
        if (std::abs(c.distance(q)) < 0.05 && c.a.dot(q - c.p) > lo - 0.05 && c.a.dot(q - c.p) < hi + 0.05)
          witnesses.push_back(&q);
    long outside = 0, inside = 0;
    for (const Vec3* w : witnesses) {
      const double d = c.distance(*w);
      outside += d > tol;
      inside += d < -tol;
    }
    if (outside + inside == 0 || outside < 20 * inside) return out;
    // The rest outside it, and no free space inside it along its contacts' stretch.
    out.verdict = SupportVerdict::rest_not_above;
    const std::optional<std::size_t> above = rest_above(contacts, s, [&](const Vec3& p) { return c.distance(p); });
    if (!above) return out;
    out.verdict = SupportVerdict::free_behind;
    const double margin = s.free_margin >= 0.0 ? s.free_margin : s.tolerance;
    std::size_t free_near = 0, free_inside = 0;
    for (const Vec3& q : free) {
      const double t = c.a.dot(q - c.p);
      if (t < lo || t > hi) continue;
      const double d = c.distance(q);
      if (d > c.r) continue;   // within a radius of its surface, outside or in
      ++free_near;
      free_inside += d < -margin;
    }
    if (free_near > 0 && 50 * free_inside > free_near) return out;
    out.found = true;
    out.verdict = SupportVerdict::found;
    out.shape = SupportSurface::Shape::cylinder;
    out.axis = c.a;
    out.point = c.p;
    out.radius = c.r;
    out.contacts_on = static_cast<std::size_t>(std::count_if(contacts.points.begin(), contacts.points.end(),
                                                             [&](const Vec3& p) { return std::abs(c.distance(p)) < tol; }));
    out.contacts_above = *above;
    out.grasps_on = on_grasps.size();
    return out;
  }
};

SupportSurface estimate_cylinder(const PointCloud& contacts, const GraspGroups& grasps, const std::vector<Vec3>& free,
                                 const SupportSettings& s, std::uint64_t seed, std::uint64_t step) {
  // Surface elements: each grasp's patch (when flat within the tolerance), or without grasp
  // groups seeded contacts with their normals.
  const std::vector<Plane> patches = flat_patches(grasps, s.tolerance);
  const double agree = 2.0 * s.tolerance;
  std::vector<Cylinder> candidates;
  for (std::size_t g = 0; g < patches.size(); ++g)
    for (std::size_t h = g + 1; h < patches.size(); ++h) {
      if (patches[g].normal.squaredNorm() == 0.0 || patches[h].normal.squaredNorm() == 0.0) continue;
      Cylinder c;
      if (cylinder_through(patches[g].point, patches[g].normal, patches[h].point, patches[h].normal, agree, c))
        candidates.push_back(c);
    }
  if (candidates.empty() && contacts.has_normals() && contacts.points.size() >= 2) {   // no grasp groups, or
                                                                                      // fewer than two flat patches
    Rng rng(seed, kStreamSupport, step);
    const std::size_t n = contacts.points.size();
    for (std::size_t k = 0; k < s.triplets; ++k) {
      const std::size_t i = rng.index(n), j = rng.index(n);
      Cylinder c;
      if (cylinder_through(contacts.points[i], contacts.normals[i], contacts.points[j], contacts.normals[j], agree, c))
        candidates.push_back(c);
    }
  }
  const CylinderJudge judge{contacts, grasps, free, s, patches};
  // The 16 with the most contacts on them (ties: the first) are judged.
  std::vector<std::pair<std::size_t, std::size_t>> order;   // (contacts on, candidate)
  for (std::size_t k = 0; k < candidates.size(); ++k)
    if (judge.radius_ok(candidates[k].r)) order.emplace_back(judge.on(candidates[k]).size(), k);
  std::stable_sort(order.begin(), order.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
  SupportSurface best;
  Largest largest(candidates.empty());
  for (std::size_t k = 0; k < std::min<std::size_t>(16, order.size()); ++k) {
    if (order[k].first < s.min_contacts) break;
    const SupportSurface j = judge(candidates[order[k].second]);
    largest.add(j);
    if (j.found && (!best.found || j.grasps_on > best.grasps_on ||
                    (j.grasps_on == best.grasps_on && j.contacts_on > best.contacts_on)))
      best = j;
  }
  best.shape = SupportSurface::Shape::cylinder;
  best.candidates = candidates.size();
  largest.report(best);
  return best;
}
}  // namespace

const char* to_string(SupportVerdict v) {
  switch (v) {
    case SupportVerdict::not_looked: return "not_looked";
    case SupportVerdict::no_candidate: return "no_candidate";
    case SupportVerdict::few_contacts: return "few_contacts";
    case SupportVerdict::few_grasps: return "few_grasps";
    case SupportVerdict::side_unclear: return "side_unclear";
    case SupportVerdict::rest_not_above: return "rest_not_above";
    case SupportVerdict::free_behind: return "free_behind";
    case SupportVerdict::found: return "found";
  }
  return "unknown";
}

SupportSurface estimate_support(const PointCloud& contacts, const GraspGroups& grasps, const std::vector<Vec3>& free,
                                const SupportSettings& s, std::uint64_t seed, std::uint64_t step) {
  check(s);
  if (s.mode == SupportMode::off) return {};
  if (s.mode == SupportMode::cylinder) return estimate_cylinder(contacts, grasps, free, s, seed, step);
  std::vector<Plane> candidates;
  for (const Plane& p : flat_patches(grasps, s.tolerance))
    if (p.normal.squaredNorm() > 0.0) candidates.push_back(p);
  if (grasps.empty() && contacts.points.size() >= 3) {
    Rng rng(seed, kStreamSupport, step);
    const std::size_t n = contacts.points.size();
    for (std::size_t k = 0; k < s.triplets; ++k) {
      const Vec3& a = contacts.points[rng.index(n)];
      const Vec3& b = contacts.points[rng.index(n)];
      const Vec3& d = contacts.points[rng.index(n)];
      const Vec3 normal = (b - a).cross(d - a);
      if (!(normal.norm() > 1e-6)) continue;   // under about 1 mm x 1 mm: no plane
      candidates.push_back({normal.normalized(), a, 0.0});
    }
  }
  const Judge judge{contacts, grasps, free, s};
  SupportSurface best;
  Largest largest(candidates.empty());
  for (const Plane& p : candidates) {
    const SupportSurface j = judge(p);
    largest.add(j);
    if (j.found && (!best.found || j.contacts_on > best.contacts_on)) best = j;
  }
  best.candidates = candidates.size();
  largest.report(best);
  return best;
}

PointCloud without_support(const PointCloud& contacts, const SupportSurface& support, double tolerance) {
  if (!support.found) return contacts;
  PointCloud out;
  for (std::size_t i = 0; i < contacts.points.size(); ++i) {
    if (support.explains(contacts.points[i], tolerance)) continue;
    out.points.push_back(contacts.points[i]);
    if (contacts.has_normals()) out.normals.push_back(contacts.normals[i]);
  }
  return out;
}

GraspGroups without_support(const GraspGroups& grasps, const SupportSurface& support, double tolerance) {
  if (!support.found) return grasps;
  GraspGroups out;
  out.free = grasps.free;
  out.free_first = grasps.free_first;
  out.pivots = grasps.pivots;
  out.first = {0};
  for (std::size_t g = 0; g < grasps.grasps(); ++g) {
    for (std::uint32_t i = grasps.first[g]; i < grasps.first[g + 1]; ++i)
      if (!support.explains(grasps.points[i], tolerance)) out.points.push_back(grasps.points[i]);
    out.first.push_back(static_cast<std::uint32_t>(out.points.size()));
  }
  return out;
}

}  // namespace ts::inline recognition
