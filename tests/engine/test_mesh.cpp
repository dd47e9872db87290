#include "engine/geometry/mesh.hpp"
#include "mesh_shapes.hpp"

#include <doctest/doctest.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <limits>
#include <map>
#include <numbers>

using namespace ts;
using ts::test::flipped;
using ts::test::make_box;
using ts::test::make_sphere;
using ts::test::make_torus;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

Vec3 vtx(const Mesh& m, int f, int k) { return m.vertices[m.faces[f][k]]; }

// Independent oracles, written differently from the engine's code paths.

/// Ray-plane intersection followed by an edge-side test (not Möller–Trumbore).
double brute_ray_triangle(const Vec3& o, const Vec3& d, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double denom = n.dot(d);
  if (std::abs(denom) < 1e-300) return kInf;
  const double t = n.dot(a - o) / denom;
  if (!(t > 0.0)) return kInf;
  const Vec3 p = o + t * d;
  const double s0 = (b - a).cross(p - a).dot(n), s1 = (c - b).cross(p - b).dot(n),
               s2 = (a - c).cross(p - c).dot(n);
  return (s0 >= 0 && s1 >= 0 && s2 >= 0) ? t : kInf;
}

double brute_raycast(const Mesh& m, const Vec3& o, const Vec3& d) {
  double best = kInf;
  for (int f = 0; f < static_cast<int>(m.faces.size()); ++f)
    best = std::min(best, brute_ray_triangle(o, d, vtx(m, f, 0), vtx(m, f, 1), vtx(m, f, 2)));
  return best;
}

double segment_distance(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
  return (p - (a + t * ab)).norm();
}

/// Distance to a triangle: to its plane if the projection falls inside, else to its edges.
double brute_point_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a).normalized();
  const Vec3 q = p - n.dot(p - a) * n;
  const bool in = (b - a).cross(q - a).dot(n) >= 0 && (c - b).cross(q - b).dot(n) >= 0 &&
                  (a - c).cross(q - c).dot(n) >= 0;
  if (in) return std::abs(n.dot(p - a));
  return std::min({segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)});
}

double brute_distance(const Mesh& m, const Vec3& p) {
  double best = kInf;
  for (int f = 0; f < static_cast<int>(m.faces.size()); ++f)
    best = std::min(best, brute_point_triangle(p, vtx(m, f, 0), vtx(m, f, 1), vtx(m, f, 2)));
  return best;
}

std::vector<std::pair<std::string, Mesh>> test_meshes() {
  return {{"sphere", make_sphere(0.1, 3)},
          {"cube", make_box(Vec3(0.05, 0.08, 0.1), 6, Vec3(0.01, -0.02, 0.03))},
          {"torus", make_torus(0.07, 0.025, 48, 24)}};
}

}  // namespace

TEST_CASE("mesh measurements: unit cube area, volume and winding") {
  const Mesh cube = make_box(Vec3(0.5, 0.5, 0.5), 3, Vec3(10.0, -3.0, 2.0));
  CHECK(mesh_area(cube) == doctest::Approx(6.0).epsilon(1e-12));
  CHECK(mesh_signed_volume(cube) == doctest::Approx(1.0).epsilon(1e-12));
  CHECK(mesh_signed_volume(flipped(cube)) == doctest::Approx(-1.0).epsilon(1e-12));
  const auto box = mesh_bounds(cube);
  CHECK((box.min() - Vec3(9.5, -3.5, 1.5)).norm() < 1e-12);
  CHECK((box.max() - Vec3(10.5, -2.5, 2.5)).norm() < 1e-12);

  // Tessellated sphere and torus approach the analytic values from below.
  const double r = 0.1;
  const double vs = mesh_signed_volume(make_sphere(r, 4));
  CHECK(vs < 4.0 / 3.0 * std::numbers::pi * r * r * r);
  // Relative tolerances (.scale(0)): these values are far below 1, where doctest's default
  // scale would make epsilon an absolute tolerance that accepts anything.
  CHECK(vs == doctest::Approx(4.0 / 3.0 * std::numbers::pi * r * r * r).epsilon(0.01).scale(0));
  const double vt = mesh_signed_volume(make_torus(0.07, 0.025, 96, 48));
  CHECK(vt == doctest::Approx(2.0 * std::numbers::pi * std::numbers::pi * 0.07 * 0.025 * 0.025).epsilon(0.01).scale(0));
  CHECK(mesh_area(make_torus(0.07, 0.025, 96, 48)) ==
        doctest::Approx(4.0 * std::numbers::pi * std::numbers::pi * 0.07 * 0.025).epsilon(0.01).scale(0));
}

TEST_CASE("mesh topology: closed, open and non-manifold meshes") {
  for (const auto& [name, m] : test_meshes()) {
    const std::string label = name;   // (clang 14 cannot capture a structured binding)
    CAPTURE(label);
    const auto topo = mesh_topology(m);
    CHECK(topo.boundary_edges == 0);
    CHECK(topo.nonmanifold_edges == 0);
    CHECK(topo.closed());
  }
  Mesh open = make_box(Vec3(1, 1, 1), 2);
  open.faces.pop_back();  // removes one triangle: its 3 edges become boundary edges
  auto topo = mesh_topology(open);
  CHECK(topo.boundary_edges == 3);
  CHECK(topo.nonmanifold_edges == 0);
  CHECK_FALSE(topo.closed());

  Mesh fin = make_box(Vec3(1, 1, 1), 2);
  const auto f0 = fin.faces[0];
  fin.vertices.emplace_back(5.0, 5.0, 5.0);
  fin.faces.emplace_back(f0[0], f0[1], static_cast<int>(fin.vertices.size()) - 1);
  topo = mesh_topology(fin);
  CHECK(topo.nonmanifold_edges == 1);  // edge (f0[0], f0[1]) now has three faces
  CHECK(topo.boundary_edges == 2);     // the fin's two new edges
}

TEST_CASE("MeshIndex raycast agrees with brute force on random rays") {
  for (const auto& [name, m] : test_meshes()) {
    const std::string label = name;   // (clang 14 cannot capture a structured binding)
    CAPTURE(label);
    const MeshIndex index(m);
    Rng rng(11);
    int hits = 0;
    for (int i = 0; i < 3000; ++i) {
      // Origins inside and around the object, random directions (some rays start inside).
      const Vec3 o(rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15));
      const Vec3 d = rng.unit_vector() * rng.uniform(0.5, 2.0);  // not unit on purpose
      const double expect = brute_raycast(m, o, d.normalized());
      const auto hit = index.raycast(o, d);
      REQUIRE(hit.has_value() == (expect < kInf));
      CHECK(index.occluded(o, d) == hit.has_value());   // the any-hit form of the same test
      if (!hit) continue;
      ++hits;
      CHECK(hit->t == doctest::Approx(expect).epsilon(1e-9));
      CHECK((hit->point - (o + expect * d.normalized())).norm() < 1e-10);
      // The reported face is hit at that t and the normal is its unit normal.
      const int f = hit->face;
      const Vec3 n = (vtx(m, f, 1) - vtx(m, f, 0)).cross(vtx(m, f, 2) - vtx(m, f, 0)).normalized();
      CHECK((hit->normal - n).norm() < 1e-12);
      CHECK(std::abs(n.dot(hit->point - vtx(m, f, 0))) < 1e-12);
      // t_max cuts the ray short; t_min skips the first hit.
      CHECK_FALSE(index.raycast(o, d, 0.999 * expect).has_value());
      CHECK_FALSE(index.occluded(o, d, 0.999 * expect));
      const auto second = index.raycast(o, d, 1e30, hit->t * (1.0 + 1e-9));
      if (second) CHECK(second->t > hit->t);
      CHECK(index.occluded(o, d, 1e30, hit->t * (1.0 + 1e-9)) == second.has_value());
    }
    CHECK(hits > 300);
  }
}

TEST_CASE("MeshIndex raycast does not slip through shared edges and vertices") {
  for (const auto& [name, m] : test_meshes()) {
    const std::string label = name;   // (clang 14 cannot capture a structured binding)
    CAPTURE(label);
    const MeshIndex index(m);
    const Vec3 c = mesh_bounds(m).center();
    int misses = 0, tested = 0;
    for (const auto& f : m.faces) {
      for (int k = 0; k < 3; ++k) {
        const Vec3 a = m.vertices[f[k]], b = m.vertices[f[(k + 1) % 3]];
        for (const Vec3& target : {Vec3(0.5 * (a + b)), a}) {
          // Aim at the edge midpoint / vertex from outside, along a direction through the
          // bounding-box centre; a closed mesh must be hit at or before the target.
          Vec3 d = target - c;
          if (d.norm() < 1e-9) continue;
          d.normalize();
          const Vec3 o = target + 0.5 * d;
          const auto hit = index.raycast(o, -d);
          ++tested;
          if (!hit || hit->t > 0.5 + 1e-9) ++misses;
        }
      }
    }
    CHECK(tested > 1000);
    CHECK(misses == 0);
  }
  // Axis-aligned rays (with +0.0 and -0.0 components) exactly through the lattice vertices of
  // every box face, including rays lying in the side faces' planes.
  const Mesh box = make_box(Vec3(1, 1, 1), 4);
  const MeshIndex index(box);
  int misses = 0;
  for (int axis = 0; axis < 3; ++axis)
    for (const double sign : {1.0, -1.0})
      for (int i = 0; i <= 4; ++i)
        for (int j = 0; j <= 4; ++j) {
          Vec3 o, d = Vec3::Zero();
          o[axis] = 5.0 * sign;
          o[(axis + 1) % 3] = -1.0 + 0.5 * i;
          o[(axis + 2) % 3] = -1.0 + 0.5 * j;
          d[axis] = -sign;
          d[(axis + 1) % 3] = sign > 0 ? 0.0 : -0.0;
          const auto hit = index.raycast(o, d);
          if (!hit || std::abs(hit->t - 4.0) > 1e-12) ++misses;
        }
  CHECK(misses == 0);
}

TEST_CASE("MeshIndex closest point agrees with brute force") {
  for (const auto& [name, m] : test_meshes()) {
    const std::string label = name;   // (clang 14 cannot capture a structured binding)
    CAPTURE(label);
    const MeshIndex index(m);
    Rng rng(5);
    for (int i = 0; i < 2000; ++i) {
      // Mix of far points and points near the surface.
      Vec3 p(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3));
      if (i % 2 == 0) {
        const auto& v = m.vertices[rng.index(m.vertices.size())];
        p = v + 0.01 * rng.unit_vector() * rng.uniform();
      }
      const double expect = brute_distance(m, p);
      const ClosestPoint cp = index.closest(p);
      REQUIRE(cp.face >= 0);
      CHECK(cp.distance == doctest::Approx(expect).epsilon(1e-9).scale(1e-12));
      CHECK(std::abs((cp.point - p).norm() - cp.distance) < 1e-12);
      // The point lies on the reported face.
      const int f = cp.face;
      CHECK(brute_point_triangle(cp.point, vtx(m, f, 0), vtx(m, f, 1), vtx(m, f, 2)) < 1e-12);

      const double limit = rng.uniform(0.0, 0.05);
      const auto within = index.closest_within(p, limit);
      CHECK(within.has_value() == (expect < limit));
      if (within) {
        CHECK(within->distance == doctest::Approx(cp.distance).epsilon(1e-12));
        CHECK(within->face == cp.face);
      }
    }
  }
}

TEST_CASE("MeshIndex inside test on sphere and torus") {
  const double r = 0.1;
  const MeshIndex sphere(make_sphere(r, 3));
  const double R = 0.07, rt = 0.025;
  const MeshIndex torus(make_torus(R, rt, 64, 32));
  Rng rng(3);
  int checked = 0;
  for (int i = 0; i < 4000; ++i) {
    const Vec3 p(rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15));
    // Only points clearly away from the tessellated surface (analytic vs tessellation error).
    if (sphere.closest(p).distance > 2e-3) {
      CHECK(sphere.inside(p) == (p.norm() < r));
      ++checked;
    }
    const double ring = std::hypot(p.x(), p.y()) - R;
    if (torus.closest(p).distance > 1e-3) {
      CHECK(torus.inside(p) == (ring * ring + p.z() * p.z() < rt * rt));
      ++checked;
    }
  }
  CHECK(checked > 6000);
  // Points exactly on axis-aligned lines through box lattice vertices still vote correctly.
  const MeshIndex box(make_box(Vec3(1, 1, 1), 4));
  CHECK(box.inside(Vec3(0, 0, 0)));
  CHECK(box.inside(Vec3(0.5, 0.5, 0.5)));
  CHECK_FALSE(box.inside(Vec3(1.5, 0.5, 0.5)));
  CHECK_FALSE(box.inside(Vec3(0, 0, 2)));
}

TEST_CASE("MeshIndex queries are thread-safe and equal to serial ones") {
  const MeshIndex index(make_torus(0.07, 0.025, 64, 32));
  const int n = 4000;
  std::vector<Vec3> pts(n), dirs(n);
  Rng rng(9);
  for (int i = 0; i < n; ++i) {
    pts[i] = Vec3(rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15));
    dirs[i] = rng.unit_vector();
  }
  std::vector<double> serial_t(n), serial_d(n), par_t(n), par_d(n);
  std::vector<int> serial_in(n), par_in(n);
  auto run = [&](int i, std::vector<double>& t, std::vector<double>& d, std::vector<int>& in) {
    const auto hit = index.raycast(pts[i], dirs[i]);
    t[i] = hit ? hit->t : -1.0;
    d[i] = index.closest(pts[i]).distance;
    in[i] = index.inside(pts[i]) ? 1 : 0;
  };
  for (int i = 0; i < n; ++i) run(i, serial_t, serial_d, serial_in);
  tbb::parallel_for(0, n, [&](int i) { run(i, par_t, par_d, par_in); });
  CHECK(serial_t == par_t);
  CHECK(serial_d == par_d);
  CHECK(serial_in == par_in);
}

TEST_CASE("MeshIndex handles empty meshes, bad rays and bad indices") {
  const MeshIndex empty{Mesh{}};
  CHECK_FALSE(empty.raycast(Vec3::Zero(), Vec3::UnitX()).has_value());
  CHECK_FALSE(empty.occluded(Vec3::Zero(), Vec3::UnitX()));
  CHECK(empty.closest(Vec3::Zero()).face == -1);
  CHECK_FALSE(empty.inside(Vec3::Zero()));
  const MeshIndex sphere(make_sphere(1.0, 1));
  CHECK_FALSE(sphere.raycast(Vec3(0, 0, 5), Vec3::Zero()).has_value());
  CHECK_FALSE(sphere.raycast(Vec3(0, 0, std::nan("")), Vec3::UnitZ()).has_value());
  CHECK_FALSE(sphere.occluded(Vec3(0, 0, 5), Vec3::Zero()));
  CHECK_FALSE(sphere.occluded(Vec3(0, 0, std::nan("")), Vec3::UnitZ()));
  CHECK(sphere.occluded(Vec3(0, 0, 5), Vec3(0, 0, -1)));
  CHECK_FALSE(sphere.closest_within(Vec3(0, 0, 5), 1.0).has_value());
  // A degenerate (zero-area) triangle neither crashes nor produces NaN.
  Mesh m = make_sphere(1.0, 1);
  m.faces.emplace_back(0, 0, 1);
  const MeshIndex with_degenerate(m);
  const auto hit = with_degenerate.raycast(Vec3(0, 0, 5), Vec3(0, 0, -1));
  REQUIRE(hit.has_value());
  CHECK(finite(hit->normal));
  Mesh bad = make_sphere(1.0, 0);
  bad.faces.emplace_back(0, 1, 99);
  CHECK_THROWS_AS(MeshIndex{bad}, Error);
}

namespace {

/// brute_distance, with a face of (nearly) zero area taken as its three edges
/// (brute_point_triangle needs a normal, and a collinear face's is rounding noise).
double brute_distance_any(const Mesh& m, const Vec3& p) {
  const auto segment_distance = [](const Vec3& q, const Vec3& a, const Vec3& b) {
    return (b - a).squaredNorm() > 0.0 ? ::segment_distance(q, a, b) : (q - a).norm();
  };
  double best = kInf;
  for (int f = 0; f < static_cast<int>(m.faces.size()); ++f) {
    const Vec3 a = vtx(m, f, 0), b = vtx(m, f, 1), c = vtx(m, f, 2);
    best = std::min(best, (b - a).cross(c - a).norm() > 1e-10 * (b - a).norm() * (c - a).norm()
                              ? brute_point_triangle(p, a, b, c)
                              : std::min({segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)}));
  }
  return best;
}

}  // namespace

TEST_CASE("MeshIndex shell: every lattice point within the radius, with closest()'s answer, and none beyond") {
  // Against the brute-force distance of every lattice point of the grown box, and against
  // closest() itself (the same distance, point and face, bit for bit). A large thin triangle
  // (cut into pieces by the shell) and a degenerate one (zero area) too.
  Mesh big;
  big.vertices = {{-0.20, -0.15, 0.013}, {0.25, -0.02, -0.031}, {0.01, 0.22, 0.047}, {0.3, 0.3, 0.3}, {0.3, 0.33, 0.3}};
  big.faces = {{0, 1, 2}, {3, 4, 4}};   // the second: a segment (repeated vertex)
  Mesh sliver;
  sliver.vertices = {{0, 0, 0}, {0.05, 0.01, -0.02}, {0.1, 0.02, -0.04}};   // collinear
  sliver.faces = {{0, 1, 2}};
  struct Case {
    std::string name;
    Mesh mesh;
    double voxel, radius;
  };
  const Case cases[] = {{"sphere", make_sphere(0.03, 1), 0.002, 0.8660254037844386 * 0.002},
                        {"torus", make_torus(0.03, 0.01, 16, 8), 0.0017, 0.004},
                        {"big triangle", big, 0.01, 0.009},
                        {"collinear sliver", sliver, 0.003, 0.0026},
                        {"sphere, radius of 5 voxels", make_sphere(0.02, 1), 0.002, 0.01}};
  for (const auto& c : cases) {
    CAPTURE(c.name);
    const MeshIndex index(c.mesh);
    const std::vector<ShellVoxel> shell = index.shell(c.voxel, c.radius);
    REQUIRE(shell.size() > 50);
    for (std::size_t n = 1; n < shell.size(); ++n) CHECK(shell[n - 1].ijk < shell[n].ijk);
    std::map<std::array<std::int32_t, 3>, const ShellVoxel*> by_ijk;
    for (const auto& s : shell) by_ijk[s.ijk] = &s;
    Eigen::AlignedBox3d bb;
    for (const auto& v : c.mesh.vertices) bb.extend(v);
    const Eigen::Array3i lo = ((bb.min().array() - c.radius) / c.voxel).floor().cast<int>() - 1;
    const Eigen::Array3i hi = ((bb.max().array() + c.radius) / c.voxel).ceil().cast<int>() + 1;
    int within = 0, missing = 0, extra = 0, differ = 0;
    for (int i = lo.x(); i <= hi.x(); ++i)
      for (int j = lo.y(); j <= hi.y(); ++j)
        for (int k = lo.z(); k <= hi.z(); ++k) {
          const Vec3 p = Vec3(i, j, k) * c.voxel;
          const double d = brute_distance_any(c.mesh, p);
          const auto it = by_ijk.find({i, j, k});
          if (d <= c.radius * (1 - 1e-9)) {
            ++within;
            if (it == by_ijk.end()) {
              ++missing;
              continue;
            }
          }
          if (it == by_ijk.end()) continue;
          if (d > c.radius * (1 + 1e-9)) ++extra;
          const ShellVoxel& s = *it->second;
          const ClosestPoint cp = index.closest(p);
          if (std::sqrt(s.sq_distance) != cp.distance || s.point != cp.point || s.face != cp.face) ++differ;
        }
    MESSAGE(c.name << ": " << within << " lattice points within the radius, " << shell.size() << " in the shell");
    CHECK(within > 50);
    CHECK(missing == 0);
    CHECK(extra == 0);
    CHECK(differ == 0);
  }
  // The same shell for any thread count.
  const MeshIndex torus(make_torus(0.03, 0.01, 32, 16));
  std::vector<ShellVoxel> one;
  tbb::task_arena(1).execute([&] { one = torus.shell(0.0017, 0.003); });
  const std::vector<ShellVoxel> all = torus.shell(0.0017, 0.003);
  REQUIRE(one.size() == all.size());
  bool same = true;
  for (std::size_t n = 0; n < one.size(); ++n)
    same = same && one[n].ijk == all[n].ijk && one[n].sq_distance == all[n].sq_distance && one[n].face == all[n].face;
  CHECK(same);
  CHECK_THROWS_AS(torus.shell(0.0, 0.003), Error);
  CHECK_THROWS_AS(torus.shell(0.001, -1.0), Error);
}

TEST_CASE("MeshIndex side: the pseudonormal tells inside from outside, on faces, edges and vertices") {
  // Points near the surface (within a few mm, where the closest point is often an edge or a
  // vertex) and far from it, against the analytic solid; a box's corners and edges exactly.
  const double r = 0.05, R = 0.07, rt = 0.025;
  const Mesh sphere_mesh = make_sphere(r, 2), torus_mesh = make_torus(R, rt, 24, 12);
  const MeshIndex sphere(sphere_mesh), torus(torus_mesh);
  REQUIRE(sphere.oriented());
  REQUIRE(torus.oriented());
  Rng rng(17);
  int checked = 0, wrong = 0;
  for (int i = 0; i < 6000; ++i) {
    const bool near = i % 2 == 0;
    const auto& v = sphere_mesh.vertices[rng.index(sphere_mesh.vertices.size())];
    const Vec3 p = near ? Vec3(v + 0.004 * rng.unit_vector() * rng.uniform())
                        : Vec3(rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12));
    const ClosestPoint cs = sphere.closest(p);
    if (cs.distance > 1e-9) {
      ++checked;
      if ((sphere.side(p, cs) < 0.0) != sphere.inside(p)) ++wrong;
    }
    const Vec3 q = near ? Vec3(torus_mesh.vertices[rng.index(torus_mesh.vertices.size())] + 0.004 * rng.unit_vector() * rng.uniform())
                        : p;
    const ClosestPoint ct = torus.closest(q);
    if (ct.distance > 1e-9) {
      ++checked;
      if ((torus.side(q, ct) < 0.0) != torus.inside(q)) ++wrong;
    }
  }
  CHECK(checked > 11000);
  CHECK(wrong == 0);
  // A box: just outside a corner and an edge (where a face's own normal can point the wrong way).
  const MeshIndex box(make_box(Vec3(0.05, 0.05, 0.05), 1));
  REQUIRE(box.oriented());
  for (const Vec3& p : {Vec3(0.051, 0.051, 0.051), Vec3(0.06, 0.0502, 0.0), Vec3(0.0501, 0.07, -0.0501)})
    CHECK(box.side(p, box.closest(p)) > 0.0);
  for (const Vec3& p : {Vec3(0.049, 0.049, 0.049), Vec3(0.0499, 0.0498, 0.0), Vec3(0.0, 0.0, 0.0)})
    CHECK(box.side(p, box.closest(p)) < 0.0);
  // Not oriented: open, faces wound both ways, a repeated vertex; side() then answers 0.
  Mesh open = make_sphere(r, 2);
  open.faces.pop_back();
  Mesh mixed = make_sphere(r, 2);
  std::swap(mixed.faces[3][1], mixed.faces[3][2]);
  Mesh repeated = make_sphere(r, 2);
  repeated.faces.push_back({0, 0, 1});
  for (const Mesh* m : {&open, &mixed, &repeated}) {
    const MeshIndex index(*m);
    CHECK_FALSE(index.oriented());
    CHECK(index.side(Vec3(0.2, 0, 0), index.closest(Vec3(0.2, 0, 0))) == 0.0);
  }
  // Every part must be wound outward: a sphere turned inward, alone or beside an outward one, is
  // not oriented; two outward spheres are.
  CHECK_FALSE(MeshIndex(flipped(make_sphere(r, 2))).oriented());
  const auto two = [&](bool second_inward) {
    Mesh m = make_sphere(r, 1);
    Mesh other = make_sphere(0.02, 1, Vec3(0.2, 0.0, 0.0));
    if (second_inward) other = flipped(other);
    const int base = static_cast<int>(m.vertices.size());
    m.vertices.insert(m.vertices.end(), other.vertices.begin(), other.vertices.end());
    for (const auto& f : other.faces) m.faces.emplace_back(f[0] + base, f[1] + base, f[2] + base);
    return m;
  };
  CHECK(MeshIndex(two(false)).oriented());
  CHECK_FALSE(MeshIndex(two(true)).oriented());
}
