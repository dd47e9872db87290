// Benchmark of the simulated laser scanner (Section 4.2) on the default objects: per-object
// scan time and surface coverage, and a summary. The time includes building the mesh's BVH
// (what build_object pays), not the mesh import.
//
//   build/bench/bench_scan [MANIFEST=datasets/dev45.tsv] [THREADS=1] [--build]
//
// With --build, each object is built completely (build_object: scan, normals + FPFH, distance
// field, default DatabaseSettings) and the per-stage times are printed as well.
//
// Run from the repository root (the manifest's relative paths resolve against its folder).
#include "datasets/archive.hpp"
#include "datasets/manifest.hpp"
#include "engine/database/database.hpp"
#include "engine/geometry/scanner.hpp"
#include "experiments/resources.hpp"
#include "io/mesh_import.hpp"

#include <CLI/CLI.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <exception>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace {

double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

struct Row {
  std::string name;
  std::size_t faces = 0;
  bool closed = false;
  ts::ScanResult scan;
  ts::BuildTimings timings;
  double wall = 0.0, cpu = 0.0;
};

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

}  // namespace

int main(int argc, char** argv) {
  std::string manifest = "datasets/dev45.tsv";
  int threads = 1;
  bool build = false;
  CLI::App app{"bench_scan: the simulated laser scanner's time and coverage per object"};
  app.add_option("manifest", manifest, "Mesh manifest (default datasets/dev45.tsv)");
  app.add_option("threads", threads, "Threads (default 1)")->check(CLI::Range(1, 1024));
  app.add_flag("--build", build, "Build each object completely and print the per-stage times");
  CLI11_PARSE(app, argc, argv);
  try {
    const auto entries = ts::datasets::read_manifest(manifest);

    // Read every archive once.
    std::map<std::string, std::set<std::string>> wanted;
    for (const auto& e : entries)
      if (!e.member.empty()) wanted[e.path.string()].insert(e.member);
    std::map<std::string, std::map<std::string, std::string>> members;
    for (const auto& [archive, names] : wanted) members[archive] = ts::datasets::read_archive_members(archive, names);

    const ts::DatabaseSettings db_settings;
    const ts::ScanSettings& settings = db_settings.scan;
    std::printf("bench_scan: %zu objects from %s, %d thread(s), %s\n", entries.size(), manifest.c_str(),
                threads, ts::experiments::machine_description().c_str());
    std::printf("settings: fine_spacing %.4f m, ray pitch %.2f x fine, coverage radius %.4f m, "
                "target %.3f, max incidence %.0f/%.0f deg, max extent 0.20 m\n",
                settings.fine_spacing, settings.ray_pitch, settings.coverage_radius,
                settings.target_coverage, settings.max_incidence_deg, settings.grazing_incidence_deg);
    std::printf("%-22s %7s %6s %5s %9s %7s %6s %8s %8s %8s%s\n", "object", "faces", "closed", "views",
                "rays", "fine", "coarse", "coverage", "wall_s", "cpu_s",
                build ? "   scan_s   feat_s  field_s" : "");

    tbb::task_arena arena(threads);
    std::vector<Row> rows;
    for (const auto& e : entries) {
      const std::string label = e.member.empty() ? e.path.string() : e.path.string() + ":" + e.member;
      const auto imported = e.member.empty()
                                ? ts::io::import_mesh(e.path)
                                : ts::io::import_mesh_from_memory(members[e.path.string()][e.member], label);
      Row row;
      row.name = e.name;
      row.faces = imported.mesh.faces.size();
      row.closed = imported.closed;
      const auto t0 = std::chrono::steady_clock::now();
      const double c0 = cpu_seconds();
      arena.execute([&] {
        if (build) {
          ts::ObjectInfo info;
          info.name = e.name;
          ts::BuiltObject obj = ts::build_object(imported.mesh, info, db_settings, 1);
          row.timings = obj.timings;
          row.scan.fine = std::move(obj.fine);
          row.scan.coarse = std::move(obj.features.coarse);
          row.scan.coverage = obj.info.coverage;
          row.scan.views = -1;  // not reported by build_object
        } else {
          const ts::MeshIndex index(imported.mesh);
          row.scan = ts::scan_mesh(index, settings, 1);
        }
      });
      row.cpu = cpu_seconds() - c0;
      row.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::printf("%-22s %7zu %6s %5d %9zu %7zu %6zu %8.4f %8.3f %8.3f", row.name.c_str(), row.faces,
                  row.closed ? "yes" : "no", row.scan.views, row.scan.rays, row.scan.fine.size(),
                  row.scan.coarse.size(), row.scan.coverage, row.wall, row.cpu);
      if (build) std::printf(" %8.3f %8.3f %8.3f", row.timings.scan_s, row.timings.features_s, row.timings.field_s);
      std::printf("\n");
      std::fflush(stdout);
      rows.push_back(std::move(row));
    }

    std::vector<double> wall, cpu, cov_closed;
    std::size_t closed = 0, closed_ok = 0;
    std::string below;
    for (const auto& r : rows) {
      wall.push_back(r.wall);
      cpu.push_back(r.cpu);
      if (!r.closed) continue;
      ++closed;
      cov_closed.push_back(r.scan.coverage);
      if (r.scan.coverage >= 0.99) ++closed_ok;
      else below += " " + r.name + "(" + std::to_string(r.scan.coverage).substr(0, 6) + ")";
    }
    auto sum = [](const std::vector<double>& v) { double s = 0; for (double x : v) s += x; return s; };
    std::printf("\nsummary: %zu objects, %d thread(s)%s\n", rows.size(), threads,
                build ? ", full build_object (views/rays not reported)" : ", scan only");
    if (build) {
      double scan = 0, feat = 0, field = 0;
      for (const auto& r : rows) scan += r.timings.scan_s, feat += r.timings.features_s, field += r.timings.field_s;
      std::printf("  stage totals (wall s): scan %.2f  features %.2f  field %.2f\n", scan, feat, field);
    }
    std::printf("  wall s per object: mean %.3f  median %.3f  max %.3f  total %.2f\n",
                sum(wall) / std::max<std::size_t>(1, rows.size()), median(wall),
                wall.empty() ? 0.0 : *std::max_element(wall.begin(), wall.end()), sum(wall));
    std::printf("  cpu  s per object: mean %.3f  median %.3f  max %.3f  total %.2f\n",
                sum(cpu) / std::max<std::size_t>(1, rows.size()), median(cpu),
                cpu.empty() ? 0.0 : *std::max_element(cpu.begin(), cpu.end()), sum(cpu));
    std::printf("  closed meshes: %zu, coverage >= 0.99: %zu, min %.4f, median %.4f%s%s\n", closed, closed_ok,
                cov_closed.empty() ? 0.0 : *std::min_element(cov_closed.begin(), cov_closed.end()),
                median(cov_closed), below.empty() ? "" : ", below 0.99:", below.c_str());
    return 0;
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "bench_scan: error: %s\n", ex.what());
    return 1;
  }
}
