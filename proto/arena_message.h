// A tempokey.v1 message whose fields live in an arena of its own, for the server's and the
// client's streams.
#ifndef TEMPOKEY_PROTO_ARENA_MESSAGE_H_
#define TEMPOKEY_PROTO_ARENA_MESSAGE_H_

#include <cstddef>

#include "google/protobuf/arena.h"

namespace tempokey::wire {

// Blocks of 64 KiB growing to 256 KiB: a short clip's slices for a few hundred channels take
// two or three. Below the mapping threshold the server gives glibc (1 MiB, memory_budget.h), so
// there blocks come from the heap and are reused, not mapped and zeroed afresh for every message;
// a larger field gets a block of its own size, as it would get its own allocation without an
// arena. (A client keeps glibc's own threshold, which adapts upwards the same way.)
inline google::protobuf::ArenaOptions MessageArenaOptions() {
  google::protobuf::ArenaOptions options;
  options.start_block_size = std::size_t{64} << 10;
  options.max_block_size = std::size_t{256} << 10;
  return options;
}

// One message parsed from the wire whose fields live in an arena of their own, all freed together
// when it goes out of scope. A clip's slices parse into a message per channel, each with its own
// repeated field: from the heap that was some 400 allocations and frees per Process call, and
// malloc and free took about a quarter of the server's CPU under 16 clients; from the arena it is
// a few blocks (paired runs: 0.75-0.80 -> 0.67-0.70 ms of server CPU per job). For a message kept
// for a while (a client's header, sent again on a retry) and for an upload's slices (not
// measured with the scratch arena: an upload's time is in page faults); the Process and result
// streams' messages, made and dropped within one step, use ScratchMessage (scratch_arena.h),
// which keeps its block from one message to the next. An arena frees nothing before it ends: not
// for a message cleared and refilled without bound. Not for messages built from parts made on
// the heap: moving a message between arenas copies it.
template <typename Message>
class ArenaMessage {
 public:
  ArenaMessage()
      : arena_(MessageArenaOptions()),
        message_(google::protobuf::Arena::CreateMessage<Message>(&arena_)) {}
  ArenaMessage(const ArenaMessage&) = delete;
  ArenaMessage& operator=(const ArenaMessage&) = delete;

  Message* get() { return message_; }
  Message& operator*() { return *message_; }
  Message* operator->() { return message_; }

 private:
  google::protobuf::Arena arena_;
  Message* message_;  // owned by arena_
};

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_ARENA_MESSAGE_H_
