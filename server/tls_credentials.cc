// The server's TLS credentials (tls_credentials.h).
#include "server/tls_credentials.h"

#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>

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

using Bio = std::unique_ptr<BIO, decltype(&BIO_free)>;
using Certificate = std::unique_ptr<X509, decltype(&X509_free)>;

Bio BioOf(const std::string& pem) {
  return Bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())), &BIO_free);
}

absl::StatusOr<std::string> ReadPem(std::string_view flag, const std::string& path) {
  absl::StatusOr<std::string> pem = core::ReadFile(path, 1 << 20);
  if (!pem.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("--", core::AsAbsl(flag), " ", path, ": ",
                                                   pem.status().message()));
  }
  return pem;
}

// Warns of what makes every standard client refuse the server's certificate (RFC 5280: its
// validity period, 4.1.2.5; an extended key usage without serverAuth, 4.2.1.12).
void WarnAboutServerCertificate(const std::string& path, X509* cert) {
  if (X509_cmp_current_time(X509_get0_notAfter(cert)) < 0) {
    spdlog::warn("--tls_cert {}: the certificate has expired; clients will refuse it", path);
  }
  if (X509_cmp_current_time(X509_get0_notBefore(cert)) > 0) {
    spdlog::warn("--tls_cert {}: the certificate is not valid yet; clients will refuse it", path);
  }
  if ((X509_get_extension_flags(cert) & EXFLAG_XKUSAGE) != 0 &&
      (X509_get_extended_key_usage(cert) & XKU_SSL_SERVER) == 0) {
    spdlog::warn("--tls_cert {}: its extended key usage lacks serverAuth; clients will refuse "
                 "it", path);
  }
}

// The certificate and key parse and belong together (wire::CheckPemKeyPair()); then what would
// make clients refuse the certificate is warned of.
absl::Status CheckKeyPair(const ServerOptions& o, const std::string& cert_pem,
                          const std::string& key_pem) {
  TEMPOKEY_RETURN_IF_ERROR(wire::CheckPemKeyPair(absl::StrCat("--tls_cert ", o.tls_cert_file),
                                                 cert_pem,
                                                 absl::StrCat("--tls_key ", o.tls_key_file),
                                                 key_pem));
  Bio bio = BioOf(cert_pem);
  const Certificate cert(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr), &X509_free);
  ERR_clear_error();
  if (cert != nullptr) WarnAboutServerCertificate(o.tls_cert_file, cert.get());
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
