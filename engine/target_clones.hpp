// TS_TARGET_CLONES: an AVX2 clone and a default one of a hot loop, chosen at load time by an
// ifunc resolver. Off under ThreadSanitizer: GCC instruments the resolver, which the dynamic
// loader runs before the TSan runtime is set up, and every program then dies at start-up.
#pragma once

#if defined(__SANITIZE_THREAD__)
#define TS_TARGET_CLONES
#else
#define TS_TARGET_CLONES __attribute__((target_clones("avx2", "default")))
#endif
