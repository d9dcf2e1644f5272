// The server's TLS credentials (tls_credentials.h).
#include "server/tls_credentials.h"

#include <memory>
#include <string>
#include <string_view>

#include "absl/strings/str_cat.h"
#include "proto/pem_check.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

absl::StatusOr<std::string> ReadPem(std::string_view flag, const std::string& path) {
  absl::StatusOr<std::string> pem = core::ReadFile(path, 1 << 20);
  if (!pem.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("--", core::AsAbsl(flag), " ", path, ": ",
                                                   pem.status().message()));
  }
  return pem;
}

// The certificate and key parse and belong together (wire::CheckPemKeyPair()); then what would
// make clients refuse the certificate is warned of.
absl::Status CheckKeyPair(const ServerOptions& o, const std::string& cert_pem,
                          const std::string& key_pem) {
  TEMPOKEY_RETURN_IF_ERROR(wire::CheckPemKeyPair(absl::StrCat("--tls_cert ", o.tls_cert_file),
                                                 cert_pem,
                                                 absl::StrCat("--tls_key ", o.tls_key_file),
                                                 key_pem));
  for (const std::string& problem : wire::ServerCertificateProblems(cert_pem)) {
    spdlog::warn("--tls_cert {}: {}; clients will refuse it", o.tls_cert_file, problem);
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> BuildCredentials(const ServerOptions& o) {
  if (o.tls_cert_file.empty()) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions ssl(o.tls_client_ca_file.empty()
                                            ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
                                            : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
  TEMPOKEY_ASSIGN_OR_RETURN(pair.cert_chain, ReadPem("tls_cert", o.tls_cert_file));
  TEMPOKEY_ASSIGN_OR_RETURN(pair.private_key, ReadPem("tls_key", o.tls_key_file));
  TEMPOKEY_RETURN_IF_ERROR(CheckKeyPair(o, pair.cert_chain, pair.private_key));
  ssl.pem_key_cert_pairs.push_back(std::move(pair));
  if (!o.tls_client_ca_file.empty()) {
    TEMPOKEY_ASSIGN_OR_RETURN(ssl.pem_root_certs, ReadPem("tls_client_ca", o.tls_client_ca_file));
    // An empty CA file made gRPC refuse every client, and garbage failed the bind.
    TEMPOKEY_RETURN_IF_ERROR(wire::CheckPemCertificates(
        absl::StrCat("--tls_client_ca ", o.tls_client_ca_file), ssl.pem_root_certs));
  }
  return grpc::SslServerCredentials(ssl);
}

}  // namespace tempokey::server
