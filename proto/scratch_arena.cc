#include "proto/scratch_arena.h"

#include <cstdio>
#include <cstdlib>
#include <memory>

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/asan_interface.h>
#endif

namespace tempokey::wire::scratch_internal {
namespace {

// The kept block between messages: poisoned for AddressSanitizer (its bytes are still mapped and
// would read back), open while a message or a look at the arena uses it.
void Poison(char* block) {
#if defined(__SANITIZE_ADDRESS__)
  ASAN_POISON_MEMORY_REGION(block, kScratchBlockBytes);
#else
  (void)block;
#endif
}
void Unpoison(char* block) {
#if defined(__SANITIZE_ADDRESS__)
  ASAN_UNPOISON_MEMORY_REGION(block, kScratchBlockBytes);
#else
  (void)block;
#endif
}

// The arena starts in `block`, which it keeps across Reset(): protobuf frees on a reset every
// block but an initial one its user provided (ArenaOptions::initial_block).
google::protobuf::ArenaOptions ScratchOptions(char* block) {
  google::protobuf::ArenaOptions options = MessageArenaOptions();
  options.initial_block = block;
  options.initial_block_size = kScratchBlockBytes;
  return options;
}

struct ThreadScratch {
  ThreadScratch()
      : block(std::make_unique_for_overwrite<char[]>(kScratchBlockBytes)),
        arena(ScratchOptions(block.get())) {
    Poison(block.get());
  }
  // The arena reads its state in the block as it ends.
  ~ThreadScratch() { Unpoison(block.get()); }
  ThreadScratch(const ThreadScratch&) = delete;
  ThreadScratch& operator=(const ThreadScratch&) = delete;

  std::unique_ptr<char[]> block;  // declared first: the arena uses it until its own end
  google::protobuf::Arena arena;
  bool held = false;
};

ThreadScratch& ThisThread() {
  thread_local ThreadScratch scratch;
  return scratch;
}

}  // namespace

google::protobuf::Arena* Acquire() {
  ThreadScratch& scratch = ThisThread();
  if (scratch.held) return nullptr;
  scratch.held = true;
  Unpoison(scratch.block.get());
  return &scratch.arena;
}

void Release(google::protobuf::Arena* arena) {
  ThreadScratch& scratch = ThisThread();
  if (arena != &scratch.arena || !scratch.held) {
    std::fprintf(stderr,
                 "tempokey: a scratch message was dropped on a thread other than its own, or "
                 "twice (scratch_arena.h)\n");
    std::abort();
  }
  scratch.arena.Reset();
  scratch.held = false;
  Poison(scratch.block.get());
}

std::size_t ThreadArenaBytes() {
  ThreadScratch& scratch = ThisThread();
  if (!scratch.held) Unpoison(scratch.block.get());
  const auto bytes = static_cast<std::size_t>(scratch.arena.SpaceAllocated());
  if (!scratch.held) Poison(scratch.block.get());
  return bytes;
}

}  // namespace tempokey::wire::scratch_internal
