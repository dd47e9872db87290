// DistanceField against brute force: exact point-to-triangle distances and a winding-number
// inside test written here, on closed meshes (icosphere, box, torus) and an open one (a bent
// sheet); serialization round trip; independence from the thread count; bad input.
#include "engine/geometry/distance_field.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <cstring>
#include <map>
#include <set>

using namespace ts;

namespace {

// ---- Test meshes ------------------------------------------------------------------------------

Mesh icosphere(double radius, int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  Mesh m;
  m.vertices = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  m.faces = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
             {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
             {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.vertices.push_back((m.vertices[a] + m.vertices[b]) / 2.0);
      return mid[key] = static_cast<int>(m.vertices.size()) - 1;
    };
    std::vector<Eigen::Vector3i> faces;
    for (const auto& f : m.faces) {
      const int a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]), c = midpoint(f[2], f[0]);
      faces.insert(faces.end(), {{f[0], a, c}, {f[1], b, a}, {f[2], c, b}, {a, b, c}});
    }
    m.faces = faces;
  }
  for (auto& v : m.vertices) v = radius * v.normalized();
  return m;
}

Mesh box(const Vec3& half) {
  Mesh m;
  for (int i = 0; i < 8; ++i)
    m.vertices.emplace_back((i & 1 ? 1 : -1) * half.x(), (i & 2 ? 1 : -1) * half.y(), (i & 4 ? 1 : -1) * half.z());
  m.faces = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
             {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

Mesh torus(double R, double r, int nu, int nv) {
  Mesh m;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const double u = 2 * M_PI * i / nu, v = 2 * M_PI * j / nv;
      m.vertices.emplace_back((R + r * std::cos(v)) * std::cos(u), (R + r * std::cos(v)) * std::sin(u), r * std::sin(v));
    }
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const int a = i * nv + j, b = ((i + 1) % nu) * nv + j, c = ((i + 1) % nu) * nv + (j + 1) % nv, d = i * nv + (j + 1) % nv;
      m.faces.emplace_back(a, b, c);
      m.faces.emplace_back(a, c, d);
    }
  return m;
}

/// Open, curved sheet (a quarter cylinder): only an unsigned field makes sense.
Mesh sheet() {
  Mesh m;
  const int nu = 24, nv = 10;
  for (int i = 0; i <= nu; ++i)
    for (int j = 0; j <= nv; ++j) {
      const double a = 0.5 * M_PI * i / nu;
      m.vertices.emplace_back(0.05 * std::cos(a) - 0.02, 0.05 * std::sin(a) - 0.02, -0.04 + 0.08 * j / nv);
    }
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const int a = i * (nv + 1) + j, b = (i + 1) * (nv + 1) + j;
      m.faces.emplace_back(a, b, b + 1);
      m.faces.emplace_back(a, b + 1, a + 1);
    }
  return m;
}

// ---- Brute-force oracle -------------------------------------------------------------------------

/// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

double unsigned_distance(const Mesh& m, const Vec3& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& f : m.faces)
    best = std::min(best, (p - closest_on_triangle(p, m.vertices[f[0]], m.vertices[f[1]], m.vertices[f[2]])).norm());
  return best;
}

/// Generalized winding number (solid angles, Van Oosterom & Strackee): ~1 inside, ~0 outside.
double winding_number(const Mesh& m, const Vec3& p) {
  double total = 0;
  for (const auto& f : m.faces) {
    const Vec3 a = m.vertices[f[0]] - p, b = m.vertices[f[1]] - p, c = m.vertices[f[2]] - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    total += 2.0 * std::atan2(num, den);
  }
  return total / (4.0 * M_PI);
}

double exact_distance(const Mesh& m, const Vec3& p, bool is_signed) {
  const double d = unsigned_distance(m, p);
  return (is_signed && winding_number(m, p) > 0.5) ? -d : d;
}

struct Errors {
  double near = 0, far = 0;   // worst |field - exact| near the surface / in the coarse region
  int sign_errors = 0, bound_errors = 0, near_n = 0, far_n = 0;
};

/// Random points near the surface (vertices and face points pushed off by up to 8 mm) and in
/// the whole coarse box, checked against brute force.
Errors check_field(const Mesh& m, bool is_signed, const DistanceField& df, const DistanceFieldSettings& s, Rng& rng,
                   int n) {
  Eigen::AlignedBox3d bb;
  for (const auto& v : m.vertices) bb.extend(v);
  const double fine_reach = (s.fine_band_voxels - 1) * s.fine_voxel;
  const double tol_far = 0.5 * s.coarse_voxel + 5e-4;
  Errors e;
  for (int q = 0; q < n; ++q) {
    Vec3 p;
    if (q % 2) {
      const auto& f = m.faces[rng.index(m.faces.size())];
      double u = rng.uniform(), v = rng.uniform();
      if (u + v > 1) u = 1 - u, v = 1 - v;
      p = m.vertices[f[0]] + u * (m.vertices[f[1]] - m.vertices[f[0]]) + v * (m.vertices[f[2]] - m.vertices[f[0]]);
      p += rng.uniform(0, 0.008) * rng.unit_vector();
    } else {
      const Vec3 lo = bb.min().array() - s.coarse_margin, hi = bb.max().array() + s.coarse_margin;
      p = Vec3(rng.uniform(lo.x(), hi.x()), rng.uniform(lo.y(), hi.y()), rng.uniform(lo.z(), hi.z()));
    }
    const double ex = exact_distance(m, p, is_signed);
    const double got = df.distance(p);
    if (is_signed && std::abs(ex) > 0.2 * s.fine_voxel && (got < 0) != (ex < 0)) ++e.sign_errors;
    const double err = std::abs(got - ex);
    if (std::abs(ex) < fine_reach - std::sqrt(3.0) * s.fine_voxel) {
      e.near = std::max(e.near, err);
      ++e.near_n;
    } else if (std::abs(ex) < s.coarse_margin) {
      e.far = std::max(e.far, err);
      ++e.far_n;
    } else if (got < s.coarse_margin - tol_far || got > ex + tol_far) {
      ++e.bound_errors;   // beyond the margin: about the margin, or more, but not above the truth
    }
  }
  return e;
}

}  // namespace

TEST_CASE("Distance field matches brute force on closed meshes, with correct signs") {
  DistanceFieldSettings s;
  Rng rng(7);
  struct Case {
    std::string name;
    Mesh mesh;
  };
  const Case cases[] = {{"icosphere", icosphere(0.05, 3)},
                        {"box", box(Vec3(0.04, 0.02, 0.03))},
                        {"torus", torus(0.06, 0.02, 48, 24)}};
  for (const auto& c : cases) {
    CAPTURE(c.name);
    const DistanceField df = DistanceField::build(c.mesh, true, s);
    REQUIRE_FALSE(df.empty());
    CHECK(df.is_signed());
    const Errors e = check_field(c.mesh, true, df, s, rng, 1200);
    MESSAGE(c.name << ": worst near " << e.near * 1e3 << " mm (" << e.near_n << " pts), far " << e.far * 1e3
                   << " mm (" << e.far_n << " pts)");
    CHECK(e.near_n > 300);
    CHECK(e.far_n > 300);
    CHECK(e.near <= 0.5 * s.fine_voxel + 1e-4);
    CHECK(e.far <= 0.5 * s.coarse_voxel + 5e-4);
    CHECK(e.sign_errors == 0);
    CHECK(e.bound_errors == 0);

    // Voxel-centre values are the exact distances to within half the level's quantum (at most
    // 1 um fine, 8 um coarse), with the right sign; coarse voxels beyond coarse_margin + 2
    // voxels hold that cap.
    const double cap = s.coarse_margin + 2 * s.coarse_voxel;
    CHECK(df.fine_compact().quantum <= 1e-6);
    CHECK(df.coarse_compact().quantum <= 8e-6);
    for (const auto& [g, quantum] : {std::pair{df.fine_sparse(), df.fine_compact().quantum},
                                     std::pair{df.coarse_sparse(), df.coarse_compact().quantum}}) {
      int wrong = 0;
      for (std::size_t n = 0; n < g.ijk.size(); n += 1 + g.ijk.size() / 250) {
        const Vec3 p = Vec3(g.ijk[n][0], g.ijk[n][1], g.ijk[n][2]) * g.voxel;
        const double ex = exact_distance(c.mesh, p, true);
        const double want = std::abs(ex) > cap ? std::copysign(cap, ex) : ex;
        // Signs everywhere but on the surface itself (pseudonormals since 2026-11-28; before,
        // meshToVolume's classification left the voxels the surface crosses unchecked).
        const bool sign_checked = std::abs(ex) > 1e-9;
        const double got = sign_checked ? g.value[n] : std::abs(g.value[n]);
        if (std::abs(got - (sign_checked ? want : std::abs(want))) > 0.5 * quantum + 1e-7 * std::abs(want)) ++wrong;
      }
      CHECK(wrong == 0);
    }
  }
}

TEST_CASE("The fine level holds every voxel within the band's half-width, and none beyond") {
  // The band is the shell (MeshIndex::shell) grown by dilation and cut by exact distance:
  // against brute force, every voxel centre within fine_band_voxels voxels of the surface is
  // active (all of them for the boxes, a random sample for the torus and the sheet), and no
  // active one (a sample of about 400) is farther. Bands of 1 to 4 voxels; a box whose faces lie
  // on the voxel lattice's centres and one shifted off it by a tenth of a voxel.
  struct Case {
    std::string name;
    Mesh mesh;
    bool is_signed;
    int band;
    int samples;   // 0: every voxel of the box around the mesh
  };
  Mesh shifted = box(Vec3(0.04, 0.02, 0.03));
  for (Vec3& v : shifted.vertices) v += Vec3(0.0002, 0.0002, 0.0002);
  // Two boxes 3 mm (1.5 voxels) apart: meshToVolume, which made the shell until 2026-11-28,
  // left holes in gaps narrower than about 1.7 voxels.
  Mesh pair = box(Vec3(0.02, 0.015, 0.01));
  for (Vec3& v : pair.vertices) v.x() -= 0.0215;
  {
    Mesh other = box(Vec3(0.02, 0.015, 0.01));
    const int base = static_cast<int>(pair.vertices.size());
    for (Vec3& v : other.vertices) pair.vertices.push_back(v + Vec3(0.0215, 0.0003, 0.0));
    for (const auto& f : other.faces) pair.faces.emplace_back(f[0] + base, f[1] + base, f[2] + base);
  }
  const Case cases[] = {{"box", box(Vec3(0.04, 0.02, 0.03)), true, 4, 0},
                        {"box", box(Vec3(0.04, 0.02, 0.03)), true, 3, 0},
                        {"box", box(Vec3(0.04, 0.02, 0.03)), true, 2, 0},
                        {"box", box(Vec3(0.04, 0.02, 0.03)), true, 1, 0},
                        {"shifted box", shifted, true, 4, 0},
                        {"shifted box", shifted, true, 2, 0},
                        {"two boxes 3 mm apart", pair, true, 4, 0},
                        {"torus", torus(0.06, 0.02, 48, 24), true, 4, 6000},
                        {"sheet", sheet(), false, 4, 6000}};
  Rng rng(31);
  for (const auto& c : cases) {
    CAPTURE(c.name);
    CAPTURE(c.band);
    DistanceFieldSettings s;
    s.fine_band_voxels = c.band;
    const DistanceField df = DistanceField::build(c.mesh, c.is_signed, s);
    const SparseGrid fine = df.fine_sparse();
    const std::set<std::array<std::int32_t, 3>> active(fine.ijk.begin(), fine.ijk.end());
    const double half = s.fine_band_voxels * s.fine_voxel;
    for (std::size_t n = 0; n < fine.ijk.size(); n += 1 + fine.ijk.size() / 400) {
      const Vec3 p = Vec3(fine.ijk[n][0], fine.ijk[n][1], fine.ijk[n][2]) * s.fine_voxel;
      CHECK(unsigned_distance(c.mesh, p) <= half + 1e-6);
    }
    Eigen::AlignedBox3d bb;
    for (const auto& v : c.mesh.vertices) bb.extend(v);
    const Eigen::Array3i lo = ((bb.min().array() - half) / s.fine_voxel).floor().cast<int>() - 1;
    const Eigen::Array3i hi = ((bb.max().array() + half) / s.fine_voxel).ceil().cast<int>() + 1;
    int inside = 0, missing = 0;
    auto visit = [&](const std::array<std::int32_t, 3>& ijk) {
      const double d = unsigned_distance(c.mesh, Vec3(ijk[0], ijk[1], ijk[2]) * s.fine_voxel);
      if (d > half - 1e-12) return;   // (voxels exactly on the half-width count: lattice-aligned faces)
      ++inside;
      if (!active.count(ijk)) ++missing;
    };
    if (c.samples == 0) {
      for (int i = lo.x(); i <= hi.x(); ++i)
        for (int j = lo.y(); j <= hi.y(); ++j)
          for (int k = lo.z(); k <= hi.z(); ++k) visit({i, j, k});
    } else {
      for (int q = 0; q < c.samples; ++q)
        visit({static_cast<std::int32_t>(lo.x() + rng.index(static_cast<std::size_t>(hi.x() - lo.x() + 1))),
               static_cast<std::int32_t>(lo.y() + rng.index(static_cast<std::size_t>(hi.y() - lo.y() + 1))),
               static_cast<std::int32_t>(lo.z() + rng.index(static_cast<std::size_t>(hi.z() - lo.z() + 1)))});
    }
    MESSAGE(c.name << ": " << inside << " voxels within the band checked, " << fine.ijk.size() << " active");
    CHECK(inside > (c.samples == 0 ? 1000 * c.band : 300));
    CHECK(missing == 0);
  }
}

TEST_CASE("A closed mesh wound both ways gets its signs by ray parity") {
  // Every other face of a torus turned inward: closed, but its pseudonormals mean nothing
  // (MeshIndex::oriented is false), so the field asks ray parity, which does not care about
  // winding. Oracle: the consistently wound torus. Sampled voxels of both levels, and queries.
  const Mesh good = torus(0.06, 0.02, 48, 24);
  Mesh mixed = good;
  for (std::size_t f = 0; f < mixed.faces.size(); f += 2) std::swap(mixed.faces[f][1], mixed.faces[f][2]);
  REQUIRE_FALSE(MeshIndex(mixed).oriented());
  DistanceFieldSettings s;
  const DistanceField df = DistanceField::build(mixed, true, s);
  const DistanceField reference = DistanceField::build(good, true, s);
  int checked = 0, wrong = 0;
  for (const auto& [g, r] : {std::pair{df.fine_sparse(), reference.fine_sparse()},
                             std::pair{df.coarse_sparse(), reference.coarse_sparse()}}) {
    REQUIRE(g.ijk == r.ijk);
    for (std::size_t n = 0; n < g.ijk.size(); n += 1 + g.ijk.size() / 500) {
      const Vec3 p = Vec3(g.ijk[n][0], g.ijk[n][1], g.ijk[n][2]) * g.voxel;
      const double ex = exact_distance(good, p, true);
      if (std::abs(ex) < 1e-9) continue;
      ++checked;
      if ((g.value[n] < 0) != (ex < 0) || g.value[n] != r.value[n]) ++wrong;
    }
  }
  CHECK(checked > 800);
  CHECK(wrong == 0);
  Rng rng(3);
  const Errors e = check_field(good, true, df, s, rng, 600);
  CHECK(e.sign_errors == 0);
}

TEST_CASE("Unsigned distance field of an open sheet matches brute force") {
  DistanceFieldSettings s;
  const Mesh m = sheet();
  const DistanceField df = DistanceField::build(m, false, s);
  CHECK_FALSE(df.is_signed());
  Rng rng(8);
  const Errors e = check_field(m, false, df, s, rng, 1500);
  MESSAGE("sheet: worst near " << e.near * 1e3 << " mm, far " << e.far * 1e3 << " mm");
  CHECK(e.near <= 0.5 * s.fine_voxel + 1e-4);
  CHECK(e.far <= 0.5 * s.coarse_voxel + 5e-4);
  CHECK(e.bound_errors == 0);
  // Unsigned: never negative, even on the concave side.
  for (int q = 0; q < 200; ++q) CHECK(df.distance(Vec3(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1))) >= 0.0);
}

TEST_CASE("Distance field outside the coarse domain is a lower bound of at least the margin") {
  DistanceFieldSettings s;
  s.coarse_margin = 0.05;
  const Mesh m = icosphere(0.03, 2);
  const DistanceField df = DistanceField::build(m, true, s);
  Rng rng(9);
  for (int q = 0; q < 300; ++q) {
    const Vec3 p = rng.uniform(0.09, 3.0) * rng.unit_vector();
    const double got = df.distance(p), ex = exact_distance(m, p, true);
    CHECK(got >= s.coarse_margin - 1e-9);
    CHECK(got <= ex + 1e-9);
  }
  CHECK(std::isinf(df.distance(Vec3(std::nan(""), 0, 0))));
  CHECK(df.distance(Vec3(1e12, 0, 0)) >= s.coarse_margin);
}

TEST_CASE("Distance field survives the sparse round trip bit for bit and ignores the thread count") {
  DistanceFieldSettings s;
  const Mesh m = torus(0.05, 0.015, 40, 20);
  DistanceField one, two;
  tbb::task_arena(1).execute([&] { one = DistanceField::build(m, true, s); });
  tbb::task_arena(2).execute([&] { two = DistanceField::build(m, true, s); });
  const SparseGrid f1 = one.fine_sparse(), c1 = one.coarse_sparse();
  const SparseGrid f2 = two.fine_sparse(), c2 = two.coarse_sparse();
  REQUIRE(f1.ijk.size() == f2.ijk.size());
  REQUIRE(c1.ijk.size() == c2.ijk.size());
  CHECK(f1.voxel == s.fine_voxel);
  CHECK(c1.voxel == s.coarse_voxel);
  CHECK(std::memcmp(f1.ijk.data(), f2.ijk.data(), f1.ijk.size() * sizeof(f1.ijk[0])) == 0);
  CHECK(std::memcmp(f1.value.data(), f2.value.data(), f1.value.size() * sizeof(float)) == 0);
  CHECK(std::memcmp(c1.ijk.data(), c2.ijk.data(), c1.ijk.size() * sizeof(c1.ijk[0])) == 0);
  CHECK(std::memcmp(c1.value.data(), c2.value.data(), c1.value.size() * sizeof(float)) == 0);
  CHECK(std::is_sorted(f1.ijk.begin(), f1.ijk.end()));
  CHECK(std::is_sorted(c1.ijk.begin(), c1.ijk.end()));
  CHECK(std::adjacent_find(f1.ijk.begin(), f1.ijk.end()) == f1.ijk.end());
  const DistanceField via_index = DistanceField::build(MeshIndex(m), true, s);   // BVH overload
  CHECK(via_index.fine_sparse().value == f1.value);
  CHECK(via_index.coarse_sparse().value == c1.value);

  const DistanceField back = DistanceField::from_sparse(f1, c1, true, s.coarse_margin);
  CHECK(back.is_signed());
  CHECK(back.coarse_margin() == s.coarse_margin);
  const SparseGrid f3 = back.fine_sparse(), c3 = back.coarse_sparse();
  CHECK(f3.ijk == f1.ijk);
  CHECK(f3.value == f1.value);
  CHECK(c3.ijk == c1.ijk);
  CHECK(c3.value == c1.value);
  Rng rng(10);
  std::vector<Vec3> pts;
  for (int q = 0; q < 3000; ++q) pts.push_back(Vec3(rng.uniform(-0.35, 0.35), rng.uniform(-0.35, 0.35), rng.uniform(-0.3, 0.3)));
  for (const auto& p : pts) CHECK(back.distance(p) == one.distance(p));

  // Batch form: the same values after the transform.
  Pose T = Pose::Identity();
  T.linear() = rng.rotation().toRotationMatrix();
  T.translation() = Vec3(0.01, -0.02, 0.03);
  std::vector<double> out(pts.size());
  back.distances(pts.data(), pts.size(), T, out.data());
  for (std::size_t i = 0; i < pts.size(); ++i) CHECK(out[i] == one.distance(T * pts[i]));
}

TEST_CASE("Distance field rejects bad input; an empty field answers +inf") {
  DistanceFieldSettings s;
  CHECK_THROWS_AS(DistanceField::build(Mesh{}, true, s), Error);
  Mesh bad = box(Vec3(0.01, 0.01, 0.01));
  bad.faces[3][1] = 99;
  CHECK_THROWS_AS(DistanceField::build(bad, true, s), Error);
  DistanceFieldSettings zero = s;
  zero.fine_voxel = 0;
  CHECK_THROWS_AS(DistanceField::build(box(Vec3(0.01, 0.01, 0.01)), true, zero), Error);
  DistanceFieldSettings huge = s;
  huge.coarse_voxel = 1e-4;   // a dense coarse box of ~(0.42 m / 0.1 mm)^3 voxels
  CHECK_THROWS_AS(DistanceField::build(box(Vec3(0.01, 0.01, 0.01)), true, huge), Error);
  huge = s;
  huge.fine_voxel = 1e-6;
  CHECK_THROWS_AS(DistanceField::build(box(Vec3(0.01, 0.01, 0.01)), true, huge), Error);
  SparseGrid g;
  g.voxel = 0.01;
  g.ijk.push_back({0, 0, 0});
  CHECK_THROWS_AS(DistanceField::from_sparse(g, g, true, 0.2), Error);   // value missing
  const DistanceField empty;
  CHECK(empty.empty());
  CHECK(std::isinf(empty.distance(Vec3::Zero())));
  double out[2];
  const Vec3 pts[2] = {Vec3::Zero(), Vec3::Ones()};
  empty.distances(pts, 2, Pose::Identity(), out);
  CHECK(std::isinf(out[0]));
}

TEST_CASE("Distance field gradient is the derivative of its own interpolant") {
  DistanceFieldSettings s;
  const DistanceField df = DistanceField::build(icosphere(0.05, 3), true, s);
  Rng rng(11);
  int fine = 0, coarse = 0;
  for (int n = 0; n < 400; ++n) {
    // Points near the surface (fine level) and farther out (coarse level).
    const Vec3 dir = Vec3(rng.normal(), rng.normal(), rng.normal()).normalized();
    const double r = n % 2 ? 0.05 + rng.uniform(-0.004, 0.004) : rng.uniform(0.07, 0.2);
    const Vec3 p = r * dir;
    double d = 0.0;
    Vec3 g;
    df.distances_gradients(&p, 1, Pose::Identity(), &d, &g);
    CHECK(d == df.distance(p));
    // Central differences with a step far below a voxel: equal unless a cell border lies
    // between, where the interpolant has a kink; such samples are skipped.
    const double h = 1e-6;
    Vec3 fd;
    bool kink = false;
    for (int a = 0; a < 3; ++a) {
      Vec3 e = Vec3::Zero();
      e[a] = h;
      const double up = (df.distance(p + e) - d) / h, down = (d - df.distance(p - e)) / h;
      kink = kink || std::abs(up - down) > 1e-3;
      fd[a] = 0.5 * (up + down);
    }
    if (kink || !fd.allFinite()) continue;
    const bool near = std::abs(r - 0.05) < 0.005;
    (near ? fine : coarse) += 1;
    CHECK((g - fd).norm() < 1e-4);
    // A distance field's gradient has unit length up to interpolation error, pointing outward.
    CHECK(std::abs(g.norm() - 1.0) < 0.08);   // at most 0.042 off here
    CHECK(g.dot(dir) > 0.9);
  }
  CHECK(fine > 150);
  CHECK(coarse > 150);
  // Far outside the coarse grid only a bound is known: no gradient.
  const Vec3 far(3.0, 0.0, 0.0);
  double d;
  Vec3 g;
  df.distances_gradients(&far, 1, Pose::Identity(), &d, &g);
  CHECK(d >= s.coarse_margin);
  CHECK(g == Vec3::Zero());
}
