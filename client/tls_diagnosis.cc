// Probing a server to explain a failed connection (tls_diagnosis.h).
#include "client/tls_diagnosis.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <future>
#include <memory>
#include <system_error>
#include <thread>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/time/time.h"
#include "proto/loopback.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;
using Clock = std::chrono::steady_clock;
using Findings = TlsProbeFindings;

// ---- targets ------------------------------------------------------------------------------------

// `text` without `prefix` when it starts with it (case-insensitive, as URI schemes are).
bool ConsumePrefix(std::string_view& text, std::string_view prefix) {
  if (!absl::StartsWithIgnoreCase(AsAbsl(text), AsAbsl(prefix))) return false;
  text.remove_prefix(prefix.size());
  return true;
}

// "host:port" or "[v6]:port", and nothing else.
std::optional<ProbeAddress> HostAndPort(std::string_view text) {
  std::string_view port;
  if (text.starts_with('[')) {
    const std::size_t close = text.find(']');
    if (close == std::string_view::npos || text.substr(close).rfind("]:", 0) != 0) return {};
    port = text.substr(close + 2);
  } else {
    const std::size_t colon = text.find(':');
    if (colon == std::string_view::npos || text.rfind(':') != colon) return {};
    port = text.substr(colon + 1);
  }
  ProbeAddress address{.host = wire::HostOf(text)};
  if (address.host.empty() || port.empty() || port.size() > 5 ||
      !std::all_of(port.begin(), port.end(), [](char c) { return absl::ascii_isdigit(c); })) {
    return {};
  }
  address.port = std::stoi(std::string(port));
  if (address.port < 1 || address.port > 65535) return {};
  return address;
}

bool IsIpLiteral(const std::string& host) {
  unsigned char bytes[sizeof(in6_addr)];
  return inet_pton(AF_INET, host.c_str(), bytes) == 1 || inet_pton(AF_INET6, host.c_str(), bytes) == 1;
}

// ---- sockets ------------------------------------------------------------------------------------

class FileDescriptor {
 public:
  explicit FileDescriptor(int fd = -1) : fd_(fd) {}
  ~FileDescriptor() {
    if (fd_ >= 0) close(fd_);
  }
  FileDescriptor(FileDescriptor&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  FileDescriptor& operator=(FileDescriptor&& other) noexcept {
    std::swap(fd_, other.fd_);
    return *this;
  }
  int get() const { return fd_; }

 private:
  int fd_;
};

// Waits until `fd` is ready for `events` (or has an error for the next call to find); false when
// `deadline` passes first.
bool WaitUntilReady(int fd, short events, Clock::time_point deadline) {
  while (true) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    if (left <= 0) return false;
    pollfd entry{.fd = fd, .events = events, .revents = 0};
    const int ready = poll(&entry, 1, static_cast<int>(std::min<long long>(left, INT_MAX)));
    if (ready > 0) return true;
    if (ready == 0 || errno != EINTR) return false;
  }
}

struct Endpoint {
  sockaddr_storage address{};
  socklen_t length = 0;
};

std::vector<Endpoint> ResolveNow(const std::string& host, int port, int flags) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_NUMERICSERV | flags;
  addrinfo* list = nullptr;
  std::vector<Endpoint> endpoints;
  if (getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &list) != 0) return endpoints;
  for (const addrinfo* entry = list; entry != nullptr; entry = entry->ai_next) {
    Endpoint endpoint;
    std::memcpy(&endpoint.address, entry->ai_addr, entry->ai_addrlen);
    endpoint.length = entry->ai_addrlen;
    endpoints.push_back(endpoint);
  }
  freeaddrinfo(list);
  return endpoints;
}

// A name goes to the resolver on a thread of its own, left behind if the deadline passes: the
// system resolver's own time-outs (several tries of seconds each) could outlast the probe's.
std::vector<Endpoint> Resolve(const ProbeAddress& address, Clock::time_point deadline) {
  if (IsIpLiteral(address.host)) return ResolveNow(address.host, address.port, AI_NUMERICHOST);
  auto result = std::make_shared<std::promise<std::vector<Endpoint>>>();
  std::future<std::vector<Endpoint>> endpoints = result->get_future();
  try {
    std::thread([result, host = address.host, port = address.port] {
      result->set_value(ResolveNow(host, port, 0));
    }).detach();
  } catch (const std::system_error&) {
    return {};  // no thread to spare (a process limit): no probe, the error line as gRPC wrote it
  }
  if (endpoints.wait_until(deadline) != std::future_status::ready) return {};
  return endpoints.get();
}

// A non-blocking TCP connection to the first endpoint that accepts one before `deadline`.
FileDescriptor ConnectTcp(const std::vector<Endpoint>& endpoints, Clock::time_point deadline) {
  for (const Endpoint& endpoint : endpoints) {
    FileDescriptor socket_fd(socket(endpoint.address.ss_family,
                                    SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
    if (socket_fd.get() < 0) continue;
    if (connect(socket_fd.get(), reinterpret_cast<const sockaddr*>(&endpoint.address),
                endpoint.length) == 0) {
      return socket_fd;
    }
    if (errno != EINPROGRESS || !WaitUntilReady(socket_fd.get(), POLLOUT, deadline)) continue;
    int error = 0;
    socklen_t size = sizeof(error);
    if (getsockopt(socket_fd.get(), SOL_SOCKET, SO_ERROR, &error, &size) == 0 && error == 0) {
      return socket_fd;
    }
  }
  return FileDescriptor();
}

// OpenSSL writes with write(2), which raises SIGPIPE on a connection the server has closed and
// would end the CLI. SIGPIPE stays blocked in this thread while the probe runs; one raised
// meanwhile is taken off the pending set before the old mask returns.
class ScopedSigpipeBlock {
 public:
  ScopedSigpipeBlock() {
    sigemptyset(&sigpipe_);
    sigaddset(&sigpipe_, SIGPIPE);
    sigset_t pending;
    sigemptyset(&pending);
    was_pending_ = sigpending(&pending) == 0 && sigismember(&pending, SIGPIPE) == 1;
    pthread_sigmask(SIG_BLOCK, &sigpipe_, &old_mask_);
  }
  ~ScopedSigpipeBlock() {
    sigset_t pending;
    sigemptyset(&pending);
    if (!was_pending_ && sigpending(&pending) == 0 && sigismember(&pending, SIGPIPE) == 1) {
      const timespec no_wait{};
      sigtimedwait(&sigpipe_, nullptr, &no_wait);
    }
    pthread_sigmask(SIG_SETMASK, &old_mask_, nullptr);
  }
  ScopedSigpipeBlock(const ScopedSigpipeBlock&) = delete;
  ScopedSigpipeBlock& operator=(const ScopedSigpipeBlock&) = delete;

 private:
  sigset_t sigpipe_;
  sigset_t old_mask_;
  bool was_pending_ = false;
};

// ---- OpenSSL ------------------------------------------------------------------------------------

using Bio = std::unique_ptr<BIO, decltype(&BIO_free)>;
using SslContext = std::unique_ptr<SSL_CTX, decltype(&SSL_CTX_free)>;
using Ssl = std::unique_ptr<SSL, decltype(&SSL_free)>;
using Certificate = std::unique_ptr<X509, decltype(&X509_free)>;
using PrivateKey = std::unique_ptr<EVP_PKEY, decltype(&EVP_PKEY_free)>;

Bio BioOf(const std::string& pem) {
  return Bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())), &BIO_free);
}

// Never a passphrase prompt (proto/pem_check.cc refused encrypted keys already).
int NoPassphrase(char*, int, int, void*) { return 0; }

// The roots the client's channel uses: --ca's certificates, else the system's.
// Without --ca, gRPC 1.51 takes the file GRPC_DEFAULT_SSL_ROOTS_FILE_PATH names, else the
// system's roots (/etc/ssl/certs/ca-certificates.crt on Debian, which OpenSSL's default paths
// also reach): the probe takes the same.
bool LoadRoots(SSL_CTX* context, const std::string& root_ca_pem) {
  if (root_ca_pem.empty()) {
    const char* roots_file = std::getenv("GRPC_DEFAULT_SSL_ROOTS_FILE_PATH");
    if (roots_file != nullptr && *roots_file != '\0') {
      return SSL_CTX_load_verify_locations(context, roots_file, nullptr) == 1;
    }
    return SSL_CTX_set_default_verify_paths(context) == 1;
  }
  X509_STORE* store = SSL_CTX_get_cert_store(context);
  Bio bio = BioOf(root_ca_pem);
  int added = 0;
  while (X509* root = PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr)) {
    if (X509_STORE_add_cert(store, root) == 1) ++added;
    X509_free(root);
  }
  return added > 0;
}

bool LoadClientCertificate(SSL_CTX* context, const TlsOptions& tls) {
  if (tls.cert_chain_pem.empty()) return true;
  Bio chain = BioOf(tls.cert_chain_pem);
  const Certificate leaf(PEM_read_bio_X509(chain.get(), nullptr, NoPassphrase, nullptr),
                         &X509_free);
  if (leaf == nullptr || SSL_CTX_use_certificate(context, leaf.get()) != 1) return false;
  while (X509* intermediate = PEM_read_bio_X509(chain.get(), nullptr, NoPassphrase, nullptr)) {
    if (SSL_CTX_add0_chain_cert(context, intermediate) != 1) X509_free(intermediate);
  }
  Bio key_bio = BioOf(tls.private_key_pem);
  const PrivateKey key(PEM_read_bio_PrivateKey(key_bio.get(), nullptr, NoPassphrase, nullptr),
                       &EVP_PKEY_free);
  return key != nullptr && SSL_CTX_use_PrivateKey(context, key.get()) == 1;
}

// OpenSSL calls the certificate callback of a client when the server's CertificateRequest
// arrives, whether or not a certificate is set ("It is always called even if a certificate is
// already set", SSL_CTX_set_cert_cb(3): https://docs.openssl.org/3.0/man3/SSL_CTX_set_cert_cb/;
// tls_prepare_client_certificate() in
// https://github.com/openssl/openssl/blob/master/ssl/statem/statem_clnt.c).
int NoteCertificateRequest(SSL*, void* requested) {
  *static_cast<bool*>(requested) = true;
  return 1;
}

std::string NameText(const X509_NAME* name) {
  Bio bio(BIO_new(BIO_s_mem()), &BIO_free);
  if (bio == nullptr || X509_NAME_print_ex(bio.get(), name, 0, XN_FLAG_RFC2253) < 0) return "";
  char* data = nullptr;
  const long size = BIO_get_mem_data(bio.get(), &data);
  return size > 0 ? std::string(data, static_cast<std::size_t>(size)) : std::string();
}

std::int64_t UnixSeconds(const ASN1_TIME* time) {
  std::tm fields{};
  if (time == nullptr || ASN1_TIME_to_tm(time, &fields) != 1) return 0;
  return static_cast<std::int64_t>(timegm(&fields));
}

std::vector<std::string> SubjectAltNames(X509* certificate) {
  std::vector<std::string> names;
  auto* general_names = static_cast<GENERAL_NAMES*>(
      X509_get_ext_d2i(certificate, NID_subject_alt_name, nullptr, nullptr));
  if (general_names == nullptr) return names;
  for (int i = 0; i < sk_GENERAL_NAME_num(general_names); ++i) {
    const GENERAL_NAME* name = sk_GENERAL_NAME_value(general_names, i);
    if (name->type == GEN_DNS) {
      const ASN1_STRING* dns = name->d.dNSName;
      names.emplace_back(reinterpret_cast<const char*>(ASN1_STRING_get0_data(dns)),
                         static_cast<std::size_t>(ASN1_STRING_length(dns)));
    } else if (name->type == GEN_IPADD) {
      const ASN1_OCTET_STRING* ip = name->d.iPAddress;
      char text[INET6_ADDRSTRLEN] = {};
      const int family = ASN1_STRING_length(ip) == 4 ? AF_INET : AF_INET6;
      if (inet_ntop(family, ASN1_STRING_get0_data(ip), text, sizeof(text)) != nullptr) {
        names.emplace_back(text);
      }
    }
  }
  GENERAL_NAMES_free(general_names);
  return names;
}

Findings::Verification Classify(long verify_result) {
  switch (verify_result) {
    case X509_V_OK:
      return Findings::Verification::kOk;
    case X509_V_ERR_CERT_HAS_EXPIRED:
      return Findings::Verification::kExpired;
    case X509_V_ERR_CERT_NOT_YET_VALID:
      return Findings::Verification::kNotYetValid;
    case X509_V_ERR_DEPTH_ZERO_SELF_SIGNED_CERT:
    case X509_V_ERR_SELF_SIGNED_CERT_IN_CHAIN:
    case X509_V_ERR_UNABLE_TO_GET_ISSUER_CERT:
    case X509_V_ERR_UNABLE_TO_GET_ISSUER_CERT_LOCALLY:
    case X509_V_ERR_UNABLE_TO_VERIFY_LEAF_SIGNATURE:
    case X509_V_ERR_CERT_UNTRUSTED:
      return Findings::Verification::kUntrusted;
    default:
      return Findings::Verification::kOtherError;
  }
}

// The server's certificate as the handshake left it: described, verified, and checked for the
// name the client expects.
void ReadServerCertificate(SSL* ssl, Findings& findings) {
  const Certificate peer(SSL_get1_peer_certificate(ssl), &X509_free);
  if (peer == nullptr) return;
  findings.certificate = Findings::Certificate{
      .subject = NameText(X509_get_subject_name(peer.get())),
      .issuer = NameText(X509_get_issuer_name(peer.get())),
      .not_before_unix_seconds = UnixSeconds(X509_get0_notBefore(peer.get())),
      .not_after_unix_seconds = UnixSeconds(X509_get0_notAfter(peer.get())),
      .names = SubjectAltNames(peer.get())};
  // With SSL_VERIFY_NONE a client still verifies the server's certificate and keeps the result
  // for SSL_get_verify_result(), but goes on with the handshake whatever it is
  // (SSL_CTX_set_verify(3): "The handshake will be continued regardless of the verification
  // result", https://docs.openssl.org/3.0/man3/SSL_CTX_set_verify/; SSL_get_verify_result(3),
  // https://docs.openssl.org/3.0/man3/SSL_get_verify_result/: X509_V_OK also when no
  // certificate came, hence the peer certificate first).
  const long verify_result = SSL_get_verify_result(ssl);
  findings.verification = Classify(verify_result);
  if (verify_result != X509_V_OK) {
    findings.verify_error = X509_verify_cert_error_string(verify_result);
  }
  const std::string& name = findings.expected_name;
  findings.name_matches =
      IsIpLiteral(name) ? X509_check_ip_asc(peer.get(), name.c_str(), 0) == 1
                        : X509_check_host(peer.get(), name.data(), name.size(), 0, nullptr) == 1;
}

std::vector<std::string> AcceptableClientCas(const SSL* ssl) {
  std::vector<std::string> names;
  const STACK_OF(X509_NAME)* list = SSL_get_client_CA_list(ssl);
  for (int i = 0; list != nullptr && i < sk_X509_NAME_num(list); ++i) {
    names.push_back(NameText(sk_X509_NAME_value(list, i)));
  }
  return names;
}

// Whether an OpenSSL error in the queue says the peer's bytes are not TLS records ("wrong version
// number": a plaintext HTTP/2 server answers a ClientHello with an HTTP/2 frame).
bool PeerIsNotTls() {
  bool not_tls = false;
  while (const unsigned long error = ERR_get_error()) {
    if (ERR_GET_LIB(error) == ERR_LIB_SSL && ERR_GET_REASON(error) == SSL_R_WRONG_VERSION_NUMBER) {
      not_tls = true;
    }
  }
  return not_tls;
}

enum class Progress { kDone, kFailed, kTimedOut };

// Runs the non-blocking `step` (SSL_connect, SSL_read) until it succeeds or fails, waiting on the
// socket as OpenSSL asks, never past `deadline`. On kFailed, sets `*not_tls`.
template <typename Step>
Progress Drive(SSL* ssl, int fd, Clock::time_point deadline, Step step, bool* not_tls) {
  while (true) {
    ERR_clear_error();
    const int result = step();
    if (result > 0) return Progress::kDone;
    const int error = SSL_get_error(ssl, result);
    if (error != SSL_ERROR_WANT_READ && error != SSL_ERROR_WANT_WRITE) {
      *not_tls = PeerIsNotTls();
      return Progress::kFailed;
    }
    if (!WaitUntilReady(fd, error == SSL_ERROR_WANT_READ ? POLLIN : POLLOUT, deadline)) {
      return Progress::kTimedOut;
    }
  }
}

// The probe itself; the caller clears OpenSSL's error queue.
Findings Probe(const ProbeAddress& address, const ClientOptions& options,
               Clock::time_point deadline) {
  Findings findings;
  findings.expected_name =
      options.tls.target_name_override.empty() ? address.host : options.tls.target_name_override;

  SslContext context(SSL_CTX_new(TLS_client_method()), &SSL_CTX_free);
  if (context == nullptr) return findings;
  SSL_CTX_set_default_passwd_cb(context.get(), NoPassphrase);
  SSL_CTX_set_verify(context.get(), SSL_VERIFY_NONE, nullptr);
  bool certificate_requested = false;
  SSL_CTX_set_cert_cb(context.get(), NoteCertificateRequest, &certificate_requested);
  if (!LoadRoots(context.get(), options.tls.root_ca_pem) ||
      !LoadClientCertificate(context.get(), options.tls)) {
    return findings;
  }

  const FileDescriptor socket_fd = ConnectTcp(Resolve(address, deadline), deadline);
  if (socket_fd.get() < 0) return findings;
  Ssl ssl(SSL_new(context.get()), &SSL_free);
  if (ssl == nullptr || SSL_set_fd(ssl.get(), socket_fd.get()) != 1) return findings;
  // As a gRPC client asks: HTTP/2 by ALPN (a gRPC server closes the connection of a peer without
  // it, grpc_ssl_check_alpn() in https://github.com/grpc/grpc/blob/v1.51.1/src/core/lib/security/
  // security_connector/ssl_utils.cc, and the probe would read that as a refused certificate), the
  // name as SNI unless it is an address literal (RFC 6066 3 allows only host names there).
  static constexpr unsigned char kAlpnH2[] = {2, 'h', '2'};
  SSL_set_alpn_protos(ssl.get(), kAlpnH2, sizeof(kAlpnH2));
  if (!IsIpLiteral(findings.expected_name)) {
    SSL_set_tlsext_host_name(ssl.get(), findings.expected_name.c_str());
  }

  bool not_tls = false;
  const Progress handshake = Drive(
      ssl.get(), socket_fd.get(), deadline, [&] { return SSL_connect(ssl.get()); }, &not_tls);
  findings.client_certificate_requested = certificate_requested;
  findings.acceptable_client_cas = AcceptableClientCas(ssl.get());
  if (handshake == Progress::kTimedOut) return findings;
  if (handshake == Progress::kFailed) {
    findings.handshake = not_tls ? Findings::Handshake::kNotTls : Findings::Handshake::kFailed;
    return findings;
  }
  findings.handshake = Findings::Handshake::kCompleted;
  ReadServerCertificate(ssl.get(), findings);
  if (!certificate_requested) return findings;

  // A TLS 1.3 server checks a client's certificate after the client's Finished: the client's
  // handshake has completed by then, and a refusal shows only on the next read (openssl/openssl
  // #8500 and #11118: https://github.com/openssl/openssl/issues/8500,
  // https://github.com/openssl/openssl/issues/11118). A gRPC server that refuses it closes the
  // connection without an alert; one that accepts it sends its HTTP/2 SETTINGS. Nothing is
  // written here.
  char byte = 0;
  const Progress read = Drive(
      ssl.get(), socket_fd.get(), deadline, [&] { return SSL_read(ssl.get(), &byte, 1); },
      &not_tls);
  if (read == Progress::kDone) findings.after_handshake = Findings::AfterHandshake::kAccepted;
  if (read == Progress::kFailed) findings.after_handshake = Findings::AfterHandshake::kClosed;
  return findings;
}

// ---- explanations -------------------------------------------------------------------------------

std::string Day(std::int64_t unix_seconds) {
  return absl::FormatTime("%Y-%m-%d", absl::FromUnixSeconds(unix_seconds), absl::UTCTimeZone());
}

std::string Minute(std::int64_t unix_seconds) {
  return absl::FormatTime("%Y-%m-%d %H:%M UTC", absl::FromUnixSeconds(unix_seconds),
                          absl::UTCTimeZone());
}

// "the server's certificate (CN=localhost, issued by CN=tempokey test CA[, valid D to D])".
std::string CertificateNamed(const Findings::Certificate& certificate, bool with_validity) {
  std::string text = absl::StrCat("the server's certificate (", certificate.subject,
                                  ", issued by ", certificate.issuer);
  if (with_validity) {
    absl::StrAppend(&text, ", valid ", Day(certificate.not_before_unix_seconds), " to ",
                    Day(certificate.not_after_unix_seconds));
  }
  return absl::StrCat(text, ")");
}

std::string CertificateProblem(const Findings& findings, const TlsOptions& tls,
                               const TlsFlagFiles& files) {
  const Findings::Certificate& certificate = *findings.certificate;
  switch (findings.verification) {
    case Findings::Verification::kOk:
      break;
    case Findings::Verification::kExpired:
      return absl::StrCat(CertificateNamed(certificate, false), " expired on ",
                          Minute(certificate.not_after_unix_seconds));
    case Findings::Verification::kNotYetValid:
      return absl::StrCat(CertificateNamed(certificate, false), " is not valid before ",
                          Minute(certificate.not_before_unix_seconds));
    case Findings::Verification::kUntrusted: {
      const std::string roots = !files.ca.empty()            ? absl::StrCat("--ca ", files.ca)
                                : !tls.root_ca_pem.empty() ? std::string("the given roots")
                                                           : std::string("the system's roots");
      return absl::StrCat(CertificateNamed(certificate, true), " is not signed by a CA in ", roots,
                          " (OpenSSL: ", findings.verify_error, ")");
    }
    case Findings::Verification::kOtherError:
      return absl::StrCat(CertificateNamed(certificate, true),
                          " fails verification (OpenSSL: ", findings.verify_error, ")");
  }
  if (!findings.name_matches) {
    return absl::StrCat(CertificateNamed(certificate, false),
                        certificate.names.empty()
                            ? " holds no DNS or IP name (subject alternative name)"
                            : absl::StrCat(" holds the names ", absl::StrJoin(certificate.names, ", ")),
                        ", not ", findings.expected_name,
                        ": connect by a name it holds, or give the one it was issued for with "
                        "--tls-server-name NAME");
  }
  return "";
}

std::string ClientCertificateProblem(const Findings& findings, const TlsOptions& tls,
                                     const TlsFlagFiles& files) {
  const bool refused = findings.after_handshake == Findings::AfterHandshake::kClosed ||
                       findings.handshake == Findings::Handshake::kFailed;
  if (!findings.client_certificate_requested || !refused) return "";
  if (tls.cert_chain_pem.empty()) {
    return "the server requires a client certificate (mutual TLS): pass --cert FILE and --key FILE";
  }
  std::string text = absl::StrCat(
      findings.handshake == Findings::Handshake::kFailed
          ? "the server refused the handshake"
          : "the server closed the connection after the handshake",
      ": it does not accept the client certificate",
      files.cert.empty() ? "" : absl::StrCat(" in --cert ", files.cert));
  if (!findings.acceptable_client_cas.empty()) {
    absl::StrAppend(&text, " (it asks for certificates from: ",
                    absl::StrJoin(findings.acceptable_client_cas, " or "), ")");
  }
  return text;
}

}  // namespace

std::optional<ProbeAddress> SingleAddressOf(std::string_view target) {
  if (target.find(',') != std::string_view::npos) return {};
  if (ConsumePrefix(target, "dns:")) {
    if (ConsumePrefix(target, "//") && !ConsumePrefix(target, "/")) return {};  // an authority
  } else if (!ConsumePrefix(target, "ipv4:") && !ConsumePrefix(target, "ipv6:")) {
    // Other schemes: unix:, unix-abstract:, vsock:, xds:///, ...
    for (const std::string_view scheme : {"unix:", "unix-abstract:", "vsock:"}) {
      if (absl::StartsWithIgnoreCase(AsAbsl(target), AsAbsl(scheme))) return {};
    }
    if (target.find("://") != std::string_view::npos) return {};
  }
  return HostAndPort(target);
}

bool MayBeTransportSecurityFailure(std::string_view message) {
  // gRPC 1.51's own texts for a connection whose set-up failed (its "last error" of "connections
  // to all backends failing"), matched as gRPC writes them: words like "tls" or "certificate"
  // anywhere (a file name, a server's message) are not a sign.
  for (const std::string_view sign :
       {"Ssl handshake failed", "Socket closed", "Peer name ", "certificate verify failed",
        "wrong version number", "Connection reset by peer", "End of TCP stream",
        "Handshake read failed", "Handshake write failed"}) {
    if (absl::StrContains(AsAbsl(message), AsAbsl(sign))) return true;
  }
  return false;
}

TlsProbeFindings ProbeTls(const ProbeAddress& address, const ClientOptions& options,
                          std::chrono::milliseconds timeout) {
  const ScopedSigpipeBlock no_sigpipe;
  ERR_clear_error();
  TlsProbeFindings findings = Probe(address, options, Clock::now() + timeout);
  ERR_clear_error();
  return findings;
}

std::string ExplainTlsProbe(const TlsProbeFindings& findings, const TlsOptions& tls,
                            const TlsFlagFiles& files) {
  if (!tls.enabled) {
    return findings.handshake == Findings::Handshake::kCompleted
               ? "the server speaks TLS: connect with --tls (and --ca FILE if a private CA signed "
                 "its certificate)"
               : "";
  }
  if (findings.handshake == Findings::Handshake::kNotTls) {
    return "the server does not speak TLS: connect without --tls, --ca, --cert and --key";
  }
  if (findings.certificate) {
    if (std::string problem = CertificateProblem(findings, tls, files); !problem.empty()) {
      return problem;
    }
  }
  return ClientCertificateProblem(findings, tls, files);
}

std::string DiagnoseConnectionFailure(const ClientOptions& options, const TlsFlagFiles& files,
                                      std::string_view message) {
  if (!MayBeTransportSecurityFailure(message)) return "";
  const std::optional<ProbeAddress> address = SingleAddressOf(options.target);
  if (!address) return "";
  std::chrono::milliseconds timeout = kMaxTlsProbeTime;
  if (options.timeout_seconds > 0) {
    timeout = std::min(timeout, std::chrono::milliseconds(
                                    std::llround(options.timeout_seconds * 1000.0)));
  }
  return ExplainTlsProbe(ProbeTls(*address, options, timeout), options.tls, files);
}

}  // namespace tempokey::client
