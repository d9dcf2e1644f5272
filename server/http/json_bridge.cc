#include "server/http/json_bridge.h"

#include <chrono>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "google/protobuf/dynamic_message.h"
#include "google/protobuf/util/json_util.h"
#include "grpcpp/client_context.h"
#include "grpcpp/completion_queue.h"
#include "grpcpp/generic/generic_stub.h"
#include "grpcpp/impl/codegen/proto_utils.h"
#include "grpcpp/support/byte_buffer.h"
#include "proto/retry_hint.h"
#include "server/http/json_names.h"

namespace tempokey::server::http {
namespace {

namespace pb = ::google::protobuf;

absl::Status FromGrpc(const grpc::Status& status) {
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
}

std::unique_ptr<pb::Message> NewMessage(const pb::Descriptor* type) {
  return std::unique_ptr<pb::Message>(pb::MessageFactory::generated_factory()->GetPrototype(type)->New());
}

// Waits for the operation tagged `tag` on `cq`; its ok flag.
bool Await(grpc::CompletionQueue& cq, void* tag) {
  void* got = nullptr;
  bool ok = false;
  if (!cq.Next(&got, &ok)) return false;
  return ok && got == tag;
}

// Tags of the one operation in flight at a time: only their addresses matter.
char start_tag, write_tag, writes_done_tag, read_tag, finish_tag;

// One call on its own completion queue, driven step by step from the calling thread.
class DrivenCall {
 public:
  DrivenCall(grpc::GenericStub& stub, const std::string& path, std::string_view authorization) {
    if (!authorization.empty()) context_.AddMetadata("authorization", std::string(authorization));
    call_ = stub.PrepareCall(&context_, path, &cq_);
    call_->StartCall(&start_tag);
    alive_ = Await(cq_, &start_tag);
  }
  ~DrivenCall() {
    cq_.Shutdown();
    void* tag = nullptr;
    bool ok = false;
    while (cq_.Next(&tag, &ok)) {
    }
  }

  bool Write(const pb::Message& message) {
    if (!alive_) return false;
    grpc::ByteBuffer buffer;
    bool own = false;
    if (!grpc::SerializationTraits<pb::Message>::Serialize(message, &buffer, &own).ok()) {
      return false;
    }
    call_->Write(buffer, &write_tag);
    alive_ = Await(cq_, &write_tag);
    return alive_;
  }
  void WritesDone() {
    if (!alive_) return;
    call_->WritesDone(&writes_done_tag);
    alive_ = Await(cq_, &writes_done_tag);
  }
  // False at the end of the response stream (or when the call broke). While it waits, asks
  // `gone` every `look` whether the client has left, and cancels the call once it has
  // (`*cancelled` is then set; the read ends, failed).
  bool Read(pb::Message& message, const std::function<bool()>& gone,
            std::chrono::milliseconds look, bool* cancelled) {
    grpc::ByteBuffer buffer;
    call_->Read(&buffer, &read_tag);
    while (true) {
      void* got = nullptr;
      bool ok = false;
      // Once cancelled, only the read's end is awaited.
      const auto wait = *cancelled ? std::chrono::milliseconds(std::chrono::hours(1)) : look;
      const grpc::CompletionQueue::NextStatus next =
          cq_.AsyncNext(&got, &ok, std::chrono::system_clock::now() + wait);
      if (next == grpc::CompletionQueue::SHUTDOWN) return false;
      if (next == grpc::CompletionQueue::GOT_EVENT) {
        if (!ok || got != &read_tag) return false;
        return grpc::SerializationTraits<pb::Message>::Deserialize(&buffer, &message).ok();
      }
      if (!*cancelled && gone()) {
        *cancelled = true;
        Cancel();
      }
    }
  }
  void Cancel() { context_.TryCancel(); }
  grpc::Status Finish() {
    grpc::Status status;
    call_->Finish(&status, &finish_tag);
    Await(cq_, &finish_tag);
    return status;
  }
  std::optional<std::chrono::milliseconds> RetryAfter() const {
    const auto& trailers = context_.GetServerTrailingMetadata();
    auto it = trailers.find(wire::kRetryAfterMetadataKey);
    std::int64_t ms = 0;
    if (it == trailers.end() ||
        !absl::SimpleAtoi(absl::string_view(it->second.data(), it->second.size()), &ms)) {
      return std::nullopt;
    }
    return std::chrono::milliseconds(ms);
  }

 private:
  grpc::ClientContext context_;
  grpc::CompletionQueue cq_;
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call_;
  bool alive_ = false;
};

}  // namespace

absl::StatusOr<std::string> MessageToJson(const pb::Message& message) {
  pb::util::JsonPrintOptions options;
  options.always_print_primitive_fields = true;
  std::string json;
  pb::util::Status status = pb::util::MessageToJsonString(message, &json, options);
  if (!status.ok()) {
    return absl::InternalError(absl::StrCat("cannot write the response as JSON: ",
                                            std::string(status.message())));
  }
  return json;
}

JsonBridge::JsonBridge(std::shared_ptr<grpc::Channel> channel, std::int64_t max_message_bytes)
    : channel_(std::move(channel)), max_message_bytes_(max_message_bytes) {}

const pb::MethodDescriptor* JsonBridge::FindMethod(std::string_view path) {
  // "/<service>/<method>"
  if (path.size() < 2 || path.front() != '/') return nullptr;
  path.remove_prefix(1);
  const std::size_t slash = path.find('/');
  if (slash == std::string_view::npos || path.substr(0, slash) != kBridgedService) return nullptr;
  const pb::ServiceDescriptor* service =
      pb::DescriptorPool::generated_pool()->FindServiceByName(kBridgedService);
  if (service == nullptr) return nullptr;
  return service->FindMethodByName(std::string(path.substr(slash + 1)));
}

JsonBridge::Outcome JsonBridge::Call(const pb::MethodDescriptor& method,
                                     std::string_view authorization, Stream& stream) const {
  Outcome outcome;
  grpc::GenericStub stub(channel_);
  const std::string path =
      absl::StrCat("/", method.service()->full_name(), "/", method.name());
  DrivenCall call(stub, path, authorization);

  // Requests: every one the stream gives, checked against the method's input type.
  std::unique_ptr<pb::Message> request = NewMessage(method.input_type());
  pb::util::JsonParseOptions parse_options;
  for (int index = 1;; ++index) {
    absl::StatusOr<std::optional<std::string>> json = stream.NextRequest();
    absl::Status bad;
    if (!json.ok()) {
      bad = json.status();
    } else if (!json->has_value()) {
      break;
    } else {
      request->Clear();
      pb::util::Status parsed = pb::util::JsonStringToMessage(**json, request.get(), parse_options);
      if (!parsed.ok()) {
        bad = absl::InvalidArgumentError(
            absl::StrCat("request message ", index, " is not a ", method.input_type()->full_name(),
                         " in JSON: ", std::string(parsed.message())));
      } else if (absl::Status names = CheckNoRepeatedNames(**json); !names.ok()) {
        bad = absl::InvalidArgumentError(
            absl::StrCat("request message ", index, ": ", names.message()));
      }
    }
    if (!bad.ok()) {
      call.Cancel();
      call.Finish();
      outcome.status = bad;
      return outcome;
    }
    if (!call.Write(*request)) break;  // the call ended early: its status says why
    if (!method.client_streaming()) break;
  }
  call.WritesDone();

  // Responses, in order, until the stream ends.
  std::unique_ptr<pb::Message> response = NewMessage(method.output_type());
  const auto gone = [&stream] { return stream.ClientGone(); };
  while (call.Read(*response, gone, kDepartureLook, &outcome.client_gone)) {
    // A response that crossed the cancel is not sent to a client that has gone.
    if (outcome.client_gone) {
      response->Clear();
      continue;
    }
    absl::StatusOr<std::string> json = MessageToJson(*response);
    if (!json.ok()) {
      call.Cancel();
      call.Finish();
      outcome.status = json.status();
      return outcome;
    }
    if (!stream.WriteResponse(*json)) {
      call.Cancel();
      call.Finish();
      outcome.status = absl::CancelledError("the HTTP client went away");
      return outcome;
    }
    ++outcome.responses;
    response->Clear();
  }
  if (outcome.client_gone) {
    call.Finish();
    outcome.status = absl::CancelledError("the HTTP client went away");
    return outcome;
  }
  outcome.status = FromGrpc(call.Finish());
  outcome.retry_after = call.RetryAfter();
  return outcome;
}

}  // namespace tempokey::server::http
