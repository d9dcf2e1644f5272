// The server's gRPC credentials from its TLS flags (--tls_cert, --tls_key, --tls_client_ca),
// checked before gRPC sees them: gRPC only fails the bind, with no reason a user can act on
// ("address in use or invalid?"), and OpenSSL's defaults would prompt for a passphrase.
#ifndef TEMPOKEY_SERVER_TLS_CREDENTIALS_H_
#define TEMPOKEY_SERVER_TLS_CREDENTIALS_H_

#include <memory>

#include "absl/status/statusor.h"
#include "grpcpp/security/server_credentials.h"
#include "server/server_options.h"

namespace tempokey::server {

// Insecure credentials without --tls_cert; otherwise TLS with the certificate chain and key,
// requiring client certificates signed by --tls_client_ca when it is given. Logs a warning for a
// certificate no standard client accepts (expired, not yet valid, an extended key usage without
// serverAuth): the server still starts, as an operator may be replacing it.
// Errors (kInvalidArgument, naming the flag and file): a file that cannot be read; no PEM
// certificate in --tls_cert or --tls_client_ca; no PEM key in --tls_key, or an encrypted one
// (gRPC takes unencrypted keys; no passphrase is ever asked for); a key that is not the
// certificate's.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> BuildCredentials(
    const ServerOptions& options);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_TLS_CREDENTIALS_H_
