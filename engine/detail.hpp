// Small helpers the engine's (and its dependants') .cpp files share: angle constants, a stopwatch,
// a check that throws ts::Error, a parallel loop over an index range and OpenVDB's one-time
// initialization. Not part of the API: include it from .cpp files only. One definition here
// instead of a copy per file (a unity build puts several files in one translation unit).
#pragma once

#include "engine/core.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <chrono>
#include <cstddef>
#include <numbers>
#include <string>

namespace ts::detail {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kRadPerDeg = std::numbers::pi / 180.0;  ///< degrees to radians
inline constexpr double kDegPerRad = 180.0 / std::numbers::pi;  ///< radians to degrees

using Clock = std::chrono::steady_clock;
/// Seconds since t0 on the steady clock.
inline double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// Throws ts::Error(what, file, field) unless ok.
inline void require(bool ok, const std::string& what, const std::string& file, const std::string& field) {
  if (!ok) throw Error(what, file, field);
}

/// f(i) for i in [0, n) over TBB, `grain` indices per task at least.
template <class F>
void parallel_each(std::size_t n, std::size_t grain, F&& f) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
                    });
}

/// openvdb::initialize() once per process (defined in free_space.cpp: OpenVDB's headers stay there).
void init_openvdb();

}  // namespace ts::detail
