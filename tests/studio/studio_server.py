"""A real tempokey-server with its HTTP front end on free loopback ports, for the studio tests."""

import os
import queue
import re
import signal
import subprocess
import tempfile
import threading
import unittest

STARTUP_TIMEOUT_SECONDS = 60
SHUTDOWN_TIMEOUT_SECONDS = 60
LISTENING = re.compile(r"tempokey-server listening on (\S+:\d+)")
STUDIO = re.compile(r"tempokey-server studio on (\S+)")


def env_path(name):
    value = os.environ.get(name)
    if not value:
        raise unittest.SkipTest("%s is not set; run through ctest -L browser" % name)
    return value


class StudioServer:
    """tempokey-server on 127.0.0.1:0 with --http_address 127.0.0.1:0 (or the given flags) for the
    `with` block; stopped with SIGTERM, its exit status kept in `exit_code`."""

    def __init__(self, *flags, http_address="127.0.0.1:0"):
        self.flags = list(flags)
        self.http_address = http_address
        self.log = tempfile.TemporaryFile(mode="w+")
        self.process = None
        self.exit_code = None

    def __enter__(self):
        binary = env_path("TEMPOKEY_SERVER")
        args = [binary, "--address", "127.0.0.1:0", "--log_level", "warn",
                "--drain_grace_seconds", "5"]
        if self.http_address:
            args += ["--http_address", self.http_address]
        self.process = subprocess.Popen(args + self.flags, stdout=subprocess.PIPE, stderr=self.log,
                                        text=True)
        lines = queue.Queue()
        threading.Thread(target=self._forward, args=(lines,), daemon=True).start()
        self.grpc_target = None
        self.http_url = None
        while self.grpc_target is None or (self.http_address and self.http_url is None):
            try:
                line = lines.get(timeout=STARTUP_TIMEOUT_SECONDS)
            except queue.Empty:
                line = None
            if line is None:
                self.process.kill()
                self.process.wait()
                self.log.seek(0)
                raise AssertionError("tempokey-server did not start: " + self.log.read())
            if LISTENING.search(line):
                self.grpc_target = LISTENING.search(line).group(1)
            if STUDIO.search(line):
                self.http_url = STUDIO.search(line).group(1)
        return self

    def _forward(self, lines):
        for line in self.process.stdout:
            lines.put(line)
        lines.put(None)

    def __exit__(self, *exc):
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            self.exit_code = self.process.wait(timeout=SHUTDOWN_TIMEOUT_SECONDS)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.exit_code = self.process.wait()
        return False

    def server_log(self):
        """The log so far. Read with pread, at no file offset: the server writes through the same
        open file, so moving its offset (seek) while it runs would put its next lines over old ones."""
        fd = self.log.fileno()
        return os.pread(fd, os.fstat(fd).st_size, 0).decode("utf-8", "replace")
