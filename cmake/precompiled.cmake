# Precompiled headers: the heavy third-party headers that most translation units include, parsed
# once per target instead of once per file (Eigen, oneTBB and the standard library take several
# seconds a file to parse; nlohmann/json, CLI11 and doctest several more). scripts/ci_profile
# measures what they save. TS_PCH=OFF builds without them (e.g. to check that every file still
# includes what it uses).
option(TS_PCH "Precompile the heavy third-party headers" ON)

set(TS_PCH_BASE
  <Eigen/Core> <Eigen/Geometry> <Eigen/Eigenvalues>
  <tbb/parallel_for.h> <tbb/blocked_range.h> <tbb/task_arena.h>
  <algorithm> <array> <cmath> <cstdint> <filesystem> <functional> <map> <memory> <optional>
  <span> <sstream> <string> <unordered_map> <utility> <vector>)

# ts_precompile(TARGET [HEADER...]): precompile TS_PCH_BASE and the HEADERs for TARGET's files.
function(ts_precompile target)
  if(TS_PCH)
    target_precompile_headers(${target} PRIVATE ${TS_PCH_BASE} ${ARGN})
  endif()
endfunction()
