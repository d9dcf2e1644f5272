// PrefaultForWriting against the kernel's own account of which pages are mapped (mincore()).
#include "proto/prefault.h"

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstring>
#include <vector>

#include "gtest/gtest.h"

namespace tempokey::wire {
namespace {

// Pages of [begin, begin + bytes) (page-aligned) the kernel reports resident.
int ResidentPages(void* begin, std::size_t bytes) {
  const auto page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  std::vector<unsigned char> resident((bytes + page - 1) / page);
  if (mincore(begin, bytes, resident.data()) != 0) return -1;
  int count = 0;
  for (unsigned char r : resident) count += r & 1;
  return count;
}

class PrefaultTest : public ::testing::Test {
 protected:
  void SetUp() override {
    page_ = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
    bytes_ = 64 * page_;
    void* mapped =
        mmap(nullptr, bytes_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    ASSERT_NE(mapped, MAP_FAILED);
    region_ = static_cast<unsigned char*>(mapped);
    // With transparent huge pages set to "always" the kernel may map a whole 2 MiB page around
    // the range; the tests count 4 KiB pages.
    madvise(region_, bytes_, MADV_NOHUGEPAGE);
  }
  void TearDown() override {
    if (region_ != nullptr) munmap(region_, bytes_);
  }

  std::size_t page_ = 0;
  std::size_t bytes_ = 0;
  unsigned char* region_ = nullptr;
};

TEST_F(PrefaultTest, MapsEveryWholePageOfTheRangeAndNoneOutsideIt) {
  ASSERT_EQ(ResidentPages(region_, bytes_), 0);
  // From the middle of page 1 to the middle of page 40: pages 2..39 are whole.
  void* begin = region_ + page_ + page_ / 2;
  const std::size_t bytes = 39 * page_;

  if (!PrefaultForWriting(begin, bytes)) GTEST_SKIP() << "the kernel has no MADV_POPULATE_WRITE";

  EXPECT_EQ(ResidentPages(region_, 2 * page_), 0);
  EXPECT_EQ(ResidentPages(region_ + 2 * page_, 38 * page_), 38);
  EXPECT_EQ(ResidentPages(region_ + 40 * page_, 24 * page_), 0);
}

TEST_F(PrefaultTest, LeavesWhatTheMappedPagesHoldUnchangedAndMapsTheRest) {
  // Every fourth page written before: the others are not mapped yet (and are not read here,
  // which would map them to the zero page).
  std::vector<unsigned char> expected(bytes_, 0);
  for (std::size_t i = 0; i < bytes_; i += 4 * page_) {
    region_[i] = expected[i] = static_cast<unsigned char>(i / page_ + 1);
    region_[i + page_ - 1] = expected[i + page_ - 1] = 0xa5;
  }
  ASSERT_EQ(ResidentPages(region_, bytes_), 16);

  if (!PrefaultForWriting(region_, bytes_)) GTEST_SKIP() << "the kernel has no MADV_POPULATE_WRITE";

  EXPECT_EQ(ResidentPages(region_, bytes_), 64);
  EXPECT_EQ(std::memcmp(expected.data(), region_, bytes_), 0);
}

TEST_F(PrefaultTest, RangesBelowTheMinimumAreLeftToFault) {
  if (4 * page_ >= kMinPrefaultBytes) GTEST_SKIP() << "pages of " << page_ << " bytes";

  EXPECT_FALSE(PrefaultForWriting(region_, 4 * page_));
  EXPECT_EQ(ResidentPages(region_, bytes_), 0);
}

}  // namespace
}  // namespace tempokey::wire
