// UploadClip: a ClipHeader, then ChannelSamples slices; each message is checked as it arrives
// (wire::ClipAssembler) and digested, so a bad upload stops at its first bad message and memory
// stays bounded by the header's declared size.
#include <memory>
#include <optional>
#include <span>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/clip_convert.h"
#include "proto/clip_digest.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

class UploadReactor final : public grpc::ServerReadReactor<v1::UploadClipRequest> {
 public:
  UploadReactor(ServiceContext* service, grpc::CallbackServerContext* call,
                v1::UploadClipResponse* response)
      : service_(service), call_(call), response_(response), assembler_(service->clip_limits) {
    absl::Status admitted = service_->CheckAuth(*call_);
    if (admitted.ok()) admitted = service_->AdmitStream();
    if (!admitted.ok()) {
      Finish(ToGrpcStatus(admitted, call_));
      return;
    }
    holds_stream_ = true;
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      // End of the client's stream (or the call broke): the clip is complete or never will be.
      Finish(ToGrpcStatus(Complete(), call_));
      return;
    }
    ++messages_;
    service_->BytesIn(static_cast<std::int64_t>(request_.ByteSizeLong()));
    absl::Status status = Accept();
    if (!status.ok()) {
      spdlog::debug("upload refused at message {}: {}", messages_, status.ToString());
      Finish(ToGrpcStatus(status, call_));
      return;
    }
    StartRead(&request_);
  }

  void OnDone() override {
    if (holds_stream_) service_->CloseStream();
    delete this;
  }

 private:
  absl::Status Accept() {
    switch (request_.part_case()) {
      case v1::UploadClipRequest::kHeader:
        TEMPOKEY_RETURN_IF_ERROR(assembler_.AddHeader(request_.header()));
        digest_.emplace(assembler_.clip());
        return absl::OkStatus();
      case v1::UploadClipRequest::kSamples:
        return AcceptSlice(request_.samples());
      case v1::UploadClipRequest::kSampleSlices:
        for (const v1::ChannelSamples& slice : request_.sample_slices().slices()) {
          TEMPOKEY_RETURN_IF_ERROR(AcceptSlice(slice));
        }
        return absl::OkStatus();
      case v1::UploadClipRequest::PART_NOT_SET:
        break;
    }
    return absl::InvalidArgumentError(
        absl::StrCat("upload message ", messages_, " has neither header nor samples"));
  }

  absl::Status AcceptSlice(const v1::ChannelSamples& samples) {
    TEMPOKEY_RETURN_IF_ERROR(assembler_.AddSamples(samples));
    digest_->Offer(samples.channel_index(), samples.first_frame(),
                   std::span<const double>(samples.samples().data(),
                                           static_cast<std::size_t>(samples.samples_size())));
    return absl::OkStatus();
  }

  absl::Status Complete() {
    if (call_->IsCancelled()) return absl::CancelledError("the upload was cancelled");
    if (!assembler_.has_header()) {
      return absl::InvalidArgumentError("the upload ended before a clip header arrived");
    }
    TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, std::move(assembler_).Finish());
    const std::string id = digest_->Finish(clip);
    const std::int64_t frames = clip.frame_count;
    const auto channels = static_cast<std::int32_t>(clip.channels.size());
    const std::int64_t samples = clip.sample_count();
    TEMPOKEY_ASSIGN_OR_RETURN(ClipStore::PutResult stored, service_->clips->Put(id, std::move(clip)));
    response_->set_clip_id(id);
    response_->set_frame_count(frames);
    response_->set_channel_count(channels);
    response_->set_sample_count(samples);
    response_->set_already_stored(stored.already_stored);
    spdlog::info("upload clip={} frames={} channels={} messages={} already_stored={}", id, frames,
                 channels, messages_, stored.already_stored);
    return absl::OkStatus();
  }

  ServiceContext* const service_;
  grpc::CallbackServerContext* const call_;
  v1::UploadClipResponse* const response_;
  bool holds_stream_ = false;
  v1::UploadClipRequest request_;
  wire::ClipAssembler assembler_;
  std::optional<wire::IncrementalClipDigest> digest_;
  std::int64_t messages_ = 0;
};

}  // namespace

grpc::ServerReadReactor<v1::UploadClipRequest>* NewUploadReactor(
    ServiceContext* service, grpc::CallbackServerContext* call, v1::UploadClipResponse* response) {
  return new UploadReactor(service, call, response);
}

}  // namespace tempokey::server
