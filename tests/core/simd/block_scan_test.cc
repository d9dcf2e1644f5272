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
  if (found == n) return;  // ... so nothing is flagged at all
  // ... and the scan stops at the flagged block, or leaves less than a block to the caller.
  EXPECT_TRUE(found + kScanBlock > n || (first >= found && first < found + kScanBlock));
  EXPECT_EQ((found - from) % kScanBlock, 0u);
  // A flag among the samples after the last whole block is what leaves them to the caller,
  // unless they are all there is.
  if (n - from >= kScanBlock && found + kScanBlock > n) {
    EXPECT_LT(first, n);
  }
}

TEST(BlockScanTest, FindsTheBlockOfTheFirstFlaggedSampleAtEveryPosition) {
  for (std::size_t n = 0; n <= 3 * kScanBlock + 5; ++n) {
    ExpectFindsFirst(0, n, {});
    for (std::size_t at = 0; at < n; ++at) ExpectFindsFirst(0, n, {at});
  }
}

TEST(BlockScanTest, ReadsPastTheLastWholeBlockWhenNothingThereIsFlagged) {
  // 183 samples, a short clip's channel: five whole blocks, then 23 samples tested as the block
  // that ends at the last one, never left to the caller's loop.
  for (std::size_t from = 0; from <= 3; ++from) {
    std::vector<double> samples(183, 0.0);
    EXPECT_EQ(FirstFlaggedBlock(samples.data(), from, samples.size(), Negative), samples.size());
    samples[182] = -1.0;
    EXPECT_EQ(FirstFlaggedBlock(samples.data(), from, samples.size(), Negative),
              from + 5 * kScanBlock);
  }
  // Fewer samples than a block: all left to the caller, as before.
  const std::vector<double> few(kScanBlock - 1, 0.0);
  EXPECT_EQ(FirstFlaggedBlock(few.data(), 0, few.size(), Negative), 0u);
}

TEST(BlockScanTest, ReadsOnlyVectorsWithinItsSamplesAndTheOneBeforeThem) {
  // The seam and unwrap scans read the sample before each vector (p - 1) from `from` = 1: every
  // vector tested must start at or after `from` and end by n, for every length, the overlapping
  // last block included (a rule keyed on n alone would read data[-1] at n = 32, from = 1).
  for (std::size_t from = 0; from <= 3; ++from) {
    for (std::size_t n = from; n <= 3 * kScanBlock + 5; ++n) {
      std::vector<double> samples(n, 0.0);
      // Flagged only before `from`: never to be seen.
      if (from > 0) samples[from - 1] = -1.0;
      const double* data = samples.data();
      bool in_bounds = true;
      const auto recorded = [&](const double* p) {
        const auto at = static_cast<std::size_t>(p - data);
        in_bounds = in_bounds && at >= from && at + kScanLanes <= n;
        return Negative(p);
      };
      const std::size_t found = FirstFlaggedBlock(data, from, n, recorded);
      EXPECT_TRUE(in_bounds) << "from " << from << ", n " << n;
      // Nothing flagged from `from` on: the whole scan, or all but its short tail.
      EXPECT_TRUE(found == n || (found == from && n - from < kScanBlock))
          << "from " << from << ", n " << n << ": " << found;
    }
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
