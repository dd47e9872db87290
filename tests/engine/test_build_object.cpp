#include "engine/database/database.hpp"
#include "mesh_shapes.hpp"

#include <doctest/doctest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <set>

using namespace ts;

namespace {

ObjectInfo named(const std::string& name) {
  ObjectInfo info;
  info.name = name;
  info.source = "generated";
  info.mesh_sha256 = "abc";
  info.scale = 2.5;
  info.centre = Vec3(1, 2, 3);
  return info;
}

/// Defaults, but a distance field with a small margin (keeps the test fast; the field's own
/// tests cover its settings).
DatabaseSettings test_settings() {
  DatabaseSettings s;
  s.field.coarse_margin = 0.03;
  return s;
}

}  // namespace

TEST_CASE("build_object: a complete, consistent object from a closed mesh") {
  const Mesh mesh = test::make_sphere(0.04, 3, Vec3(0.001, -0.002, 0.0));
  const DatabaseSettings settings = test_settings();
  const BuiltObject obj = build_object(mesh, named("ball"), settings, 5);

  // Caller's fields kept, builder's fields filled.
  CHECK(obj.info.name == "ball");
  CHECK(obj.info.source == "generated");
  CHECK(obj.info.mesh_sha256 == "abc");
  CHECK(obj.info.scale == 2.5);
  CHECK(obj.info.centre == Vec3(1, 2, 3));
  CHECK((obj.info.extent - mesh_bounds(mesh).sizes()).norm() < 1e-12);
  CHECK(obj.info.closed);
  CHECK(obj.info.coverage >= 0.99);
  CHECK(obj.info.fine_points == obj.fine.size());
  CHECK(obj.info.coarse_points == obj.features.coarse.size());
  CHECK(obj.mesh.vertices == mesh.vertices);
  CHECK(obj.mesh.faces == mesh.faces);
  CHECK(obj.timings.scan_s >= 0.0);

  // Fine cloud: on the sphere, outward normals.
  REQUIRE(obj.fine.has_normals());
  REQUIRE(obj.fine.size() > 1000);
  const Vec3 c(0.001, -0.002, 0.0);
  for (std::size_t i = 0; i < obj.fine.size(); ++i) {
    CHECK(obj.fine.normals[i].dot(obj.fine.points[i] - c) > 0.0);
  }

  // Features: one per coarse point; coarse points are fine points; PCA normals outward.
  const auto& f = obj.features;
  REQUIRE(f.coarse.has_normals());
  REQUIRE(f.features.size() == f.coarse.size());
  REQUIRE(f.coarse.size() > 100);
  const std::set<std::array<double, 3>> fine_set = [&] {
    std::set<std::array<double, 3>> s;
    for (const auto& p : obj.fine.points) s.insert({p.x(), p.y(), p.z()});
    return s;
  }();
  for (std::size_t i = 0; i < f.coarse.size(); ++i) {
    const Vec3& p = f.coarse.points[i];
    CHECK(fine_set.count({p.x(), p.y(), p.z()}) == 1);
    CHECK(std::abs(f.coarse.normals[i].norm() - 1.0) < 1e-9);
    CHECK(f.coarse.normals[i].dot((p - c).normalized()) > 0.98);  // PCA on a 40 mm sphere
    for (int block = 0; block < 3; ++block) {
      double sum = 0.0;
      for (int b = 0; b < 11; ++b) {
        const float v = f.features.row(i)[block * 11 + b];
        CHECK(std::isfinite(v));
        CHECK(v >= 0.0f);
        sum += v;
      }
      CHECK(sum == doctest::Approx(100.0).epsilon(1e-3));
    }
  }

  // Distance field: ~0 on the scanned surface, negative inside, positive outside.
  REQUIRE_FALSE(obj.field.empty());
  CHECK(obj.field.is_signed());
  for (std::size_t i = 0; i < obj.fine.size(); i += 50)
    CHECK(std::abs(obj.field.distance(obj.fine.points[i])) < settings.field.fine_voxel);
  CHECK(obj.field.distance(c) < -0.03);
  CHECK(obj.field.distance(c + Vec3(0.06, 0, 0)) > 0.015);
}

TEST_CASE("build_object: identical objects for 1 and 2 threads; open meshes are unsigned") {
  const Mesh mesh = test::make_box(Vec3(0.03, 0.02, 0.015), 2);
  const DatabaseSettings settings = test_settings();
  BuiltObject a, b;
  tbb::task_arena(1).execute([&] { a = build_object(mesh, named("box"), settings, 9); });
  tbb::task_arena(2).execute([&] { b = build_object(mesh, named("box"), settings, 9); });
  CHECK(a.fine.points == b.fine.points);
  CHECK(a.fine.normals == b.fine.normals);
  CHECK(a.features.coarse.points == b.features.coarse.points);
  CHECK(a.features.coarse.normals == b.features.coarse.normals);
  CHECK(a.features.features == b.features.features);
  CHECK(a.info.coverage == b.info.coverage);
  const SparseGrid fa = a.field.fine_sparse(), fb = b.field.fine_sparse();
  CHECK(fa.ijk == fb.ijk);
  CHECK(fa.value == fb.value);
  const SparseGrid ca = a.field.coarse_sparse(), cb = b.field.coarse_sparse();
  CHECK(ca.ijk == cb.ijk);
  CHECK(ca.value == cb.value);

  Mesh open = mesh;
  open.faces.pop_back();
  open.faces.pop_back();
  const BuiltObject o = build_object(open, named("open box"), settings, 9);
  CHECK_FALSE(o.info.closed);
  CHECK_FALSE(o.field.is_signed());
  CHECK(o.info.coverage >= 0.99);
  CHECK(o.features.features.size() == o.features.coarse.size());
}
