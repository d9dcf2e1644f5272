// A tempokey.v1 message in an arena its thread keeps from one message to the next, for the
// messages a stream builds or parses, uses and drops within one step (a result part serialized
// for a write, a request parsed into the clip being assembled).
#ifndef TEMPOKEY_PROTO_SCRATCH_ARENA_H_
#define TEMPOKEY_PROTO_SCRATCH_ARENA_H_

#include <cstddef>
#include <optional>

#include "google/protobuf/arena.h"
#include "proto/arena_message.h"

namespace tempokey::wire {

// The block each thread keeps: a Process call's clip of about 200 channels of 128 frames (header,
// slices and their arrays; about 150 KB for 132 channels) fits in it. A larger message takes more
// blocks, given back when it is dropped.
inline constexpr std::size_t kScratchBlockBytes = std::size_t{256} << 10;

namespace scratch_internal {

// The calling thread's scratch arena, or nullptr while a ScratchMessage of this thread holds it.
google::protobuf::Arena* Acquire();
// Ends the hold of `arena`, which Acquire() gave on this thread: frees everything in it but its
// kept block. Aborts, naming the misuse, when `arena` is not this thread's held arena (a
// message destroyed on another thread would otherwise reset that thread's arena under its
// message).
void Release(google::protobuf::Arena* arena);
// Bytes the calling thread's scratch arena holds (its kept block once released), for tests.
std::size_t ThreadArenaBytes();

}  // namespace scratch_internal

// A message whose fields live in its thread's scratch arena, all dropped together when it goes
// out of scope, the arena's kept block then ready for the next one: a result part of a Process
// call was some 600 allocations and frees on the heap (a message and a repeated field per
// channel, and the header's per-channel messages and names), and a parsed request some 64 KiB
// arena blocks taken from glibc and given back, whose frees made glibc consolidate its bins.
// While one is alive on a thread, another on the same thread gets an arena of its own (a
// client's progress callback, run while a response is held, may make another call). Must be
// destroyed on the thread that made it: a local variable. In AddressSanitizer builds the kept
// block is poisoned between messages, so a pointer kept into a dropped message is still caught.
template <typename Message>
class ScratchMessage {
 public:
  ScratchMessage() : shared_(scratch_internal::Acquire()) {
    if (shared_ == nullptr) own_.emplace(MessageArenaOptions());
    message_ = google::protobuf::Arena::CreateMessage<Message>(shared_ != nullptr ? shared_
                                                                                   : &*own_);
  }
  ~ScratchMessage() {
    if (shared_ != nullptr) scratch_internal::Release(shared_);
  }
  ScratchMessage(const ScratchMessage&) = delete;
  ScratchMessage& operator=(const ScratchMessage&) = delete;

  Message* get() { return message_; }
  Message& operator*() { return *message_; }
  Message* operator->() { return message_; }
  // Whether this one has the thread's kept arena (false: it is nested in another).
  bool shared() const { return shared_ != nullptr; }

 private:
  google::protobuf::Arena* shared_;
  std::optional<google::protobuf::Arena> own_;
  Message* message_;  // owned by the arena
};

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_SCRATCH_ARENA_H_
