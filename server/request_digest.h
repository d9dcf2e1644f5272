// A digest of a whole request message, the same for equal messages however they were encoded
// (map entries in any order): what makes a reused request_id with a different request visible.
#ifndef TEMPOKEY_SERVER_REQUEST_DIGEST_H_
#define TEMPOKEY_SERVER_REQUEST_DIGEST_H_

#include <string>

#include "google/protobuf/message.h"

namespace tempokey::server {

// SHA-256 (hex) of the deterministic serialization of `message`, streamed (no copy of it).
std::string RequestDigest(const google::protobuf::Message& message);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_REQUEST_DIGEST_H_
