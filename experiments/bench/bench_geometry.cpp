// Benchmark of what loading an object's geometry costs (what a cache miss under --memory-budget
// costs a step, and what a one-shot recognition pays per object it touches): for a spread of
// objects of a database file, the wall time of each part of a load (fine cloud read, its k-d
// tree, distance field read and build) and the memory each part holds.
//
//   build/bench/bench_geometry --db DB.h5 [--objects 40] [--repeat 2]
//
// Loads run one at a time on the calling thread (the page cache warm after the first repeat;
// the last repeat is reported). Prints the machine, thread count and every figure.
#include "experiments/allocator.hpp"
#include "experiments/resources.hpp"
#include "io/db_store.hpp"

#include <CLI/CLI.hpp>

#include <tbb/info.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

namespace {

using namespace ts;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

struct Row {
  double fine_s = 0, tree_s = 0, field_s = 0;
  double fine_mb = 0, tree_mb = 0, field_mb = 0;
};

}  // namespace

int main(int argc, char** argv) {
  std::string db_path;
  std::size_t objects = 40, repeat = 2;
  CLI::App app{"bench_geometry: what loading an object's geometry costs"};
  app.add_option("--db", db_path, "Object database (HDF5)")->required();
  app.add_option("--objects", objects, "Objects loaded, spread over the database")->check(CLI::Range(1, 1000000));
  app.add_option("--repeat", repeat, "Loads of each object (the last reported)")->check(CLI::Range(1, 1000));
  CLI11_PARSE(app, argc, argv);
  try {
    io::DbReader reader(db_path);
    std::vector<std::size_t> pick;
    const std::size_t n = std::min(objects, reader.size());
    for (std::size_t k = 0; k < n; ++k) pick.push_back(k * reader.size() / n);
    std::printf("bench_geometry: cost of loading an object's geometry\nmachine: %s, %d threads; first touch of fresh memory %.2f ms/MB\n"
                "database: %s (%zu objects), %zu objects loaded %zu times each (last reported)\n",
                experiments::machine_description().c_str(), tbb::info::default_concurrency(),
                experiments::first_touch_ms_per_mb(), db_path.c_str(), reader.size(), pick.size(), repeat);
    std::vector<Row> rows;
    for (std::size_t r = 0; r < repeat; ++r) {
      rows.clear();
      for (std::size_t o : pick) {
        Row row;
        auto t0 = Clock::now();
        PointCloud fine = reader.load_fine(o);
        row.fine_s = seconds_since(t0);
        t0 = Clock::now();
        const KdTree3 tree = KdTree3::over(fine.points);   // as the database holds it
        row.tree_s = seconds_since(t0);
        t0 = Clock::now();
        DistanceField field = reader.load_field(o);
        row.field_s = seconds_since(t0);
        row.fine_mb = 1e-6 * double((fine.points.capacity() + fine.normals.capacity()) * sizeof(Vec3));
        row.tree_mb = 1e-6 * double(tree.memory_bytes());
        row.field_mb = 1e-6 * double(field.memory_bytes());
        rows.push_back(row);
      }
    }
    auto stat = [&](auto get) {
      std::vector<double> v;
      for (const auto& r : rows) v.push_back(get(r));
      std::sort(v.begin(), v.end());
      double mean = 0;
      for (double x : v) mean += x;
      mean /= double(v.size());
      return std::array<double, 3>{mean, v[v.size() / 2], v[(v.size() * 9) / 10]};
    };
    std::printf("\n%-26s %10s %10s %10s\n", "part", "mean", "median", "p90");
    auto line = [&](const char* name, auto get, double scale) {
      const auto s = stat(get);
      std::printf("%-26s %10.2f %10.2f %10.2f\n", name, s[0] * scale, s[1] * scale, s[2] * scale);
    };
    line("fine cloud read (ms)", [](const Row& r) { return r.fine_s; }, 1e3);
    line("fine k-d tree build (ms)", [](const Row& r) { return r.tree_s; }, 1e3);
    line("distance field load (ms)", [](const Row& r) { return r.field_s; }, 1e3);
    line("whole load (ms)", [](const Row& r) { return r.fine_s + r.tree_s + r.field_s; }, 1e3);
    line("fine cloud (MB)", [](const Row& r) { return r.fine_mb; }, 1.0);
    line("fine k-d tree (MB)", [](const Row& r) { return r.tree_mb; }, 1.0);
    line("distance field (MB)", [](const Row& r) { return r.field_mb; }, 1.0);
    line("whole geometry (MB)", [](const Row& r) { return r.fine_mb + r.tree_mb + r.field_mb; }, 1.0);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_geometry: error: %s\n", e.what());
    return 1;
  }
}
