#include "proto/scratch_arena.h"

#include <memory>

namespace tempokey::wire::scratch_internal {
namespace {

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
        arena(ScratchOptions(block.get())) {}

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
  return &scratch.arena;
}

void Release() {
  ThreadScratch& scratch = ThisThread();
  scratch.arena.Reset();
  scratch.held = false;
}

std::size_t ThreadArenaBytes() {
  return static_cast<std::size_t>(ThisThread().arena.SpaceAllocated());
}

}  // namespace tempokey::wire::scratch_internal
