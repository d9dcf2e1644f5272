// Scratch messages (proto/scratch_arena.h): a thread's messages share one arena that keeps its
// block and gives back everything else when each message is dropped; a message made while another
// holds the arena gets its own; each thread has its own; a message dropped on another thread is
// refused loudly, and under AddressSanitizer a dropped message's bytes cannot be read.
#include "proto/scratch_arena.h"

#include <cstdio>
#include <memory>
#include <string>
#include <thread>

#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "tempokey/v1/motion_service.pb.h"
#include "tests/server/test_clips.h"

namespace tempokey::wire {
namespace {

using ::tempokey::testing::MakeClip;

// A part of `samples` doubles, well past the kept block when large.
void FillPart(v1::ResultPart& part, int samples) {
  v1::ChannelSamples* slice = part.mutable_samples();
  slice->set_channel_index(3);
  for (int i = 0; i < samples; ++i) slice->add_samples(0.5 * i);
}

TEST(ScratchArenaTest, ConsecutiveMessagesShareTheThreadsArena) {
  google::protobuf::Arena* first = nullptr;
  {
    ScratchMessage<v1::ResultPart> part;
    EXPECT_TRUE(part.shared());
    first = part->GetArena();
    ASSERT_NE(first, nullptr);
  }
  ScratchMessage<v1::ProcessResponse> next;
  EXPECT_TRUE(next.shared());
  EXPECT_EQ(next->GetArena(), first);
}

TEST(ScratchArenaTest, ADroppedMessageLeavesOnlyTheKeptBlock) {
  constexpr int kSamples = 200'000;  // 1.6 MB of doubles: blocks beyond the kept one
  {
    ScratchMessage<v1::ResultPart> part;
    FillPart(*part, kSamples);
    EXPECT_GT(scratch_internal::ThreadArenaBytes(), kScratchBlockBytes);
    EXPECT_EQ(part->samples().samples_size(), kSamples);
    EXPECT_EQ(part->samples().samples(kSamples - 1), 0.5 * (kSamples - 1));
  }
  EXPECT_EQ(scratch_internal::ThreadArenaBytes(), kScratchBlockBytes);
  // The kept block serves the next message whole.
  ScratchMessage<v1::ResultPart> again;
  FillPart(*again, 1000);
  EXPECT_EQ(again->samples().samples(999), 499.5);
  EXPECT_EQ(scratch_internal::ThreadArenaBytes(), kScratchBlockBytes);
}

TEST(ScratchArenaTest, AMessageMadeWhileAnotherHoldsTheArenaGetsItsOwn) {
  ScratchMessage<v1::ResultPart> outer;
  FillPart(*outer, 100);
  {
    ScratchMessage<v1::ResultPart> inner;
    EXPECT_FALSE(inner.shared());
    EXPECT_NE(inner->GetArena(), nullptr);
    EXPECT_NE(inner->GetArena(), outer->GetArena());
    FillPart(*inner, 50'000);
  }
  // The inner one's end neither reset nor let go of the outer one's arena.
  ASSERT_EQ(outer->samples().samples_size(), 100);
  EXPECT_EQ(outer->samples().samples(99), 49.5);
  EXPECT_EQ(outer->samples().channel_index(), 3);
  ScratchMessage<v1::ResultPart> third;
  EXPECT_FALSE(third.shared());
}

TEST(ScratchArenaDeathTest, AMessageDroppedOnAnotherThreadAborts) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(
      {
        auto part = std::make_unique<ScratchMessage<v1::ResultPart>>();
        std::thread other([&] { part.reset(); });
        other.join();
      },
      "dropped on a thread other than its own");
}

#if defined(__SANITIZE_ADDRESS__)
// The kept block's bytes stay mapped after a message is dropped: AddressSanitizer must still see a
// read through a pointer kept into it.
TEST(ScratchArenaDeathTest, ReadingADroppedMessageIsCaughtUnderAddressSanitizer) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(
      {
        const double* kept = nullptr;
        {
          ScratchMessage<v1::ResultPart> part;
          FillPart(*part, 100);
          kept = part->samples().samples().data();
        }
        std::printf("%f\n", kept[10]);
      },
      "use-after-poison");
}
#endif

TEST(ScratchArenaTest, EachThreadHasItsOwnArena) {
  ScratchMessage<v1::ResultPart> here;
  google::protobuf::Arena* there = nullptr;
  bool there_shared = false;
  std::thread other([&] {
    ScratchMessage<v1::ResultPart> part;
    there = part->GetArena();
    there_shared = part.shared();
  });
  other.join();
  EXPECT_TRUE(here.shared());
  EXPECT_TRUE(there_shared);  // not nested: the other thread's arena was free
  EXPECT_NE(there, here->GetArena());
}

TEST(ScratchArenaTest, AMessageParsedIntoScratchEqualsOneParsedOnTheHeap) {
  v1::ResultPart original;
  original.mutable_header()->set_allocated_clip(ClipHeaderOnArena(MakeClip(5, 20), nullptr));
  const std::string bytes = original.SerializeAsString();

  {
    // A message large enough for blocks beyond the kept one, dropped before the parse.
    ScratchMessage<v1::ResultPart> large;
    FillPart(*large, 100'000);
  }
  ScratchMessage<v1::ResultPart> parsed;
  EXPECT_TRUE(parsed.shared());
  ASSERT_TRUE(parsed->ParseFromString(bytes));
  v1::ResultPart heap;
  ASSERT_TRUE(heap.ParseFromString(bytes));

  EXPECT_EQ(parsed->SerializeAsString(), bytes);
  EXPECT_EQ(heap.SerializeAsString(), bytes);
  EXPECT_EQ(parsed->header().clip().channels_size(), original.header().clip().channels_size());
}

}  // namespace
}  // namespace tempokey::wire
