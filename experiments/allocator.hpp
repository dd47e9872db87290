// The programs' memory allocator (TS_SCALABLE_MALLOC, CMakeLists.txt): oneTBB's scalable
// allocator replaces malloc and new in touchstone and the benchmarks. It keeps freed memory in
// caches for reuse, which is what makes a step fast (no page faults for the search results each
// step) but holds memory the process no longer uses; release_free_memory() hands the caches back
// at the natural pauses (after the set-up, between runs and inputs).
#pragma once

#include <cstddef>
#include <string>

namespace ts::experiments {

/// "tbbmalloc" (the scalable allocator replaces malloc: the default build of the programs) or
/// "glibc malloc".
std::string allocator_name();

/// Return the allocator's cached free memory to the system (tbbmalloc: every thread's and the
/// global caches; glibc: malloc_trim). Thread-safe; costs page faults when the memory is needed
/// again, so call it between units of work, not inside a step.
void release_free_memory();

/// What writing fresh memory costs on this machine, in ms per MB: `mb` MB of anonymous memory
/// mapped and written once, a byte per page (the page faults and whatever the host does to back
/// the pages). The benchmarks print it beside the machine: on a virtual machine it varies from day
/// to day, and a process that loads much (a one-shot recognition) pays it for every page.
double first_touch_ms_per_mb(std::size_t mb = 64);

}  // namespace ts::experiments
