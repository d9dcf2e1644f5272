// Why a connection to a server failed, when gRPC's own text does not say ("Socket closed", "Ssl
// handshake failed: ... certificate verify failed"): the client probes the server itself with
// OpenSSL, the way its channel would connect, and says what it found in one sentence.
//
// The probe only opens a TCP connection and runs a TLS handshake (SNI, ALPN "h2", the client's
// roots and certificate); it never sends a request, a token or any application data.
#ifndef TEMPOKEY_CLIENT_TLS_DIAGNOSIS_H_
#define TEMPOKEY_CLIENT_TLS_DIAGNOSIS_H_

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "client/client.h"

namespace tempokey::client {

// One host and TCP port to probe.
struct ProbeAddress {
  std::string host;  // a name or an address literal, IPv6 without brackets
  int port = 0;      // 1..65535
};

// The single host:port a gRPC target names: "host:port", "dns:///host:port", "dns:host:port",
// "ipv4:ADDR:PORT", "ipv6:[ADDR]:PORT", "[v6]:port". nullopt for anything else: address lists,
// unix sockets, other schemes, a DNS authority, a missing or bad port.
std::optional<ProbeAddress> SingleAddressOf(std::string_view target);

// Whether an UNAVAILABLE `message` may come from a failed TLS set-up (a handshake failure, a
// socket closed by the peer), as opposed to causes a probe cannot explain better (no server
// listening, a name that does not resolve, a draining server).
bool MayBeTransportSecurityFailure(std::string_view message);

// What a probe found out about a server. Filled by ProbeTls(), read by ExplainTlsProbe().
struct TlsProbeFindings {
  enum class Handshake {
    kNotReached,  // no TCP connection, or the probe's time ran out
    kCompleted,   // the TLS handshake completed (the server speaks TLS)
    kNotTls,      // the server answered with something that is not TLS
    kFailed,      // the handshake failed otherwise
  };
  Handshake handshake = Handshake::kNotReached;

  // The server's certificate, when the handshake got that far.
  struct Certificate {
    std::string subject;  // "CN=localhost" (RFC 2253)
    std::string issuer;   // "CN=tempokey test CA"
    std::int64_t not_before_unix_seconds = 0;
    std::int64_t not_after_unix_seconds = 0;
    std::vector<std::string> names;  // its DNS and IP subject alternative names
  };
  std::optional<Certificate> certificate;
  // OpenSSL's verification of `certificate` against the client's roots, and OpenSSL's text for
  // its error ("self-signed certificate").
  enum class Verification { kOk, kUntrusted, kExpired, kNotYetValid, kOtherError };
  Verification verification = Verification::kOk;
  std::string verify_error;
  // Whether `certificate` holds the name the client expects (the target's host, or
  // --tls-server-name). Meaningful only with a certificate.
  bool name_matches = true;
  std::string expected_name;

  // The server asked for a client certificate (mutual TLS), naming the CAs it accepts.
  bool client_certificate_requested = false;
  std::vector<std::string> acceptable_client_cas;
  // After a completed handshake in which a client certificate was requested: whether the server
  // then sent data (kAccepted: a gRPC server's HTTP/2 SETTINGS) or closed the connection
  // (kClosed: TLS 1.3 servers refuse a client certificate only after the client's Finished, so
  // the client sees a completed handshake and then a close). kNotChecked: no certificate was
  // requested, or the server said nothing in time.
  enum class AfterHandshake { kNotChecked, kAccepted, kClosed };
  AfterHandshake after_handshake = AfterHandshake::kNotChecked;
};

// Connects to `address` and runs a TLS handshake with the roots, client certificate and server
// name of `options.tls` (whether or not options.tls.enabled: a plaintext client's probe asks
// whether the server speaks TLS). Returns within `timeout` (a slow name lookup is left running
// on a thread of its own). Blocks SIGPIPE in the calling thread while it runs (a server closing
// the connection must not end the process); a SIGPIPE raised meanwhile is discarded.
TlsProbeFindings ProbeTls(const ProbeAddress& address, const ClientOptions& options,
                          std::chrono::milliseconds timeout);

// The flag values behind ClientOptions::tls, to name the files in an explanation.
struct TlsFlagFiles {
  std::string ca;    // --ca FILE, or empty
  std::string cert;  // --cert FILE, or empty
};

// One lower-case sentence that explains why a client with `tls` cannot talk to the server the
// probe found, e.g. "the server does not speak TLS: connect without --tls, --ca, --cert and
// --key"; empty when the findings explain nothing. Pure.
std::string ExplainTlsProbe(const TlsProbeFindings& findings, const TlsOptions& tls,
                            const TlsFlagFiles& files);

// The longest a probe may take, whatever the client's own deadline.
inline constexpr std::chrono::seconds kMaxTlsProbeTime{10};

// The explanation of a call that failed UNAVAILABLE with `message`: probes the server of
// `options.target` (a single host:port only) when the message may come from TLS set-up, within
// `options.timeout_seconds` (when > 0) and kMaxTlsProbeTime. Empty when there is nothing to add.
std::string DiagnoseConnectionFailure(const ClientOptions& options, const TlsFlagFiles& files,
                                      std::string_view message);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_TLS_DIAGNOSIS_H_
