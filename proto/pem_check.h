// PEM certificates and keys checked before gRPC sees them, by the server (its TLS flags) and the
// CLI (its --ca, --cert and --key): gRPC reports a bad file only as a failed bind or a channel
// with "empty address list", and OpenSSL's defaults would prompt for a passphrase.
#ifndef TEMPOKEY_PROTO_PEM_CHECK_H_
#define TEMPOKEY_PROTO_PEM_CHECK_H_

#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"

namespace tempokey::wire {

// OK when `pem` holds at least one PEM certificate. `what` names it in the error ("--ca
// roots.pem"). Errors: kInvalidArgument "<what>: holds no PEM certificate".
absl::Status CheckPemCertificates(std::string_view what, const std::string& pem);

// OK when the first certificate of `cert_pem` parses, `key_pem` holds an unencrypted private key
// (no passphrase is ever asked for), and the key is the certificate's. `cert_what` and
// `key_what` name them ("--tls_cert server.pem"). Errors: kInvalidArgument "<cert_what>: holds no
// PEM certificate", "<key_what>: the key is encrypted, ...", "<key_what>: holds no PEM private
// key", "<key_what> is not the private key of the certificate in <cert_what>".
absl::Status CheckPemKeyPair(std::string_view cert_what, const std::string& cert_pem,
                             std::string_view key_what, const std::string& key_pem);

// What makes every standard client refuse the first certificate of `cert_pem` as a server's
// (RFC 5280: its validity period, 4.1.2.5; an extended key usage without serverAuth, 4.2.1.12):
// "the certificate has expired", "the certificate is not valid yet", "its extended key usage
// lacks serverAuth". Empty when none applies, or when it does not parse.
std::vector<std::string> ServerCertificateProblems(const std::string& cert_pem);

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_PEM_CHECK_H_
