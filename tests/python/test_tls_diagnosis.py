"""A call that fails UNAVAILABLE with gRPC's bare "certificate verify failed", "wrong version
number", "Peer name ... is not in peer certificate" or "Socket closed" says why: the client probes
the server (tempokey/_tls_diagnosis.py) and appends one sentence naming connect()'s arguments, as
the CLI does (tests/client/cli_security_test.cc pins the CLI's sentences for the same cases).

Real tempokey-server processes on 127.0.0.1:0 with certificates made by the openssl
command-line tool; fixed validity dates (`openssl ca -startdate/-enddate`) make the sentences
exact. Run by CTest (label `python`) like test_python_client.py, whose environment it uses.
"""

import os
import subprocess
import unittest

import grpc

import tempokey as tk
from tempokey import _tls_diagnosis

from test_bad_input import OPENSSL, CertificateTestCase
from test_python_client import CALL_TIMEOUT_SECONDS, SUBPROCESS_TIMEOUT_SECONDS, RunningServer

# gRPC's error text is its own; the tests pin what follows it.
EXPLANATION_SEPARATOR = "; "


def run_openssl(folder, *args):
    subprocess.run([OPENSSL] + list(args), cwd=folder, check=True, capture_output=True,
                   stdin=subprocess.DEVNULL, timeout=SUBPROCESS_TIMEOUT_SECONDS)


def make_dated_certificate(folder, name, issuer, start, end):
    """`name`.pem + `name`.key in `folder`: CN=localhost for localhost and 127.0.0.1, valid from
    `start` to `end` (openssl's YYYYMMDDHHMMSSZ), signed by `issuer` (its .pem and .key) or by
    itself when `issuer` is None; `openssl ca` is the OpenSSL 3.0 tool that takes fixed dates."""
    with open(os.path.join(folder, "ca.cnf"), "w", encoding="ascii") as stream:
        stream.write("[ca]\ndefault_ca = test_ca\n[test_ca]\ndatabase = %s/index.txt\n"
                     "new_certs_dir = %s\nserial = %s/serial\ndefault_md = sha256\n"
                     "policy = any_name\nunique_subject = no\n[any_name]\n"
                     "commonName = supplied\n" % (folder, folder, folder))
    open(os.path.join(folder, "index.txt"), "w", encoding="ascii").close()
    with open(os.path.join(folder, "serial"), "w", encoding="ascii") as stream:
        stream.write("1000\n")
    run_openssl(folder, "req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
                "-nodes", "-keyout", name + ".key", "-out", name + ".csr", "-subj", "/CN=localhost")
    signer = (["-selfsign", "-keyfile", name + ".key"] if issuer is None
              else ["-cert", issuer + ".pem", "-keyfile", issuer + ".key"])
    run_openssl(folder, "ca", "-batch", "-notext", "-config", "ca.cnf", "-in", name + ".csr",
                "-out", name + ".pem", "-startdate", start, "-enddate", end, "-extfile",
                "server.ext", *signer)


def make_other_ca_and_its_client(folder):
    """A second CA, "CN=other CA" (other-ca.pem + .key), and a client certificate it signed for
    the key of make_certificates()'s client (stranger.pem, with client.key)."""
    run_openssl(folder, "req", "-x509", "-newkey", "ec", "-pkeyopt",
                "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", "other-ca.key", "-out",
                "other-ca.pem", "-days", "2", "-subj", "/CN=other CA")
    run_openssl(folder, "x509", "-req", "-in", "client.csr", "-CA", "other-ca.pem", "-CAkey",
                "other-ca.key", "-set_serial", "3", "-days", "2", "-out", "stranger.pem",
                "-extfile", "client.ext")


class TlsDiagnosisTest(CertificateTestCase):
    """connect()'s clients against servers they cannot talk to (make_certificates()' ca, server
    with CN=server, client; and those made below)."""

    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        # The probe's own cap (10 s) lifted to the calls' timeout: a loaded machine must not
        # turn a finding into "not reached".
        cls._probe_cap = _tls_diagnosis.MAX_PROBE_SECONDS
        _tls_diagnosis.MAX_PROBE_SECONDS = CALL_TIMEOUT_SECONDS

    @classmethod
    def tearDownClass(cls):
        _tls_diagnosis.MAX_PROBE_SECONDS = cls._probe_cap
        super().tearDownClass()

    @classmethod
    def make_more_certificates(cls, folder):
        make_other_ca_and_its_client(folder)
        make_dated_certificate(folder, "self-signed", None, "20200101000000Z", "20991231235959Z")
        make_dated_certificate(folder, "long-lived", "ca", "20200101000000Z", "20991231235959Z")
        make_dated_certificate(folder, "expired", "ca", "20200101000000Z", "20200201000000Z")

    def tls_server(self, certificate="server", *flags):
        return RunningServer("--tls_cert", self.path(certificate + ".pem"), "--tls_key",
                             self.path(certificate + ".key"), *flags)

    def failure(self, server, call="health", **connect_arguments):
        """The TempokeyError of `call` (health, or watch of a job) from a client of `server`."""
        with tk.connect(server.address, timeout=CALL_TIMEOUT_SECONDS,
                        **connect_arguments) as client:
            with self.assertRaises(tk.TempokeyError) as caught:
                if call == "health":
                    client.health()
                else:
                    client.watch("job-1")
        return caught.exception

    def assertExplainedAs(self, error, explanation):
        self.assertEqual(error.code, grpc.StatusCode.UNAVAILABLE, error.details)
        self.assertTrue(str(error).startswith("UNAVAILABLE: "), str(error))
        self.assertTrue(error.details.endswith(EXPLANATION_SEPARATOR + explanation),
                        "%r\ndoes not end with\n%r" % (error.details, explanation))
        self.assertEqual(error.details.count(EXPLANATION_SEPARATOR + "the server"), 1,
                         error.details)

    # gRPC says "certificate verify failed".
    def test_a_ca_that_did_not_sign_the_server_certificate_is_explained_with_both(self):
        cases = [("self-signed", "CN=localhost", "self-signed certificate"),
                 ("long-lived", "CN=tempokey python test CA",
                  "unable to get local issuer certificate")]

        for certificate, issuer, reason in cases:
            with self.subTest(certificate=certificate):
                with self.tls_server(certificate) as server:
                    error = self.failure(server, tls=True,
                                         root_certificates=self.pem("other-ca.pem"))
                    server.stop()

                self.assertExplainedAs(
                    error, "the server's certificate (CN=localhost, issued by %s, valid "
                           "2020-01-01 to 2099-12-31) is not signed by a CA in root_certificates "
                           "(OpenSSL: %s)" % (issuer, reason))

    def test_an_expired_server_certificate_is_explained_with_its_end_date(self):
        with self.tls_server("expired") as server:
            error = self.failure(server, tls=True, root_certificates=self.pem("ca.pem"))
            server.stop()

        self.assertExplainedAs(error, "the server's certificate (CN=localhost, issued by "
                                      "CN=tempokey python test CA) expired on 2020-02-01 00:00 UTC")

    # gRPC says "wrong version number".
    def test_tls_to_a_plaintext_server_is_explained_as_the_server_not_speaking_tls(self):
        with RunningServer() as server:
            error = self.failure(server, tls=True)
            server.stop()

        self.assertExplainedAs(error, "the server does not speak TLS: connect without tls=True, "
                                      "root_certificates, certificate_chain, private_key and "
                                      "target_name_override")

    # gRPC says "Socket closed"; watch() fails through the client's own retries.
    def test_plaintext_to_a_tls_server_is_explained_as_the_server_speaking_tls(self):
        with self.tls_server() as server:
            unary = self.failure(server)
            streaming = self.failure(server, call="watch")
            server.stop()

        for error in (unary, streaming):
            self.assertExplainedAs(error, "the server speaks TLS: connect with tls=True (and "
                                          "root_certificates if a private CA signed its "
                                          "certificate)")

    # gRPC says "Socket closed": the server sends no alert.
    def test_mutual_tls_without_a_client_certificate_is_explained_as_requiring_one(self):
        with self.tls_server("server", "--tls_client_ca", self.path("ca.pem")) as server:
            error = self.failure(server, tls=True, root_certificates=self.pem("ca.pem"))
            server.stop()

        self.assertExplainedAs(error, "the server requires a client certificate (mutual TLS): "
                                      "pass certificate_chain and private_key")

    # gRPC says "Socket closed": with TLS 1.3 the client's handshake completes before the server
    # refuses its certificate.
    def test_mutual_tls_with_a_certificate_of_another_ca_is_explained_as_refused(self):
        with self.tls_server("server", "--tls_client_ca", self.path("ca.pem")) as server:
            error = self.failure(server, tls=True, root_certificates=self.pem("ca.pem"),
                                 certificate_chain=self.pem("stranger.pem"),
                                 private_key=self.pem("client.key"))
            server.stop()

        self.assertExplainedAs(error, "the server closed the connection after the handshake: it "
                                      "does not accept the client certificate in "
                                      "certificate_chain")

    # gRPC says "Peer name other.example is not in peer certificate".
    def test_a_server_name_the_certificate_lacks_is_explained_with_the_names_it_holds(self):
        with self.tls_server() as server:
            error = self.failure(server, tls=True, root_certificates=self.pem("ca.pem"),
                                 target_name_override="other.example")
            server.stop()

        self.assertExplainedAs(error, "the server's certificate (CN=server, issued by "
                                      "CN=tempokey python test CA) holds the names localhost, "
                                      "127.0.0.1, not other.example: connect by a name it holds, "
                                      "or give the one it was issued for as target_name_override")

    # The probe reads a close after the handshake as a refused client certificate: one the
    # server accepts must not read so (the server then sends its HTTP/2 SETTINGS).
    def test_the_probe_finds_an_accepted_client_certificate_accepted(self):
        settings = _tls_diagnosis.ChannelSettings(
            target="", tls=True, root_certificates=self.pem("ca.pem"),
            certificate_chain=self.pem("client.pem"), private_key=self.pem("client.key"),
            target_name_override=None)

        with self.tls_server("server", "--tls_client_ca", self.path("ca.pem")) as server:
            host, port = server.address.rsplit(":", 1)
            findings = _tls_diagnosis.probe(host, int(port), settings, CALL_TIMEOUT_SECONDS)
            server.stop()

        self.assertEqual(findings.handshake, _tls_diagnosis.Handshake.COMPLETED)
        self.assertEqual((findings.verify_code, findings.name_matches), (0, True))
        self.assertEqual(findings.after_handshake, _tls_diagnosis.AfterHandshake.ACCEPTED)
        self.assertEqual(_tls_diagnosis.explain(findings, settings), "")

    def test_a_target_of_several_addresses_is_not_probed(self):
        with self.tls_server() as server:
            address_list = "ipv4:%s,%s" % (server.address, server.address)
            with tk.connect(address_list, timeout=CALL_TIMEOUT_SECONDS) as client:
                with self.assertRaises(tk.TempokeyError) as caught:
                    client.health()
            server.stop()

        self.assertEqual(caught.exception.code, grpc.StatusCode.UNAVAILABLE)
        self.assertTrue(caught.exception.details.endswith("Socket closed"),
                        caught.exception.details)


class SingleAddressTest(unittest.TestCase):
    """Which targets are probed: one host and port, as the C++ SingleAddressOf() (the same
    table as tests/client/tls_diagnosis_test.cc)."""

    def test_every_form_of_one_host_and_port_is_accepted(self):
        cases = {"localhost:50051": ("localhost", 50051),
                 "dns:///tempokey.example:443": ("tempokey.example", 443),
                 "DNS:tempokey.example:443": ("tempokey.example", 443),
                 "ipv4:127.0.0.1:8080": ("127.0.0.1", 8080),
                 "ipv6:[::1]:8080": ("::1", 8080),
                 "[::1]:65535": ("::1", 65535)}

        found = {target: _tls_diagnosis.single_address_of(target) for target in cases}

        self.assertEqual(found, cases)

    def test_lists_sockets_schemes_and_bad_ports_are_refused(self):
        targets = ["ipv4:127.0.0.1:1,127.0.0.1:2", "unix:/tmp/tempokey.sock",
                   "unix-abstract:tempokey", "vsock:3:50051", "xds:///tempokey",
                   "dns://8.8.8.8/tempokey.example:443", "localhost", "localhost:",
                   "localhost:0", "localhost:65536", "localhost:+80", "localhost:http",
                   "localhost:\u0661\u0662", "::1", "[::1]", "[::1]8080", ":50051", ""]

        found = {target: _tls_diagnosis.single_address_of(target) for target in targets}

        self.assertEqual(found, {target: None for target in targets})


if __name__ == "__main__":
    unittest.main()
