// The run-time kernel level (core/src/simd/instruction_set.h): never above the processor's, and
// lowered by TEMPOKEY_MAX_ISA (this test also runs as avx2.* with the cap set: tests/CMakeLists.txt).
#include "core/src/simd/instruction_set.h"

#include <cstdlib>
#include <string_view>

#include "gtest/gtest.h"

namespace tempokey::core::simd {
namespace {

TEST(InstructionSetTest, TheRunningLevelIsNeverAboveTheProcessors) {
  EXPECT_LE(RunningInstructionSet(), ProcessorInstructionSet());
}

TEST(InstructionSetTest, TheEnvironmentCapLowersTheRunningLevel) {
  const char* cap = std::getenv("TEMPOKEY_MAX_ISA");
  if (cap == nullptr) GTEST_SKIP() << "TEMPOKEY_MAX_ISA not set (see the avx2.* run)";
  const std::string_view name(cap);
  if (name == "avx2") {
    EXPECT_LE(RunningInstructionSet(), InstructionSet::kAvx2);
  }
  if (name == "baseline") {
    EXPECT_EQ(RunningInstructionSet(), InstructionSet::kBaseline);
  }
}

}  // namespace
}  // namespace tempokey::core::simd
