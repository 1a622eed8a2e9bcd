// Run-time selection of the frame-path kernels' instruction set (private to runtime/).
//
// x86-64 with GCC: a function marked TETRIG_MULTIVERSION is compiled for x86-64-v4 (AVX-512),
// x86-64-v3 (AVX2 + FMA) and the baseline, and the dynamic loader picks the widest the CPU runs
// (ifunc). Elsewhere (clang, aarch64, or TETRIG_NO_MULTIVERSION) the portable build only.
#pragma once

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(TETRIG_NO_MULTIVERSION)
#define TETRIG_MULTIVERSION __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#define TETRIG_MULTIVERSION_ENABLED 1
#else
#define TETRIG_MULTIVERSION
#endif
