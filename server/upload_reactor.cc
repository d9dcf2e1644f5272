// UploadClip: a ClipHeader, then ChannelSamples slices; each message is checked as it arrives
// (wire::ClipAssembler), so a bad upload stops at its first bad message, and digested beside the
// reads that follow (BackgroundClipDigest). Memory is charged to the server's budget as samples
// arrive, never for the sizes the header declares. A client that sends nothing for the idle
// timeout while the server waits gets DEADLINE_EXCEEDED and its stream slot back.
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/arena_message.h"
#include "proto/clip_convert.h"
#include "server/background_digest.h"
#include "server/memory_size.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "server/wire_codec.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/io/printable_text.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

class UploadReactor final : public grpc::ServerReadReactor<grpc::ByteBuffer> {
 public:
  UploadReactor(ServiceContext* service, grpc::CallbackServerContext* call,
                grpc::ByteBuffer* response)
      : service_(service), call_(call), response_(response) {
    absl::Status admitted = Admit();
    if (!admitted.ok()) {
      FinishOnce(admitted);
      return;
    }
    if (service_->idle != nullptr) {
      idle_ = service_->idle->NewTimer([this] {
        FinishOnce(IdleError("UploadClip", service_->idle->timeout()));
      });
    }
    Read();
  }

  void OnReadDone(bool ok) override {
    if (idle_ != nullptr) idle_->Disarm();
    {
      std::lock_guard lock(mu_);
      if (finished_) return;  // the idle timer ended the call; this read was its last
    }
    if (!ok) {
      // End of the client's stream (or the call broke): the clip is complete or never will be.
      const absl::Status completed = Complete();
      if (!completed.ok()) ReleaseHeld();
      FinishOnce(completed);
      return;
    }
    ++messages_;
    service_->BytesIn(static_cast<std::int64_t>(buffer_.Length()));
    // Shared with the digest, which may hash the message's samples after this returns.
    auto request = std::make_shared<wire::ArenaMessage<v1::UploadClipRequest>>();
    absl::Status status =
        ParseMessage(buffer_, absl::StrCat("upload message ", messages_), request->get());
    if (status.ok()) status = Accept(request);
    if (!status.ok()) {
      spdlog::debug("upload refused at message {}: {} {}", messages_,
                    absl::StatusCodeToString(status.code()),
                    core::LogValue(core::AsStd(status.message())));
      ReleaseHeld();
      FinishOnce(status);
      return;
    }
    Read();
  }

  void OnDone() override {
    if (idle_ != nullptr) idle_->Close();
    delete this;
  }

 private:
  absl::Status Admit() {
    TEMPOKEY_ASSIGN_OR_RETURN(owner_, service_->Authenticate(*call_));
    TEMPOKEY_ASSIGN_OR_RETURN(reservation_,
                              ReserveMemory(*service_, MemoryUse::kUpload, "an upload"));
    assembler_.emplace(service_->clip_limits, ChargeTo(&reservation_));
    return slot_.Claim(*service_);
  }

  // Reads the next message, unless the call has finished: checked and started under the lock
  // FinishOnce() finishes under, so no read starts after the idle timer's Finish() (the timer may
  // fire between a read's completion and the next; gRPC runs the reactions a start causes after
  // the current one returns, never inside it).
  void Read() {
    std::lock_guard lock(mu_);
    if (finished_) return;
    if (idle_ != nullptr) idle_->Arm();
    StartRead(&buffer_);
  }

  // What a refused or incomplete upload holds goes back to the budget now, before the client sees
  // the status, not when gRPC destroys the call: the client's next upload may need it at once.
  // Called only from OnReadDone() with no read pending, so nothing else touches these.
  void ReleaseHeld() {
    digest_.reset();
    assembler_.reset();
    reservation_.Release();
  }

  // Finishes the call once, from a gRPC callback or the idle timer (another thread).
  void FinishOnce(const absl::Status& status) {
    std::lock_guard lock(mu_);
    if (finished_) return;
    finished_ = true;
    slot_.Release();
    Finish(ToGrpcStatus(status, call_));
  }

  using Request = std::shared_ptr<wire::ArenaMessage<v1::UploadClipRequest>>;

  absl::Status Accept(const Request& message) {
    const v1::UploadClipRequest& request = **message;
    switch (request.part_case()) {
      case v1::UploadClipRequest::kHeader:
        TEMPOKEY_RETURN_IF_ERROR(assembler_->AddHeader(request.header()));
        digest_.emplace(assembler_->clip(), &service_->digest_threads);
        return absl::OkStatus();
      case v1::UploadClipRequest::kSamples:
        return AcceptSlice(message, request.samples());
      case v1::UploadClipRequest::kSampleSlices:
        // No slices brings no sample: a stream of such messages would keep the upload alive
        // (each resets its idle timeout) without ever completing the clip.
        if (request.sample_slices().slices().empty()) {
          return absl::InvalidArgumentError(
              absl::StrCat("upload message ", messages_, ": sample_slices carries no slices"));
        }
        for (const v1::ChannelSamples& slice : request.sample_slices().slices()) {
          TEMPOKEY_RETURN_IF_ERROR(AcceptSlice(message, slice));
        }
        return absl::OkStatus();
      case v1::UploadClipRequest::PART_NOT_SET:
        break;
    }
    return absl::InvalidArgumentError(
        absl::StrCat("upload message ", messages_, " has neither header nor samples"));
  }

  absl::Status AcceptSlice(const Request& message, const v1::ChannelSamples& samples) {
    TEMPOKEY_RETURN_IF_ERROR(assembler_->AddSamples(samples));
    digest_->Offer(message, samples.channel_index(), samples.first_frame(),
                   std::span<const double>(samples.samples().data(),
                                           static_cast<std::size_t>(samples.samples_size())));
    return absl::OkStatus();
  }

  absl::Status Complete() {
    if (call_->IsCancelled()) return absl::CancelledError("the upload was cancelled");
    if (!assembler_->has_header()) {
      return absl::InvalidArgumentError("the upload ended before a clip header arrived");
    }
    TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, std::move(*assembler_).Finish());
    assembler_.reset();
    const std::string id = digest_->Finish(clip);
    digest_.reset();  // its thread, if it started one, ends here rather than with the call
    const std::int64_t frames = clip.frame_count;
    const auto channels = static_cast<std::int32_t>(clip.channels.size());
    const std::int64_t samples = clip.sample_count();
    reservation_.Settle(ClipBytes(clip));
    reservation_.ChangeUse(MemoryUse::kStoredClip);
    TEMPOKEY_ASSIGN_OR_RETURN(
        ClipStore::PutResult stored,
        service_->clips->Put(owner_, id, ShareWithReservation(std::move(clip), std::move(reservation_))));
    v1::UploadClipResponse response;
    response.set_clip_id(id);
    response.set_frame_count(frames);
    response.set_channel_count(channels);
    response.set_sample_count(samples);
    response.set_already_stored(stored.already_stored);
    SerializeMessage(response, response_);
    spdlog::info("upload clip={} frames={} channels={} messages={} already_stored={}", id, frames,
                 channels, messages_, stored.already_stored);
    return absl::OkStatus();
  }

  ServiceContext* const service_;
  grpc::CallbackServerContext* const call_;
  grpc::ByteBuffer* const response_;
  std::string owner_;
  StreamSlot slot_;
  std::shared_ptr<IdleReaper::Timer> idle_;
  grpc::ByteBuffer buffer_;
  // Declared before the assembler, which charges it.
  MemoryBudget::Reservation reservation_;
  std::optional<wire::ClipAssembler> assembler_;
  std::optional<BackgroundClipDigest> digest_;
  std::int64_t messages_ = 0;
  std::mutex mu_;
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
};

}  // namespace

grpc::ServerReadReactor<grpc::ByteBuffer>* NewUploadReactor(ServiceContext* service,
                                                            grpc::CallbackServerContext* call,
                                                            grpc::ByteBuffer* response) {
  return new UploadReactor(service, call, response);
}

}  // namespace tempokey::server
