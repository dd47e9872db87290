# The tier (ctest label) and timeout of every test. Included by tests/CMakeLists.txt and by the
# doctest discovery script (cmake/doctestAddTests.cmake), which labels each discovered test case.
#
#   unit         one part's behaviour, in process (engine/, io/, datasets/);  ctest -L unit
#   integration  the parts together: the command's code, drivers, stores, the fuzz corpus,
#                benchmarks that start (experiments/, bench/)
#   slow         unit or integration tests that take longest (TS_SLOW_TESTS below): the release
#                suite runs them, CI's sanitizer run leaves them out (.ci/run: -LE slow)
#   python       the Python module under pytest
#   package      `cmake --install` and a consumer project built against it
#
# Every test has a timeout (TIMEOUT, seconds): a test that hangs is stopped and ctest names it
# ("***Timeout"). The timeouts hold under AddressSanitizer, about 3-5 times slower than release.

# Test names (regular expressions, whole names) in the slow tier: the tests that took 45 s or
# more each under ASan+UBSan (2026-11-29: the first eight on 2 cores shared with two builds,
# the last two in a cold CI profile; 2-6 s each in release), together about 660 s of the
# sanitizer suite. Each is a whole-experiment test of the run engine
# or the driver (shards, merge, active touch, diagnostics) or an exhaustive oracle over a
# distance field, whose code the faster unit and integration tests also run under the
# sanitizers. Keep this list short: what is here is not run under the sanitizers.
set(TS_SLOW_TESTS
  "experiments/experiment --shard I/N, then merge: .*"
  "experiments/merge: a missing, repeated, foreign, unsharded or incomplete shard .*"
  "experiments/Recognition engine: diagnostics\\.oracle_belief .*"
  "experiments/Recognition engine: diagnostics\\.truth_pose .*"
  "experiments/Recognition engine: active exploration plans each grasp .*"
  "experiments/Recognition engine: consistent records, thread-count and resume independent"
  "experiments/Stress study, reduced: .*"
  "engine/The fine level holds every voxel within the band's half-width, and none beyond"
  "engine/MeshIndex shell: every lattice point within the radius, with closest\\(\\)'s answer, and none beyond"
  "engine/Objects of 1 cm and 2 m with scaled parameters are recognized alike"
)

# COST orders a fresh build's first run (later runs use ctest's own record of the times): the
# longest tests start first, so that none of them starts last and leaves a core idle.
set(TS_TIER_COST_unit 1)
set(TS_TIER_COST_integration 10)
set(TS_TIER_COST_slow 100)
set(TS_TIER_COST_python 50)
set(TS_TIER_COST_package 50)

set(TS_TIER_TIMEOUT_unit 300)
set(TS_TIER_TIMEOUT_integration 600)
set(TS_TIER_TIMEOUT_slow 1200)
set(TS_TIER_TIMEOUT_python 900)
set(TS_TIER_TIMEOUT_package 900)

# ts_test_tier(NAME PROPERTIES_VAR): the test properties of the test called NAME: its tier's
# label, timeout and cost.
function(ts_test_tier name properties_var)
  set(label unit)
  if(name MATCHES "^python/")
    set(label python)
  elseif(name MATCHES "^package/")
    set(label package)
  else()
    foreach(pattern ${TS_SLOW_TESTS})
      if(name MATCHES "^${pattern}$")
        set(label slow)
        break()
      endif()
    endforeach()
    if(label STREQUAL unit AND name MATCHES "^(experiments|bench)/")
      set(label integration)
    endif()
  endif()
  set(${properties_var} LABELS ${label} TIMEOUT ${TS_TIER_TIMEOUT_${label}} COST ${TS_TIER_COST_${label}}
      PARENT_SCOPE)
endfunction()
