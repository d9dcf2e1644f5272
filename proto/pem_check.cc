// PEM certificates and keys (pem_check.h).
#include "proto/pem_check.h"

#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::wire {
namespace {

using Bio = std::unique_ptr<BIO, decltype(&BIO_free)>;
using Certificate = std::unique_ptr<X509, decltype(&X509_free)>;

Bio BioOf(const std::string& pem) {
  return Bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())), &BIO_free);
}

// OpenSSL's default passphrase callback prompts on the terminal or stdin: a server started by a
// supervisor with an encrypted key waited there for ever. No passphrase, ever.
int NoPassphrase(char*, int, int, void*) { return 0; }

// An encrypted PEM key: PKCS#8 "ENCRYPTED PRIVATE KEY", or a traditional key with
// "Proc-Type: 4,ENCRYPTED".
bool IsEncryptedPemKey(const std::string& pem) {
  return pem.find("-----BEGIN ENCRYPTED PRIVATE KEY-----") != std::string::npos ||
         pem.find("Proc-Type: 4,ENCRYPTED") != std::string::npos;
}

}  // namespace

absl::Status CheckPemCertificates(std::string_view what, const std::string& pem) {
  Bio bio = BioOf(pem);
  const Certificate first(PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr),
                          &X509_free);
  ERR_clear_error();
  if (first == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat(core::AsAbsl(what), ": holds no PEM certificate"));
  }
  return absl::OkStatus();
}

absl::Status CheckPemKeyPair(std::string_view cert_what, const std::string& cert_pem,
                             std::string_view key_what, const std::string& key_pem) {
  Bio cert_bio = BioOf(cert_pem);
  const Certificate cert(PEM_read_bio_X509(cert_bio.get(), nullptr, NoPassphrase, nullptr),
                         &X509_free);
  Bio key_bio = BioOf(key_pem);
  const std::unique_ptr<EVP_PKEY, decltype(&EVP_PKEY_free)> key(
      PEM_read_bio_PrivateKey(key_bio.get(), nullptr, NoPassphrase, nullptr), &EVP_PKEY_free);
  const bool matches =
      cert != nullptr && key != nullptr && X509_check_private_key(cert.get(), key.get()) == 1;
  ERR_clear_error();
  if (cert == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat(core::AsAbsl(cert_what), ": holds no PEM certificate"));
  }
  if (key == nullptr && IsEncryptedPemKey(key_pem)) {
    return absl::InvalidArgumentError(absl::StrCat(
        core::AsAbsl(key_what),
        ": the key is encrypted, and gRPC takes an unencrypted PEM key (decrypt it, e.g. "
        "openssl pkey -in KEY -out PLAIN.pem, and let only its user read it)"));
  }
  if (key == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat(core::AsAbsl(key_what), ": holds no PEM private key"));
  }
  if (!matches) {
    return absl::InvalidArgumentError(absl::StrCat(core::AsAbsl(key_what),
                                                   " is not the private key of the certificate in ",
                                                   core::AsAbsl(cert_what)));
  }
  return absl::OkStatus();
}

std::vector<std::string> ServerCertificateProblems(const std::string& cert_pem) {
  Bio bio = BioOf(cert_pem);
  const Certificate cert(PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr),
                         &X509_free);
  ERR_clear_error();
  std::vector<std::string> problems;
  if (cert == nullptr) return problems;
  if (X509_cmp_current_time(X509_get0_notAfter(cert.get())) < 0) {
    problems.push_back("the certificate has expired");
  }
  if (X509_cmp_current_time(X509_get0_notBefore(cert.get())) > 0) {
    problems.push_back("the certificate is not valid yet");
  }
  if ((X509_get_extension_flags(cert.get()) & EXFLAG_XKUSAGE) != 0 &&
      (X509_get_extended_key_usage(cert.get()) & XKU_SSL_SERVER) == 0) {
    problems.push_back("its extended key usage lacks serverAuth");
  }
  return problems;
}

}  // namespace tempokey::wire
