// Benchmark of the feature stages on the default objects:
//   - FPFH throughput: features of every object's coarse cloud over its fine cloud (what the
//     database build pays), keypoints per second;
//   - FeatureIndex: recall@W of the approximate mode (seeded randomized k-d forest) against the
//     exact mode for W = 3000 and W = 100, over a sweep of `checks`, and the query times of both
//     modes (FLANN's own randomized KDTreeIndex, which is not reproducible, is measured alongside
//     for reference). Queries are FPFH of noisy contact-like data: points of a random object's
//     scan jittered by 0.5 mm, normals re-estimated (7 mm), features over the jittered cloud;
//   - DistanceField: build time, voxels, accuracy against the exact mesh distance (MeshIndex),
//     and query throughput with 1 and 2 threads.
//
//   build/bench/bench_features [MANIFEST=datasets/dev45.tsv] [THREADS=2] [QUERIES=300] [OBJECTS=all]
//
// Run from the repository root (the manifest's relative paths resolve against its folder).
#include "datasets/archive.hpp"
#include "datasets/manifest.hpp"
#include "engine/features/fpfh.hpp"
#include "engine/geometry/cloud.hpp"
#include "engine/geometry/distance_field.hpp"
#include "engine/geometry/scanner.hpp"
#include "engine/geometry/search.hpp"
#include "experiments/resources.hpp"
#include "io/mesh_import.hpp"

#include <CLI/CLI.hpp>
#include <flann/algorithms/dist.h>
#include <flann/algorithms/kdtree_index.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <map>
#include <set>

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

struct Object {
  std::string name;
  ts::io::ImportedMesh mesh;
  ts::ScanResult scan;
  std::vector<ts::Feature> features;
  std::vector<bool> valid;
  ts::DistanceField field;
  double field_wall = 0, field_cpu = 0;
};

double recall(const std::vector<ts::Neighbour>& got, const std::vector<ts::Neighbour>& truth) {
  if (truth.empty()) return 1.0;
  std::vector<std::uint32_t> a, b;
  for (const auto& n : got) a.push_back(n.index);
  for (const auto& n : truth) b.push_back(n.index);
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  std::vector<std::uint32_t> common;
  std::set_intersection(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(common));
  return static_cast<double>(common.size()) / static_cast<double>(truth.size());
}

/// Contact-like queries: jittered scan points, re-estimated normals, FPFH over the jittered cloud.
std::vector<ts::Feature> make_queries(const std::vector<Object>& objs, int n, tbb::task_arena& arena) {
  std::vector<ts::Feature> queries;
  ts::Rng rng(12345);
  const int per_object = std::max(1, n / static_cast<int>(objs.size()));
  for (std::size_t o = 0; o < objs.size() && static_cast<int>(queries.size()) < n; ++o) {
    const auto& fine = objs[o].scan.fine;
    if (fine.size() < 50) continue;
    ts::PointCloud noisy;
    noisy.points = fine.points;
    for (auto& p : noisy.points) p += 0.0005 * ts::Vec3(rng.normal(), rng.normal(), rng.normal());
    arena.execute([&] { noisy.normals = ts::estimate_normals(noisy.points, ts::NormalSettings{}); });
    for (std::size_t i = 0; i < fine.size(); ++i)
      if (noisy.normals[i].dot(fine.normals[i]) < 0) noisy.normals[i] = -noisy.normals[i];
    std::vector<ts::Vec3> kps;
    for (int k = 0; k < per_object; ++k) kps.push_back(noisy.points[rng.index(noisy.size())]);
    ts::FpfhResult r;
    arena.execute([&] { r = ts::compute_fpfh(kps, {}, noisy, ts::KdTree3(noisy.points), ts::FpfhSettings{}); });
    for (std::size_t k = 0; k < kps.size(); ++k)
      if (r.valid[k]) queries.push_back(r.features[k]);
  }
  return queries;
}

}  // namespace

int main(int argc, char** argv) {
  std::string manifest = "datasets/dev45.tsv";
  int threads = 2, nqueries = 300;
  std::size_t max_objects = 1000000;
  CLI::App app{"bench_features: FPFH throughput, FeatureIndex recall and speed, DistanceField accuracy"};
  app.add_option("manifest", manifest, "Mesh manifest (default datasets/dev45.tsv)");
  app.add_option("threads", threads, "Threads (default 2)")->check(CLI::Range(1, 1024));
  app.add_option("queries", nqueries, "Feature queries (default 300)")->check(CLI::Range(10, 100000000));
  app.add_option("objects", max_objects, "The manifest's first objects only (default all)")->check(CLI::Range(1, 1000000));
  CLI11_PARSE(app, argc, argv);
  try {
    auto entries = ts::datasets::read_manifest(manifest);
    if (entries.size() > max_objects) entries.resize(max_objects);
    std::printf("bench_features: %zu objects from %s, %d thread(s), %s\n", entries.size(), manifest.c_str(),
                threads, ts::experiments::machine_description().c_str());
    tbb::task_arena arena(threads);

    std::map<std::string, std::set<std::string>> wanted;
    for (const auto& e : entries)
      if (!e.member.empty()) wanted[e.path.string()].insert(e.member);
    std::map<std::string, std::map<std::string, std::string>> members;
    for (const auto& [archive, names] : wanted) members[archive] = ts::datasets::read_archive_members(archive, names);

    // ---- Scan (not measured here: see bench_scan) and FPFH of each object's coarse cloud ----
    const ts::FpfhSettings fpfh;
    std::vector<Object> objs;
    double fpfh_wall = 0, fpfh_cpu = 0;
    std::size_t fpfh_points = 0, fpfh_valid = 0;
    for (const auto& e : entries) {
      Object o;
      o.name = e.name;
      const std::string label = e.member.empty() ? e.path.string() : e.path.string() + ":" + e.member;
      o.mesh = e.member.empty() ? ts::io::import_mesh(e.path)
                                : ts::io::import_mesh_from_memory(members[e.path.string()][e.member], label);
      arena.execute([&] { o.scan = ts::scan_mesh(ts::MeshIndex(o.mesh.mesh), ts::ScanSettings{}, 1); });
      const ts::KdTree3 tree(o.scan.fine.points);
      const auto t0 = Clock::now();
      const double c0 = cpu_seconds();
      ts::FpfhResult r;
      arena.execute([&] { r = ts::compute_fpfh(o.scan.coarse.points, o.scan.coarse.normals, o.scan.fine, tree, fpfh); });
      fpfh_wall += since(t0);
      fpfh_cpu += cpu_seconds() - c0;
      fpfh_points += r.features.size();
      for (bool v : r.valid) fpfh_valid += v;
      o.features = std::move(r.features);
      o.valid = std::move(r.valid);
      objs.push_back(std::move(o));
    }
    std::printf("\nFPFH (feature radius %.0f mm, coarse keypoints over the fine cloud)\n", fpfh.feature_radius * 1e3);
    std::printf("  %zu keypoints (%zu valid) in %.2f s wall, %.2f s cpu: %.0f keypoints/s wall, %.0f keypoints/s per core\n",
                fpfh_points, fpfh_valid, fpfh_wall, fpfh_cpu, fpfh_points / fpfh_wall, fpfh_points / fpfh_cpu);

    // ---- Feature index ----
    std::vector<ts::Feature> feats;
    std::vector<ts::FeatureRef> refs;
    for (std::uint32_t o = 0; o < objs.size(); ++o)
      for (std::uint32_t i = 0; i < objs[o].features.size(); ++i)
        if (objs[o].valid[i]) {
          feats.push_back(objs[o].features[i]);
          refs.push_back({o, i});
        }
    const auto queries = make_queries(objs, nqueries, arena);
    std::printf("\nFeatureIndex: %zu database features, %zu queries (noisy contact-like FPFH)\n", feats.size(),
                queries.size());

    auto t0 = Clock::now();
    ts::FeatureIndexSettings exact_settings;
    exact_settings.exact = true;
    const ts::FeatureIndex exact(ts::FeatureRows(feats), refs, exact_settings);
    std::printf("  exact build %.3f s\n", since(t0));

    for (const std::size_t w : {std::size_t(3000), std::size_t(100)}) {
      std::vector<std::vector<ts::Neighbour>> truth(queries.size());
      t0 = Clock::now();
      for (std::size_t q = 0; q < queries.size(); ++q) truth[q] = exact.knn(queries[q].data(), w);
      const double t_exact = since(t0) / static_cast<double>(queries.size());
      std::printf("  W = %zu: exact %.3f ms/query (1 thread)\n", w, t_exact * 1e3);
      std::printf("    %-28s %7s %9s %11s\n", "approximate", "checks", "recall", "ms/query");
      for (const int trees : {4, 8}) {
        for (const int checks : {256, 1024, 4096, 16384, 65536}) {
          if (static_cast<std::size_t>(checks) < w / 4) continue;
          ts::FeatureIndexSettings s;
          s.exact = false;
          s.trees = trees;
          s.checks = checks;
          const ts::FeatureIndex approx(ts::FeatureRows(feats), refs, s);
          double rec = 0;
          t0 = Clock::now();
          std::vector<std::vector<ts::Neighbour>> got(queries.size());
          for (std::size_t q = 0; q < queries.size(); ++q) got[q] = approx.knn(queries[q].data(), w);
          const double t = since(t0) / static_cast<double>(queries.size());
          for (std::size_t q = 0; q < queries.size(); ++q) rec += recall(got[q], truth[q]);
          std::printf("    ts forest, %d trees %12s %7d %9.4f %11.3f\n", trees, "", checks, rec / queries.size(), t * 1e3);
        }
      }
      // FLANN's randomized forest for reference (std::random_device inside: not reproducible).
      flann::Matrix<float> data(feats.front().data(), feats.size(), ts::kFeatureDim);
      for (const int checks : {1024, 4096, 16384}) {
        if (static_cast<std::size_t>(checks) < w / 4) continue;
        flann::KDTreeIndex<flann::L2<float>> index(data, flann::KDTreeIndexParams(4));
        index.buildIndex();
        std::vector<std::size_t> idx(w);
        std::vector<float> dist(w);
        double rec = 0;
        t0 = Clock::now();
        for (std::size_t q = 0; q < queries.size(); ++q) {
          flann::Matrix<float> qm(const_cast<float*>(queries[q].data()), 1, ts::kFeatureDim);
          flann::Matrix<std::size_t> im(idx.data(), 1, w);
          flann::Matrix<float> dm(dist.data(), 1, w);
          flann::SearchParams sp(checks);
          sp.cores = 1;
          index.knnSearch(qm, im, dm, w, sp);
          std::vector<ts::Neighbour> got;
          for (std::size_t k = 0; k < w; ++k) got.push_back({static_cast<std::uint32_t>(idx[k]), dist[k]});
          rec += recall(got, truth[q]);
        }
        const double t = since(t0) / static_cast<double>(queries.size());
        std::printf("    FLANN KDTreeIndex, 4 trees %5s %7d %9.4f %11.3f\n", "", checks, rec / queries.size(), t * 1e3);
      }
    }

    // ---- Distance fields ----
    const ts::DistanceFieldSettings dfs;
    std::printf("\nDistanceField (fine %.1f mm x +-%d voxels, coarse %.0f mm over bbox + %.2f m)\n", dfs.fine_voxel * 1e3,
                dfs.fine_band_voxels, dfs.coarse_voxel * 1e3, dfs.coarse_margin);
    std::printf("  %-22s %7s %6s %8s %8s %9s %9s %10s %10s\n", "object", "faces", "closed", "wall_s", "cpu_s",
                "fine_vox", "coarse_vox", "near_mm", "far_mm");
    double sum_wall = 0, sum_cpu = 0, worst_near = 0, worst_far = 0;
    std::size_t sum_fine = 0, sum_coarse = 0;
    for (auto& o : objs) {
      const auto w0 = Clock::now();
      const double c0 = cpu_seconds();
      arena.execute([&] { o.field = ts::DistanceField::build(o.mesh.mesh, o.mesh.closed, dfs); });
      o.field_wall = since(w0);
      o.field_cpu = cpu_seconds() - c0;
      const auto fine_n = o.field.fine_sparse().ijk.size(), coarse_n = o.field.coarse_sparse().ijk.size();
      // Accuracy of |distance| against the exact unsigned distance (signs are tested in the unit
      // tests; MeshIndex::inside is not an oracle for meshes whose edges sit on ray paths).
      const ts::MeshIndex mi(o.mesh.mesh);
      ts::Rng rng(3);
      double near = 0, far = 0;
      for (int q = 0; q < 2000; ++q) {
        const auto& f = o.mesh.mesh.faces[rng.index(o.mesh.mesh.faces.size())];
        const ts::Vec3 p = o.mesh.mesh.vertices[f[0]] + rng.uniform(0, 0.03) * rng.unit_vector();
        const double ex = mi.closest(p).distance, got = std::abs(o.field.distance(p));
        if (ex < (dfs.fine_band_voxels - 1) * dfs.fine_voxel - 0.0035) near = std::max(near, std::abs(got - ex));
        else if (ex < dfs.coarse_margin) far = std::max(far, std::abs(got - ex));
      }
      std::printf("  %-22s %7zu %6s %8.3f %8.3f %9zu %9zu %10.3f %10.3f\n", o.name.c_str(), o.mesh.mesh.faces.size(),
                  o.mesh.closed ? "yes" : "no", o.field_wall, o.field_cpu, fine_n, coarse_n, near * 1e3, far * 1e3);
      std::fflush(stdout);
      sum_wall += o.field_wall;
      sum_cpu += o.field_cpu;
      sum_fine += fine_n;
      sum_coarse += coarse_n;
      worst_near = std::max(worst_near, near);
      worst_far = std::max(worst_far, far);
    }
    const double n = static_cast<double>(objs.size());
    std::printf("  total: build %.2f s wall (%.3f s/object), %.2f s cpu (%.3f s/object); %zu fine + %zu coarse voxels "
                "(%.1f MB as SparseGrid); worst |error| near %.3f mm, far %.3f mm\n",
                sum_wall, sum_wall / n, sum_cpu, sum_cpu / n, sum_fine, sum_coarse,
                (sum_fine + sum_coarse) * 16.0 / 1e6, worst_near * 1e3, worst_far * 1e3);

    // Query throughput: points near the surfaces (the common case) and spread over the boxes.
    std::vector<std::vector<ts::Vec3>> pts(objs.size());
    ts::Rng rng(4);
    for (std::size_t o = 0; o < objs.size(); ++o) {
      const auto& fine = objs[o].scan.fine;
      for (int q = 0; q < 20000; ++q) {
        if (q % 2 && !fine.empty()) pts[o].push_back(fine.points[rng.index(fine.size())] + 0.003 * rng.unit_vector());
        else pts[o].push_back(ts::Vec3(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3)));
      }
    }
    for (const int t : {1, 2}) {
      tbb::task_arena a(t);
      double sink = 0;
      const int reps = 5;
      std::vector<double> out(objs.size() * reps, 0.0);
      const auto q0 = Clock::now();
      a.execute([&] {
        tbb::parallel_for(std::size_t(0), objs.size() * reps, [&](std::size_t job) {
          const std::size_t o = job % objs.size();
          std::vector<double> d(pts[o].size());
          objs[o].field.distances(pts[o].data(), pts[o].size(), ts::Pose::Identity(), d.data());
          double s = 0;
          for (double v : d) s += v;
          out[job] = s;   // keep the work observable
        });
      });
      const double secs = since(q0);
      for (double v : out) sink += v;
      const double total = static_cast<double>(reps) * static_cast<double>(objs.size()) * 20000.0;
      std::printf("  queries, %d thread(s): %.2f M/s (batch API, 20000 points per call, %.0f ns/query per thread) [checksum %.6g]\n", t,
                  total / secs / 1e6, secs * t / total * 1e9, sink);
    }
    return 0;
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "bench_features: error: %s\n", ex.what());
    return 1;
  }
}
