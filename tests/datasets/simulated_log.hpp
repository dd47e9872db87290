// A simulated log written with a given thread count (the determinism tests of the simulator's
// sensing modes: the same bytes for any thread count).
#pragma once

#include "datasets/simulator.hpp"
#include "io/log_store.hpp"

#include <tbb/task_arena.h>

#include <filesystem>
#include <string>

namespace ts::test {

inline TactileLog simulate_and_write(const Mesh& mesh, const std::string& name, const datasets::SimulatorSettings& s,
                                     int threads, const std::filesystem::path& path) {
  tbb::task_arena arena(threads);
  datasets::SimulationResult r;
  arena.execute([&] { r = datasets::Simulator(mesh, name, Gripper(), s).run(); });
  io::write_log(path, r.log);
  return r.log;
}

}  // namespace ts::test
