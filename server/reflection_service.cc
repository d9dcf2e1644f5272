#include "server/reflection_service.h"

#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "google/protobuf/descriptor.h"
#include "google/protobuf/descriptor.pb.h"
#include "google/protobuf/dynamic_message.h"
#include "grpc/health/v1/health.pb.h"
#include "grpcpp/ext/proto_server_reflection_plugin.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "server/wire_codec.h"

namespace tempokey::server {

// Referencing the plugin keeps libgrpc++_reflection linked (an object with external linkage is
// always emitted), whose static initializers register the protocol's descriptors in the
// generated pool; the plugin itself is never installed.
extern void (*const keep_reflection_linked)();
void (*const keep_reflection_linked)() = &grpc::reflection::InitProtoReflectionServerBuilderPlugin;
// The same for grpc.health.v1 (proto/grpc/health/v1/health.proto, in tempokey_proto): without a
// reference its object is left out of the binary, and the Health service that list_services
// names could not be described ("symbol not found": grpcurl could not call it).
extern const google::protobuf::Descriptor* (*const keep_health_linked)();
const google::protobuf::Descriptor* (*const keep_health_linked)() =
    &grpc::health::v1::HealthCheckRequest::descriptor;

namespace {

using google::protobuf::Descriptor;
using google::protobuf::DescriptorPool;
using google::protobuf::FieldDescriptor;
using google::protobuf::FileDescriptor;
using google::protobuf::Message;

constexpr int kNotFound = static_cast<int>(grpc::StatusCode::NOT_FOUND);
constexpr int kUnimplemented = static_cast<int>(grpc::StatusCode::UNIMPLEMENTED);

const Descriptor* FindType(const std::string& name) {
  return DescriptorPool::generated_pool()->FindMessageTypeByName(name);
}

// Reflection accessors by field name (the messages are dynamic).
const FieldDescriptor* FieldOf(const Message& m, const std::string& name) {
  return m.GetDescriptor()->FindFieldByName(name);
}
std::string GetString(const Message& m, const std::string& name) {
  return m.GetReflection()->GetString(m, FieldOf(m, name));
}
Message* Mutable(Message* m, const std::string& name) {
  return m->GetReflection()->MutableMessage(m, FieldOf(*m, name));
}
Message* AddMessage(Message* m, const std::string& name) {
  return m->GetReflection()->AddMessage(m, FieldOf(*m, name));
}
void SetString(Message* m, const std::string& name, std::string value) {
  m->GetReflection()->SetString(m, FieldOf(*m, name), std::move(value));
}
void SetInt32(Message* m, const std::string& name, int value) {
  m->GetReflection()->SetInt32(m, FieldOf(*m, name), value);
}

void SetError(Message* response, int code, const std::string& message) {
  Message* error = Mutable(response, "error_response");
  SetInt32(error, "error_code", code);
  SetString(error, "error_message", message);
}

// `file` and every file it imports, each once, into the FileDescriptorResponse of `response`.
void AddFiles(const FileDescriptor* file, Message* response) {
  Message* files = Mutable(response, "file_descriptor_response");
  const FieldDescriptor* protos = FieldOf(*files, "file_descriptor_proto");
  std::set<std::string> sent;
  std::vector<const FileDescriptor*> pending = {file};
  while (!pending.empty()) {
    const FileDescriptor* next = pending.back();
    pending.pop_back();
    if (!sent.insert(next->name()).second) continue;
    google::protobuf::FileDescriptorProto proto;
    next->CopyTo(&proto);
    files->GetReflection()->AddString(files, protos, proto.SerializeAsString());
    for (int i = 0; i < next->dependency_count(); ++i) pending.push_back(next->dependency(i));
  }
}

class ReflectionReactor final : public grpc::ServerGenericBidiReactor {
 public:
  ReflectionReactor(ServiceContext* service, const std::vector<std::string>* services,
                    grpc::GenericCallbackServerContext* call)
      : service_(service), services_(services), call_(call) {
    const absl::Status admitted = Admit();
    if (!admitted.ok()) {
      End(ToGrpcStatus(admitted, call_));
      return;
    }
    if (service_->idle != nullptr) {
      // DEADLINE_EXCEEDED saying why, as every other stream ends when it idles (a cancel read
      // "Cancelled on the server side").
      idle_ = service_->idle->NewTimer([this] {
        End(ToGrpcStatus(IdleError("ServerReflectionInfo", service_->idle->timeout())));
      });
    }
    Read();
  }

  void OnReadDone(bool ok) override {
    if (idle_ != nullptr) idle_->Disarm();
    if (Ended()) return;  // the idle timer ended the call; this read was its last
    if (!ok) {
      End(grpc::Status::OK);  // the client half-closed: every request was answered
      return;
    }
    // ParseMessage(): its item count first, as every request's (reflection may be open to
    // callers without a token).
    std::unique_ptr<Message> request(factory_.GetPrototype(request_type_)->New());
    if (absl::Status parsed = ParseMessage(in_, "ServerReflectionInfo request", request.get());
        !parsed.ok()) {
      End(ToGrpcStatus(parsed));
      return;
    }
    std::unique_ptr<Message> response = Answer(*request);
    SerializeMessage(*response, &out_);
    std::lock_guard lock(end_mutex_);
    if (ended_) return;  // the idle timer ended the call meanwhile: nothing may start after it
    if (idle_ != nullptr) idle_->Arm();
    StartWrite(&out_);
  }

  void OnWriteDone(bool ok) override {
    if (idle_ != nullptr) idle_->Disarm();
    if (Ended()) return;
    if (!ok) {
      End(ToGrpcStatus(absl::CancelledError("the reflection stream broke")));
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
    if (call_->method() != kReflectionMethod) {
      return absl::UnimplementedError(
          absl::StrCat("method ", call_->method(), " is not served by tempokey-server"));
    }
    if (!service_->options.open_reflection) {
      if (absl::Status auth = service_->CheckAuth(*call_); !auth.ok()) return auth;
    }
    request_type_ = FindType("grpc.reflection.v1alpha.ServerReflectionRequest");
    response_type_ = FindType("grpc.reflection.v1alpha.ServerReflectionResponse");
    if (request_type_ == nullptr || response_type_ == nullptr) {
      return absl::UnimplementedError("server reflection is not built into this server");
    }
    return slot_.Claim(*service_, /*allow_while_draining=*/true);
  }

  // Reads the next request, unless the call has ended: checked and started under the lock End()
  // finishes under, so no read starts after the idle timer's Finish() (gRPC runs the reactions a
  // start causes after the current one returns, never inside it).
  void Read() {
    std::lock_guard lock(end_mutex_);
    if (ended_) return;
    if (idle_ != nullptr) idle_->Arm();
    StartRead(&in_);
  }

  bool Ended() {
    std::lock_guard lock(end_mutex_);
    return ended_;
  }

  // Finishes the call once, from a gRPC callback or the idle timer (another thread).
  void End(const grpc::Status& status) {
    std::lock_guard lock(end_mutex_);
    if (ended_) return;
    ended_ = true;
    slot_.Release();
    Finish(status);
  }

  std::unique_ptr<Message> Answer(const Message& request) {
    std::unique_ptr<Message> response(factory_.GetPrototype(response_type_)->New());
    SetString(response.get(), "valid_host", GetString(request, "host"));
    Mutable(response.get(), "original_request")->CopyFrom(request);
    const DescriptorPool* pool = DescriptorPool::generated_pool();
    const google::protobuf::OneofDescriptor* oneof =
        request_type_->FindOneofByName("message_request");
    const FieldDescriptor* asked =
        oneof == nullptr ? nullptr : request.GetReflection()->GetOneofFieldDescriptor(request, oneof);
    const std::string kind = asked == nullptr ? "" : asked->name();
    if (kind == "list_services") {
      Message* list = Mutable(response.get(), "list_services_response");
      for (const std::string& name : *services_) SetString(AddMessage(list, "service"), "name", name);
    } else if (kind == "file_by_filename" || kind == "file_containing_symbol") {
      const std::string name = GetString(request, kind);
      const FileDescriptor* file = kind == "file_by_filename" ? pool->FindFileByName(name)
                                                              : pool->FindFileContainingSymbol(name);
      if (file == nullptr) {
        SetError(response.get(), kNotFound, absl::StrCat(kind == "file_by_filename" ? "file \"" : "symbol \"", name, "\" not found"));
      } else {
        AddFiles(file, response.get());
      }
    } else if (kind == "file_containing_extension") {
      const Message& ask = request.GetReflection()->GetMessage(request, asked);
      const Descriptor* type = pool->FindMessageTypeByName(GetString(ask, "containing_type"));
      const int number = ask.GetReflection()->GetInt32(ask, FieldOf(ask, "extension_number"));
      const FieldDescriptor* extension =
          type == nullptr ? nullptr : pool->FindExtensionByNumber(type, number);
      if (extension == nullptr) {
        SetError(response.get(), kNotFound, "extension not found");
      } else {
        AddFiles(extension->file(), response.get());
      }
    } else if (kind == "all_extension_numbers_of_type") {
      const std::string name = GetString(request, kind);
      const Descriptor* type = pool->FindMessageTypeByName(name);
      if (type == nullptr) {
        SetError(response.get(), kNotFound, absl::StrCat("type \"", name, "\" not found"));
      } else {
        Message* numbers = Mutable(response.get(), "all_extension_numbers_response");
        SetString(numbers, "base_type_name", type->full_name());
        std::vector<const FieldDescriptor*> extensions;
        pool->FindAllExtensions(type, &extensions);
        const FieldDescriptor* field = FieldOf(*numbers, "extension_number");
        for (const FieldDescriptor* extension : extensions) {
          numbers->GetReflection()->AddInt32(numbers, field, extension->number());
        }
      }
    } else {
      SetError(response.get(), kUnimplemented, "the request names no known reflection query");
    }
    return response;
  }

  ServiceContext* const service_;
  const std::vector<std::string>* const services_;
  grpc::GenericCallbackServerContext* const call_;
  const Descriptor* request_type_ = nullptr;
  const Descriptor* response_type_ = nullptr;
  google::protobuf::DynamicMessageFactory factory_;
  std::shared_ptr<IdleReaper::Timer> idle_;
  std::mutex end_mutex_;
  bool ended_ = false;
  StreamSlot slot_;
  grpc::ByteBuffer in_;
  grpc::ByteBuffer out_;
};

}  // namespace

grpc::ServerGenericBidiReactor* ReflectionService::CreateReactor(
    grpc::GenericCallbackServerContext* call) {
  return new ReflectionReactor(context_, &services_, call);
}

}  // namespace tempokey::server
