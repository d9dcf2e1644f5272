// FirstFlaggedBlock() (core/src/simd/block_scan.h), the scan under clip validation, seam and
// constant-channel tests: for every length and every flagged position, the block it returns
// holds the first flagged sample, or the samples after the last whole block do, and nothing
// before it is flagged.
#include "core/src/simd/block_scan.h"

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "gtest/gtest.h"

#pragma GCC diagnostic ignored "-Wpsabi"

namespace tempokey::core::simd {
namespace {

// Flags the lanes holding a negative sample.
ScanMask Negative(const double* p) { return LoadScanVector(p) < 0.0; }

// Checks the scan of samples [from, n) with `flagged` (sorted) negative and the rest 0.
void ExpectFindsFirst(std::size_t from, std::size_t n, const std::vector<std::size_t>& flagged) {
  std::vector<double> samples(n, 0.0);
  for (std::size_t at : flagged) samples[at] = -1.0;
  const std::size_t found = FirstFlaggedBlock(samples.data(), from, n, Negative);
  std::size_t first = n;
  for (std::size_t at : flagged) {
    if (at >= from && at < first) first = at;
  }
  SCOPED_TRACE(testing::Message() << "from " << from << ", n " << n << ", first flag " << first);
  ASSERT_GE(found, from);
  // Nothing flagged is skipped ...
  EXPECT_LE(found, first);
  // ... and the scan stops at the flagged block, or leaves less than a block to the caller.
  EXPECT_TRUE(found + kScanBlock > n || (first >= found && first < found + kScanBlock));
  EXPECT_EQ((found - from) % kScanBlock, 0u);
}

TEST(BlockScanTest, FindsTheBlockOfTheFirstFlaggedSampleAtEveryPosition) {
  for (std::size_t n = 0; n <= 3 * kScanBlock + 5; ++n) {
    ExpectFindsFirst(0, n, {});
    for (std::size_t at = 0; at < n; ++at) ExpectFindsFirst(0, n, {at});
  }
}

TEST(BlockScanTest, StartsAtItsFirstSampleAndStopsAtTheEarlierOfTwoFlags) {
  const std::size_t n = 4 * kScanBlock + 3;
  for (std::size_t from = 0; from < kScanBlock + 2; ++from) {
    for (std::size_t at = 0; at < n; ++at) ExpectFindsFirst(from, n, {at, n - 1 - at / 2});
  }
}

TEST(BlockScanTest, FlagsANotANumberInAnyLane) {
  // The clip validator's form of the test: |v| beyond a limit, or not a number.
  const auto out_of_range = [](const double* p) {
    const ScanVector size =
        (ScanVector)((ScanMask)LoadScanVector(p) & std::numeric_limits<std::int64_t>::max());
    return !(size <= 1e9);
  };
  for (std::size_t at = 0; at < 2 * kScanBlock; ++at) {
    std::vector<double> samples(2 * kScanBlock, -5.0);
    samples[at] = std::numeric_limits<double>::quiet_NaN();
    const std::size_t found = FirstFlaggedBlock(samples.data(), 0, samples.size(), out_of_range);
    EXPECT_EQ(found, at - at % kScanBlock) << "NaN at " << at;
  }
}

}  // namespace
}  // namespace tempokey::core::simd
