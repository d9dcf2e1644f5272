// Server reflection (what grpcurl and grpc_cli use) on a real server: it lists MotionService and
// health, and describes MotionService's file with the files it imports; with bearer tokens it
// needs one, unless --open_reflection opens it. The request and response messages are built from
// the descriptors libgrpc++_reflection registers, so the test speaks the real protocol without
// compiling reflection.proto again.
#include <memory>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "google/protobuf/descriptor.h"
#include "google/protobuf/dynamic_message.h"
#include "grpcpp/generic/generic_stub.h"
#include "grpcpp/support/byte_buffer.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "google/protobuf/descriptor.pb.h"
#include "tempokey/core/io/file_io.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::Contains;
using google::protobuf::Descriptor;
using google::protobuf::DescriptorPool;
using google::protobuf::DynamicMessageFactory;
using google::protobuf::Message;

constexpr char kMethod[] = "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo";

// One request on a ServerReflectionInfo stream, its response read back.
class ReflectionClient {
 public:
  explicit ReflectionClient(const std::shared_ptr<grpc::Channel>& channel)
      : stub_(channel),
        request_type_(Find("grpc.reflection.v1alpha.ServerReflectionRequest")),
        response_type_(Find("grpc.reflection.v1alpha.ServerReflectionResponse")) {}

  bool ready() const { return request_type_ != nullptr && response_type_ != nullptr; }

  // Sends a request with string field `field` set to `value` (with "authorization: Bearer
  // <token>" unless `token` is empty); the parsed response, or null. `status` (optional) gets
  // the call's status.
  std::unique_ptr<Message> Ask(const std::string& field, const std::string& value,
                               const std::string& token = "", grpc::Status* status_out = nullptr) {
    std::unique_ptr<Message> request(factory_.GetPrototype(request_type_)->New());
    request->GetReflection()->SetString(request.get(), request_type_->FindFieldByName(field),
                                        value);
    std::string bytes;
    if (!request->SerializeToString(&bytes)) return nullptr;

    grpc::ClientContext context;
    SetDeadline(context);
    if (!token.empty()) context.AddMetadata("authorization", "Bearer " + token);
    grpc::CompletionQueue queue;
    std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call =
        stub_.PrepareCall(&context, kMethod, &queue);
    grpc::Slice slice(bytes);
    grpc::ByteBuffer out(&slice, 1);
    grpc::ByteBuffer in;
    grpc::Status status;
    int tag = 0;
    // Each step runs only if the one before succeeded; the status is read in any case (a server
    // that refuses the call ends it before the request is written).
    call->StartCall(&tag);
    bool open = Step(queue);
    if (open) {
      call->Write(out, &tag);
      open = Step(queue);
    }
    if (open) {
      call->WritesDone(&tag);
      open = Step(queue);
    }
    bool read = false;
    if (open) {
      call->Read(&in, &tag);
      read = Step(queue);
    }
    call->Finish(&status, &tag);
    Step(queue);
    if (status_out != nullptr) *status_out = status;
    if (!read || !status.ok()) return nullptr;

    std::vector<grpc::Slice> slices;
    if (!in.Dump(&slices).ok()) return nullptr;
    std::string response_bytes;
    for (const grpc::Slice& s : slices) {
      response_bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
    }
    std::unique_ptr<Message> response(factory_.GetPrototype(response_type_)->New());
    if (!response->ParseFromString(response_bytes)) return nullptr;
    return response;
  }

 private:
  static const Descriptor* Find(const std::string& name) {
    return DescriptorPool::generated_pool()->FindMessageTypeByName(name);
  }

  // Waits for the one operation in flight on `queue`.
  static bool Step(grpc::CompletionQueue& queue) {
    void* got = nullptr;
    bool ok = false;
    return queue.Next(&got, &ok) && ok;
  }

  grpc::GenericStub stub_;
  DynamicMessageFactory factory_;
  const Descriptor* request_type_;
  const Descriptor* response_type_;
};

// The sub-message `name` of `message` (by reflection).
const Message& Field(const Message& message, const std::string& name) {
  return message.GetReflection()->GetMessage(message,
                                             message.GetDescriptor()->FindFieldByName(name));
}

TEST(ReflectionTest, ListsTheServicesAndDescribesMotionService) {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  ASSERT_NE(server, nullptr);
  ReflectionClient client(Connect(server->target()));
  ASSERT_TRUE(client.ready()) << "reflection descriptors are not registered";

  const std::unique_ptr<Message> listed = client.Ask("list_services", "");
  const std::unique_ptr<Message> described =
      client.Ask("file_containing_symbol", "tempokey.v1.MotionService");

  ASSERT_NE(listed, nullptr);
  const Message& services = Field(*listed, "list_services_response");
  const auto* service_field = services.GetDescriptor()->FindFieldByName("service");
  std::vector<std::string> names;
  for (int i = 0; i < services.GetReflection()->FieldSize(services, service_field); ++i) {
    const Message& service =
        services.GetReflection()->GetRepeatedMessage(services, service_field, i);
    names.push_back(service.GetReflection()->GetString(
        service, service.GetDescriptor()->FindFieldByName("name")));
  }
  EXPECT_THAT(names, Contains("tempokey.v1.MotionService"));
  EXPECT_THAT(names, Contains("grpc.health.v1.Health"));
  ASSERT_NE(described, nullptr);
  const Message& files = Field(*described, "file_descriptor_response");
  const auto* proto_field = files.GetDescriptor()->FindFieldByName("file_descriptor_proto");
  EXPECT_GE(files.GetReflection()->FieldSize(files, proto_field), 1);
}

// Names listed by list_services, and the file descriptors a reflection response carries.
std::vector<std::string> ListedServices(const Message& listed) {
  const Message& services = Field(listed, "list_services_response");
  const auto* field = services.GetDescriptor()->FindFieldByName("service");
  std::vector<std::string> names;
  for (int i = 0; i < services.GetReflection()->FieldSize(services, field); ++i) {
    const Message& service = services.GetReflection()->GetRepeatedMessage(services, field, i);
    names.push_back(service.GetReflection()->GetString(
        service, service.GetDescriptor()->FindFieldByName("name")));
  }
  return names;
}
std::vector<google::protobuf::FileDescriptorProto> DescribedFiles(const Message& described) {
  std::vector<google::protobuf::FileDescriptorProto> files;
  if (!described.GetDescriptor()->FindFieldByName("file_descriptor_response")) return files;
  const Message& response = Field(described, "file_descriptor_response");
  const auto* field = response.GetDescriptor()->FindFieldByName("file_descriptor_proto");
  for (int i = 0; i < response.GetReflection()->FieldSize(response, field); ++i) {
    files.emplace_back().ParseFromString(response.GetReflection()->GetRepeatedString(response, field, i));
  }
  return files;
}

// A generic client (grpcurl) resolves every call through reflection: the health service was
// listed but not described ("symbol not found"), so it could not be called that way. Its
// description is checked against gRPC's own health service: a Check request built from it gets
// an answer that it reads as SERVING.
TEST(ReflectionTest, EveryListedServiceIsDescribedAndHealthsDescriptionReadsItsAnswers) {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  ASSERT_NE(server, nullptr);
  const std::shared_ptr<grpc::Channel> channel = Connect(server->target());
  ReflectionClient client(channel);
  ASSERT_TRUE(client.ready());
  const std::unique_ptr<Message> listed = client.Ask("list_services", "");
  ASSERT_NE(listed, nullptr);

  for (const std::string& name : ListedServices(*listed)) {
    const std::unique_ptr<Message> described = client.Ask("file_containing_symbol", name);
    ASSERT_NE(described, nullptr) << name;
    EXPECT_FALSE(DescribedFiles(*described).empty()) << name << " is not described";
  }
  const std::unique_ptr<Message> health = client.Ask("file_containing_symbol", "grpc.health.v1.Health");
  ASSERT_NE(health, nullptr);
  DescriptorPool pool;  // the client's own, from the described files only
  for (const google::protobuf::FileDescriptorProto& file : DescribedFiles(*health)) {
    ASSERT_NE(pool.BuildFile(file), nullptr) << file.name();
  }
  const google::protobuf::ServiceDescriptor* service = pool.FindServiceByName("grpc.health.v1.Health");
  ASSERT_NE(service, nullptr);
  ASSERT_NE(service->FindMethodByName("Check"), nullptr);
  ASSERT_NE(service->FindMethodByName("Watch"), nullptr);
  EXPECT_TRUE(service->FindMethodByName("Watch")->server_streaming());
  const google::protobuf::MethodDescriptor* check = service->FindMethodByName("Check");
  DynamicMessageFactory factory(&pool);
  std::unique_ptr<Message> request(factory.GetPrototype(check->input_type())->New());
  request->GetReflection()->SetString(request.get(), check->input_type()->FindFieldByName("service"),
                                      "tempokey.v1.MotionService");
  const absl::StatusOr<std::string> response_bytes =
      CallUnaryBytes(channel, "/grpc.health.v1.Health/Check", request->SerializeAsString());
  ASSERT_TRUE(response_bytes.ok()) << response_bytes.status();
  std::unique_ptr<Message> response(factory.GetPrototype(check->output_type())->New());
  ASSERT_TRUE(response->ParseFromString(*response_bytes));

  const google::protobuf::FieldDescriptor* status = check->output_type()->FindFieldByName("status");
  ASSERT_NE(status, nullptr);
  EXPECT_EQ(response->GetReflection()->GetEnum(*response, status)->name(), "SERVING");
}

TEST(ReflectionTest, FileByNameComesWithTheFilesItImports) {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  ASSERT_NE(server, nullptr);
  ReflectionClient client(Connect(server->target()));
  ASSERT_TRUE(client.ready());

  const std::unique_ptr<Message> described =
      client.Ask("file_by_filename", "tempokey/v1/motion_service.proto");
  const std::unique_ptr<Message> missing = client.Ask("file_containing_symbol", "no.Such");

  ASSERT_NE(described, nullptr);
  const Message& files = Field(*described, "file_descriptor_response");
  const auto* proto_field = files.GetDescriptor()->FindFieldByName("file_descriptor_proto");
  std::vector<std::string> names;
  for (int i = 0; i < files.GetReflection()->FieldSize(files, proto_field); ++i) {
    google::protobuf::FileDescriptorProto file;
    ASSERT_TRUE(file.ParseFromString(files.GetReflection()->GetRepeatedString(files, proto_field, i)));
    names.push_back(file.name());
  }
  EXPECT_THAT(names, ::testing::UnorderedElementsAre(
                         "tempokey/v1/motion_service.proto", "tempokey/v1/clip.proto",
                         "tempokey/v1/operations.proto", "tempokey/v1/editing.proto",
                         "google/protobuf/timestamp.proto"));
  ASSERT_NE(missing, nullptr);
  const Message& error = Field(*missing, "error_response");
  EXPECT_EQ(error.GetReflection()->GetInt32(error, error.GetDescriptor()->FindFieldByName("error_code")),
            static_cast<int>(grpc::StatusCode::NOT_FOUND));
}

// A tempokey-server child with the bearer token "reflection-token" and `flags`.
std::unique_ptr<ServerProcess> StartWithToken(const std::vector<std::string>& flags) {
  const std::string dir = MakeTempDir();
  EXPECT_TRUE(core::WriteFileAtomically(dir + "/tokens", "reflection-token\n").ok());
  std::vector<std::string> all = {"--auth_token_file", dir + "/tokens"};
  all.insert(all.end(), flags.begin(), flags.end());
  absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(dir, all);
  EXPECT_TRUE(server.ok()) << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

TEST(ReflectionAccessTest, WithTokensReflectionNeedsOneLikeEveryMotionServiceCall) {
  std::unique_ptr<ServerProcess> server = StartWithToken({});
  ASSERT_NE(server, nullptr);
  ReflectionClient client(Connect(server->target()));
  grpc::Status anonymous;
  grpc::Status wrong;

  const std::unique_ptr<Message> refused = client.Ask("list_services", "", "", &anonymous);
  client.Ask("list_services", "", "guessed-token", &wrong);
  const std::unique_ptr<Message> listed = client.Ask("list_services", "", "reflection-token");
  // Health stays open: probes carry no token.
  const absl::StatusOr<int> live = CheckHealth(Connect(server->target()), "");

  EXPECT_EQ(refused, nullptr);
  EXPECT_THAT(anonymous, GrpcStatusIs(grpc::StatusCode::UNAUTHENTICATED,
                                      "missing \"authorization: Bearer <token>\" metadata"));
  EXPECT_THAT(wrong, GrpcStatusIs(grpc::StatusCode::UNAUTHENTICATED,
                                  "the bearer token is not accepted"));
  EXPECT_NE(listed, nullptr);
  ASSERT_TRUE(live.ok()) << live.status();
  EXPECT_EQ(*live, 1);
}

TEST(ReflectionAccessTest, OpenReflectionServesCallersWithoutAToken) {
  std::unique_ptr<ServerProcess> server = StartWithToken({"--open_reflection"});
  ASSERT_NE(server, nullptr);
  ReflectionClient client(Connect(server->target()));

  const std::unique_ptr<Message> listed = client.Ask("list_services", "");

  EXPECT_NE(listed, nullptr);
}

}  // namespace
}  // namespace tempokey::testing
