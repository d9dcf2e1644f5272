// Plain HTTP/1.1 over a loopback socket for the metrics endpoint (no client library of ours in
// between), and the sample lines of a Prometheus text exposition.
#ifndef TEMPOKEY_TESTS_SERVER_HTTP_UTIL_H_
#define TEMPOKEY_TESTS_SERVER_HTTP_UTIL_H_

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"

namespace tempokey::testing {

// A TCP connection to 127.0.0.1:`port` whose reads give up after 60 s (a hang guard); -1 on
// failure. The caller closes it.
inline int ConnectLoopback(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return -1;
  timeval timeout{.tv_sec = 60, .tv_usec = 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// Everything the peer sends until it closes the connection (or the hang guard fires, or the
// connection is reset); `closed_by_peer`, when given, says whether it ended with the peer's close.
inline std::string ReadToEnd(int fd, bool* closed_by_peer = nullptr) {
  std::string response;
  char buffer[8192];
  ssize_t n = 0;
  while ((n = ::recv(fd, buffer, sizeof buffer, 0)) > 0) {
    response.append(buffer, static_cast<std::size_t>(n));
  }
  if (closed_by_peer != nullptr) *closed_by_peer = n == 0;
  return response;
}

// How an exchange on a new connection ended: the bytes read, whether it connected, whether every
// byte sent was taken (false: the peer reset the connection while they went), and whether the
// answer ended with the peer's close (false: a reset, or the 60 s hang guard).
struct ExchangeEnding {
  std::string answer;
  bool connected = false;
  bool all_sent = false;
  bool closed = false;
};

// Sends `bytes` on a new connection to 127.0.0.1:`port`, then reads until the peer closes it.
inline ExchangeEnding ExchangeWithEnding(int port, const std::string& bytes) {
  ExchangeEnding ending;
  const int fd = ConnectLoopback(port);
  if (fd < 0) return ending;
  ending.connected = true;
  ending.all_sent =
      ::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(bytes.size());
  ending.answer = ReadToEnd(fd, &ending.closed);
  ::close(fd);
  return ending;
}

// Sends `bytes` on a new connection to 127.0.0.1:`port` and reads everything until the peer
// closes it (or the hang guard fires); nullopt when it cannot connect or send.
inline std::optional<std::string> Exchange(int port, const std::string& bytes) {
  ExchangeEnding ending = ExchangeWithEnding(port, bytes);
  if (!ending.all_sent) return std::nullopt;
  return std::move(ending.answer);
}

// GET `path` from 127.0.0.1:`port` with the extra header lines `headers` ("Name: value\r\n"
// each); the whole response, headers included.
inline std::optional<std::string> HttpGet(int port, const std::string& path,
                                          const std::string& headers = "") {
  return Exchange(port, "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\n" + headers +
                            "Connection: close\r\n\r\n");
}

// Sample lines of a Prometheus text exposition: "name{labels}" -> value.
inline std::map<std::string, double> ParseSamples(const std::string& text) {
  std::map<std::string, double> samples;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    if (line.empty() || line.front() == '#') continue;
    const std::size_t space = line.rfind(' ');
    if (space == absl::string_view::npos) continue;
    double value = 0.0;
    if (absl::SimpleAtod(line.substr(space + 1), &value)) {
      samples[std::string(line.substr(0, space))] = value;
    }
  }
  return samples;
}

inline double Sample(const std::map<std::string, double>& samples, const std::string& name) {
  const auto it = samples.find(name);
  return it == samples.end() ? 0.0 : it->second;
}

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_SERVER_HTTP_UTIL_H_
