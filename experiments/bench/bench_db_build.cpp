// Benchmark: build the default 45-object database and open its summary (what `db info` does).
// Targets (issue 2): build <= 60 s and info <= 1 s on a 2-core machine.
//
//   build/bench/bench_db_build [MANIFEST (default datasets/dev45.tsv)] [THREADS (default: all)]
//                              [COMPRESS (zlib level, default: as db build)]
//
// Run from the repository root. Prints the machine, thread count, per-stage times and totals.
#include "datasets/db_builder.hpp"
#include "experiments/resources.hpp"
#include "io/db_store.hpp"

#include <CLI/CLI.hpp>
#include <sys/resource.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <optional>
#include <fstream>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

namespace {
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}
/// 1-minute load average: other processes on the machine inflate wall times.
std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string one;
  in >> one;
  return one.empty() ? "unknown" : one;
}
}  // namespace

int main(int argc, char** argv) {
  std::string manifest = "datasets/dev45.tsv";
  int threads = tbb::info::default_concurrency();
  std::optional<int> compress;
  CLI::App app{"bench_db_build: build a database and open its summary"};
  app.add_option("manifest", manifest, "Mesh manifest (default datasets/dev45.tsv)");
  app.add_option("threads", threads, "Threads (default: all)")->check(CLI::Range(1, 1024));
  app.add_option("compress", compress, "zlib level of the stored data (default: as db build)")->check(CLI::Range(0, 9));
  CLI11_PARSE(app, argc, argv);
  const auto out = std::filesystem::temp_directory_path() / ("bench_db_" + std::to_string(::getpid()) + ".h5");
  using Clock = std::chrono::steady_clock;
  try {
    const auto inputs = ts::datasets::inputs_from_manifest(manifest);
    ts::datasets::BuildSettings settings;
    if (compress) settings.write.deflate = *compress;
    tbb::task_arena arena(threads);
    const std::string load_before = load_average();
    const double cpu0 = cpu_seconds();
    const auto report = arena.execute([&] { return ts::datasets::build_database(inputs, out, settings); });
    const auto& t = report.times;
    const double cpu = cpu_seconds() - cpu0;
    const std::string load_after = load_average();

    // `db info`: open the database and read every object's summary, as the command does.
    std::vector<double> opens;
    std::size_t fine = 0;
    for (int rep = 0; rep < 5; ++rep) {
      const auto t0 = Clock::now();
      ts::io::DbReader db(out);
      fine = 0;
      for (std::size_t i = 0; i < db.size(); ++i) fine += db.info(i).fine_points;
      opens.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
    }
    std::sort(opens.begin(), opens.end());
    // What the recognizer pays when it touches objects: every object's arrays, loaded once.
    double load_all = 0.0;
    {
      ts::io::DbReader db(out);
      const auto t0 = Clock::now();
      for (std::size_t i = 0; i < db.size(); ++i) {
        (void)db.load_features(i);
        (void)db.load_fine(i);
        (void)db.load_field(i);
      }
      load_all = std::chrono::duration<double>(Clock::now() - t0).count();
    }
    double coverage_min = 1.0;
    for (double c : report.coverage) coverage_min = std::min(coverage_min, c);

    std::printf("bench_db_build: %s\n", manifest.c_str());
    std::printf("machine: %s; threads: %d; compression level %d\n", ts::experiments::machine_description().c_str(), threads,
                settings.write.deflate);
    std::printf("objects: %zu, fine points: %zu, file: %.1f MB, lowest coverage: %.2f %%\n", report.names.size(), fine,
                static_cast<double>(std::filesystem::file_size(out)) / 1e6, 100.0 * coverage_min);
    std::printf("load average (1 min) before/after: %s / %s (other processes slow the wall time)\n",
                load_before.c_str(), load_after.c_str());
    std::printf("build wall time: %.2f s (target <= 60 s); CPU time %.2f s\n", t.wall_s, cpu);
    std::printf("  read archives %.2f s (wall)\n", t.read_s);
    std::printf("  import        %.2f s (summed over objects)\n", t.import_s);
    std::printf("  scan          %.2f s (summed over objects)\n", t.scan_s);
    std::printf("  features      %.2f s (summed over objects)\n", t.features_s);
    std::printf("  field         %.2f s (summed over objects)\n", t.field_s);
    std::printf("  write         %.2f s (wall)\n", t.write_s);
    std::printf("db info (open + every summary), median of 5: %.4f s (target <= 1 s)\n", opens[2]);
    std::printf("load every object's features, fine cloud and distance field: %.2f s\n", load_all);
  } catch (const std::exception& e) {
    std::cerr << "bench_db_build: " << e.what() << '\n';
    std::filesystem::remove(out);
    return 1;
  }
  std::filesystem::remove(out);
  return 0;
}
