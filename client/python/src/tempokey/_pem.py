"""PEM certificates and keys checked before gRPC sees them (private), as the CLI and the server
check theirs (proto/pem_check.h), with the same messages, naming connect()'s arguments.

grpcio (1.51, Debian 12) takes any bytes: a key or empty bytes as root_certificates, an
encrypted key or another certificate's key made a channel whose every call failed with
UNAVAILABLE "empty address list", naming neither the argument nor the problem; empty bytes as
certificate_chain or private_key aborted the process (an assertion in ssl_credentials.cc).

Only the standard library's ssl module (the same OpenSSL) parses them. A key is read by
SSLContext.load_cert_chain() from files in a private temporary folder, always removed, with a
passphrase callback that refuses: OpenSSL's default one would prompt on the terminal.
"""

import os
import re
import ssl
import tempfile
from typing import Optional

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
    with tempfile.TemporaryDirectory(prefix="tempokey-pem-") as folder:
        cert_path = os.path.join(folder, "certificate.pem")
        key_path = os.path.join(folder, "key.pem")
        _write_private(cert_path, certificate)
        _write_private(key_path, key_pem)
        try:
            ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT).load_cert_chain(cert_path, key_path,
                                                                    password=_no_passphrase)
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
