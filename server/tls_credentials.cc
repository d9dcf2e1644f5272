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

// OpenSSL's default passphrase callback prompts on the terminal or stdin: a server started by a
// supervisor with an encrypted key would wait there for ever. No passphrase, ever.
int NoPassphrase(char*, int, int, void*) { return 0; }

// An encrypted PEM key: PKCS#8 "ENCRYPTED PRIVATE KEY", or a traditional key with
// "Proc-Type: 4,ENCRYPTED".
bool IsEncryptedPemKey(const std::string& pem) {
  return pem.find("-----BEGIN ENCRYPTED PRIVATE KEY-----") != std::string::npos ||
         pem.find("Proc-Type: 4,ENCRYPTED") != std::string::npos;
}

// The certificates of `pem`, in order (none when it holds none).
int CountCertificates(const std::string& pem) {
  Bio bio = BioOf(pem);
  int count = 0;
  while (Certificate cert{PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr),
                          &X509_free}) {
    ++count;
  }
  ERR_clear_error();
  return count;
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

// The first certificate of `cert_pem` and the key of `key_pem` parse, and the key is the
// certificate's.
absl::Status CheckKeyPair(const ServerOptions& o, const std::string& cert_pem,
                          const std::string& key_pem) {
  Bio cert_bio = BioOf(cert_pem);
  Certificate cert(PEM_read_bio_X509(cert_bio.get(), nullptr, NoPassphrase, nullptr),
                   &X509_free);
  Bio key_bio = BioOf(key_pem);
  std::unique_ptr<EVP_PKEY, decltype(&EVP_PKEY_free)> key(
      PEM_read_bio_PrivateKey(key_bio.get(), nullptr, NoPassphrase, nullptr), &EVP_PKEY_free);
  const bool matches =
      cert != nullptr && key != nullptr && X509_check_private_key(cert.get(), key.get()) == 1;
  ERR_clear_error();
  if (cert == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat("--tls_cert ", o.tls_cert_file, ": holds no PEM certificate"));
  }
  if (key == nullptr && IsEncryptedPemKey(key_pem)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--tls_key ", o.tls_key_file, ": the key is encrypted, and gRPC takes an unencrypted PEM "
        "key (decrypt it, e.g. openssl pkey -in KEY -out PLAIN.pem, and let only the server read "
        "it)"));
  }
  if (key == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat("--tls_key ", o.tls_key_file, ": holds no PEM private key"));
  }
  if (!matches) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--tls_key ", o.tls_key_file, " is not the private key of the certificate in --tls_cert ",
        o.tls_cert_file));
  }
  WarnAboutServerCertificate(o.tls_cert_file, cert.get());
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
    // An empty or unreadable CA file made gRPC refuse every client, or fail the bind.
    if (CountCertificates(ssl.pem_root_certs) == 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--tls_client_ca ", o.tls_client_ca_file,
          ": holds no PEM certificate (the CAs whose client certificates are accepted)"));
    }
  }
  return grpc::SslServerCredentials(ssl);
}

}  // namespace tempokey::server
