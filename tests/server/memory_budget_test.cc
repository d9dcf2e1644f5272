// MemoryBudget: reservations, refusals that name the budget, caches asked for memory, memory
// handed back to the system after large releases. No gRPC: runs under ThreadSanitizer.
#include "server/memory_budget.h"

#include <malloc.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "proto/retry_hint.h"
#include "gtest/gtest.h"

namespace tempokey::server {
namespace {

using ::testing::HasSubstr;

TEST(MemoryBudgetTest, ReservationsCountUntilReleasedAndRefuseBeyondTheBudget) {
  MemoryBudget budget(1000);

  absl::StatusOr<MemoryBudget::Reservation> a = budget.Reserve(600, MemoryUse::kUpload, "an upload");
  ASSERT_TRUE(a.ok()) << a.status();
  absl::StatusOr<MemoryBudget::Reservation> b = budget.Reserve(500, MemoryUse::kJob, "a job");
  const std::int64_t used_while_a = budget.used();
  a->Release();
  absl::StatusOr<MemoryBudget::Reservation> c = budget.Reserve(500, MemoryUse::kJob, "a job");

  EXPECT_EQ(b.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(b.status().message(),
            "the server's memory budget (--memory_budget_bytes=1000) cannot take a job of 500 "
            "more bytes: 400 bytes free; retry later or send less");
  // It fits once others give memory back: the refusal carries the retry hint.
  EXPECT_EQ(wire::GetRetryAfter(b.status()), kMemoryRetryAfter);
  EXPECT_EQ(used_while_a, 600);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(budget.used(), 500);
  EXPECT_EQ(budget.used(MemoryUse::kJob), 500);
  EXPECT_EQ(budget.used(MemoryUse::kUpload), 0);
}

TEST(MemoryBudgetTest, GrowingReservationStopsAtTheBudgetAndKeepsWhatItHad) {
  MemoryBudget budget(100);
  MemoryBudget::Reservation upload = *budget.Reserve(0, MemoryUse::kUpload, "an upload");

  const absl::Status first = upload.Grow(60);
  const absl::Status second = upload.Grow(60);

  EXPECT_TRUE(first.ok());
  EXPECT_EQ(second.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(upload.bytes(), 60);
  EXPECT_EQ(budget.used(), 60);
}

// A reservation that would hold more than the whole budget never fits, however much is given
// back: its refusal says so and carries no retry hint (HTTP answers it 413, not 429).
TEST(MemoryBudgetTest, MoreThanTheWholeBudgetIsRefusedWithoutARetryHint) {
  MemoryBudget budget(100);
  MemoryBudget::Reservation upload = *budget.Reserve(60, MemoryUse::kUpload, "an upload");

  const absl::Status grown_past = upload.Grow(41);
  const absl::Status grown_to = upload.Grow(40);
  const absl::StatusOr<MemoryBudget::Reservation> alone =
      budget.Reserve(101, MemoryUse::kJob, "a job");
  const absl::StatusOr<MemoryBudget::Reservation> busy = budget.Reserve(1, MemoryUse::kJob, "a job");

  EXPECT_EQ(grown_past.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(grown_past.message(),
            "the server's memory budget (--memory_budget_bytes=100) cannot take an upload of 41 "
            "more bytes: 101 bytes in all, more than the whole budget; send less");
  EXPECT_EQ(wire::GetRetryAfter(grown_past), std::nullopt);
  EXPECT_TRUE(grown_to.ok()) << grown_to;
  EXPECT_EQ(alone.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(alone.status().message()),
              HasSubstr("101 bytes in all, more than the whole budget; send less"));
  EXPECT_EQ(wire::GetRetryAfter(alone.status()), std::nullopt);
  // The budget full of the upload: a byte fits once it is given back.
  EXPECT_EQ(wire::GetRetryAfter(busy.status()), kMemoryRetryAfter);
}

// A copy of a stored clip needs the clip and the copy at once: beside what its holder pins, a
// growth past the whole budget never fits, is refused at once (no cache is emptied for it) and
// carries no retry hint; one that fits beside the pin is taken.
TEST(MemoryBudgetTest, AGrowthThatCannotFitBesideWhatItsHolderPinsIsRefusedAtOnceWithoutAHint) {
  MemoryBudget budget(100);
  int reclaims = 0;
  budget.AddReclaimer([&](std::int64_t) { ++reclaims; });
  MemoryBudget::Reservation stored = *budget.Reserve(60, MemoryUse::kStoredClip, "a clip");
  MemoryBudget::Reservation copy = *budget.Reserve(0, MemoryUse::kResult, "a clip read back");
  MemoryBudget::Reservation part = *budget.Reserve(0, MemoryUse::kResult, "a clip read back");
  copy.Pin(60);
  part.Pin(60);

  const absl::Status whole = copy.Grow(60);
  const absl::Status some = part.Grow(30);

  EXPECT_EQ(whole.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(whole.message(),
            "the server's memory budget (--memory_budget_bytes=100) cannot take a clip read back "
            "of 60 more bytes: 120 bytes in all, more than the whole budget; send less");
  EXPECT_EQ(wire::GetRetryAfter(whole), std::nullopt);
  EXPECT_EQ(reclaims, 0);
  EXPECT_TRUE(some.ok()) << some;
  EXPECT_EQ(budget.used(), 90);
}

TEST(MemoryBudgetTest, ReclaimersAreAskedForWhatIsMissingInOrder) {
  MemoryBudget budget(1000);
  // Two caches holding reservations they give up when asked.
  std::vector<MemoryBudget::Reservation> clips;
  std::vector<MemoryBudget::Reservation> results;
  for (int i = 0; i < 3; ++i) clips.push_back(*budget.Reserve(200, MemoryUse::kStoredClip, "a clip"));
  results.push_back(*budget.Reserve(300, MemoryUse::kResult, "a result"));
  std::vector<std::int64_t> asked;
  budget.AddReclaimer([&](std::int64_t wanted) {
    asked.push_back(wanted);
    if (!clips.empty()) clips.pop_back();  // frees 200, not enough
  });
  budget.AddReclaimer([&](std::int64_t wanted) {
    asked.push_back(wanted);
    results.clear();  // frees 300
  });

  absl::StatusOr<MemoryBudget::Reservation> big = budget.Reserve(500, MemoryUse::kJob, "a job");

  ASSERT_TRUE(big.ok()) << big.status();
  EXPECT_THAT(asked, ::testing::ElementsAre(400, 200));  // 100 free: 400 missing, then 200
  EXPECT_EQ(budget.used(), 400 + 500);
}

TEST(MemoryBudgetTest, SharedValueIsCountedUntilItsLastHolderGoes) {
  MemoryBudget budget(1 << 20);
  std::shared_ptr<const std::vector<double>> first = ShareWithReservation(
      std::vector<double>(1000), *budget.Reserve(8000, MemoryUse::kResult, "a result"));
  std::shared_ptr<const std::vector<double>> second = first;

  first.reset();
  const std::int64_t while_held = budget.used();
  second.reset();

  EXPECT_EQ(while_held, 8000);
  EXPECT_EQ(budget.used(), 0);
}

TEST(MemoryBudgetTest, SettleAndChangeUseKeepTheAccountsExact) {
  MemoryBudget budget(1000);
  MemoryBudget::Reservation clip = *budget.Reserve(300, MemoryUse::kUpload, "an upload");

  clip.Settle(1200);  // the clip exists: counted even past the budget
  const std::int64_t over = budget.used();
  clip.Settle(400);
  clip.ChangeUse(MemoryUse::kStoredClip);

  EXPECT_EQ(over, 1200);
  EXPECT_EQ(budget.used(), 400);
  EXPECT_EQ(budget.used(MemoryUse::kUpload), 0);
  EXPECT_EQ(budget.used(MemoryUse::kStoredClip), 400);
}

TEST(MemoryBudgetTest, LargeReleasesHandMemoryBackToTheSystem) {
  MemoryBudget budget(std::int64_t{1} << 30);
  const std::int64_t before = budget.trims();
  {
    MemoryBudget::Reservation big =
        *budget.Reserve(MemoryBudget::kTrimThresholdBytes, MemoryUse::kResult, "a result");
  }

  budget.WaitForTrim();

  EXPECT_EQ(budget.trims(), before + 1);
}

// Claims `bytes` for a new holder, then gives back the oldest of `held`.
void ReplaceOldest(MemoryBudget& budget, std::vector<MemoryBudget::Reservation>& held,
                   std::int64_t bytes, MemoryUse use) {
  held.push_back(*budget.Reserve(bytes, use, "a replacement"));
  held.erase(held.begin());
}

TEST(MemoryBudgetTest, MemoryGivenBackAndClaimedAgainIsNotTrimmedBeforeItsTurnover) {
  // A stream of calls, each freeing what the next one takes: never more than 4 MB below the
  // peak. (Counting every 8 MiB released trimmed every few calls.)
  MemoryBudget budget(std::int64_t{1} << 30);
  const std::int64_t before = budget.trims();
  constexpr std::int64_t kCall = std::int64_t{1} << 20;
  constexpr int kInFlight = 4;
  std::vector<MemoryBudget::Reservation> in_flight;
  for (int i = 0; i < kInFlight; ++i) {
    in_flight.push_back(*budget.Reserve(kCall, MemoryUse::kProcess, "a Process result"));
  }
  auto next_call = [&] { ReplaceOldest(budget, in_flight, kCall, MemoryUse::kProcess); };
  for (int i = 0; i + 1 < MemoryBudget::kTurnoverTrimBytes / kCall; ++i) next_call();
  budget.WaitForTrim();
  const std::int64_t before_turnover = budget.trims();
  next_call();  // the turnover's last megabyte
  budget.WaitForTrim();

  EXPECT_EQ(before_turnover, before);
  EXPECT_EQ(budget.trims(), before + 1);
}

TEST(MemoryBudgetTest, ReplacingWhatIsHeldAtASteadyLevelTrimsOnceAsMuchWasGivenBack) {
  // Stored clips replaced one by one: what the budget holds never falls by more than a clip,
  // but glibc keeps what each thread's arena freed.
  MemoryBudget budget(std::int64_t{1} << 40);
  constexpr std::int64_t kClip = std::int64_t{16} << 20;
  constexpr int kStored = 16;  // 256 MiB held: the turnover is at 256 MiB given back
  std::vector<MemoryBudget::Reservation> stored;
  for (int i = 0; i < kStored; ++i) {
    stored.push_back(*budget.Reserve(kClip, MemoryUse::kStoredClip, "a clip"));
  }
  const std::int64_t before = budget.trims();
  auto replace_oldest = [&] { ReplaceOldest(budget, stored, kClip, MemoryUse::kStoredClip); };
  for (int i = 0; i + 1 < kStored; ++i) replace_oldest();
  budget.WaitForTrim();
  const std::int64_t before_turnover = budget.trims();
  replace_oldest();
  budget.WaitForTrim();

  EXPECT_EQ(before_turnover, before);
  EXPECT_EQ(budget.trims(), before + 1);
}

TEST(MemoryBudgetTest, AFallOfTheThresholdBelowThePeakTrimsOnceAndStartsAFreshPeak) {
  MemoryBudget budget(std::int64_t{1} << 30);
  const std::int64_t half_threshold = MemoryBudget::kTrimThresholdBytes / 2;
  const std::int64_t before = budget.trims();
  std::vector<MemoryBudget::Reservation> held;
  for (int i = 0; i < 3; ++i) {
    held.push_back(*budget.Reserve(half_threshold, MemoryUse::kJob, "a job"));
  }

  held[0].Release();  // half the threshold below the peak
  budget.WaitForTrim();
  const std::int64_t after_first = budget.trims();
  held[1].Release();  // the threshold below the peak
  budget.WaitForTrim();
  const std::int64_t after_second = budget.trims();
  held[2].Release();  // half the threshold below the peak left by the trim
  budget.WaitForTrim();

  EXPECT_EQ(after_first, before);
  EXPECT_EQ(after_second, before + 1);
  EXPECT_EQ(budget.trims(), before + 1);
}

TEST(MemoryBudgetTest, AClipSettledPastItsClaimRaisesThePeakItsReleaseFallsFrom) {
  MemoryBudget budget(std::int64_t{1} << 30);
  const std::int64_t before = budget.trims();
  MemoryBudget::Reservation clip = *budget.Reserve(0, MemoryUse::kUpload, "an upload");

  clip.Settle(MemoryBudget::kTrimThresholdBytes);  // the clip exists: counted past any claim
  clip.Release();
  budget.WaitForTrim();

  EXPECT_EQ(budget.trims(), before + 1);
}

TEST(MemoryBudgetTest, LargeTransientMessagesTrimAndSmallOnesDoNot) {
  MemoryBudget budget(std::int64_t{1} << 30);
  const std::int64_t before = budget.trims();

  for (int i = 0; i < 100; ++i) budget.NoteFreed(std::int64_t{1} << 20);
  budget.WaitForTrim();
  const std::int64_t after_small = budget.trims();
  budget.NoteFreed(MemoryBudget::kTrimThresholdBytes);
  budget.WaitForTrim();

  EXPECT_EQ(after_small, before);
  EXPECT_EQ(budget.trims(), before + 1);
}

// new[] whose pointer escapes, so the compiler cannot leave the allocation out.
std::unique_ptr<char[]> Allocate(std::size_t bytes) {
  std::unique_ptr<char[]> buffer = std::make_unique_for_overwrite<char[]>(bytes);
  asm volatile("" : : "r"(buffer.get()) : "memory");
  return buffer;
}

TEST(AllocatorTuningTest, ClipSizedBuffersComeFromTheArenasOnceTunedForServing) {
#if defined(TEMPOKEY_SANITIZED)
  GTEST_SKIP() << "the sanitizers' allocators refuse glibc's settings";
#endif
  // glibc maps a chunk of its own for a request past its mmap threshold (128 KiB to start with)
  // that no free chunk can hold; mallinfo2().hblks counts those mappings, fordblks the free
  // bytes the arenas hold.
  ASSERT_TRUE(TuneAllocatorForServing().ok());
  const struct mallinfo2 start = mallinfo2();
  std::vector<std::unique_ptr<char[]>> buffers;
  for (int i = 0; i < 8; ++i) {
    buffers.push_back(Allocate(std::size_t{kServingMmapThresholdBytes} / 4));  // 256 KiB
  }
  const std::size_t mapped_with_buffers = mallinfo2().hblks;
  // Larger than the threshold and than anything free: its own mapping.
  const std::unique_ptr<char[]> big =
      Allocate(std::size_t{kServingMmapThresholdBytes} + start.fordblks + (std::size_t{1} << 20));
  const std::size_t mapped_with_big = mallinfo2().hblks;

  EXPECT_EQ(mapped_with_buffers, start.hblks);
  EXPECT_EQ(mapped_with_big, start.hblks + 1);
}

TEST(MemoryBudgetTest, ManyThreadsNeverOvercommit) {
  constexpr std::int64_t kCapacity = 10'000;
  MemoryBudget budget(kCapacity);
  std::atomic<std::int64_t> peak{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 2000; ++i) {
        absl::StatusOr<MemoryBudget::Reservation> r = budget.Reserve(700, MemoryUse::kJob, "a job");
        if (!r.ok()) continue;
        std::int64_t seen = budget.used();
        std::int64_t was = peak.load();
        while (seen > was && !peak.compare_exchange_weak(was, seen)) {
        }
      }
    });
  }
  for (std::thread& t : threads) t.join();

  EXPECT_LE(peak.load(), kCapacity);
  EXPECT_EQ(budget.used(), 0);
}

}  // namespace
}  // namespace tempokey::server
