// Which vector instruction set the kernels chosen at run time by the library (not by the
// compiler's target_clones) may use: the AVX-512 and AVX2 instantiations of the pack kernels
// (reduce/lane_pack.h), the 8-lane retime kernels (retime/rotation_batch.cc) and the kernels run
// through RunForInstructionSet() (forward kinematics' blocks, keyed curves' sampling). Every level
// computes the same bits; the narrower ones are what most machines run, so tests run them on a
// wider machine too by capping the level with TEMPOKEY_MAX_ISA.
#ifndef TEMPOKEY_CORE_SRC_SIMD_INSTRUCTION_SET_H_
#define TEMPOKEY_CORE_SRC_SIMD_INSTRUCTION_SET_H_

#include <cstdlib>
#include <string_view>

// Kernels the compiler clones for several instruction sets, the loader picking one per machine
// (target_clones): every clone performs the same operations (no FMA contraction:
// -ffp-contract=off), so they give the same bits. Sanitizer builds keep the portable code only:
// the loader runs the clone resolver (an ifunc) before the sanitizer's runtime is up, and an
// instrumented resolver crashes there (TSan).
#if defined(TEMPOKEY_SANITIZED)
#define TEMPOKEY_CLONES_AVX
#define TEMPOKEY_CLONES_AVX2
#else
#define TEMPOKEY_CLONES_AVX __attribute__((target_clones("avx", "default")))
#define TEMPOKEY_CLONES_AVX2 __attribute__((target_clones("avx2", "default")))
#endif

// The attributes of a kernel's AVX-512 and AVX2 builds chosen at run time by the library: the
// AVX-512 level has F, DQ, VL and BW (ProcessorInstructionSet()).
#define TEMPOKEY_TARGET_AVX512 __attribute__((target("avx512f,avx512dq,avx512vl,avx512bw")))
#define TEMPOKEY_TARGET_AVX2 __attribute__((target("avx2")))

// Whether the 8-lane kernels written with GCC's vector extensions inside target("avx512...")
// functions are built: by GCC, without sanitizers. Clang rejects passing 8-lane vectors to the
// helpers (lambdas) those kernels call, which do not carry the target attribute, and sanitizer
// builds take the baseline kernels anyway (the fuzz stage is both).
#if !defined(TEMPOKEY_SANITIZED) && defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define TEMPOKEY_WIDE_KERNELS 1
#else
#define TEMPOKEY_WIDE_KERNELS 0
#endif

namespace tempokey::core::simd {

enum class InstructionSet { kBaseline, kAvx2, kAvx512 };

// The processor's level: AVX-512 needs F, DQ, VL and BW (the 8-lane kernels use all four).
inline InstructionSet ProcessorInstructionSet() {
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512bw")) {
    return InstructionSet::kAvx512;
  }
  return __builtin_cpu_supports("avx2") ? InstructionSet::kAvx2 : InstructionSet::kBaseline;
}

// The level the kernels use, read once per process: the processor's, lowered to
// TEMPOKEY_MAX_ISA when that is "avx2" or "baseline" (any other value leaves it as it is).
// Sanitizer builds always take the baseline kernels (as they keep no clones, above).
inline InstructionSet RunningInstructionSet() {
#if defined(TEMPOKEY_SANITIZED)
  return InstructionSet::kBaseline;
#else
  static const InstructionSet level = [] {
    const InstructionSet processor = ProcessorInstructionSet();
    const char* cap = std::getenv("TEMPOKEY_MAX_ISA");
    if (cap == nullptr) return processor;
    const std::string_view name(cap);
    InstructionSet limit = InstructionSet::kAvx512;
    if (name == "avx2") limit = InstructionSet::kAvx2;
    if (name == "baseline") limit = InstructionSet::kBaseline;
    return limit < processor ? limit : processor;
  }();
  return level;
#endif
}

template <class Body>
TEMPOKEY_TARGET_AVX512 void RunBuiltForAvx512(const Body& body) {
  body();
}
template <class Body>
TEMPOKEY_TARGET_AVX2 void RunBuiltForAvx2(const Body& body) {
  body();
}

// Runs body(), an always_inline callable, compiled for RunningInstructionSet(): the loops the
// compiler vectorises in it use AVX-512, AVX2 or the baseline's SSE2 (the same operations lane by
// lane, so the same bits), and TEMPOKEY_MAX_ISA reaches each build, which target_clones' choice
// by the loader does not.
template <class Body>
void RunForInstructionSet(const Body& body) {
  switch (RunningInstructionSet()) {
    case InstructionSet::kAvx512:
      RunBuiltForAvx512(body);
      return;
    case InstructionSet::kAvx2:
      RunBuiltForAvx2(body);
      return;
    case InstructionSet::kBaseline:
      break;
  }
  body();
}

}  // namespace tempokey::core::simd

#endif  // TEMPOKEY_CORE_SRC_SIMD_INSTRUCTION_SET_H_
