// The socket of one HTTP connection. civetweb 1.15 hands its handlers a connection without its
// descriptor; the peer's address and port it reports, with the front end's port, name the one
// socket of this process that carries it.
#ifndef TEMPOKEY_SERVER_HTTP_CONNECTION_SOCKET_H_
#define TEMPOKEY_SERVER_HTTP_CONNECTION_SOCKET_H_

#include <string>

namespace tempokey::server::http {

// The descriptor of this process's socket connected from `remote_address`:`remote_port` (IPv4,
// as civetweb reports it) to `local_port`, found among /proc/self/fd. -1 when there is none (the
// connection is gone already) or more than one (with the front end on 0.0.0.0 one peer may reach
// two local addresses: which is meant cannot be told). Descriptors duplicated from one socket
// count once. The descriptor stays its owner's: use it only while the connection is held.
int FindConnectionSocket(int local_port, const std::string& remote_address, int remote_port);

// True once the peer of connected socket `socket` has closed its side or the connection has
// failed (a shutdown, a reset). Data waiting to be read is not a departure. Does not block.
bool PeerHasLeft(int socket);

// Ends the connection of `socket` at once, keeping the descriptor (its owner, civetweb, still
// closes it): connect() to AF_UNSPEC, which on Linux resets a TCP connection (tcp_disconnect()).
// A shutdown is not enough: on Linux data keeps arriving on a socket shut both ways, and
// civetweb, which reads what is left of a request's body after its handler, read it for as long
// as the peer sent it. Reads of the socket then fail; what the peer has received already (an
// answer and its FIN) stays readable on its side. Thread-safe, async-signal-safe.
void AbortConnection(int socket);

}  // namespace tempokey::server::http

#endif  // TEMPOKEY_SERVER_HTTP_CONNECTION_SOCKET_H_
