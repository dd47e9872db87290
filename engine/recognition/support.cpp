#include "engine/recognition/support.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
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
  require(std::isfinite(s.attribution) && s.attribution > 0 && s.attribution <= 1, "support.attribution",
          "must lie in (0, 1] m");
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

struct Judge {
  const PointCloud& contacts;
  const GraspGroups& grasps;
  const std::vector<Vec3>& free;
  const SupportSettings& s;

  /// The candidate `plane` refitted and judged; found = false when it is not a support.
  SupportPlane operator()(Plane plane) const {
    SupportPlane out;
    const double tol = s.tolerance;
    auto within = [&](const Plane& q) {
      std::vector<Vec3> near;
      for (const Vec3& p : contacts.points)
        if (std::abs(q.normal.dot(p - q.point)) < tol) near.push_back(p);
      return near;
    };
    std::vector<Vec3> on = within(plane);
    if (on.size() < s.min_contacts || !fit_plane(on, plane)) return out;
    on = within(plane);   // those of the refitted plane
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
      if (g + 1 < grasps.free_first.size())
        for (std::uint32_t i = grasps.free_first[g]; i < grasps.free_first[g + 1]; ++i)
          witnesses.push_back(&grasps.free[i]);
    }
    if (!grasps.empty() && grasps_on < s.min_grasps) return out;
    const double reach = radius + 0.05;
    if (witnesses.empty())
      for (const Vec3& q : free)
        if ((q - c).norm() < reach) witnesses.push_back(&q);
    const int side = free_side(plane.normal, c, witnesses, tol);
    if (side == 0) return out;
    const Vec3 n = side * plane.normal;
    // The rest above it, and no free space below it where it was touched.
    std::size_t above = 0, below = 0;
    for (const Vec3& p : contacts.points) {
      const double d = n.dot(p - c);
      above += d >= tol;
      below += d <= -tol;
    }
    if (above + below < s.min_contacts || static_cast<double>(above) < s.above_share * static_cast<double>(above + below))
      return out;
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
    out.normal = n;
    out.offset = n.dot(c);
    out.contacts_on = on.size();
    out.contacts_above = above;
    out.grasps_on = grasps_on;
    return out;
  }
};

}  // namespace

SupportPlane estimate_support(const PointCloud& contacts, const GraspGroups& grasps, const std::vector<Vec3>& free,
                              const SupportSettings& s, std::uint64_t seed, std::uint64_t step) {
  check(s);
  std::vector<Plane> candidates;
  for (std::size_t g = 0; g < grasps.grasps(); ++g) {
    const std::vector<Vec3> patch(grasps.points.begin() + grasps.first[g], grasps.points.begin() + grasps.first[g + 1]);
    Plane p;
    if (fit_plane(patch, p) && p.rms < 0.5 * s.tolerance) candidates.push_back(p);
  }
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
  SupportPlane best;
  for (const Plane& p : candidates) {
    const SupportPlane j = judge(p);
    if (j.found && (!best.found || j.contacts_on > best.contacts_on)) best = j;
  }
  best.candidates = candidates.size();
  return best;
}

PointCloud without_support(const PointCloud& contacts, const SupportPlane& plane, double tolerance) {
  if (!plane.found) return contacts;
  PointCloud out;
  for (std::size_t i = 0; i < contacts.points.size(); ++i) {
    if (std::abs(plane.signed_distance(contacts.points[i])) < tolerance) continue;
    out.points.push_back(contacts.points[i]);
    if (contacts.has_normals()) out.normals.push_back(contacts.normals[i]);
  }
  return out;
}

GraspGroups without_support(const GraspGroups& grasps, const SupportPlane& plane, double tolerance) {
  if (!plane.found) return grasps;
  GraspGroups out;
  out.free = grasps.free;
  out.free_first = grasps.free_first;
  out.pivots = grasps.pivots;
  out.first = {0};
  for (std::size_t g = 0; g < grasps.grasps(); ++g) {
    for (std::uint32_t i = grasps.first[g]; i < grasps.first[g + 1]; ++i)
      if (std::abs(plane.signed_distance(grasps.points[i])) >= tolerance) out.points.push_back(grasps.points[i]);
    out.first.push_back(static_cast<std::uint32_t>(out.points.size()));
  }
  return out;
}

}  // namespace ts::inline recognition
