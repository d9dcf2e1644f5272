"""Tests of the tempokey Python package (client/python) against the real tempokey-server.

Run by CTest (label `python`) with the interpreter of the virtual environment the package was
installed into (tests/python/install_package.py); tests/python/CMakeLists.txt sets:
  PYTHONPATH            this folder only: `tempokey` comes from the installed package
  TEMPOKEY_SERVER       the tempokey-server binary; TEMPOKEY_CLI the tempokey binary
  TEMPOKEY_SHARED_DIR   ../shared (captures under data/bvh)
  TEMPOKEY_CLIENT_DIR   client/python (the example script); TEMPOKEY_PYTHON the interpreter

Every server is started on 127.0.0.1:0, found through the line it prints once serving, and
stopped with SIGTERM, its exit status asserted 0. Every wait is bounded by a timeout.
"""

import functools
import json
import math
import os
import queue
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import unittest

import grpc

import tempokey as tk

# Bounds, generous for a loaded 2-core CI machine; none of them is a performance assertion.
STARTUP_TIMEOUT_SECONDS = 60
CALL_TIMEOUT_SECONDS = 120
SUBPROCESS_TIMEOUT_SECONDS = 180
# Drain grace given to test servers; shutdown waits for it plus a margin.
DRAIN_GRACE_SECONDS = 5
SHUTDOWN_TIMEOUT_SECONDS = 60
# Reduction bounds are checked by the server at every frame; reports round nothing, so only
# the last bits of floating point separate the report from the bound.
BOUND_SLACK = 1e-9
# The retimed ramp is exact linear interpolation of exact values.
RAMP_EXACT = 1e-12

LISTENING = re.compile(r"tempokey-server listening on (\S+:\d+)")


def env_path(name):
    value = os.environ.get(name)
    if not value:
        raise unittest.SkipTest("%s is not set; run through ctest -L python" % name)
    return value


SERVER_BINARY = env_path("TEMPOKEY_SERVER")
CLI_BINARY = env_path("TEMPOKEY_CLI")
SHARED_DIR = env_path("TEMPOKEY_SHARED_DIR")
CLIENT_DIR = env_path("TEMPOKEY_CLIENT_DIR")
PYTHON = os.environ.get("TEMPOKEY_PYTHON") or sys.executable
CMU_BVH = os.path.join(SHARED_DIR, "data", "bvh", "cmu", "131_01.bvh")
EXAMPLE = os.path.join(CLIENT_DIR, "example_pipeline.py")


class RunningServer:
    """A tempokey-server process on a free loopback port, for the `with` block it is used in."""

    def __init__(self, *flags):
        self._flags = list(flags)
        self._log = tempfile.TemporaryFile(mode="w+")
        self.process = None
        self._reader = None
        self.address = None

    def __enter__(self):
        self.process = subprocess.Popen(
            [SERVER_BINARY, "--address", "127.0.0.1:0", "--log_level", "warn",
             "--drain_grace_seconds", str(DRAIN_GRACE_SECONDS)] + self._flags,
            stdout=subprocess.PIPE, stderr=self._log, text=True)
        lines = queue.Queue()
        self._reader = threading.Thread(target=self._forward_stdout, args=(lines,), daemon=True)
        self._reader.start()
        try:
            line = lines.get(timeout=STARTUP_TIMEOUT_SECONDS)
        except queue.Empty:
            self._kill()
            raise AssertionError("tempokey-server did not announce itself within %d s: %s"
                                 % (STARTUP_TIMEOUT_SECONDS, self.log()))
        match = LISTENING.search(line or "")
        if not match:
            self._kill()
            raise AssertionError("tempokey-server did not start (first output %r): %s"
                                 % (line, self.log()))
        self.address = match.group(1)
        return self

    def _forward_stdout(self, lines):
        for line in self.process.stdout:
            lines.put(line)
        lines.put(None)  # end of output: the process exited

    def _kill(self):
        self.process.kill()
        self.process.wait(timeout=SHUTDOWN_TIMEOUT_SECONDS)

    def log(self):
        self._log.seek(0)
        return self._log.read()[-2000:]

    def stop(self):
        """SIGTERM, then the exit status (the server drains, then exits 0)."""
        self.process.send_signal(signal.SIGTERM)
        try:
            return self.process.wait(timeout=SHUTDOWN_TIMEOUT_SECONDS)
        except subprocess.TimeoutExpired:
            self._kill()
            raise AssertionError("tempokey-server ignored SIGTERM for %d s: %s"
                                 % (SHUTDOWN_TIMEOUT_SECONDS, self.log()))

    def __exit__(self, *exc):
        if self.process.poll() is None:
            self._kill()
        self._reader.join(timeout=SHUTDOWN_TIMEOUT_SECONDS)  # EOF follows the exit
        self.process.stdout.close()
        self._log.close()


@functools.lru_cache(maxsize=None)
def cmu_clip():
    """CMU 131_01 (994 frames, 96 channels) read and converted as the example does, so the tests
    send exactly what the example sends. Shared: callers do not modify it."""
    return tk.read_bvh_clip(CMU_BVH)


def ramp_clip(frames, fps=30):
    """`frames` frames at `fps`: joint "root" Xposition i/2 at frame i, and a flat scalar."""
    return tk.make_clip("ramp", 1.0 / fps,
                        channels=[tk.ChannelSpec("Xposition", joint_index=0), "blend"],
                        samples=[[0.5 * i for i in range(frames)], [1.0] * frames],
                        joints=[tk.JointSpec("root")])


def closed_form_output_frames(source_frames, fps, speed):
    """SPEC 3.1: M = floor(T_o * f_o + 1e-9) + 1, T_o = T_s / speed, T_s = (N - 1) / f_s."""
    source_duration = (source_frames - 1) / fps
    return math.floor(source_duration / speed * fps + 1e-9) + 1


def run_cli(*args):
    return subprocess.run([CLI_BINARY] + list(args), capture_output=True, text=True,
                          timeout=SUBPROCESS_TIMEOUT_SECONDS)


class ModuleServer:
    """One RunningServer for a test module: `setUpModule = SERVER.start`, `tearDownModule =
    SERVER.stop`; its address is `SERVER.address` in between. Stopping checks the drain's exit."""

    def __init__(self):
        self._server = None

    @property
    def address(self):
        return self._server.address

    def start(self):
        self._server = RunningServer().__enter__()

    def stop(self):
        try:
            status = self._server.stop()
            if status != 0:
                raise AssertionError("tempokey-server exited %d after SIGTERM: %s"
                                     % (status, self._server.log()))
        finally:
            self._server.__exit__(None, None, None)


_server = ModuleServer()
setUpModule = _server.start
tearDownModule = _server.stop


class ServerTestCase(unittest.TestCase):
    """A client of the module's server, per test."""

    def setUp(self):
        self.client = tk.connect(_server.address, timeout=CALL_TIMEOUT_SECONDS)
        self.addCleanup(self.client.close)

    def assertServing(self):
        self.assertEqual(self.client.health(tk.MOTION_SERVICE), "SERVING")

    def assertRaisesStatus(self, code, call, *args, **kwargs):
        with self.assertRaises(tk.TempokeyError) as caught:
            call(*args, **kwargs)
        self.assertEqual(caught.exception.code, code, caught.exception.details)
        return caught.exception


class HealthAndInfoTest(ServerTestCase):

    def test_health_is_serving_live_and_ready(self):
        live = self.client.health("")
        ready = self.client.health(tk.MOTION_SERVICE)

        self.assertEqual(live, "SERVING")
        self.assertEqual(ready, "SERVING")

    def test_health_of_unknown_service_is_not_found(self):
        self.assertRaisesStatus(grpc.StatusCode.NOT_FOUND, self.client.health, "no.such.Service")

    def test_server_info_reports_default_limits_and_operations(self):
        info = self.client.server_info()

        self.assertEqual(info.max_message_bytes, 64 << 20)
        self.assertEqual(info.max_clip_samples, 32 << 20)
        self.assertIn("retime", info.operations)
        self.assertIn("reduce", info.operations)
        self.assertEqual(list(info.features), ["sample_slices", "batch_parts"])


class SampleBatchTest(unittest.TestCase):
    """Packing of slices for servers with the "sample_slices" feature (no server needed)."""

    def test_batches_fill_the_budget_across_channels_and_keep_every_sample(self):
        clip = tk.make_clip("many", 1.0 / 30, channels=["a", "b", "c"],
                            samples=[[float(c * 1000 + i) for i in range(130)] for c in range(3)])

        batches = list(tk.sample_batches(clip, slice_bytes=8 * 100))

        self.assertEqual([sum(len(s.samples) for s in b.slices) for b in batches],
                         [100, 100, 100, 90])
        rebuilt = {}
        for batch in batches:
            for piece in batch.slices:
                rebuilt.setdefault(piece.channel_index, {}).update(
                    {piece.first_frame + i: v for i, v in enumerate(piece.samples)})
        for c in range(3):
            self.assertEqual([rebuilt[c][i] for i in range(130)],
                             [float(c * 1000 + i) for i in range(130)])


class UploadTest(ServerTestCase):

    def test_uploading_a_capture_twice_gives_the_same_id(self):
        clip = cmu_clip()

        first = self.client.upload_clip(clip)
        second = self.client.upload_clip(clip)

        self.assertTrue(first.clip_id.startswith("sha256:"), first.clip_id)
        self.assertEqual(second.clip_id, first.clip_id)
        self.assertTrue(second.already_stored)
        self.assertEqual((first.frame_count, first.channel_count, first.sample_count),
                         (994, 96, 994 * 96))

    def test_small_slices_reassemble_to_the_same_clip(self):
        clip = cmu_clip()
        whole = self.client.upload_clip(clip)

        with tk.connect(_server.address, timeout=CALL_TIMEOUT_SECONDS,
                        slice_bytes=4096) as sliced_client:
            sliced = sliced_client.upload_clip(clip)

        self.assertEqual(sliced.clip_id, whole.clip_id)

    def test_python_bvh_reader_uploads_what_the_cli_uploads(self):
        ours = self.client.upload_clip(cmu_clip())

        cli = run_cli("--server", _server.address, "upload", CMU_BVH)

        self.assertEqual(cli.returncode, 0, cli.stderr)
        self.assertIn(ours.clip_id, cli.stdout)


class RetimeTest(ServerTestCase):

    def test_constant_speed_two_gives_the_closed_form_frame_count(self):
        frames, fps = 101, 30
        expected = closed_form_output_frames(frames, fps, 2.0)  # T_o * f_o = 50, an integer

        result = self.client.process(ramp_clip(frames, fps),
                                     [tk.retime_operation(speed="0s:2", filter="linear")])

        self.assertEqual(expected, 51)
        self.assertEqual(result.clip.header.frame_count, expected)
        self.assertEqual(result.retime_report.output_frame_count, expected)
        self.assertEqual(result.retime_report.fit_factor, 1.0)
        # Output frame j shows source frame 2j: root.Xposition (i/2 at frame i) reads j.
        ramp = result.clip.samples[0].samples
        self.assertEqual(len(ramp), expected)
        for j, value in enumerate(ramp):
            self.assertAlmostEqual(value, float(j), delta=RAMP_EXACT)

    def test_without_fit_to_grid_the_frame_count_is_floored(self):
        frames, fps = 100, 30
        expected = closed_form_output_frames(frames, fps, 2.0)  # floor(49.5) + 1

        result = self.client.process(ramp_clip(frames, fps),
                                     [tk.retime_operation(speed=[(0.0, 2.0)], fit_to_grid=False)])

        self.assertEqual(expected, 50)
        self.assertEqual(result.clip.header.frame_count, expected)
        self.assertEqual(result.retime_report.output_frame_count, expected)

    def test_capture_retime_matches_the_cli(self):
        result = self.client.process(cmu_clip(), [tk.retime_operation(speed="0s:2")])

        with tempfile.TemporaryDirectory() as directory:
            cli = run_cli("--server", _server.address, "retime", CMU_BVH,
                          "-o", os.path.join(directory, "fast.bvh"), "--speed", "0s:2")

        self.assertEqual(cli.returncode, 0, cli.stderr)
        cli_frames = int(re.search(r"output frames:\s+(\d+)", cli.stdout).group(1))
        self.assertEqual(result.clip.header.frame_count, cli_frames)
        self.assertEqual(len(result.clip.samples), 96)
        for channel in result.clip.samples:
            self.assertEqual(len(channel.samples), cli_frames)


class ReduceTest(ServerTestCase):

    TOLERANCE = 0.5  # degrees for rotations, file units for positions

    def test_tolerance_reduction_keeps_fewer_keys_within_the_bound(self):
        clip = cmu_clip()

        result = self.client.process(clip, [tk.reduce_operation(
            tolerance=self.TOLERANCE, position_tolerance=self.TOLERANCE)])

        report = result.reduction_report
        keyed = result.keyed_clip
        self.assertIsNone(result.clip)
        self.assertEqual(report.sample_count, 994 * 96)
        self.assertLess(report.key_count, report.sample_count)
        self.assertLessEqual(report.max_error, self.TOLERANCE + BOUND_SLACK)
        for channel in report.channels:
            self.assertLessEqual(channel.max_error, self.TOLERANCE + BOUND_SLACK)
        self.assertEqual(len(keyed.curves), 96)
        self.assertEqual(sum(len(c.time_seconds) for c in keyed.curves), report.key_count)

    def test_tighter_tolerance_keeps_more_keys(self):
        clip = cmu_clip()

        loose = self.client.process(clip, [tk.reduce_operation(tolerance=0.5)])
        tight = self.client.process(clip, [tk.reduce_operation(tolerance=0.1)])

        self.assertGreater(tight.reduction_report.key_count, loose.reduction_report.key_count)

    def test_noise_method_reports_each_channels_level_given_or_estimated(self):
        clip = cmu_clip()

        given = self.client.process(clip, [tk.reduce_operation(method="noise", noise=0.3)])
        estimated = self.client.process(clip, [tk.reduce_operation(method="noise")])

        rotation_kinds = {tk.CHANNEL_KINDS[name] for name in ("Xrotation", "Yrotation", "Zrotation")}
        header = given.keyed_clip.header
        rotations = [c for c in given.reduction_report.channels
                     if header.channels[c.channel_index].kind in rotation_kinds]
        self.assertEqual(len(rotations), 93)
        for channel in rotations:
            self.assertEqual(channel.noise_sigma, 0.3)
            self.assertFalse(channel.noise_sigma_estimated)
        for channel in estimated.reduction_report.channels:
            self.assertGreater(channel.noise_sigma, 0.0)
            self.assertTrue(channel.noise_sigma_estimated)
        self.assertLess(estimated.reduction_report.key_count, estimated.reduction_report.sample_count)

    def test_euler_filter_is_on_for_noise_and_asked_for_tolerance(self):
        clip = cmu_clip()

        noise = self.client.process(clip, [tk.reduce_operation(method="noise", noise=0.3)])
        noise_off = self.client.process(clip, [tk.reduce_operation(
            method="noise", noise=0.3, euler_filter=False)])
        tolerance = self.client.process(clip, [tk.reduce_operation()])
        tolerance_on = self.client.process(clip, [tk.reduce_operation(euler_filter=True)])

        self.assertGreater(noise.reduction_report.euler_filtered_frames, 0)
        self.assertEqual(noise_off.reduction_report.euler_filtered_frames, 0)
        self.assertEqual(tolerance.reduction_report.euler_filtered_frames, 0)
        self.assertEqual(tolerance_on.reduction_report.euler_filtered_frames,
                         noise.reduction_report.euler_filtered_frames)

    def test_keyed_json_equals_the_cli_output(self):
        result = self.client.process(cmu_clip(), [tk.reduce_operation()])

        with tempfile.TemporaryDirectory() as directory:
            path = os.path.join(directory, "cli.json")
            cli = run_cli("--server", _server.address, "reduce", CMU_BVH, "-o", path)
            self.assertEqual(cli.returncode, 0, cli.stderr)
            with open(path, encoding="utf-8") as stream:
                cli_document = json.load(stream)

        self.assertEqual(tk.keyed_clip_to_dict(result.keyed_clip), cli_document)


class InvalidRequestTest(ServerTestCase):

    def test_speed_knot_not_positive_is_invalid_argument_with_the_servers_message(self):
        operations = [tk.retime_operation(speed="0s:1,2s:-1")]

        error = self.assertRaisesStatus(grpc.StatusCode.INVALID_ARGUMENT, self.client.process,
                                        ramp_clip(100), operations)

        self.assertEqual(error.details,
                         "operation 1 (retime): speed knot 2 (2s:-1): speed must be > 0")
        self.assertEqual(str(error), "INVALID_ARGUMENT: " + error.details)
        self.assertServing()

    def test_nan_sample_is_invalid_argument_naming_channel_and_frame(self):
        clip = tk.make_clip("nan", 1.0 / 30, ["a", "b"],
                            [[0.0] * 5, [0.0, 1.0, 2.0, float("nan"), 4.0]])

        error = self.assertRaisesStatus(grpc.StatusCode.INVALID_ARGUMENT, self.client.process,
                                        clip, [tk.reduce_operation()])

        self.assertIn("channel 1 (b): sample at frame 3 is NaN", error.details)
        self.assertServing()

    def test_server_keeps_serving_after_refusals(self):
        for operations in ([tk.retime_operation(speed="0s:0")],
                           [tk.reduce_operation(tolerance=-1)]):
            self.assertRaisesStatus(grpc.StatusCode.INVALID_ARGUMENT, self.client.process,
                                    ramp_clip(100), operations)

        result = self.client.process(ramp_clip(101), [tk.retime_operation(speed="0s:2")])

        self.assertEqual(result.clip.header.frame_count, 51)
        self.assertServing()

    def test_unknown_clip_and_job_are_not_found(self):
        self.assertRaisesStatus(grpc.StatusCode.NOT_FOUND, self.client.submit,
                                [tk.reduce_operation()], clip_id="sha256:00")
        self.assertRaisesStatus(grpc.StatusCode.NOT_FOUND, self.client.result, "no-such-job")

    def test_noise_levels_belong_to_the_noise_method(self):
        with self.assertRaises(ValueError):
            tk.reduce_operation(noise=0.5)
        with self.assertRaises(ValueError):
            tk.reduce_operation(method="noise", tolerance=0.5)

    def test_client_side_encoding_errors_are_value_errors(self):
        with self.assertRaisesRegex(ValueError, r"speed knot 2 \('2x:1'\)"):
            tk.parse_speed("0s:1,2x:1")
        with self.assertRaisesRegex(ValueError, "channel 1 has 2 samples, channel 0 has 3"):
            tk.make_clip("ragged", 0.1, ["a", "b"], [[1, 2, 3], [1, 2]])


class ReduceOptionsTest(ServerTestCase):
    """reduce_operation() builds ReduceOperation from its keyword table, REDUCE_OPTIONS."""

    def test_every_option_lands_in_its_field_and_the_server_takes_it(self):
        values = {"tolerance": 0.75, "position_tolerance": 0.25, "scalar_tolerance": 0.125,
                  "key_budget": 400, "pose_alignment": "joint", "joint_tolerance": "0.5%",
                  "noise": 0.25, "position_noise": 0.5, "euler_filter": True,
                  "fewest_keys": True}
        # Options that choose their field from their value: where this value must land.
        chosen_fields = {"joint_tolerance": ("tolerance.max_joint_error_percent_of_height", 0.5),
                         "noise": ("noise.rotation_sigma_degrees", 0.25),
                         "position_noise": ("noise.position_sigma", 0.5)}
        methods = {"noise": "noise", "position_noise": "noise"}
        self.assertEqual(set(values), set(tk.REDUCE_OPTIONS), "a new option needs a value here")

        for keyword, value in values.items():
            with self.subTest(option=keyword):
                option = tk.REDUCE_OPTIONS[keyword]
                field, expected = chosen_fields.get(keyword, (option.field, None))
                if keyword not in chosen_fields:
                    expected = option.convert(value)
                operation = tk.reduce_operation(method=methods.get(keyword, "tolerance"),
                                                **{keyword: value})
                found = operation.reduce
                for part in field.split("."):
                    found = getattr(found, part)
                self.assertEqual(found, expected, field)
                result = self.client.process(cmu_clip(), [operation])
                self.assertIsNotNone(result.keyed_clip)

    def test_unknown_keywords_and_options_of_another_method_are_refused(self):
        with self.assertRaisesRegex(TypeError, r"unexpected keyword argument 'tolerence' "
                                               r"\(options: tolerance, position_tolerance"):
            tk.reduce_operation(tolerence=0.5)
        with self.assertRaisesRegex(ValueError, "key_budget belongs to method 'tolerance', "
                                                "not 'paper'"):
            tk.reduce_operation(method="paper", key_budget=10)
        with self.assertRaisesRegex(ValueError, "paper parameter 'no_such_field'"):
            tk.reduce_operation(method="paper", paper={"no_such_field": 1})

    def test_none_leaves_an_option_at_the_servers_default(self):
        self.assertEqual(tk.reduce_operation(tolerance=None), tk.reduce_operation())


class StoredJobTest(ServerTestCase):

    def test_submit_watch_result_matches_process(self):
        clip = cmu_clip()
        operations = [tk.retime_operation(speed="0s:1,2s:1,2s:0.5,4s:0.5,4s:1"),
                      tk.reduce_operation(tolerance=0.5)]
        uploaded = self.client.upload_clip(clip)
        versions = []

        job = self.client.submit(operations, clip_id=uploaded.clip_id, labels={"test": "python"})
        final = self.client.watch(job.job_id, on_update=lambda j: versions.append(j.version))
        stored = self.client.result(job.job_id, slice_bytes=4096)  # curves arrive in pieces
        direct = self.client.process(clip, operations)

        self.assertEqual(final.state, tk.motion_service_pb2.JOB_STATE_SUCCEEDED,
                         final.error_message)
        self.assertEqual(versions, sorted(set(versions)))
        self.assertEqual(stored.keyed_clip, direct.keyed_clip)
        self.assertEqual(stored.reports, direct.reports)

    def test_submit_refuses_an_invalid_pipeline_before_queueing(self):
        operations = [tk.bake_operation()]  # bake evaluates curves: a sampled clip has none

        error = self.assertRaisesStatus(grpc.StatusCode.INVALID_ARGUMENT, self.client.submit,
                                        operations, clip=ramp_clip(10))

        self.assertEqual(error.details,
                         "operation 1 (bake): needs a keyed clip, got a sampled clip")

    def test_repeated_request_id_returns_the_first_job(self):
        request_id = "python-client-test-%d" % os.getpid()
        operations = [tk.retime_operation(speed="0s:2")]

        first = self.client.submit(operations, clip=ramp_clip(101), request_id=request_id)
        second = self.client.submit(operations, clip=ramp_clip(101), request_id=request_id)
        final = self.client.watch(first.job_id)
        result = self.client.result(first.job_id)

        self.assertEqual(second.job_id, first.job_id)
        self.assertEqual(final.state, tk.motion_service_pb2.JOB_STATE_SUCCEEDED,
                         final.error_message)
        self.assertEqual(result.clip.header.frame_count, 51)


class SmallMessageLimitTest(unittest.TestCase):
    """A server whose message limit (256 KiB) is below one channel of the clip sent (100 000
    samples, 800 KB) and below the client's default 1 MiB slices: the client holds its slices
    to half the server's limit."""

    LIMIT_BYTES = 256 << 10
    FRAMES = 100000

    def long_clip(self):
        wave = [math.sin(2.0 * math.pi * i / 1200.0) for i in range(self.FRAMES)]
        return tk.make_clip("long", 1.0 / 120, ["wave"], [wave])

    def test_upload_and_process_fit_the_servers_limit_then_sigterm_exits_zero(self):
        clip = self.long_clip()
        with RunningServer("--max_message_bytes", str(self.LIMIT_BYTES)) as server:
            with tk.connect(server.address, timeout=CALL_TIMEOUT_SECONDS) as client:
                uploaded = client.upload_clip(clip)
                result = client.process(clip, [tk.reduce_operation(scalar_tolerance=0.01)])
            whole_channel = self.upload_in_one_message(server.address, clip)

            status = server.stop()

        self.assertEqual(uploaded.sample_count, self.FRAMES)
        self.assertLess(result.reduction_report.key_count, self.FRAMES)
        self.assertLessEqual(result.reduction_report.max_error, 0.01 + BOUND_SLACK)
        # The limit is real: the same clip as one message is refused.
        self.assertEqual(whole_channel, grpc.StatusCode.RESOURCE_EXHAUSTED)
        self.assertEqual(status, 0)

    def upload_in_one_message(self, address, clip):
        """The status code of an upload sending the clip's channel as one message."""
        requests = [tk.motion_service_pb2.UploadClipRequest(header=clip.header),
                    tk.motion_service_pb2.UploadClipRequest(samples=clip.samples[0])]
        with grpc.insecure_channel(address) as channel:
            stub = tk.motion_service_pb2_grpc.MotionServiceStub(channel)
            try:
                stub.UploadClip(iter(requests), timeout=CALL_TIMEOUT_SECONDS)
            except grpc.RpcError as error:
                return error.code()
        return grpc.StatusCode.OK

    def test_stopped_server_is_unavailable(self):
        with RunningServer() as server:
            self.assertEqual(server.stop(), 0)
            with tk.connect(server.address, timeout=CALL_TIMEOUT_SECONDS,
                            max_attempts=1) as client:
                with self.assertRaises(tk.TempokeyError) as caught:
                    client.server_info()

        self.assertEqual(caught.exception.code, grpc.StatusCode.UNAVAILABLE)


class SilentPeer:
    """A loopback listener that accepts connections and never says a word: a server that hangs
    before its first answer, for the `with` block it is used in."""

    def __enter__(self):
        self._listener = socket.socket()
        self._listener.bind(("127.0.0.1", 0))
        self._listener.listen(16)
        self._held = []
        threading.Thread(target=self._accept, daemon=True).start()
        self.address = "127.0.0.1:%d" % self._listener.getsockname()[1]
        return self

    def _accept(self):
        try:
            while True:
                self._held.append(self._listener.accept()[0])
        except OSError:  # closed by __exit__
            pass

    def __exit__(self, *exc):
        self._listener.close()
        for connection in self._held:
            connection.close()


class TokenTransportTest(unittest.TestCase):
    """RFC 6750 5.3: bearer tokens travel over TLS only. A fake plaintext server on another
    machine's address recorded the package's token; now only this machine, TLS or an explicit
    allowance (a network that encrypts it itself) carry one. No connection is made here: the
    refusal comes first, and a client is created without connecting."""

    # The same table as the C++ client's (tests/proto/loopback_test.cc).
    LOCAL = ["127.0.0.1:50051", "localhost:50051", "LOCALHOST", "[::1]:50051", "::1",
             "dns:///localhost:50051", "dns:localhost:50051", "dns://8.8.8.8/127.0.0.1:50051",
             "ipv4:127.0.0.1:50051,127.0.0.2:50052", "ipv6:[::1]:50051",
             "unix:/run/tempokey.sock", "unix:///run/tempokey.sock", "unix-abstract:tempokey",
             "UNIX:/run/tempokey.sock"]
    REMOTE = ["10.0.0.1:50051", "tempokey.example.com:50051", "dns:///tempokey.svc:50051",
              "ipv4:127.0.0.1:50051,10.0.0.2:50051", "ipv4:", "ipv6:[2001:db8::1]:50051",
              "dns://127.0.0.1/example.com:50051", "dns://127.0.0.1", "xds:///tempokey",
              "vsock:3:50051", "127.attacker.invalid:50051", ":50051", ""]

    def test_loopback_targets_are_those_the_cpp_client_takes(self):
        self.assertEqual([t for t in self.LOCAL if not tk.is_loopback_target(t)], [])
        self.assertEqual([t for t in self.REMOTE if tk.is_loopback_target(t)], [])

    def test_a_token_is_not_sent_in_cleartext_to_another_machine(self):
        with self.assertRaises(ValueError) as caught:
            tk.connect("192.0.2.2:50051", token="s3cret")

        self.assertEqual(str(caught.exception),
                         "refusing to send the token in cleartext to 192.0.2.2:50051, which is not "
                         "on this machine: connect with tls=True, or pass "
                         "allow_plaintext_token=True only where the network itself is trusted, as "
                         "in a service mesh that encrypts it")
        for client in (tk.connect("192.0.2.2:50051", token="s3cret", allow_plaintext_token=True),
                       tk.connect("192.0.2.2:50051", token="s3cret", tls=True),
                       tk.connect("127.0.0.1:50051", token="s3cret"),
                       tk.connect("192.0.2.2:50051")):
            client.close()


class TargetPortTest(unittest.TestCase):
    """gRPC takes a port modulo 65536: 127.0.0.1:99999 reached 127.0.0.1:34463, a server of
    someone else's perhaps. A port of digits past 65535 is refused before any channel is made,
    in every form of target, as the C++ client refuses it (tests/proto/loopback_test.cc)."""

    def test_a_port_past_65535_is_refused_in_every_form_of_target(self):
        for target, port in [("127.0.0.1:65536", "65536"), ("127.0.0.1:99999", "99999"),
                             ("[::1]:70000", "70000"), ("dns:///localhost:100000", "100000"),
                             ("dns://8.8.8.8/host:65536", "65536"),
                             ("ipv4:127.0.0.1:1,127.0.0.2:65537", "65537"),
                             ("ipv6:[::1]:1,[::1]:99999", "99999")]:
            with self.subTest(target=target):
                with self.assertRaises(ValueError) as caught:
                    tk.connect(target)
                self.assertEqual(str(caught.exception),
                                 "target %s: port %s is not a TCP port (0 to 65535)"
                                 % (target, port))
        for target in ["127.0.0.1:65535", "127.0.0.1:0", "localhost", "[::1]:443", "::1",
                       "dns:///localhost:50051", "ipv4:127.0.0.1:1,127.0.0.2:2",
                       "unix:/run/tempokey.sock:99999", "xds:///tempokey:99999",
                       "example.com:https"]:
            with self.subTest(target=target):
                tk.connect(target).close()


class ClientDeadlineTest(unittest.TestCase):
    """gRPC reports a deadline that passed on the client's side as "Deadline Exceeded", which
    names neither the timeout nor how to change it; the package and the CLI name it."""

    def test_the_packages_deadline_error_names_the_timeout(self):
        with SilentPeer() as peer:
            with tk.connect(peer.address, timeout=0.3) as client:
                with self.assertRaises(tk.TempokeyError) as caught:
                    client.server_info()

        self.assertEqual(caught.exception.code, grpc.StatusCode.DEADLINE_EXCEEDED)
        self.assertEqual(caught.exception.details,
                         "no answer within the client's timeout of 0.3 s (retries included); "
                         "connect() with a longer timeout, or timeout=None for none")

    def test_the_clis_deadline_error_names_its_timeout_flag(self):
        with SilentPeer() as peer:
            run = run_cli("--server", peer.address, "--timeout", "0.3", "server-info")

        self.assertEqual(run.returncode, 1, run.stderr)
        self.assertEqual(run.stderr, "error: server: DEADLINE_EXCEEDED: no answer within --timeout "
                                     "(default 60 s, retries included); give a longer --timeout, "
                                     "or 0 for none\n")


class WorldErrorTest(ServerTestCase):
    """Joints' world-position error (SPEC 4.4) in the report, and the joint tolerance."""

    def cli_report(self, *args):
        with tempfile.TemporaryDirectory() as directory:
            cli = run_cli("--server", _server.address, "reduce", CMU_BVH, "-o",
                          os.path.join(directory, "cli.json"), *args)
        self.assertEqual(cli.returncode, 0, cli.stderr)
        return [line for line in cli.stdout.splitlines()
                if line.startswith(("figure height:", "joint "))]

    def test_default_reduction_reports_what_the_cli_prints(self):
        result = self.client.process(cmu_clip(), [tk.reduce_operation()])

        world = result.world_error
        self.assertIsNotNone(world)
        self.assertGreater(world.max_error_units, world.rms_error_units)
        self.assertEqual(world.joint_tolerance_units, 0.0)
        self.assertEqual(tk.world_error_lines(world), self.cli_report())

    def test_joint_tolerance_in_percent_bounds_every_joint(self):
        result = self.client.process(cmu_clip(), [tk.reduce_operation(joint_tolerance="0.5%")])

        world = result.world_error
        bound = 0.005 * world.figure_height_units
        self.assertAlmostEqual(world.joint_tolerance_units, bound, delta=1e-12 * bound)
        self.assertLessEqual(world.max_error_units, world.joint_tolerance_units)
        self.assertEqual(tk.world_error_lines(world), self.cli_report("--joint-tolerance", "0.5%"))

    def test_joint_tolerance_in_file_units_travels_as_its_own_field(self):
        units = tk.reduce_operation(joint_tolerance=0.25)
        text = tk.reduce_operation(joint_tolerance="0.25")
        percent = tk.reduce_operation(joint_tolerance="1%")

        self.assertEqual(units.reduce.tolerance.max_joint_error, 0.25)
        self.assertEqual(text, units)
        self.assertEqual(percent.reduce.tolerance.max_joint_error_percent_of_height, 1.0)
        with self.assertRaisesRegex(ValueError, "got '1cm'"):
            tk.reduce_operation(joint_tolerance="1cm")
        with self.assertRaises(ValueError):
            tk.reduce_operation(method="paper", joint_tolerance=1)
        result = self.client.process(cmu_clip(), [units])
        self.assertEqual(result.world_error.joint_tolerance_units, 0.25)
        self.assertLessEqual(result.world_error.max_error_units, 0.25)


class ExampleScriptTest(unittest.TestCase):
    """example_pipeline.py as a user runs it: a subprocess, its exit code, stdout and file."""

    def setUp(self):
        directory = tempfile.TemporaryDirectory()
        self.addCleanup(directory.cleanup)
        self.directory = directory.name

    def run_example(self, *args):
        return subprocess.run([PYTHON, EXAMPLE] + list(args), capture_output=True, text=True,
                              timeout=SUBPROCESS_TIMEOUT_SECONDS)

    def write_bvh(self, name, text):
        path = os.path.join(self.directory, name)
        with open(path, "w", encoding="utf-8") as stream:
            stream.write(text)
        return path

    def test_capture_is_retimed_reduced_and_written_as_keyed_json(self):
        output = os.path.join(self.directory, "131_01-slow.json")
        # Half speed from 2 s to 4 s: those 2 source seconds last 4, T_o = T_s + 2.
        frame_time = 0.0083333
        expected_frames = math.floor(((993 * frame_time) + 2.0) / frame_time + 1e-9) + 1

        run = self.run_example("--server", _server.address, CMU_BVH, "-o", output,
                               "--speed", "0s:1,2s:1,2s:0.5,4s:0.5,4s:1", "--tolerance", "0.5")

        self.assertEqual(run.returncode, 0, run.stderr)
        self.assertEqual(run.stderr, "")
        lines = run.stdout.splitlines()
        self.assertEqual(len(lines), 1, run.stdout)
        summary = re.fullmatch(r"131_01: 994 -> (\d+) frames, (\d+) of (\d+) keys kept "
                               r"\([0-9.]+ %\), max error ([0-9.e+-]+) at \S+ frame \d+, "
                               r"joint error [0-9.e+-]+ \([0-9.]+ % of height\) at [^,]+ frame "
                               r"\d+", lines[0])
        self.assertIsNotNone(summary, lines[0])
        frames, keys, samples, max_error = summary.groups()
        self.assertEqual(int(frames), expected_frames)
        self.assertEqual(int(samples), expected_frames * 96)
        self.assertLess(int(keys), int(samples))
        self.assertLessEqual(float(max_error), 0.5 + BOUND_SLACK)
        with open(output, encoding="utf-8") as stream:
            document = json.load(stream)
        self.assertEqual(document["format"], "tempokey.keyed_clip")
        self.assertEqual(document["frame_count"], expected_frames)
        self.assertEqual(document["frame_time_seconds"], frame_time)
        self.assertEqual(len(document["channels"]), 96)
        self.assertEqual(sum(len(c["keys"]) for c in document["channels"]), int(keys))

    def test_malformed_bvh_exits_one_with_one_line_naming_the_line(self):
        path = self.write_bvh("bad.bvh", "HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n"
                                         "\tCHANNELS 3 Xposition Yposition\n}\nMOTION\n")
        output = os.path.join(self.directory, "bad.json")

        run = self.run_example("--server", _server.address, path, "-o", output)

        self.assertEqual(run.returncode, 1)
        self.assertEqual(run.stdout, "")
        self.assertEqual(run.stderr, "error: %s:5:2: CHANNELS declares 3 channels but 2 names "
                                     "follow\n" % path)
        self.assertFalse(os.path.exists(output))

    def test_short_motion_section_names_the_last_line(self):
        path = self.write_bvh("short.bvh", "HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n"
                                           "\tCHANNELS 1 Xposition\n}\nMOTION\nFrames: 3\n"
                                           "Frame Time: 0.1\n1\n2\n")

        run = self.run_example("--server", _server.address, path, "-o",
                               os.path.join(self.directory, "short.json"))

        self.assertEqual(run.returncode, 1)
        self.assertEqual(run.stderr, "error: %s:11:1: expected 3 motion rows (Frames: 3), got 2\n"
                         % path)

    def test_server_refusal_exits_one_with_the_servers_message(self):
        output = os.path.join(self.directory, "refused.json")

        run = self.run_example("--server", _server.address, CMU_BVH, "-o", output,
                               "--tolerance", "-1")

        self.assertEqual(run.returncode, 1)
        self.assertEqual(run.stderr, "error: server: INVALID_ARGUMENT: operation 2 (reduce): "
                                     "tolerance.max_rotation_error_degrees must be > 0, got -1\n")
        self.assertFalse(os.path.exists(output))

    def test_bad_speed_is_a_usage_error(self):
        run = self.run_example(CMU_BVH, "-o", os.path.join(self.directory, "x.json"),
                               "--speed", "0s:1,fast")

        self.assertEqual(run.returncode, 2)
        self.assertIn("speed knot 2 ('fast') is not time:speed", run.stderr)


class BvhReaderTest(unittest.TestCase):
    """The package's BVH reader on inputs the C++ reader also accepts."""

    def test_line_endings_exponents_and_end_sites(self):
        text = ("\ufeffHIERARCHY\r\nROOT Hips\r{\n OFFSET 0 +1 -2.5e-1\n CHANNELS 2 Zrotation "
                "Xposition\n End Site\n {\n  OFFSET 0 1 0\n }\n}\nMOTION\nFrames:2\n"
                "Frame Time:\t0.0083333\n1e1 2\n\n3 4.5\n")

        clip = tk.parse_bvh(text, "dir/walk.bvh")

        self.assertEqual(clip.name, "walk")
        self.assertEqual(clip.frame_time_seconds, 0.0083333)
        self.assertEqual(clip.joints[0].offset, (0.0, 1.0, -0.25))
        self.assertEqual(clip.joints[0].end_sites, [(0.0, 1.0, 0.0)])
        self.assertEqual(clip.channels, [(0, "Zrotation"), (0, "Xposition")])
        self.assertEqual(clip.samples, [[10.0, 3.0], [2.0, 4.5]])

    def test_errors_name_line_and_column(self):
        cases = [
            ("", "x.bvh:1:1: the file is empty"),
            ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 1 Wrotation\n}\n",
             'x.bvh:5:12: expected a channel name (Xposition, Yposition, Zposition, Xrotation, '
             'Yrotation, Zrotation), got "Wrotation"'),
            ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\nMOTION\n"
             "Frames: 1\nFrame Time: 0.1\nnan\n",
             'x.bvh:10:1: expected a number for motion row 1, got "nan"'),
            ("HIERARCHY\nROOT A\n{\nOFFSET 0 0 0\nJOINT A\n{\nOFFSET 0 0 0\n}\n}\n",
             'x.bvh:5:7: joint name "A" is used twice (first on line 2)'),
        ]
        for text, message in cases:
            with self.subTest(message=message):
                with self.assertRaises(tk.BvhError) as caught:
                    tk.parse_bvh(text, "x.bvh")
                self.assertEqual(str(caught.exception), message)


if __name__ == "__main__":
    unittest.main()
