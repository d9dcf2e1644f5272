"""Why a connection to a server failed, when gRPC's own text does not say (private): a call of a
connect()ed Client that fails UNAVAILABLE with "Socket closed" or "Ssl handshake failed: ...
certificate verify failed" gets one sentence of what a probe of the server found, worded with
connect()'s arguments, as the C++ CLI does (client/tls_diagnosis.h).

The probe only opens TCP connections and runs TLS handshakes with the standard library's ssl
module, the way grpcio connects (SNI, ALPN "h2", the same roots and client certificate); it never
sends a request, a token or any application data. Everything runs within one deadline, min(the
call's timeout, MAX_PROBE_SECONDS); a slow name lookup is left running on a thread of its own.

What the ssl module does not expose, and the sentences therefore leave out or infer:
  - whether the server asked for a client certificate and from which CAs (OpenSSL's certificate
    callback and client CA list): a TLS 1.3 server checks a client certificate after the
    client's handshake has completed and refuses it by closing the connection, so a close right
    after a handshake whose server certificate verified is read as that refusal (a gRPC server
    that accepts the connection sends its HTTP/2 SETTINGS at once);
  - the server certificate's fields when it fails verification (getpeercert() then gives only
    DER): _describe() reads subject, issuer, validity and alternative names from the DER itself.
"""

import dataclasses
import datetime
import enum
import ipaddress
import os
import pkgutil
import socket
import ssl
import threading
import time
from typing import List, NamedTuple, Optional, Tuple

from tempokey import _pem

# The longest a probe may take, whatever the call's own timeout.
MAX_PROBE_SECONDS = 10.0


class ChannelSettings(NamedTuple):
    """What connect() made the channel with, for a probe that connects the same way."""
    target: str
    tls: bool
    root_certificates: Optional[bytes]
    certificate_chain: Optional[bytes]
    private_key: Optional[bytes]
    target_name_override: Optional[str]


# ---- targets ------------------------------------------------------------------------------------

def _host_and_port(text: str) -> Optional[Tuple[str, int]]:
    """"host:port" or "[v6]:port", and nothing else."""
    if text.startswith("["):
        close = text.find("]")
        if close < 0 or not text.startswith("]:", close):
            return None
        host, port = text[1:close], text[close + 2:]
    elif text.count(":") == 1:
        host, port = text.split(":")
    else:
        return None
    if not host or not 1 <= len(port) <= 5 or not (port.isascii() and port.isdigit()):
        return None
    return (host, int(port)) if 1 <= int(port) <= 65535 else None


def single_address_of(target: str) -> Optional[Tuple[str, int]]:
    """The one (host, port) a gRPC target names: "host:port", "dns:///host:port",
    "dns:host:port", "ipv4:ADDR:PORT", "ipv6:[ADDR]:PORT", "[v6]:port" (IPv6 hosts without
    brackets). None for anything else: address lists, unix sockets, other schemes, a DNS
    authority, a missing or bad port. As the C++ client's SingleAddressOf()."""
    if "," in target:
        return None
    lower = target.lower()
    if lower.startswith("dns:"):
        target = target[4:]
        if target.startswith("//"):
            if not target.startswith("///"):
                return None  # an authority: dns://8.8.8.8/name:443
            target = target[3:]
    elif lower.startswith(("ipv4:", "ipv6:")):
        target = target[5:]
    elif lower.startswith(("unix:", "unix-abstract:", "vsock:")) or "://" in target:
        return None
    return _host_and_port(target)


def may_be_transport_security_failure(message: str) -> bool:
    """Whether an UNAVAILABLE `message` may come from a failed TLS set-up (a handshake failure, a
    socket closed by the peer), as opposed to what a probe cannot explain better (no server
    listening, a name that does not resolve, a draining server)."""
    lower = message.lower()
    return any(sign in lower for sign in (
        "handshake", "ssl", "tls", "certificate", "peer name", "socket closed",
        "connection reset", "end of tcp stream", "broken pipe"))


# ---- what a probe finds -------------------------------------------------------------------------

class Handshake(enum.Enum):
    NOT_REACHED = "not reached"  # no TCP connection, or the probe's time ran out
    COMPLETED = "completed"      # the TLS handshake completed: the server speaks TLS
    NOT_TLS = "not TLS"          # the server answered with something that is not TLS
    FAILED = "failed"            # the handshake failed otherwise


class AfterHandshake(enum.Enum):
    NOT_CHECKED = "not checked"  # not read, or the server said nothing in time
    ACCEPTED = "accepted"        # the server sent data (a gRPC server's HTTP/2 SETTINGS)
    CLOSED = "closed"            # the server closed the connection


class Certificate(NamedTuple):
    subject: str  # "CN=localhost" (RFC 2253, as OpenSSL prints it)
    issuer: str
    not_before: datetime.datetime  # UTC
    not_after: datetime.datetime
    names: List[str]  # its DNS and IP subject alternative names


@dataclasses.dataclass
class Findings:
    """What a probe found out about a server; defaults say nothing is wrong."""
    expected_name: str  # the name the certificate must hold: target_name_override, or the host
    handshake: Handshake = Handshake.NOT_REACHED
    alert: Optional[str] = None  # OpenSSL's reason for the handshake's failure, or the close's
    certificate: Optional[Certificate] = None  # the server's, when the handshake got that far
    # OpenSSL's verification of the certificate against the client's roots: X509_V_* code and
    # text ("self-signed certificate"); 0 when it passed or was not checked.
    verify_code: int = 0
    verify_message: str = ""
    name_matches: bool = True
    after_handshake: AfterHandshake = AfterHandshake.NOT_CHECKED


# X509_V_ERR_* codes of OpenSSL's verification (openssl/x509_vfy.h).
_NOT_YET_VALID = 9
_EXPIRED = 10
_UNTRUSTED = frozenset({2, 18, 19, 20, 21, 27})  # no trusted issuer, self-signed, untrusted
_NAME_MISMATCH = frozenset({62, 64})  # X509_V_ERR_HOSTNAME_MISMATCH, _IP_ADDRESS_MISMATCH

# Alerts a server sends about the client's certificate (ssl.SSLError.reason); the probe's own
# handshake verifies nothing (CERT_NONE), so it never sends them itself.
_CLIENT_CERTIFICATE_ALERTS = frozenset({
    "TLSV13_ALERT_CERTIFICATE_REQUIRED", "SSLV3_ALERT_BAD_CERTIFICATE",
    "SSLV3_ALERT_UNSUPPORTED_CERTIFICATE", "SSLV3_ALERT_CERTIFICATE_REVOKED",
    "SSLV3_ALERT_CERTIFICATE_EXPIRED", "SSLV3_ALERT_CERTIFICATE_UNKNOWN",
    "TLSV1_ALERT_UNKNOWN_CA"})


# ---- the certificate, from DER ------------------------------------------------------------------
# X.509 (RFC 5280 4.1) read as far as the explanation needs, because the ssl module decodes a
# peer certificate only once it verified. Any malformation gives no description (None).

_ATTRIBUTE_NAMES = {  # OpenSSL's short names of the usual name attributes
    "2.5.4.3": "CN", "2.5.4.4": "SN", "2.5.4.5": "serialNumber", "2.5.4.6": "C", "2.5.4.7": "L",
    "2.5.4.8": "ST", "2.5.4.9": "street", "2.5.4.10": "O", "2.5.4.11": "OU", "2.5.4.12": "title",
    "2.5.4.17": "postalCode", "2.5.4.42": "GN", "2.5.4.46": "dnQualifier",
    "0.9.2342.19200300.100.1.1": "UID", "0.9.2342.19200300.100.1.25": "DC",
    "1.2.840.113549.1.9.1": "emailAddress"}
_STRING_CODECS = {0x0C: "utf-8", 0x12: "ascii", 0x13: "ascii", 0x14: "latin-1", 0x16: "ascii",
                  0x1A: "ascii", 0x1C: "utf-32-be", 0x1E: "utf-16-be"}
_SUBJECT_ALT_NAME = "2.5.29.17"


def _element(data: bytes, pos: int, end: int) -> Tuple[int, int, int]:
    """The tag, content start and content end of the DER element at `pos` (before `end`)."""
    if pos + 2 > end:
        raise ValueError("truncated element")
    tag, length, pos = data[pos], data[pos + 1], pos + 2
    if length & 0x80:
        count = length & 0x7F
        if not 1 <= count <= 4 or pos + count > end:
            raise ValueError("bad length")
        length, pos = int.from_bytes(data[pos:pos + count], "big"), pos + count
    if pos + length > end:
        raise ValueError("truncated content")
    return tag, pos, pos + length


def _children(data: bytes, start: int, end: int) -> List[Tuple[int, int, int]]:
    found = []
    while start < end:
        found.append(_element(data, start, end))
        start = found[-1][2]
    return found


def _oid(body: bytes) -> str:
    numbers, value = [], 0
    for byte in body:
        value = (value << 7) | (byte & 0x7F)
        if not byte & 0x80:
            numbers.append(value)
            value = 0
    first = min(numbers[0] // 40, 2)
    return ".".join(str(n) for n in [first, numbers[0] - 40 * first] + numbers[1:])


def _escape(value: str) -> str:
    """An attribute value as OpenSSL's RFC 2253 printing escapes it (XN_FLAG_RFC2253)."""
    data = value.encode("utf-8")
    out = []
    for index, byte in enumerate(data):
        char = chr(byte)
        if byte < 0x20 or byte >= 0x7F:
            out.append("\\%02X" % byte)
        elif (char in ',+"\\<>;' or (char == "#" and index == 0)
              or (char == " " and index in (0, len(data) - 1))):
            out.append("\\" + char)
        else:
            out.append(char)
    return "".join(out)


def _name(data: bytes, start: int, end: int) -> str:
    """A Name as RFC 2253 text: its last RDN first, "," between RDNs, "+" within one."""
    rdns = []
    for _, rdn_start, rdn_end in _children(data, start, end):
        parts = []
        for _, pair_start, pair_end in _children(data, rdn_start, rdn_end):
            (_, oid_start, oid_end), (tag, value_start, value_end) = _children(
                data, pair_start, pair_end)[:2]
            oid = _oid(data[oid_start:oid_end])
            if oid in _ATTRIBUTE_NAMES and tag in _STRING_CODECS:
                value = _escape(data[value_start:value_end].decode(_STRING_CODECS[tag]))
                parts.append("%s=%s" % (_ATTRIBUTE_NAMES[oid], value))
            else:  # OpenSSL's form for others: the dotted OID, the value's DER in hex
                parts.append("%s=#%s" % (oid, data[oid_end:value_end].hex().upper()))
        rdns.append("+".join(parts))
    return ",".join(reversed(rdns))


def _time(tag: int, body: bytes) -> datetime.datetime:
    text = body.decode("ascii")
    if tag == 0x17:  # UTCTime: YYMMDDHHMMSSZ, years 50..99 are 19xx (RFC 5280 4.1.2.5.1)
        text = ("19" if int(text[:2]) >= 50 else "20") + text
    return datetime.datetime.strptime(text, "%Y%m%d%H%M%SZ").replace(
        tzinfo=datetime.timezone.utc)


def _alternative_names(data: bytes, start: int, end: int) -> List[str]:
    """The DNS names and IP addresses of the subjectAltName among the extensions."""
    names: List[str] = []
    (_, start, end), = _children(data, start, end)  # [3] { SEQUENCE OF Extension }
    for _, ext_start, ext_end in _children(data, start, end):
        fields = _children(data, ext_start, ext_end)
        if _oid(data[fields[0][1]:fields[0][2]]) != _SUBJECT_ALT_NAME:
            continue
        _, value_start, value_end = fields[-1]  # OCTET STRING { GeneralNames }
        (_, list_start, list_end), = _children(data, value_start, value_end)
        for tag, name_start, name_end in _children(data, list_start, list_end):
            body = data[name_start:name_end]
            if tag == 0x82:  # [2] dNSName
                names.append(body.decode("ascii"))
            elif tag == 0x87 and len(body) in (4, 16):  # [7] iPAddress
                family = socket.AF_INET if len(body) == 4 else socket.AF_INET6
                names.append(socket.inet_ntop(family, body))
    return names


def _describe(der: Optional[bytes]) -> Optional[Certificate]:
    """Subject, issuer, validity and alternative names of a DER certificate; None if it cannot
    be read."""
    if not der:
        return None
    try:
        _, start, end = _element(der, 0, len(der))  # Certificate
        _, tbs_start, tbs_end = _element(der, start, end)  # TBSCertificate
        fields = _children(der, tbs_start, tbs_end)
        if fields[0][0] == 0xA0:  # [0] version
            fields = fields[1:]
        issuer, validity, subject = fields[2], fields[3], fields[4]
        (before_tag, b_start, b_end), (after_tag, a_start, a_end) = _children(
            der, validity[1], validity[2])
        extensions = [f for f in fields[6:] if f[0] == 0xA3]
        return Certificate(
            subject=_name(der, subject[1], subject[2]), issuer=_name(der, issuer[1], issuer[2]),
            not_before=_time(before_tag, der[b_start:b_end]),
            not_after=_time(after_tag, der[a_start:a_end]),
            names=_alternative_names(der, extensions[0][1], extensions[0][2]) if extensions
            else [])
    except (ValueError, IndexError):  # malformed DER, text that does not decode
        return None


# ---- the probe ----------------------------------------------------------------------------------

class _Stop(Exception):
    """The probe cannot go on: its time ran out, or the server no longer takes connections."""


def _left(deadline: float) -> float:
    """Seconds until `deadline`, for a socket timeout; _Stop once it has passed."""
    left = deadline - time.monotonic()
    if left <= 0:
        raise _Stop()
    return left


def _is_ip_literal(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


def _resolve(host: str, port: int, deadline: float) -> list:
    """getaddrinfo() entries of host:port. A name goes to the resolver on a thread of its own,
    left behind if the deadline passes: the system resolver's own time-outs (several tries of
    seconds each) could outlast the probe's."""
    if _is_ip_literal(host):
        return socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                  flags=socket.AI_NUMERICHOST | socket.AI_NUMERICSERV)
    found: list = []

    def look_up() -> None:
        try:
            found.extend(socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                            flags=socket.AI_NUMERICSERV))
        except OSError:
            pass

    lookup = threading.Thread(target=look_up, name="tempokey-tls-probe-lookup", daemon=True)
    lookup.start()
    lookup.join(_left(deadline))
    if lookup.is_alive():
        raise _Stop()
    return found


def _connect(endpoints: list, deadline: float) -> socket.socket:
    """A TCP connection to the first endpoint that accepts one before `deadline`."""
    for family, kind, protocol, _, address in endpoints:
        connection = socket.socket(family, kind, protocol)
        try:
            connection.settimeout(_left(deadline))
            connection.connect(address)
            return connection
        except OSError:
            connection.close()
        except _Stop:
            connection.close()
            raise
    raise _Stop()


def _default_roots() -> Optional[str]:
    """The roots grpcio's channel trusts without root_certificates: the file named by
    GRPC_DEFAULT_SSL_ROOTS_FILE_PATH, else the roots.pem grpcio ships and hands to gRPC core
    (ssl_roots_override_callback in grpc/_cython/_cygrpc/security.pyx.pxi; core's order in
    DefaultSslRootStore::ComputePemRootCerts(), src/core/lib/security/security_connector/
    ssl_utils.cc). None: neither could be read (the system's roots stand in)."""
    path = os.environ.get("GRPC_DEFAULT_SSL_ROOTS_FILE_PATH")
    try:
        if path:
            with open(path, "rb") as stream:
                pem = stream.read()
        else:
            pem = pkgutil.get_data("grpc._cython", "_credentials/roots.pem") or b""
    except (OSError, ImportError):
        return None
    return _certificates(pem)


def _certificates(pem: bytes) -> Optional[str]:
    """The PEM certificates of `pem` as cadata takes them (ASCII only: bundles may carry UTF-8
    comments), or None when it holds none."""
    blocks = [b for b in _pem._CERTIFICATE.findall(pem) if b.isascii()]
    return b"\n".join(blocks).decode("ascii") if blocks else None


def _context(settings: ChannelSettings, verify: bool) -> ssl.SSLContext:
    """A client context as grpcio's: ALPN "h2" (a gRPC server closes the connection of a peer
    without it, grpc_ssl_check_alpn() in src/core/lib/security/security_connector/ssl_utils.cc,
    which would read as a refused client certificate). Without `verify`: no verification and the
    client's certificate, to complete the handshake whatever the server's certificate is; with
    it: the client's roots, the name unchecked (check_hostname, which the caller may set)."""
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    context.set_alpn_protocols(["h2"])
    context.check_hostname = False
    if not verify:
        context.verify_mode = ssl.CERT_NONE
        if settings.certificate_chain and settings.private_key:
            _pem.load_cert_chain(context, settings.certificate_chain, settings.private_key)
        return context
    roots = (_certificates(settings.root_certificates) if settings.root_certificates
             else _default_roots())
    if roots:
        context.load_verify_locations(cadata=roots)
    else:
        context.load_default_certs()
    return context


def _handshake(context: ssl.SSLContext, endpoints: list, server_name: str,
               deadline: float) -> ssl.SSLSocket:
    """A TLS connection over a new TCP one. Raises ssl.SSLError, OSError from the handshake,
    _Stop. The name goes as SNI unless it is an address literal (RFC 6066 3 allows only host
    names there; Python then sends none and, checking names, compares the address)."""
    connection = _connect(endpoints, deadline)
    try:
        connection.settimeout(_left(deadline))
        return context.wrap_socket(connection, server_hostname=server_name)
    except BaseException:
        connection.close()
        raise


def _look(endpoints: list, settings: ChannelSettings, findings: Findings,
          deadline: float) -> Optional[ssl.SSLSocket]:
    """The first handshake, verifying nothing: does the server speak TLS, and with which
    certificate? Returns the open connection when it completed."""
    try:
        connection = _handshake(_context(settings, verify=False), endpoints,
                                findings.expected_name, deadline)
    except socket.timeout:  # TimeoutError from Python 3.10 on
        return None  # NOT_REACHED
    except ssl.SSLError as error:
        findings.alert = error.reason
        findings.handshake = (Handshake.NOT_TLS if error.reason == "WRONG_VERSION_NUMBER"
                              else Handshake.FAILED)
        return None
    except OSError:  # reset, closed
        findings.handshake = Handshake.FAILED
        return None
    findings.handshake = Handshake.COMPLETED
    findings.certificate = _describe(connection.getpeercert(binary_form=True))
    return connection


def _verification_error(context: ssl.SSLContext, endpoints: list, server_name: str,
                        deadline: float) -> Optional[ssl.SSLCertVerificationError]:
    """How a handshake with `context` fails verification, or None. Another failure (a refused
    client certificate: the server speaks after the client verified) counts as none."""
    try:
        _handshake(context, endpoints, server_name, deadline).close()
    except ssl.SSLCertVerificationError as error:
        return error
    except socket.timeout:
        raise _Stop() from None
    except OSError:
        pass
    return None


def _verify(endpoints: list, settings: ChannelSettings, findings: Findings,
            deadline: float) -> None:
    """The server's certificate against the client's roots, then against the expected name, in
    handshakes of their own: OpenSSL checks the name before the dates, and an expired
    certificate is to be named expired whatever its names."""
    context = _context(settings, verify=True)  # its roots read once for both handshakes
    error = _verification_error(context, endpoints, findings.expected_name, deadline)
    if error is not None:
        findings.verify_code, findings.verify_message = error.verify_code, error.verify_message
        return
    context.check_hostname = True
    error = _verification_error(context, endpoints, findings.expected_name, deadline)
    findings.name_matches = error is None or error.verify_code not in _NAME_MISMATCH


def _after_handshake(connection: ssl.SSLSocket, findings: Findings,
                     deadline: float) -> AfterHandshake:
    """Whether the server, after the handshake, sent data or closed the connection. Nothing is
    written: recv() only reads (OpenSSL takes the TLS 1.3 session tickets on the way)."""
    try:
        connection.settimeout(_left(deadline))
        data = connection.recv(1)
    except socket.timeout:
        return AfterHandshake.NOT_CHECKED
    except ssl.SSLError as error:
        findings.alert = error.reason
        return AfterHandshake.CLOSED
    except OSError:
        return AfterHandshake.CLOSED
    return AfterHandshake.ACCEPTED if data else AfterHandshake.CLOSED


def probe(host: str, port: int, settings: ChannelSettings, timeout: float) -> Findings:
    """Connects to host:port the way the channel of `settings` does (whether or not
    settings.tls: a plaintext client's probe asks whether the server speaks TLS) and returns
    what it found, within `timeout` seconds."""
    deadline = time.monotonic() + timeout
    findings = Findings(expected_name=settings.target_name_override or host)
    try:
        endpoints = _resolve(host, port, deadline)
        connection = _look(endpoints, settings, findings, deadline)
        if connection is None:
            return findings
        with connection:
            if settings.tls:
                _verify(endpoints, settings, findings, deadline)
            if settings.tls and findings.verify_code == 0 and findings.name_matches:
                findings.after_handshake = _after_handshake(connection, findings, deadline)
    except (_Stop, OSError, ValueError):  # ValueError: a name the ssl module refuses
        pass  # what was found so far
    return findings


# ---- explanations -------------------------------------------------------------------------------

def _named(certificate: Optional[Certificate], with_validity: bool) -> str:
    """"the server's certificate (CN=localhost, issued by CN=CA[, valid D to D])"."""
    if certificate is None:
        return "the server's certificate"
    validity = (", valid %s to %s" % (certificate.not_before.strftime("%Y-%m-%d"),
                                      certificate.not_after.strftime("%Y-%m-%d"))
                if with_validity else "")
    return "the server's certificate (%s, issued by %s%s)" % (
        certificate.subject, certificate.issuer, validity)


def _certificate_problem(findings: Findings, settings: ChannelSettings) -> str:
    certificate = findings.certificate
    code = findings.verify_code
    if code == _EXPIRED and certificate is not None:
        return "%s expired on %s" % (_named(certificate, False),
                                     certificate.not_after.strftime("%Y-%m-%d %H:%M UTC"))
    if code == _NOT_YET_VALID and certificate is not None:
        return "%s is not valid before %s" % (
            _named(certificate, False), certificate.not_before.strftime("%Y-%m-%d %H:%M UTC"))
    if code in _UNTRUSTED:
        roots = "root_certificates" if settings.root_certificates else "grpcio's default roots"
        return "%s is not signed by a CA in %s (OpenSSL: %s)" % (
            _named(certificate, True), roots, findings.verify_message)
    if code != 0:
        return "%s fails verification (OpenSSL: %s)" % (_named(certificate, True),
                                                        findings.verify_message)
    if not findings.name_matches:
        if certificate is None:
            holds = " does not hold the name %s" % findings.expected_name
        elif certificate.names:
            holds = " holds the names %s, not %s" % (", ".join(certificate.names),
                                                     findings.expected_name)
        else:
            holds = (" holds no DNS or IP name (subject alternative name), not %s"
                     % findings.expected_name)
        return ("%s%s: connect by a name it holds, or give the one it was issued for as "
                "target_name_override" % (_named(certificate, False), holds))
    return ""


def _client_certificate_problem(findings: Findings, settings: ChannelSettings) -> str:
    refused_in_handshake = (findings.handshake is Handshake.FAILED
                            and findings.alert in _CLIENT_CERTIFICATE_ALERTS)
    if findings.after_handshake is not AfterHandshake.CLOSED and not refused_in_handshake:
        return ""
    if not settings.certificate_chain:
        return ("the server requires a client certificate (mutual TLS): pass certificate_chain "
                "and private_key")
    return "%s: it does not accept the client certificate in certificate_chain" % (
        "the server refused the handshake" if refused_in_handshake
        else "the server closed the connection after the handshake")


def explain(findings: Findings, settings: ChannelSettings) -> str:
    """One lower-case sentence that explains why a client with `settings` cannot talk to the
    server the probe found, e.g. "the server does not speak TLS: connect without tls=True, ...";
    "" when the findings explain nothing. Pure."""
    if not settings.tls:
        return ("the server speaks TLS: connect with tls=True (and root_certificates if a "
                "private CA signed its certificate)"
                if findings.handshake is Handshake.COMPLETED else "")
    if findings.handshake is Handshake.NOT_TLS:
        return ("the server does not speak TLS: connect without tls=True, root_certificates, "
                "certificate_chain, private_key and target_name_override")
    if findings.handshake is Handshake.COMPLETED:
        problem = _certificate_problem(findings, settings)
        if problem:
            return problem
    return _client_certificate_problem(findings, settings)


def diagnose(settings: ChannelSettings, message: str, timeout: Optional[float]) -> str:
    """The explanation of a call on the channel of `settings` that failed UNAVAILABLE with
    `message`: probes the server of settings.target (a single host:port only) when the message
    may come from TLS set-up, within `timeout` seconds (None: none) and MAX_PROBE_SECONDS.
    "" when there is nothing to add."""
    if not may_be_transport_security_failure(message):
        return ""
    address = single_address_of(settings.target)
    if address is None:
        return ""
    seconds = MAX_PROBE_SECONDS if timeout is None else min(timeout, MAX_PROBE_SECONDS)
    return explain(probe(address[0], address[1], settings, seconds), settings)
