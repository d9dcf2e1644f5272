"""Bad input to the tempokey Python package gets a clear error naming what is wrong, never a
crash, a hang, unbounded memory or a silent wrong answer; the CLI's behaviour is the model.

  - read_bvh / read_bvh_clip read files as the CLI reads them: devices, sockets and directories
    refused, a regular file over 256 MiB refused from its size, a FIFO read with a cap and
    refused when silent, a NUL byte refused at its line and column. Where the CLI reads the
    same file, the message is the CLI's, word for word.
  - Arguments are checked before anything reaches gRPC: a TypeError or ValueError naming the
    parameter, not UNKNOWN "Exception iterating requests!" or an instant DEADLINE_EXCEEDED.
  - connect()'s TLS PEM bytes are checked before a channel is made, with the CLI's messages
    naming the argument, where grpcio failed every call with UNAVAILABLE "empty address list"
    or aborted the process; the certificates are made by the openssl command-line tool.
  - example_pipeline.py refuses to write its output over its input, as the CLI does.

Run by CTest (label `python`) like test_python_client.py, whose environment and server fixture
it uses; one tempokey-server on 127.0.0.1:0 for the module. No test waits on a clock: the FIFO
silence limit is a parameter the tests lower.
"""

import json
import os
import shutil
import socket
import stat
import subprocess
import tempfile
import threading
import unittest

import grpc

import tempokey as tk

from test_python_client import (CALL_TIMEOUT_SECONDS, CLI_BINARY, CMU_BVH, EXAMPLE, PYTHON,
                                SUBPROCESS_TIMEOUT_SECONDS, ModuleServer, RunningServer)

# A FIFO test's silence limit: short, since the writer under test never writes.
SHORT_IDLE_SECONDS = 0.2
# Bound on waiting for a FIFO writer thread to finish once the reader is done.
WRITER_JOIN_SECONDS = 60

# The openssl command-line tool (deploy/install-deps.sh), which makes the TLS tests' PEM files.
OPENSSL = "/usr/bin/openssl"

SMALL_BVH = ("HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n\tCHANNELS 1 Xposition\n}\nMOTION\n"
             "Frames: 2\nFrame Time: 0.1\n1\n2\n")

_server = ModuleServer()
setUpModule = _server.start
tearDownModule = _server.stop


def cli_error(path):
    """The CLI's one error line for reading `path` (`tempokey info`), without "error: "."""
    run = subprocess.run([CLI_BINARY, "info", path], capture_output=True, text=True,
                         timeout=SUBPROCESS_TIMEOUT_SECONDS, stdin=subprocess.DEVNULL)
    if run.returncode != 1 or not run.stderr.startswith("error: "):
        raise AssertionError("tempokey info %s: exit %d, %r" % (path, run.returncode, run.stderr))
    return run.stderr[len("error: "):].rstrip("\n")


class TemporaryFolderTestCase(unittest.TestCase):

    def setUp(self):
        directory = tempfile.TemporaryDirectory()
        self.addCleanup(directory.cleanup)
        self.directory = directory.name

    def path(self, name):
        return os.path.join(self.directory, name)

    def write(self, name, data):
        with open(self.path(name), "wb") as stream:
            stream.write(data)
        return self.path(name)


class FifoWriter:
    """Writes `data` to the FIFO at `path` from a thread, keeps it open until release() (or at
    once after writing when `hold` is False), then closes it. The thread's open() waits for the
    reader; join() opens a reader of its own if none came, so it never waits forever."""

    def __init__(self, path, data, hold=False):
        self._path = path
        self._data = data
        self._release = threading.Event()
        if not hold:
            self._release.set()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        fd = os.open(self._path, os.O_WRONLY)
        try:
            os.write(fd, self._data)
        except BrokenPipeError:  # the reader stopped early, as it should on bad data
            pass
        self._release.wait(WRITER_JOIN_SECONDS)
        os.close(fd)

    def join(self):
        self._release.set()
        if self._thread.is_alive():
            try:  # a writer still waiting for a reader: give it one
                os.close(os.open(self._path, os.O_RDONLY | os.O_NONBLOCK))
            except OSError:
                pass
        self._thread.join(WRITER_JOIN_SECONDS)
        if self._thread.is_alive():
            raise AssertionError("the FIFO writer did not finish")


class ReadBvhRefusalTest(TemporaryFolderTestCase):
    """Files read_bvh refuses before parsing, with the CLI's messages."""

    def assertRefused(self, path, error_type, message, **limits):
        with self.assertRaises(error_type) as caught:
            tk.read_bvh_clip(path, **limits)
        self.assertEqual(str(caught.exception), message)
        return caught.exception

    def test_device_is_refused_as_not_a_file_like_the_cli(self):
        link = self.path("zero.bvh")
        os.symlink("/dev/zero", link)

        error = self.assertRefused(link, tk.BvhFileError,
                                   "%s: is a character device, not a file" % link)

        self.assertIsInstance(error, OSError)
        self.assertEqual(error.filename, link)
        self.assertEqual(str(error), cli_error(link))

    def test_directory_is_refused_like_the_cli(self):
        folder = self.path("folder.bvh")
        os.mkdir(folder)

        self.assertRefused(folder, tk.BvhFileError, "%s: is a directory, not a file" % folder)

        self.assertEqual("%s: is a directory, not a file" % folder, cli_error(folder))

    def test_socket_is_refused_as_not_a_file(self):
        path = self.path("s.bvh")
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.addCleanup(listener.close)
        listener.bind(path)

        self.assertRefused(path, tk.BvhFileError, "%s: is a socket, not a file" % path)

    def test_regular_file_over_256_mib_is_refused_from_its_size_before_reading(self):
        # Sparse: all NUL bytes, so a reader that read it would report the NUL at 1:1 instead.
        path = self.path("big.bvh")
        with open(path, "wb") as stream:
            stream.truncate(tk.bvh.MAX_FILE_BYTES + 1)

        self.assertRefused(path, tk.BvhFileError, "%s: file is %d bytes, over the limit of %d"
                           % (path, tk.bvh.MAX_FILE_BYTES + 1, tk.bvh.MAX_FILE_BYTES))

    def test_nul_byte_is_refused_at_its_line_and_column_like_the_cli(self):
        path = self.write("nul.bvh", b"HIERARCHY\nROOT a\n{\nOF\0FSET 0 0 0\n" + b"x" * 100000)

        error = self.assertRefused(path, tk.BvhError, "%s:4:3: unexpected byte 0x00; the file "
                                                      "looks binary, not text" % path)

        self.assertEqual((error.line, error.column), (4, 3))
        self.assertEqual(str(error), cli_error(path))

    def test_missing_file_is_file_not_found_naming_it(self):
        path = self.path("missing.bvh")

        with self.assertRaises(FileNotFoundError) as caught:
            tk.read_bvh(path)

        self.assertEqual(caught.exception.filename, path)

    def test_fifo_with_no_writer_is_refused_once_the_silence_limit_passes(self):
        path = self.path("fifo.bvh")
        os.mkfifo(path)

        error = self.assertRefused(path, tk.BvhFileError,
                                   "%s: is a FIFO and nothing arrived for 0.2 s (no writer?)"
                                   % path, idle_seconds=SHORT_IDLE_SECONDS)

        self.assertIsInstance(error, OSError)

    def test_fifo_whose_writer_stays_silent_is_refused(self):
        path = self.path("fifo.bvh")
        os.mkfifo(path)
        writer = FifoWriter(path, b"HIERARCHY\n", hold=True)

        try:
            self.assertRefused(path, tk.BvhFileError,
                               "%s: is a FIFO and nothing arrived for 0.2 s (no writer?)" % path,
                               idle_seconds=SHORT_IDLE_SECONDS)
        finally:
            writer.join()

    def test_fifo_sending_a_nul_is_refused_at_the_nul(self):
        path = self.path("fifo.bvh")
        os.mkfifo(path)
        writer = FifoWriter(path, b"HIERARCHY\nROOT a\n\0", hold=True)

        try:
            self.assertRefused(path, tk.BvhError, "%s:3:1: unexpected byte 0x00; the file looks "
                                                  "binary, not text" % path)
        finally:
            writer.join()

    def test_fifo_sending_more_than_the_cap_is_refused(self):
        path = self.path("fifo.bvh")
        os.mkfifo(path)
        writer = FifoWriter(path, SMALL_BVH.encode() + b" " * 1000, hold=True)

        try:
            self.assertRefused(path, tk.BvhFileError,
                               "%s: file is over the limit of 100 bytes" % path, max_bytes=100)
        finally:
            writer.join()

    def test_fifo_is_read_to_its_end_as_the_file_would_be(self):
        path = self.path("fifo.bvh")
        os.mkfifo(path)
        with open(CMU_BVH, "rb") as stream:
            data = stream.read()
        writer = FifoWriter(path, data)

        try:
            from_fifo = tk.read_bvh_clip(path)
        finally:
            writer.join()

        self.assertEqual(from_fifo.header.frame_count, 994)
        expected = tk.read_bvh_clip(CMU_BVH)
        expected.header.name = from_fifo.header.name = ""  # named after the file's stem
        self.assertEqual(from_fifo, expected)

    def test_limits_must_be_positive(self):
        path = self.write("small.bvh", SMALL_BVH.encode())

        for limits in ({"max_bytes": 0}, {"max_bytes": 2.5}, {"idle_seconds": 0},
                       {"idle_seconds": float("inf")}):
            with self.subTest(limits=limits):
                with self.assertRaisesRegex(ValueError, next(iter(limits))):
                    tk.read_bvh(path, **limits)


class BvhParseErrorTest(TemporaryFolderTestCase):
    """Malformed text is a BvhError naming file, line and column, never a bare ValueError."""

    def test_frame_count_in_non_ascii_digits_names_file_and_line(self):
        path = self.write("sup.bvh", SMALL_BVH.replace("Frames: 2", "Frames: \u00b2").encode())

        with self.assertRaises(tk.BvhError) as caught:
            tk.read_bvh(path)

        self.assertEqual(str(caught.exception),
                         '%s:8:1: expected a frame count >= 1, got "\u00b2"' % path)

    def test_channel_count_in_non_ascii_digits_names_file_line_and_column(self):
        path = self.write("sup.bvh", SMALL_BVH.replace("CHANNELS 1", "CHANNELS \u00b9").encode())

        with self.assertRaises(tk.BvhError) as caught:
            tk.read_bvh(path)

        self.assertEqual(str(caught.exception),
                         '%s:5:11: expected a channel count after CHANNELS, got "\u00b9"' % path)

    def test_frame_count_of_thousands_of_digits_is_over_the_limit(self):
        path = self.write("long.bvh", SMALL_BVH.replace("Frames: 2", "Frames: " + "9" * 5000)
                          .encode())

        with self.assertRaises(tk.BvhError) as caught:
            tk.read_bvh(path)

        self.assertRegex(str(caught.exception),
                         r'^%s:8:1: frame count "9{37}\.\.\." is over the limit of \d+ samples$'
                         % path)

    def test_unicode_line_separator_does_not_split_a_motion_row(self):
        # The C++ reader ends lines at LF, CRLF and CR only: "1<U+2028>2" is one row, one value.
        text = SMALL_BVH.replace("1\n2\n", "1\u20282\n3\n")

        with self.assertRaises(tk.BvhError) as caught:
            tk.parse_bvh(text, "x.bvh")

        self.assertEqual(str(caught.exception),
                         'x.bvh:10:1: expected a number for motion row 1, got "1\u20282"')

    def test_undecodable_byte_names_line_and_column(self):
        path = self.write("latin1.bvh", SMALL_BVH.replace("Hips", "H\u00efps").encode("latin-1"))

        with self.assertRaises(tk.BvhError) as caught:
            tk.read_bvh(path)

        self.assertEqual(str(caught.exception), "%s:2:7: byte 0xef is not UTF-8 text" % path)


class ClientArgumentTest(unittest.TestCase):
    """Arguments of the client's calls, checked before a request is made."""

    def setUp(self):
        self.client = tk.connect(_server.address, timeout=CALL_TIMEOUT_SECONDS)
        self.addCleanup(self.client.close)
        self.clip = tk.make_clip("s", 1.0 / 30, ["a"], [[0.0, 1.0, 2.0, 3.0]])
        self.operations = [tk.reduce_operation(tolerance=0.5)]

    def test_process_refuses_a_clip_that_is_not_a_clip_naming_the_argument(self):
        for clip in (None, "walk.bvh", tk.read_bvh):
            with self.subTest(clip=clip):
                with self.assertRaisesRegex(TypeError, r"^clip must be a tempokey\.v1\.Clip "):
                    self.client.process(clip, self.operations)
                with self.assertRaisesRegex(TypeError, r"^clip must be a tempokey\.v1\.Clip "):
                    self.client.upload_clip(clip)

        self.assertEqual(self.client.process(self.clip, self.operations).reduction_report
                         .key_count, 2)

    def test_process_refuses_operations_that_are_not_a_list_of_operations(self):
        cases = [(None, r"^operations must be a list of tempokey\.v1\.Operation"),
                 ("reduce", r"^operations must be a list of tempokey\.v1\.Operation"),
                 (self.operations[0], r"^operations must be a list .* got one Operation"),
                 (["reduce"], r"^operations\[0\] must be a tempokey\.v1\.Operation")]

        for operations, message in cases:
            with self.subTest(operations=operations):
                with self.assertRaisesRegex(TypeError, message):
                    self.client.process(self.clip, operations)
                with self.assertRaisesRegex(TypeError, message):
                    self.client.submit(operations, clip=self.clip)

    def test_health_refuses_a_service_that_is_not_a_str(self):
        with self.assertRaisesRegex(TypeError, r"^service must be a str, got int 5$"):
            self.client.health(5)

        self.assertEqual(self.client.health(tk.MOTION_SERVICE), "SERVING")

    def test_job_calls_refuse_a_job_id_that_is_not_a_str(self):
        for call in (self.client.get_job, self.client.cancel_job, self.client.delete_job,
                     self.client.watch, self.client.result):
            with self.subTest(call=call.__name__):
                with self.assertRaisesRegex(TypeError, r"^job_id must be a str"):
                    call(7)

    def test_connect_refuses_timeouts_that_are_not_finite_positive_seconds(self):
        for timeout in (float("inf"), float("nan"), -1.0, 0, 1e10, 1e300):
            with self.subTest(timeout=timeout):
                with self.assertRaisesRegex(ValueError, r"^timeout must be a number of seconds "
                                                        r"> 0 and at most \d+ \(a year\)"):
                    tk.connect(_server.address, timeout=timeout)
        for timeout in ("5", True):
            with self.subTest(timeout=timeout):
                with self.assertRaisesRegex(TypeError, r"^timeout must be a number"):
                    tk.connect(_server.address, timeout=timeout)

    def test_no_deadline_and_the_longest_deadline_reach_the_server(self):
        for timeout in (None, 365 * 24 * 3600):
            with self.subTest(timeout=timeout):
                with tk.connect(_server.address, timeout=timeout) as client:
                    result = client.process(self.clip, self.operations)

                self.assertEqual(result.reduction_report.key_count, 2)

    def test_tokens_with_inner_spaces_decimals_and_integer_booleans_are_accepted(self):
        # What worked before the checks, and means what it says: a token with a space inside (the
        # server's token file allows it), a Decimal tolerance, 0 or 1 for a switch, a noise level
        # as text like the CLI's --noise.
        import decimal
        tk.connect(_server.address, token="two words").close()
        self.assertEqual(tk.reduce_operation(tolerance=decimal.Decimal("0.25"))
                         .reduce.tolerance.max_rotation_error_degrees, 0.25)
        self.assertTrue(tk.retime_operation(reverse=1).retime.reverse)
        self.assertFalse(tk.retime_operation(reverse=0).retime.reverse)
        self.assertEqual(tk.reduce_operation(method="noise", noise="0.1")
                         .reduce.noise.rotation_sigma_degrees, 0.1)
        with self.assertRaisesRegex(TypeError, r"^reverse must be True or False, got int 2$"):
            tk.retime_operation(reverse=2)

    def test_connect_refuses_a_token_a_header_cannot_carry(self):
        for token in ("a\nb", "t\u00f6k", " padded"):
            with self.subTest(token=token):
                with self.assertRaisesRegex(ValueError, r"^token"):
                    tk.connect(_server.address, token=token)
        with self.assertRaisesRegex(TypeError, r"^token must be a str"):
            tk.connect(_server.address, token=b"abc")


def make_certificates(folder):
    """Made by the openssl tool in `folder`, as tests/client/cli_security_test.cc makes them: a CA
    (ca.pem, ca.key), a server certificate for localhost and 127.0.0.1 (server.pem, server.key)
    and a client certificate (client.pem, client.key) signed by it; client.key encrypted with
    the passphrase "x" as PKCS#8 (encrypted.key) and in OpenSSL's traditional form with a
    Proc-Type header (encrypted-traditional.key); an RSA key (rsa.key)."""
    def run(*args):
        subprocess.run([OPENSSL] + list(args), cwd=folder, check=True, capture_output=True,
                       stdin=subprocess.DEVNULL, timeout=SUBPROCESS_TIMEOUT_SECONDS)

    with open(os.path.join(folder, "server.ext"), "w", encoding="ascii") as stream:
        stream.write("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    with open(os.path.join(folder, "client.ext"), "w", encoding="ascii") as stream:
        stream.write("extendedKeyUsage=clientAuth\n")
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    run("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj",
        "/CN=tempokey python test CA")
    for serial, name in enumerate(["server", "client"], start=1):
        run("req", *ec, "-keyout", name + ".key", "-out", name + ".csr", "-subj", "/CN=" + name)
        run("x509", "-req", "-in", name + ".csr", "-CA", "ca.pem", "-CAkey", "ca.key",
            "-set_serial", str(serial), "-days", "2", "-out", name + ".pem", "-extfile",
            name + ".ext")
    run("pkey", "-in", "client.key", "-aes256", "-passout", "pass:x", "-out", "encrypted.key")
    run("pkey", "-in", "client.key", "-traditional", "-aes256", "-passout", "pass:x", "-out",
        "encrypted-traditional.key")
    run("genpkey", "-algorithm", "RSA", "-pkeyopt", "rsa_keygen_bits:2048", "-out", "rsa.key")


class CertificateTestCase(unittest.TestCase):
    """Tests with make_certificates()' files (and what make_more_certificates() adds) in a
    folder of their class's own, removed after them."""

    @classmethod
    def setUpClass(cls):
        if not os.access(OPENSSL, os.X_OK):
            raise AssertionError("needs %s (deploy/install-deps.sh)" % OPENSSL)
        cls._folder = tempfile.TemporaryDirectory()
        make_certificates(cls._folder.name)
        cls.make_more_certificates(cls._folder.name)

    @classmethod
    def make_more_certificates(cls, folder):
        """Makes a subclass's further PEM files in `folder`."""

    @classmethod
    def tearDownClass(cls):
        cls._folder.cleanup()

    def path(self, name):
        return os.path.join(self._folder.name, name)

    def pem(self, name):
        with open(self.path(name), "rb") as stream:
            return stream.read()


class TlsPemTest(CertificateTestCase):
    """connect()'s root_certificates, certificate_chain and private_key, checked before a channel
    is made. grpcio 1.51 (Debian 12) took them all: garbage, a key or empty bytes as
    root_certificates, another certificate's key or an encrypted key gave a client whose every
    call failed with UNAVAILABLE "empty address list: ", and empty bytes as certificate_chain
    or private_key aborted the process (an assertion in ssl_credentials.cc)."""

    def assertRefused(self, message, **pem):
        with self.assertRaises(ValueError) as caught:
            tk.connect("127.0.0.1:1", tls=True, **pem)
        self.assertEqual(str(caught.exception), message)

    def test_roots_without_a_pem_certificate_are_refused_naming_root_certificates(self):
        broken = self.pem("ca.pem").replace(b"\n", b"\n!", 2)  # its base64 made invalid
        cases = {"garbage": os.urandom(300), "a private key": self.pem("ca.key"), "empty": b"",
                 "a certificate that does not parse": broken}

        for case, roots in cases.items():
            with self.subTest(case=case):
                self.assertRefused("root_certificates: holds no PEM certificate",
                                   root_certificates=roots)

    def test_an_encrypted_key_is_refused_as_encrypted_without_asking_a_passphrase(self):
        # The key is the certificate's own: only its encryption is wrong.
        for key in ("encrypted.key", "encrypted-traditional.key"):
            with self.subTest(key=key):
                self.assertRefused(
                    "private_key: the key is encrypted, and gRPC takes an unencrypted PEM key "
                    "(decrypt it, e.g. openssl pkey -in KEY -out PLAIN.pem, and let only its "
                    "user read it)",
                    root_certificates=self.pem("ca.pem"),
                    certificate_chain=self.pem("client.pem"), private_key=self.pem(key))

    def test_another_certificates_key_is_refused_naming_both_arguments(self):
        # Another EC key, and a key of another type (OpenSSL reports each its own way).
        for key in ("server.key", "rsa.key"):
            with self.subTest(key=key):
                self.assertRefused("private_key is not the private key of the certificate in "
                                   "certificate_chain", root_certificates=self.pem("ca.pem"),
                                   certificate_chain=self.pem("client.pem"),
                                   private_key=self.pem(key))

    def test_a_chain_or_key_without_pem_is_refused_naming_it(self):
        cases = [("a key as certificate_chain", self.pem("client.key"), self.pem("client.key"),
                  "certificate_chain: holds no PEM certificate"),
                 ("a certificate as private_key", self.pem("client.pem"), self.pem("client.pem"),
                  "private_key: holds no PEM private key"),
                 ("garbage as private_key", self.pem("client.pem"), os.urandom(300),
                  "private_key: holds no PEM private key")]

        for case, chain, key, message in cases:
            with self.subTest(case=case):
                self.assertRefused(message, certificate_chain=chain, private_key=key)

    def test_empty_chain_or_key_is_refused_where_grpcio_aborted_the_process(self):
        # In a child: without the check, grpcio's assertion kills the process (SIGABRT).
        code = ("import sys, tempokey\n"
                "chain, key = (open(p, 'rb').read() for p in sys.argv[1:3])\n"
                "try:\n"
                "    tempokey.connect('127.0.0.1:1', tls=True, certificate_chain=chain,\n"
                "                     private_key=key).close()\n"
                "except ValueError as error:\n"
                "    sys.exit(str(error))\n")
        empty = self.path("empty.pem")
        open(empty, "wb").close()
        cases = [(empty, self.path("client.key"), "certificate_chain: holds no PEM certificate"),
                 (self.path("client.pem"), empty, "private_key: holds no PEM private key"),
                 (empty, empty, "certificate_chain: holds no PEM certificate")]

        for chain, key, message in cases:
            with self.subTest(chain=os.path.basename(chain), key=os.path.basename(key)):
                run = subprocess.run([PYTHON, "-c", code, chain, key], capture_output=True,
                                     text=True, stdin=subprocess.DEVNULL,
                                     timeout=SUBPROCESS_TIMEOUT_SECONDS)

                self.assertEqual((run.returncode, run.stderr), (1, message + "\n"))

    def test_a_checked_key_reaches_no_file_and_leaves_no_descriptor_open(self):
        # On Linux the key pair is read from memory: a temporary folder is not even made. Where
        # memfd_create is missing, the private folder is made and gone when connect() returns.
        from unittest import mock
        from tempokey import _pem

        def descriptors():
            return sorted(os.listdir("/proc/self/fd"))

        def connect():
            tk.connect("127.0.0.1:1", tls=True, root_certificates=self.pem("ca.pem"),
                       certificate_chain=self.pem("client.pem"),
                       private_key=self.pem("client.key")).close()

        made = []
        real_mkdtemp = tempfile.mkdtemp

        def recording_mkdtemp(*args, **kwargs):
            made.append(real_mkdtemp(*args, **kwargs))
            return made[-1]

        before = descriptors()
        with mock.patch.object(tempfile, "mkdtemp", side_effect=recording_mkdtemp):
            connect()
        self.assertEqual(made, [])
        self.assertEqual(descriptors(), before)

        with mock.patch.object(tempfile, "mkdtemp", side_effect=recording_mkdtemp), \
                mock.patch.object(_pem.os, "memfd_create", side_effect=OSError("none here")):
            connect()
        self.assertEqual(len(made), 1)
        self.assertFalse(os.path.exists(made[0]), made[0])
        self.assertEqual(descriptors(), before)

    def test_pem_that_is_not_bytes_is_a_type_error_naming_the_argument(self):
        with self.assertRaisesRegex(TypeError, r"^root_certificates must be bytes \(PEM, as read "
                                               r"with open\(path, \"rb\"\)\), got str "
                                               r"'-----BEGIN CERTIFICATE-----"):
            tk.connect("127.0.0.1:1", tls=True, root_certificates=self.pem("ca.pem").decode())
        with self.assertRaisesRegex(TypeError, r"^private_key must be bytes .* got bytearray"):
            tk.connect("127.0.0.1:1", tls=True, certificate_chain=self.pem("client.pem"),
                       private_key=bytearray(self.pem("client.key")))
        with self.assertRaisesRegex(TypeError, r"^certificate_chain must be bytes .* got int 5$"):
            tk.connect("127.0.0.1:1", tls=True, certificate_chain=5, private_key=b"")

    def test_a_good_ca_and_client_pair_reach_a_mutual_tls_server(self):
        # A bundle's comment line may hold UTF-8 (curl's cacert.pem names issuers so).
        bundle = "# Issuer: CN=F\u0151tan\u00fas\u00edtv\u00e1ny\n".encode() + self.pem("ca.pem")

        server = RunningServer("--tls_cert", self.path("server.pem"), "--tls_key",
                               self.path("server.key"), "--tls_client_ca", self.path("ca.pem"))
        health = []

        with server:
            for roots in (self.pem("ca.pem"), bundle):
                with tk.connect(server.address, timeout=CALL_TIMEOUT_SECONDS, tls=True,
                                root_certificates=roots, certificate_chain=self.pem("client.pem"),
                                private_key=self.pem("client.key")) as client:
                    health.append(client.health(tk.MOTION_SERVICE))
            status, log = server.stop(), server.log()

        self.assertEqual(health, ["SERVING", "SERVING"])
        self.assertEqual(status, 0, log)


class BuilderArgumentTest(unittest.TestCase):
    """make_clip and the operation builders: no silent conversion of a wrong value."""

    def test_make_clip_refuses_a_string_where_a_list_of_samples_is_expected(self):
        with self.assertRaisesRegex(TypeError, r"^samples\[0\] must be a list, got str '12'$"):
            tk.make_clip("x", 1.0 / 30, ["a"], ["12"])
        with self.assertRaisesRegex(TypeError, r"^channels must be a list, got str 'ab'$"):
            tk.make_clip("x", 1.0 / 30, "ab", [[1.0], [2.0]])

    def test_make_clip_refuses_samples_that_are_not_numbers_naming_channel_and_frame(self):
        for value, shown in (("1.5", "str '1.5'"), (True, "bool True"), (None, "NoneType None")):
            with self.subTest(value=value):
                with self.assertRaisesRegex(TypeError, r"^samples\[1\]\[2\] \(channel 1, frame "
                                                       r"2\) must be a number, got %s$" % shown):
                    tk.make_clip("x", 1.0 / 30, ["a", "b"], [[0, 1, 2], [0.0, 1.0, value]])

    def test_make_clip_takes_ints_and_floats_exactly(self):
        clip = tk.make_clip("x", 1.0 / 30, ["a"], [[0, 1.5, -2, 2 ** 53]])

        self.assertEqual(list(clip.samples[0].samples), [0.0, 1.5, -2.0, 2.0 ** 53])

    def test_make_clip_refuses_a_frame_time_or_index_of_the_wrong_type(self):
        with self.assertRaisesRegex(TypeError, r"^frame_time_seconds must be a number"):
            tk.make_clip("x", "0.1", ["a"], [[1.0]])
        with self.assertRaisesRegex(ValueError, r"^channels\[0\]\.joint_index must be a whole "
                                                r"number, got 0\.5$"):
            tk.make_clip("x", 0.1, [tk.ChannelSpec("Xrotation", joint_index=0.5)], [[1.0]],
                         joints=[tk.JointSpec("root")])

    def test_fit_frames_must_be_a_whole_number(self):
        with self.assertRaisesRegex(ValueError, r"^fit_frames must be a whole number, got 2\.7$"):
            tk.retime_operation(fit_frames=2.7)
        with self.assertRaisesRegex(TypeError, r"^fit_frames must be a whole number, got bool"):
            tk.retime_operation(fit_frames=True)
        with self.assertRaisesRegex(TypeError, r"^fit_frames must be a whole number, got str"):
            tk.retime_operation(fit_frames="3")
        self.assertEqual(tk.retime_operation(fit_frames=48.0).retime.fit_frames, 48)

    def test_retime_refuses_strings_for_numbers_and_flags(self):
        cases = [({"fit_seconds": "2"}, TypeError, r"^fit_seconds must be a number"),
                 ({"reverse": "false"}, TypeError, r"^reverse must be True or False"),
                 ({"fit_to_grid": 2}, TypeError, r"^fit_to_grid must be True or False"),
                 ({"pins": [(0, 2.5)]}, ValueError, r"^pin 1 output_frame must be a whole"),
                 ({"holds": [("1s", "2")]}, TypeError, r"^hold 1 duration_seconds must be a "),
                 ({"speed": [(0, "0.5")]}, TypeError, r"^speed must be a number"),
                 ({"speed": 5}, TypeError, r"^speed must be a str"),
                 ({"fps": (30.5, 1)}, ValueError, r"^frame rate numerator must be a whole"),
                 ({"fps": 1e-30}, ValueError, r"^frame rate 1e-30 is out of range")]

        for arguments, error, message in cases:
            with self.subTest(arguments=arguments):
                with self.assertRaisesRegex(error, message):
                    tk.retime_operation(**arguments)

    def test_reduce_refuses_strings_for_numbers_and_non_integral_budgets(self):
        with self.assertRaisesRegex(TypeError, r"^tolerance must be a number, got str '0\.5'$"):
            tk.reduce_operation(tolerance="0.5")
        with self.assertRaisesRegex(ValueError, r"^key_budget must be a whole number"):
            tk.reduce_operation(key_budget=10.5)
        with self.assertRaisesRegex(ValueError, r"^key_budget 1\d+ is out of range"):
            tk.reduce_operation(key_budget=10 ** 30)
        with self.assertRaisesRegex(TypeError, r"^euler_filter must be True or False"):
            tk.reduce_operation(euler_filter="no")
        with self.assertRaisesRegex(ValueError, r'^noise must be a number or "auto"'):
            tk.reduce_operation(method="noise", noise="loud")
        self.assertEqual(tk.reduce_operation(key_budget=400.0).reduce.tolerance.key_budget, 400)


class ExampleOverwriteTest(TemporaryFolderTestCase):
    """example_pipeline.py -o naming its own input, as the CLI's `reduce -o`."""

    def run_example(self, *args):
        return subprocess.run([PYTHON, EXAMPLE, "--server", _server.address] + list(args),
                              capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT_SECONDS)

    def copy_input(self):
        path = self.path("walk.bvh")
        shutil.copyfile(CMU_BVH, path)
        return path

    def assertUnchanged(self, path):
        with open(path, "rb") as copy, open(CMU_BVH, "rb") as original:
            self.assertEqual(copy.read(), original.read(), "the input was changed")

    def test_output_equal_to_the_input_is_refused_with_the_clis_message(self):
        path = self.copy_input()

        run = self.run_example(path, "-o", path)
        cli = subprocess.run([CLI_BINARY, "--server", _server.address, "reduce", path, "-o", path],
                             capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT_SECONDS)

        self.assertEqual(run.returncode, 2)
        self.assertEqual(run.stdout, "")
        self.assertEqual(run.stderr, "error: -o %s is the input (the same file); choose another "
                                     "output, or give --overwrite to replace the input\n" % path)
        self.assertEqual((run.returncode, run.stderr), (cli.returncode, cli.stderr))
        self.assertUnchanged(path)

    def test_output_linked_to_the_input_is_refused(self):
        path = self.copy_input()
        symbolic = self.path("link.bvh")
        os.symlink("walk.bvh", symbolic)
        hard = self.path("hard.bvh")
        os.link(path, hard)

        for output in (symbolic, hard, os.path.join(self.directory, ".", "walk.bvh")):
            with self.subTest(output=output):
                run = self.run_example(path, "-o", output)

                self.assertEqual(run.returncode, 2)
                self.assertEqual(run.stderr, "error: -o %s is the input %s (the same file); "
                                             "choose another output, or give --overwrite to "
                                             "replace the input\n" % (output, path))
        self.assertUnchanged(path)
        self.assertTrue(stat.S_ISLNK(os.lstat(symbolic).st_mode))

    def test_overwrite_replaces_the_input_with_the_result(self):
        path = self.copy_input()

        run = self.run_example(path, "-o", path, "--overwrite")

        self.assertEqual(run.returncode, 0, run.stderr)
        with open(path, encoding="utf-8") as stream:
            self.assertIn('"format": "tempokey.keyed_clip"', stream.read())

    def test_timeout_that_is_not_finite_positive_seconds_is_a_usage_error(self):
        for timeout in ("inf", "nan", "0", "-1", "soon"):
            with self.subTest(timeout=timeout):
                run = self.run_example(CMU_BVH, "-o", self.path("x.json"), "--timeout", timeout)

                self.assertEqual(run.returncode, 2)
                self.assertIn("argument --timeout: expected a number of seconds > 0", run.stderr)


class DecodersNotOursTest(TemporaryFolderTestCase):
    """What the server and the CLI write, read by decoders the project did not write: Python's
    json module and grpcio."""

    def test_a_batch_summary_and_manifest_with_odd_names_are_json_pythons_decoder_reads(self):
        # A Latin-1 name (not UTF-8: written with U+FFFD) and one holding U+0085 (a C1 control:
        # written escaped, \u0085), in one folder with a plain one.
        folder = self.path("in")
        os.mkdir(folder)
        names = [b"caf\xe9.bvh", "nel\u0085.bvh".encode(), b"plain.bvh"]
        for name in names:
            with open(os.path.join(os.fsencode(folder), name), "wb") as stream:
                stream.write(SMALL_BVH.encode())
        ops = self.write("ops.json", b'{"operations": [{"convert": {}}]}')
        out = self.path("out")

        run = subprocess.run([CLI_BINARY, "--server", _server.address, "batch", folder, "-o", out,
                              "--ops", ops, "--progress", "none"], capture_output=True,
                             timeout=SUBPROCESS_TIMEOUT_SECONDS, stdin=subprocess.DEVNULL)

        self.assertEqual(run.returncode, 0, run.stderr)
        summary = json.loads(run.stdout.decode("utf-8"))  # strict UTF-8, then JSON
        self.assertEqual(sorted(r["input"] for r in summary["results"]),
                         ["caf\ufffd.bvh", "nel\u0085.bvh", "plain.bvh"])
        with open(os.path.join(out, ".tempokey-batch.json"), encoding="utf-8") as stream:
            manifest = json.load(stream)
        # The Latin-1 name is not recorded (it could never match again); the others are.
        self.assertEqual(sorted(manifest["outputs"]), ["nel\u0085.bvh", "plain.bvh"])

    def test_a_message_quoting_a_long_input_reaches_grpcio_capped(self):
        # grpcio refuses a status over its 8 KiB header limit: the server's message is cut.
        with grpc.insecure_channel(_server.address) as channel:
            stub = tk.motion_service_pb2_grpc.MotionServiceStub(channel)
            with self.assertRaises(grpc.RpcError) as caught:
                stub.ListJobs(tk.motion_service_pb2.ListJobsRequest(page_token="x" * 100000),
                              timeout=CALL_TIMEOUT_SECONDS)

        self.assertEqual(caught.exception.code(), grpc.StatusCode.INVALID_ARGUMENT)
        self.assertTrue(caught.exception.details().startswith('page_token "xxx'))
        self.assertRegex(caught.exception.details(), r" \.\.\. \(\d+ more bytes not shown\)$")
        self.assertLess(len(caught.exception.details()), 2100)


if __name__ == "__main__":
    unittest.main()
