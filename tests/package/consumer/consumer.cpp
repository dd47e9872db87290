// Uses the installed libraries and command: the signed distance field of a box (engine) against
// the box's exact signed distance, a cloud written and read back as PLY (io), and the command's
// --version. Prints "consumer: ok" and exits 0 when everything holds.
#include "engine/core.hpp"
#include "engine/geometry/distance_field.hpp"
#include "engine/geometry/kabsch.hpp"   // C++20 headers (std::span): the package asks for C++20
#include "engine/geometry/search.hpp"
#include "io/cloud_io.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

int consumer_part();   // the consumer's own static library

namespace {

ts::Mesh box(const ts::Vec3& size) {
  ts::Mesh m;
  const ts::Vec3 h = size / 2;
  for (int i = 0; i < 8; ++i)
    m.vertices.emplace_back((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? h.z() : -h.z());
  const int q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& f : q) {
    m.faces.emplace_back(f[0], f[1], f[2]);
    m.faces.emplace_back(f[0], f[2], f[3]);
  }
  return m;
}

/// Exact signed distance to an axis-aligned box of half sizes h (negative inside).
double box_distance(const ts::Vec3& p, const ts::Vec3& h) {
  const ts::Vec3 q = p.cwiseAbs() - h;
  return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}

int fail(const std::string& what) {
  std::fprintf(stderr, "consumer: %s\n", what.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) return fail("usage: consumer WORK_DIR");
  if (consumer_part() != 1) return fail("the consumer's own library");
  const std::filesystem::path work = argv[1];

  // engine: a field of a 12 x 8 x 5 cm box; points in its narrow band, inside and outside.
  const ts::Vec3 size(0.12, 0.08, 0.05);
  const ts::DistanceField field = ts::DistanceField::build(box(size), true, ts::DistanceFieldSettings{});
  ts::Rng rng(7);
  double worst = 0.0;
  for (int i = 0; i < 200; ++i) {
    // A point of a face, then up to 3 mm off it: the field's fine narrow band.
    ts::Vec3 p(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));
    p[static_cast<int>(rng.index(3))] = rng.uniform() < 0.5 ? -1.0 : 1.0;
    p = p.cwiseProduct(size / 2) + rng.unit_vector() * rng.uniform(0.0, 0.003);
    worst = std::max(worst, std::abs(field.distance(p) - box_distance(p, size / 2)));
  }
  if (!(worst < 0.001)) return fail("the distance field is off by " + std::to_string(worst) + " m");

  // io: a cloud written as PLY and read back.
  ts::PointCloud cloud;
  for (int i = 0; i < 50; ++i) {
    cloud.points.push_back(rng.unit_vector() * 0.1);
    cloud.normals.push_back(rng.unit_vector());
  }
  const auto ply = work / "cloud.ply";
  ts::io::write_ply(ply, cloud);
  const ts::PointCloud back = ts::io::read_ply(ply);
  if (back.size() != cloud.size()) return fail("PLY: " + std::to_string(back.size()) + " points read back");
  for (std::size_t i = 0; i < cloud.size(); ++i)
    if ((back.points[i] - cloud.points[i]).norm() > 1e-6) return fail("PLY: point " + std::to_string(i) + " moved");

  // The installed command.
  const std::string cmd = std::string("'") + TOUCHSTONE_COMMAND + "' --version > '" + (work / "version.txt").string() + "'";
  if (std::system(cmd.c_str()) != 0) return fail("touchstone --version failed");
  std::FILE* f = std::fopen((work / "version.txt").c_str(), "r");
  char line[128] = {};
  const bool read = f && std::fgets(line, sizeof line, f);
  if (f) std::fclose(f);
  if (!read || std::string(line).rfind("touchstone ", 0) != 0) return fail("touchstone --version printed '" + std::string(line) + "'");

  std::printf("consumer: ok (field within %.2f mm, %zu PLY points)\n", worst * 1e3, back.size());
  return 0;
}
