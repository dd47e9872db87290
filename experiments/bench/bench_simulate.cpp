// Benchmark of the exploration simulator (issue targets): simulating 40 grasps on a 20 cm
// object takes <= 2 s on 2 cores, and >= 70 % of the grasps with one pad produce contact.
//
// Every mesh of the manifest (default datasets/dev45.tsv) is imported into the object frame
// (largest extent 0.20 m, as the database does), then `--grasps` grasps are simulated with one
// pad (the paper's setup) and the given noise, in a task arena of `--threads` threads, and the
// log is written. Times are wall-clock per object: simulator set-up (BVH) + grasps, and with
// the log write. Contact = the logged pad sensed at least one contact point after the noise.
//
//   build/bench/bench_simulate [--threads 2] [--grasps 40] [--noise underwater] [--seed 1]
//                              [--manifest datasets/dev45.tsv] [--sensors 1]
#include "datasets/archive.hpp"
#include "datasets/manifest.hpp"
#include "datasets/simulator.hpp"
#include "experiments/params/config.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/resources.hpp"
#include "experiments/runs/grasp_pools.hpp"
#include "io/log_store.hpp"

#include <CLI/CLI.hpp>
#include "io/mesh_import.hpp"

#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <unistd.h>

using namespace ts;

namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * (v.size() - 1) + 0.5))];
}
}  // namespace

int main(int argc, char** argv) {
  int threads = 2;
  std::size_t grasps = 40;
  std::uint64_t seed = 1;
  // Default manifest: datasets/dev45.tsv from the working directory, else beside build/bench/.
  std::filesystem::path manifest = "datasets/dev45.tsv";
  if (!std::filesystem::exists(manifest))
    manifest = std::filesystem::path(argv[0]).parent_path() / "../../datasets/dev45.tsv";
  CLI::App app{"bench_simulate: the exploration simulator's speed and contact rate"};
  app.add_option("--threads", threads, "Threads of the task arena")->check(CLI::Range(1, 1024));
  app.add_option("--grasps", grasps, "Grasps per object")->check(CLI::Range(1, 1000000));
  app.add_option("--seed", seed, "Simulator seed");
  app.add_option("--manifest", manifest, "Mesh manifest");
  // --noise (underwater here), its overrides and --sensors: the declared simulator parameters.
  experiments::ParameterFlags run_flags;
  experiments::add_parameter_flags(app, run_flags, "Simulator parameters (touchstone params)",
                                   [](const experiments::Parameter& p) {
                                     return experiments::bench_run_parameter(p) && p.kind == experiments::Parameter::Kind::simulator;
                                   });
  CLI11_PARSE(app, argc, argv);
  try {
    experiments::ExperimentConfig config;
    config.noise = "underwater";
    experiments::apply_flags(run_flags, config);
    const datasets::SimulatorSettings base = experiments::simulation_settings(config);
    const std::string noise = config.noise;
    const int sensors = config.sensors;
    const auto entries = datasets::read_manifest(manifest);
    std::printf("bench_simulate: %zu grasps per object, %d pad(s), noise %s, seed %llu, %d threads; %s\n", grasps,
                sensors, noise.c_str(), static_cast<unsigned long long>(seed), threads,
                experiments::machine_description().c_str());
    std::printf("%-22s %8s %8s %9s %9s %7s\n", "object", "faces", "sim_s", "+write_s", "contact", "rate");
    tbb::task_arena arena(threads);
    const auto tmp = std::filesystem::temp_directory_path() / ("bench_simulate_" + std::to_string(::getpid()) + ".h5");
    std::vector<double> sim_times, total_times;
    std::size_t all_grasps = 0, all_contact = 0, all_points = 0;
    double worst_rate = 1.0;
    std::string worst_object;
    for (const auto& e : entries) {
      const io::ImportedMesh m =
          e.member.empty() ? io::import_mesh(e.path)
                           : io::import_mesh_from_memory(datasets::read_archive_member(e.path, e.member),
                                                         e.path.filename().string() + ":" + e.member);
      datasets::SimulatorSettings s = base;
      s.grasps = grasps;
      s.seed = seed;
      const auto t0 = std::chrono::steady_clock::now();
      const auto result = arena.execute([&] {
        const datasets::Simulator sim(m.mesh, e.name, Gripper(), s);
        return sim.run();
      });
      const double t_sim = seconds_since(t0);
      io::write_log(tmp, result.log);
      const double t_total = seconds_since(t0);
      std::size_t contact = 0;
      for (std::size_t g = 0; g < result.log.grasps.size(); ++g) {
        const std::size_t n = grasp_contacts(result.log, g).points.size();
        contact += n > 0;
        all_points += n;
      }
      const double rate = static_cast<double>(contact) / grasps;
      if (rate < worst_rate) worst_rate = rate, worst_object = e.name;
      sim_times.push_back(t_sim);
      total_times.push_back(t_total);
      all_grasps += grasps;
      all_contact += contact;
      std::printf("%-22s %8zu %8.3f %9.3f %5zu/%-3zu %6.0f%%\n", e.name.c_str(), m.mesh.faces.size(), t_sim, t_total,
                  contact, grasps, 100.0 * rate);
      std::fflush(stdout);
    }
    std::filesystem::remove(tmp);
    std::printf("\nobjects %zu | %zu grasps per object on %d threads: time median %.3f s, max %.3f s "
                "(with log write: median %.3f s, max %.3f s) [target <= 2 s]\n",
                entries.size(), grasps, threads, percentile(sim_times, 0.5), percentile(sim_times, 1.0),
                percentile(total_times, 0.5), percentile(total_times, 1.0));
    std::printf("grasps with contact on the logged pad: %zu / %zu = %.1f %% [target >= 70 %%]; lowest object: %s %.0f %%\n",
                all_contact, all_grasps, 100.0 * all_contact / std::max<std::size_t>(1, all_grasps),
                worst_object.c_str(), 100.0 * worst_rate);
    std::printf("contact points per grasp with contact: %.1f\n",
                static_cast<double>(all_points) / std::max<std::size_t>(1, all_contact));
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "bench_simulate: error: %s\n", ex.what());
    return 1;
  }
  return 0;
}
