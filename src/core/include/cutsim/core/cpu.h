#pragma once
// What the CPU offers the hand-vectorised kernels (the stock update's and
// the comparison's), asked once.

namespace cutsim {

/// Whether the CPU has AVX2 (false off x86-64).
bool cpu_has_avx2();
/// Whether kernels with an AVX2 version take it: the CPU has AVX2 and the
/// environment does not set CUTSIM_AVX2=0 (the portable versions, to
/// compare runs with; both give the same bits).
bool use_avx2();

}  // namespace cutsim
