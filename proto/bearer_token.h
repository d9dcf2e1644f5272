// What a bearer token may hold: the rule the server's token file, the C++ client library, the
// CLI and the Python package (client.py, _check_token) share.
#ifndef TEMPOKEY_PROTO_BEARER_TOKEN_H_
#define TEMPOKEY_PROTO_BEARER_TOKEN_H_

#include <string_view>

#include "absl/status/status.h"

namespace tempokey::wire {

// OK when `token` can travel as "authorization: Bearer <token>": printable ASCII (0x20-0x7e), as
// an HTTP/2 header value must be (RFC 9113 8.2.1; gRPC aborts the process on a call whose
// metadata holds anything else), spaces inside allowed as the server's token file allows them,
// none at either end (every reader trims them, so such a token could never match). Otherwise
// InvalidArgument naming the first byte at fault by position and value, never the token itself
// (it is a secret). Empty is OK here: callers decide whether no token is allowed.
absl::Status CheckBearerToken(std::string_view token);

// The text of a token file without a UTF-8 byte order mark at its start (editors write one; it
// is no part of the first token). A view into `text`.
std::string_view TokenFileText(std::string_view text);

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_BEARER_TOKEN_H_
