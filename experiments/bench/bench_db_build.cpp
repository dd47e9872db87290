// Benchmark: build the default 45-object database and open its summary (what `db info` does).
// Targets (issue 2): build <= 60 s and info <= 1 s on a 2-core machine.
//
//   build/bench/bench_db_build [MANIFEST (default datasets/dev45.tsv)] [THREADS (default: all)]
//
// Run from the repository root. Prints the machine, thread count, per-stage times and totals.
#include "datasets/db_builder.hpp"
#include "experiments/cli_common.hpp"
#include "io/db_store.hpp"

#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  const std::string manifest = argc > 1 ? argv[1] : "datasets/dev45.tsv";
  const int threads = argc > 2 ? std::stoi(argv[2]) : tbb::info::default_concurrency();
  const auto out = std::filesystem::temp_directory_path() / ("bench_db_" + std::to_string(::getpid()) + ".h5");
  using Clock = std::chrono::steady_clock;
  try {
    const auto inputs = ts::datasets::inputs_from_manifest(manifest);
    ts::datasets::BuildSettings settings;
    tbb::task_arena arena(threads);
    const auto report = arena.execute([&] { return ts::datasets::build_database(inputs, out, settings); });
    const auto& t = report.times;

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
    double coverage_min = 1.0;
    for (double c : report.coverage) coverage_min = std::min(coverage_min, c);

    std::printf("bench_db_build: %s\n", manifest.c_str());
    std::printf("machine: %s; threads: %d\n", ts::cli::machine_description().c_str(), threads);
    std::printf("objects: %zu, fine points: %zu, file: %.1f MB, lowest coverage: %.2f %%\n", report.names.size(), fine,
                static_cast<double>(std::filesystem::file_size(out)) / 1e6, 100.0 * coverage_min);
    std::printf("build wall time: %.2f s (target <= 60 s)\n", t.wall_s);
    std::printf("  read archives %.2f s (wall)\n", t.read_s);
    std::printf("  import        %.2f s (summed over objects)\n", t.import_s);
    std::printf("  scan          %.2f s (summed over objects)\n", t.scan_s);
    std::printf("  features      %.2f s (summed over objects)\n", t.features_s);
    std::printf("  field         %.2f s (summed over objects)\n", t.field_s);
    std::printf("  write         %.2f s (wall)\n", t.write_s);
    std::printf("db info (open + every summary), median of 5: %.4f s (target <= 1 s)\n", opens[2]);
  } catch (const std::exception& e) {
    std::cerr << "bench_db_build: " << e.what() << '\n';
    std::filesystem::remove(out);
    return 1;
  }
  std::filesystem::remove(out);
  return 0;
}
