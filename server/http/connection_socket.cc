#include "server/http/connection_socket.h"

#include <arpa/inet.h>
#include <dirent.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <cstdlib>

namespace tempokey::server::http {
namespace {

// The IPv4 address and port of `address` when it is one.
bool Ipv4Of(const sockaddr_storage& address, in_addr* host, int* port) {
  if (address.ss_family != AF_INET) return false;
  const auto* v4 = reinterpret_cast<const sockaddr_in*>(&address);
  *host = v4->sin_addr;
  *port = ntohs(v4->sin_port);
  return true;
}

// Whether descriptor `fd` is a socket from `peer`:`peer_port` to `local_port`.
bool Connects(int fd, int local_port, const in_addr& peer, int peer_port) {
  sockaddr_storage local{};
  sockaddr_storage remote{};
  socklen_t local_size = sizeof local;
  socklen_t remote_size = sizeof remote;
  in_addr local_host{}, remote_host{};
  int local_at = 0, remote_at = 0;
  return getsockname(fd, reinterpret_cast<sockaddr*>(&local), &local_size) == 0 &&
         Ipv4Of(local, &local_host, &local_at) && local_at == local_port &&
         getpeername(fd, reinterpret_cast<sockaddr*>(&remote), &remote_size) == 0 &&
         Ipv4Of(remote, &remote_host, &remote_at) && remote_at == peer_port &&
         remote_host.s_addr == peer.s_addr;
}

}  // namespace

int FindConnectionSocket(int local_port, const std::string& remote_address, int remote_port) {
  in_addr peer{};
  if (inet_pton(AF_INET, remote_address.c_str(), &peer) != 1) return -1;
  DIR* fds = opendir("/proc/self/fd");
  if (fds == nullptr) return -1;
  int found = -1;
  ino_t found_socket = 0;
  bool ambiguous = false;
  while (const dirent* entry = readdir(fds)) {
    char* end = nullptr;
    const long fd = std::strtol(entry->d_name, &end, 10);
    if (end == entry->d_name || *end != '\0') continue;
    if (!Connects(static_cast<int>(fd), local_port, peer, remote_port)) continue;
    // Descriptors duplicated from one socket (civetweb keeps such) are one connection.
    struct stat info {};
    if (fstat(static_cast<int>(fd), &info) != 0) continue;
    if (found >= 0 && info.st_ino != found_socket) ambiguous = true;
    found = static_cast<int>(fd);
    found_socket = info.st_ino;
  }
  closedir(fds);
  return ambiguous ? -1 : found;
}

void AbortConnection(int socket) {
  sockaddr unspecified{};
  unspecified.sa_family = AF_UNSPEC;
  ::connect(socket, &unspecified, sizeof unspecified);
}

bool PeerHasLeft(int socket) {
  // POLLRDHUP: the peer's FIN (a browser tab closed, fetch() aborted, curl stopped); POLLHUP and
  // POLLERR, reported whatever is asked: a reset or both sides shut. POLLIN is not asked, so a
  // request pipelined behind this one is not mistaken for a departure.
  pollfd watched{.fd = socket, .events = POLLRDHUP, .revents = 0};
  return ::poll(&watched, 1, 0) > 0 && (watched.revents & (POLLRDHUP | POLLHUP | POLLERR)) != 0;
}

}  // namespace tempokey::server::http
