"""PEM certificates and keys checked before gRPC sees them (private), as the CLI and the server
check theirs (proto/pem_check.h), with the same messages, naming connect()'s arguments.

grpcio (1.51, Debian 12) takes any bytes: a key or empty bytes as root_certificates, an
encrypted key or another certificate's key made a channel whose every call failed with
UNAVAILABLE "empty address list", naming neither the argument nor the problem; empty bytes as
certificate_chain or private_key aborted the process (an assertion in ssl_credentials.cc).

Only the standard library's ssl module (the same OpenSSL) parses them. A key is read by
SSLContext.load_cert_chain() from anonymous in-memory files (memfd_create; a private temporary
folder, always removed, where there are none), with a passphrase callback that refuses:
OpenSSL's default one would prompt on the terminal (load_cert_chain(), also used by the TLS
probe of _tls_diagnosis).
"""

import contextlib
import os
import re
import ssl
import tempfile
from typing import Iterator, List, Optional

# The first PEM certificate, as OpenSSL's PEM_read_bio_X509() (the C++ check's) finds it among
# other blocks and text: a bundle's comment lines may hold UTF-8 names, which cadata refuses.
_CERTIFICATE = re.compile(rb"-----BEGIN CERTIFICATE-----.*?-----END CERTIFICATE-----", re.DOTALL)

# OpenSSL's reasons for a key that is not the certificate's: another key of the same type
# (X509_check_private_key), or a key of another type, which OpenSSL 3 files beside a
# certificate slot left empty (SSL_CTX_check_private_key).
_MISMATCH_REASONS = frozenset({"KEY_VALUES_MISMATCH", "KEY_TYPE_MISMATCH",
                               "NO_CERTIFICATE_ASSIGNED"})


class _EncryptedKey(Exception):
    """Raised by the passphrase callback: OpenSSL asks for one only for an encrypted key."""


def _no_passphrase() -> bytes:
    raise _EncryptedKey()


def _first_certificate(pem: bytes) -> Optional[bytes]:
    """The first PEM certificate of `pem` if it parses, else None."""
    found = _CERTIFICATE.search(pem)
    if found is None or not found.group().isascii():
        return None
    try:
        ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT).load_verify_locations(
            cadata=found.group().decode("ascii"))
    except ssl.SSLError:
        return None
    return found.group() + b"\n"


def _write_private(path: str, data: bytes) -> None:
    with open(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600), "wb") as stream:
        stream.write(data)


@contextlib.contextmanager
def _memory_files(*contents: bytes) -> Iterator[List[str]]:
    """Paths of anonymous in-memory files holding `contents` (Linux memfd_create(2), opened by
    name through /proc/self/fd), closed on exit: a private key never reaches a disk. Raises
    OSError where there are none (another system, no /proc)."""
    descriptors: List[int] = []
    try:
        for number, data in enumerate(contents):
            descriptor = os.memfd_create("tempokey-pem-%d" % number, os.MFD_CLOEXEC)
            descriptors.append(descriptor)
            os.write(descriptor, data)
        paths = ["/proc/self/fd/%d" % d for d in descriptors]
        if not all(os.path.exists(path) for path in paths):
            raise OSError("no /proc/self/fd")
        yield paths
    finally:
        for descriptor in descriptors:
            os.close(descriptor)


@contextlib.contextmanager
def _private_files(*contents: bytes) -> Iterator[List[str]]:
    """Paths of files holding `contents` that only this process reads, gone on exit: in memory
    where the system has memfd_create, else in a private temporary folder (mode 0600 files)."""
    with contextlib.ExitStack() as stack:
        try:
            paths = stack.enter_context(_memory_files(*contents))
        except (AttributeError, OSError):  # no os.memfd_create, no /proc
            folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="tempokey-pem-"))
            paths = [os.path.join(folder, "%d.pem" % n) for n in range(len(contents))]
            for path, data in zip(paths, contents):
                _write_private(path, data)
        yield paths


def load_cert_chain(context: ssl.SSLContext, chain_pem: bytes, key_pem: bytes) -> None:
    """Loads a certificate chain and its private key, PEM bytes, into `context` through private
    files (SSLContext.load_cert_chain() reads only files; _private_files), gone before it
    returns. No passphrase is ever asked for.

    Raises: ssl.SSLError as load_cert_chain(); _EncryptedKey for an encrypted key.
    """
    with _private_files(chain_pem, key_pem) as (cert_path, key_path):
        context.load_cert_chain(cert_path, key_path, password=_no_passphrase)


def check_certificates(what: str, pem: bytes) -> None:
    """Returns when `pem` holds a PEM certificate that parses (its first one); `what` names it.

    Raises: ValueError "<what>: holds no PEM certificate".
    """
    if _first_certificate(pem) is None:
        raise ValueError("%s: holds no PEM certificate" % what)


def check_key_pair(cert_what: str, cert_pem: bytes, key_what: str, key_pem: bytes) -> None:
    """Returns when the first certificate of `cert_pem` parses, `key_pem` holds an unencrypted
    PEM private key (no passphrase is ever asked for) and the key is the certificate's.

    Raises: ValueError "<cert_what>: holds no PEM certificate", "<key_what>: the key is
    encrypted, ...", "<key_what>: holds no PEM private key", "<key_what> is not the private key
    of the certificate in <cert_what>", or "<cert_what> and <key_what>: OpenSSL refuses them:
    <its reason>" (a certificate whose key is too small for the system's security level).
    """
    certificate = _first_certificate(cert_pem)
    if certificate is None:
        raise ValueError("%s: holds no PEM certificate" % cert_what)
    try:
        load_cert_chain(ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT), certificate, key_pem)
    except _EncryptedKey:
        raise ValueError(
            "%s: the key is encrypted, and gRPC takes an unencrypted PEM key (decrypt it, "
            "e.g. openssl pkey -in KEY -out PLAIN.pem, and let only its user read it)"
            % key_what) from None
    except ssl.SSLError as error:
        if error.reason in _MISMATCH_REASONS:
            raise ValueError("%s is not the private key of the certificate in %s"
                             % (key_what, cert_what)) from None
        if error.reason is None:  # "PEM lib": SSL_CTX_use_PrivateKey_file() read no key
            raise ValueError("%s: holds no PEM private key" % key_what) from None
        reason = error.reason.lower().replace("_", " ")  # EE_KEY_TOO_SMALL, ...
        raise ValueError("%s and %s: OpenSSL refuses them: %s"
                         % (cert_what, key_what, reason)) from None
