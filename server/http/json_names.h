// Repeated member names in a JSON request. protobuf's JSON parser takes the last of a repeated
// name without a word ({"jobId":"a","jobId":"b"} looked up "b"); RFC 8259 4 leaves such an
// object's meaning to the reader, so the front end refuses it instead of guessing.
#ifndef TEMPOKEY_SERVER_HTTP_JSON_NAMES_H_
#define TEMPOKEY_SERVER_HTTP_JSON_NAMES_H_

#include <string_view>

#include "absl/status/status.h"

namespace tempokey::server::http {

// OK unless an object of `json` names a member twice (names compared decoded: "a" and "\u0061"
// are one name); then InvalidArgument "member \"jobId\" is named twice in one object (at byte
// 14)". One pass, memory proportional to the names of the objects open at once. Text that is not
// JSON is not judged here (the parser after it refuses it); objects nested past 64 levels are
// not scanned (the parser refuses them). Thread-safe: a pure function.
absl::Status CheckNoRepeatedNames(std::string_view json);

}  // namespace tempokey::server::http

#endif  // TEMPOKEY_SERVER_HTTP_JSON_NAMES_H_
