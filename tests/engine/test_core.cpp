#include "engine/core.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <set>

using namespace ts;

TEST_CASE("Rng streams are reproducible and distinct per tuple") {
  Rng a(7, 1, 2), b(7, 1, 2), c(7, 2, 1), d(8, 1, 2);
  for (int i = 0; i < 100; ++i) {
    const auto va = a.next();
    CHECK(va == b.next());
    CHECK(va != c.next());
    CHECK(va != d.next());
  }
}

TEST_CASE("Rng distributions have the right moments") {
  Rng r(42);
  const int n = 200000;
  double su = 0, sn = 0, sn2 = 0;
  std::array<int, 7> counts{};
  for (int i = 0; i < n; ++i) {
    const double u = r.uniform();
    REQUIRE(u >= 0.0);
    REQUIRE(u < 1.0);
    su += u;
    const double g = r.normal();
    sn += g;
    sn2 += g * g;
    counts[r.index(7)]++;
  }
  CHECK(su / n == doctest::Approx(0.5).epsilon(0.01));
  CHECK(sn / n == doctest::Approx(0.0).epsilon(0.01));
  CHECK(sn2 / n == doctest::Approx(1.0).epsilon(0.02));
  for (int c : counts) CHECK(std::abs(c - n / 7.0) < 0.03 * n / 7.0);
}

TEST_CASE("Rng rotations are proper and unit vectors are unit") {
  Rng r(3);
  Vec3 mean = Vec3::Zero();
  for (int i = 0; i < 20000; ++i) {
    const Mat3 R = r.rotation().toRotationMatrix();
    REQUIRE(R.determinant() == doctest::Approx(1.0));
    const Vec3 u = r.unit_vector();
    REQUIRE(u.norm() == doctest::Approx(1.0));
    mean += u;
  }
  CHECK((mean / 20000).norm() < 0.02);
}

TEST_CASE("Error formats file and field") {
  CHECK(std::string(Error("bad shape", "db.h5", "/objects/cube/features").what()) ==
        "bad shape (db.h5, /objects/cube/features)");
  CHECK(std::string(Error("bad", "f.txt").what()) == "bad (f.txt)");
  CHECK(std::string(Error("plain").what()) == "plain");
}
