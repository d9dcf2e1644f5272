#include "server/request_digest.h"

#include <openssl/evp.h>

#include <array>

#include "absl/strings/str_cat.h"
#include "google/protobuf/io/coded_stream.h"
#include "google/protobuf/io/zero_copy_stream.h"

namespace tempokey::server {
namespace {

// Feeds whatever the serializer writes to SHA-256, a buffer at a time.
class DigestStream final : public google::protobuf::io::ZeroCopyOutputStream {
 public:
  DigestStream() : ctx_(EVP_MD_CTX_new()) { EVP_DigestInit_ex(ctx_, EVP_sha256(), nullptr); }
  ~DigestStream() override { EVP_MD_CTX_free(ctx_); }

  bool Next(void** data, int* size) override {
    Flush();
    pending_ = static_cast<int>(buffer_.size());
    *data = buffer_.data();
    *size = pending_;
    return true;
  }
  void BackUp(int count) override { pending_ -= count; }
  std::int64_t ByteCount() const override { return total_ + pending_; }

  std::string Finish() {
    Flush();
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int length = 0;
    EVP_DigestFinal_ex(ctx_, digest, &length);
    std::string hex;
    for (unsigned int i = 0; i < length; ++i) absl::StrAppend(&hex, absl::Hex(digest[i], absl::kZeroPad2));
    return hex;
  }

 private:
  void Flush() {
    if (pending_ > 0) EVP_DigestUpdate(ctx_, buffer_.data(), static_cast<std::size_t>(pending_));
    total_ += pending_;
    pending_ = 0;
  }

  EVP_MD_CTX* ctx_;
  std::array<char, 1 << 16> buffer_;
  int pending_ = 0;
  std::int64_t total_ = 0;
};

}  // namespace

std::string RequestDigest(const google::protobuf::Message& message) {
  DigestStream stream;
  {
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    message.SerializeToCodedStream(&coded);
  }  // the coded stream backs up what it did not use when it goes
  return stream.Finish();
}

}  // namespace tempokey::server
