"""The studio's HTTP/JSON API against a real tempokey-server: the same tempokey.v1 service as
gRPC, in protobuf's JSON mapping, through the same handlers.

Each test compares the HTTP answer with the gRPC answer of the same server (Python's grpc stubs
generated from the same protos) or with what the README documents: status codes, NDJSON streams,
tokens, the browser rules, size limits, TLS and mutual TLS with the server's own certificates,
and the loopback rule. Run by CTest (label `browser`, no browser needed).
"""

import base64
import http.client
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
import unittest
import urllib.error
import urllib.request

import grpc
from google.protobuf import json_format

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from studio_server import StudioServer, env_path  # noqa: E402
from tempokey.v1 import clip_pb2, editing_pb2, motion_service_pb2, motion_service_pb2_grpc, operations_pb2  # noqa: E402

SHARED_DIR = env_path("TEMPOKEY_SHARED_DIR")
CMU = os.path.join(SHARED_DIR, "data", "bvh", "cmu", "131_01.bvh")
CALL_TIMEOUT_SECONDS = 60
SERVICE = "tempokey.v1.MotionService/"


def post(url, method, body, content_type="application/json", headers=None, context=None):
    """(HTTP status, headers, body text) of one API call."""
    data = body if isinstance(body, bytes) else body.encode()
    request = urllib.request.Request(url + SERVICE + method, data=data, method="POST",
                                     headers={"Content-Type": content_type, **(headers or {})})
    try:
        with urllib.request.urlopen(request, timeout=CALL_TIMEOUT_SECONDS, context=context) as r:
            return r.status, r.headers, r.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, error.headers, error.read().decode()


def loads(text):
    """JSON text as Python values, keeping the sign of a negative zero ("-0" is a double here:
    the JSON mapping writes 64-bit integers as strings)."""
    return json.loads(text, parse_int=lambda s: -0.0 if s == "-0" else int(s))


def ndjson(text):
    return [loads(line) for line in text.splitlines() if line.strip()]


def parse_clip_request():
    with open(CMU, "rb") as f:
        content = f.read()
    return {"fileName": "131_01.bvh", "content": base64.b64encode(content).decode()}


class HttpApiTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.server = StudioServer().__enter__()
        cls.url = cls.server.http_url
        cls.channel = grpc.insecure_channel(cls.server.grpc_target,
                                            options=[("grpc.max_receive_message_length", -1)])
        cls.stub = motion_service_pb2_grpc.MotionServiceStub(cls.channel)
        status, _, body = post(cls.url, "ParseClipFile", json.dumps(parse_clip_request()))
        assert status == 200, body
        cls.clip_id = json.loads(body)["clipId"]

    @classmethod
    def tearDownClass(cls):
        cls.channel.close()
        cls.server.__exit__(None, None, None)
        assert cls.server.exit_code == 0, cls.server.server_log()

    def assert_same_messages(self, a, b):
        """Equal message lists, reported by the first difference (a full diff of megabytes of
        samples would take minutes)."""
        self.assertEqual(len(a), len(b))
        for i, (x, y) in enumerate(zip(a, b)):
            self.assertTrue(x == y, "message %d differs" % i)

    def test_unary_answer_is_the_grpc_message_in_json(self):
        status, headers, body = post(self.url, "GetServerInfo", "{}")

        self.assertEqual(status, 200)
        self.assertEqual(headers["Content-Type"], "application/json")
        over_http = json_format.ParseDict(loads(body), motion_service_pb2.ServerInfo())
        over_grpc = self.stub.GetServerInfo(motion_service_pb2.GetServerInfoRequest(),
                                            timeout=CALL_TIMEOUT_SECONDS)
        self.assertEqual(over_http, over_grpc)
        self.assertEqual([f.name for f in over_http.export_formats], ["bvh", "csv", "json", "anim", "gltf", "glb"])

    def test_errors_are_grpc_codes_as_http_statuses_with_the_same_message(self):
        cases = [("GetJob", {"jobId": "job-unknown"}, motion_service_pb2.GetJobRequest, 404, "NOT_FOUND"),
                 ("ParseSpeedKnots", {"text": "0s:1,2x:0.5"}, editing_pb2.ParseSpeedKnotsRequest, 400,
                  "INVALID_ARGUMENT"),
                 ("PlanRetime", {"clipId": self.clip_id, "retime": {"speedOverSource": [
                     {"time": {"seconds": 0}, "speed": -1}]}}, editing_pb2.PlanRetimeRequest, 400,
                  "INVALID_ARGUMENT")]
        for method, request, request_type, http_status, code in cases:
            with self.subTest(method=method):
                status, _, body = post(self.url, method, json.dumps(request))
                answer = json.loads(body)
                rpc = getattr(self.stub, method)
                grpc_request = json_format.ParseDict(request, request_type())
                with self.assertRaises(grpc.RpcError) as raised:
                    rpc(grpc_request, timeout=CALL_TIMEOUT_SECONDS)

                self.assertEqual(status, http_status)
                self.assertEqual(answer["status"], code)
                self.assertEqual(answer["code"], raised.exception.code().value[0])
                self.assertEqual(answer["message"], raised.exception.details())

    def test_a_field_over_its_limit_is_413_without_retry_after(self):
        # A request over a limit is refused again however late it comes back: 413 Content Too
        # Large (RFC 9110, 15.5.14), not the 429 that tells a client to come back (RFC 6585, 4).
        # Over gRPC both are RESOURCE_EXHAUSTED; the server's retry hint tells them apart.
        request = {"clipId": self.clip_id,
                   "operations": [{"retime": {"speedOverSource": [{"time": {"seconds": 0}, "speed": 0.5}]}}],
                   "labels": {"k%d" % i: "v" for i in range(65)}}
        status, headers, body = post(self.url, "SubmitJob", json.dumps(request))
        with self.assertRaises(grpc.RpcError) as raised:
            self.stub.SubmitJob(json_format.ParseDict(request, motion_service_pb2.SubmitJobRequest()),
                                timeout=CALL_TIMEOUT_SECONDS)
        grpc_trailers = dict(raised.exception.trailing_metadata() or ())

        self.assertEqual(status, 413, body)
        self.assertIsNone(headers.get("Retry-After"))
        self.assertEqual(json.loads(body), {"code": 8, "status": "RESOURCE_EXHAUSTED",
                                            "message": "labels has 65 entries, over the limit of 64"})
        self.assertEqual(raised.exception.code(), grpc.StatusCode.RESOURCE_EXHAUSTED)
        self.assertNotIn("retry-after-ms", grpc_trailers)

    def test_an_error_quoting_bytes_that_are_not_utf8_is_still_json(self):
        # The message quotes what the client sent; bytes that are not UTF-8 were written raw, and
        # the body was neither UTF-8 nor JSON to Python's own decoders (RFC 8259, 8.1).
        status, headers, body = post(self.url, "ParseSpeedKnots", b'{"text":"\xff\xfe"}')

        self.assertEqual(status, 400)  # post() decodes the body as strict UTF-8
        self.assertEqual(headers["Content-Type"], "application/json")
        self.assertEqual(json.loads(body)["status"], "INVALID_ARGUMENT")

    def test_malformed_file_is_refused_with_its_location(self):
        with open(CMU) as f:
            lines = f.read().split("\n")
        lines[4] = lines[4].replace("Yposition", "Ypozition")
        request = {"fileName": "broken.bvh",
                   "content": base64.b64encode("\n".join(lines).encode()).decode()}

        status, _, body = post(self.url, "ParseClipFile", json.dumps(request))

        self.assertEqual(status, 400)
        self.assertRegex(json.loads(body)["message"], r"^broken\.bvh:5:\d+: unknown channel name")

    def test_server_streaming_answer_is_ndjson_of_the_grpc_messages(self):
        status, headers, body = post(self.url, "GetClip", json.dumps({"clipId": self.clip_id}))

        self.assertEqual(status, 200)
        self.assertEqual(headers["Content-Type"], "application/x-ndjson")
        over_http = [json_format.ParseDict(line["result"], motion_service_pb2.ResultPart())
                     for line in ndjson(body)]
        over_grpc = list(self.stub.GetClip(editing_pb2.GetClipRequest(clip_id=self.clip_id),
                                           timeout=CALL_TIMEOUT_SECONDS))
        self.assert_same_messages(over_http, over_grpc)
        self.assertEqual(len(over_http), 1 + 96)  # header, then one slice per channel

    def test_client_streaming_upload_takes_ndjson_and_gives_the_same_clip_id(self):
        parts = list(self.stub.GetClip(editing_pb2.GetClipRequest(clip_id=self.clip_id),
                                       timeout=CALL_TIMEOUT_SECONDS))
        upload = [{"header": json_format.MessageToDict(parts[0].header.clip)}]
        upload += [{"samples": json_format.MessageToDict(p.samples)} for p in parts[1:]]

        status, _, body = post(self.url, "UploadClip", "\n".join(json.dumps(m) for m in upload),
                               content_type="application/x-ndjson")

        self.assertEqual(status, 200, body)
        self.assertEqual(json.loads(body)["clipId"], self.clip_id)
        self.assertEqual(json.loads(body)["alreadyStored"], True)

    def test_bidirectional_process_matches_grpc(self):
        parts = list(self.stub.GetClip(editing_pb2.GetClipRequest(clip_id=self.clip_id),
                                       timeout=CALL_TIMEOUT_SECONDS))
        retime = operations_pb2.Operation(retime=operations_pb2.RetimeOperation(
            speed_over_source=[operations_pb2.SpeedKnot(time=operations_pb2.TimePoint(seconds=0), speed=1),
                               operations_pb2.SpeedKnot(time=operations_pb2.TimePoint(seconds=2), speed=0.5)]))
        requests = [motion_service_pb2.ProcessRequest(header=parts[0].header.clip)]
        requests += [motion_service_pb2.ProcessRequest(samples=p.samples) for p in parts[1:]]
        requests.append(motion_service_pb2.ProcessRequest(
            start=motion_service_pb2.ProcessStart(operations=[retime])))

        status, _, body = post(self.url, "Process",
                               "\n".join(json_format.MessageToJson(r, indent=None) for r in requests),
                               content_type="application/x-ndjson")

        self.assertEqual(status, 200, body)
        over_http = [json_format.ParseDict(line["result"], motion_service_pb2.ProcessResponse())
                     for line in ndjson(body)]
        over_grpc = list(self.stub.Process(iter(requests), timeout=CALL_TIMEOUT_SECONDS))
        results = lambda responses: [r.result for r in responses if r.HasField("result")]
        self.assert_same_messages(results(over_http), results(over_grpc))
        self.assertEqual(results(over_http)[0].header.reports[0].retime.output_frame_count, 1840)

    def test_browser_rules_refuse_other_origins_hosts_and_content_types(self):
        cases = [({"Origin": "http://evil.example"}, "application/json", 403, "PERMISSION_DENIED"),
                 ({"Host": "evil.example:80"}, "application/json", 403, "PERMISSION_DENIED"),
                 ({}, "text/plain", 400, "INVALID_ARGUMENT")]
        for headers, content_type, http_status, code in cases:
            with self.subTest(headers=headers, content_type=content_type):
                status, _, body = post(self.url, "GetServerInfo", "{}", content_type, headers)
                self.assertEqual(status, http_status)
                self.assertEqual(json.loads(body)["status"], code)
        same_origin = {"Origin": self.url.rstrip("/")}
        self.assertEqual(post(self.url, "GetServerInfo", "{}", headers=same_origin)[0], 200)

    def test_a_refused_body_sent_whole_by_http_client_still_gets_its_answer(self):
        """Python's http.client sends the whole body before it reads the answer. A refusal
        (a form's content type) comes first, and the rest of the body, 3 MiB in 48 pieces 50 ms
        apart, is still taken: the answer read after it is the whole refusal. With a linger of
        2 s in all, the body met a reset and http.client lost the answer (BrokenPipeError)."""
        host, port = self.url.split("//")[1].rstrip("/").split(":")
        piece = b" " * (64 << 10)

        def body():
            for _ in range(48):
                time.sleep(0.05)
                yield piece

        connection = http.client.HTTPConnection(host, int(port), timeout=CALL_TIMEOUT_SECONDS)
        try:
            connection.request("POST", "/" + SERVICE + "GetServerInfo", body=body(),
                               headers={"Content-Type": "text/plain",
                                        "Content-Length": str(48 * len(piece))})
            response = connection.getresponse()
            status, answer = response.status, json.loads(response.read())
        finally:
            connection.close()
        self.assertEqual(status, 400)
        self.assertEqual(answer["status"], "INVALID_ARGUMENT")

    def test_a_member_named_twice_is_refused_not_the_last_one_taken(self):
        """protobuf's JSON parser takes the last of a repeated name: {"jobId":"a","jobId":"b"}
        looked up "b". The front end refuses the request instead."""
        status, _, body = post(self.url, "GetJob", '{"jobId":"job-a","jobId":"job-b"}')
        self.assertEqual(status, 400)
        self.assertIn('member "jobId" is named twice in one object', json.loads(body)["message"])

    def test_unknown_method_and_wrong_verbs(self):
        status, _, body = post(self.url, "NoSuchMethod", "{}")
        self.assertEqual(status, 501)
        self.assertEqual(json.loads(body)["status"], "UNIMPLEMENTED")
        with self.assertRaises(urllib.error.HTTPError) as raised:
            urllib.request.urlopen(self.url + SERVICE + "GetServerInfo", timeout=CALL_TIMEOUT_SECONDS)
        self.assertEqual(raised.exception.code, 405)

    def test_static_files_are_the_page_and_three_js_with_nothing_outside(self):
        with urllib.request.urlopen(self.url, timeout=CALL_TIMEOUT_SECONDS) as r:
            page = r.read().decode()
            self.assertIn("default-src 'self'", r.headers["Content-Security-Policy"])
        self.assertIn("tempokey studio", page)
        self.assertNotIn("http://", page.replace("http-equiv", ""))
        self.assertNotIn("https://", page)
        with urllib.request.urlopen(self.url + "three/build/three.module.js", timeout=CALL_TIMEOUT_SECONDS) as r:
            self.assertTrue(r.headers["Content-Type"].startswith("text/javascript"))
        host, port = self.url.split("//")[1].rstrip("/").split(":")
        for path in ["/../../etc/passwd", "/.hidden", "/three/../../../etc/passwd", "/js/nothing.js"]:
            with self.subTest(path=path):
                connection = http.client.HTTPConnection(host, int(port), timeout=CALL_TIMEOUT_SECONDS)
                connection.request("GET", path)
                response = connection.getresponse()
                response.read()
                connection.close()
                self.assertEqual(response.status, 404)


class HttpApiServerFlagsTest(unittest.TestCase):
    def test_bearer_token_is_checked_by_the_same_code_for_http(self):
        with tempfile.TemporaryDirectory() as work:
            token_file = os.path.join(work, "tokens")
            with open(token_file, "w") as f:
                f.write("s3cret\n")
            with StudioServer("--auth_token_file", token_file) as server:
                missing = post(server.http_url, "GetServerInfo", "{}")
                wrong = post(server.http_url, "GetServerInfo", "{}", headers={"Authorization": "Bearer nope"})
                right = post(server.http_url, "GetServerInfo", "{}", headers={"Authorization": "Bearer s3cret"})
                with urllib.request.urlopen(server.http_url, timeout=CALL_TIMEOUT_SECONDS) as page:
                    page_status = page.status
            self.assertEqual(server.exit_code, 0)

        self.assertEqual((missing[0], json.loads(missing[2])["status"]), (401, "UNAUTHENTICATED"))
        # An HTTP client is told of the HTTP header it lacks (checked before the body is read),
        # not of gRPC metadata.
        self.assertEqual(json.loads(missing[2])["message"], 'missing "Authorization: Bearer <token>" header')
        self.assertEqual((wrong[0], json.loads(wrong[2])["message"]), (401, "the bearer token is not accepted"))
        self.assertEqual(right[0], 200)
        self.assertEqual(page_status, 200)

    def test_request_message_over_the_size_limit_is_refused(self):
        with StudioServer("--max_message_bytes", "65536") as server:
            status, _, body = post(server.http_url, "ParseClipFile", json.dumps(parse_clip_request()))

        self.assertEqual(status, 413)  # Content Too Large: retrying cannot help (429 says it can)
        self.assertEqual(json.loads(body)["message"], "a request message is over the limit of 65536 bytes of JSON")

    def test_a_busy_server_answers_429_with_retry_after(self):
        # 429 "Too Many Requests" tells a client to come back (RFC 6585, 4), and Retry-After when.
        # The only stream slot held by a gRPC upload that has not ended: an HTTP upload is told
        # to come back, and when. The slot is known to be held (a gRPC WatchJob refused for it)
        # before the HTTP call is made; a held call that lost the slot to a probe is started again.
        with StudioServer("--max_concurrent_streams", "1") as server:
            channel = grpc.insecure_channel(server.grpc_target)
            grpc.channel_ready_future(channel).result(timeout=CALL_TIMEOUT_SECONDS)
            stub = motion_service_pb2_grpc.MotionServiceStub(channel)
            release = threading.Event()

            def held_upload():  # the call starts, and sends nothing until released
                release.wait(CALL_TIMEOUT_SECONDS)
                yield from ()

            def slot_taken():
                try:
                    for _ in stub.WatchJob(motion_service_pb2.WatchJobRequest(job_id="job-none"),
                                           timeout=CALL_TIMEOUT_SECONDS):
                        pass
                except grpc.RpcError as error:
                    return error.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
                return False

            held = None
            deadline = time.monotonic() + CALL_TIMEOUT_SECONDS
            taken = False
            while not taken and time.monotonic() < deadline:
                if held is None or held.done():
                    held = stub.UploadClip.future(held_upload(), timeout=CALL_TIMEOUT_SECONDS)
                taken = slot_taken()
            busy = post(server.http_url, "UploadClip", "{}", content_type="application/x-ndjson")
            release.set()
            held.exception()  # the held call ends (refused: it sent no header)
            channel.close()

        self.assertTrue(taken, "the held upload never took the only stream slot")
        self.assertEqual(busy[0], 429, busy[2])
        self.assertEqual(busy[1].get("Retry-After"), "1")
        self.assertEqual(json.loads(busy[2]), {"code": 8, "status": "RESOURCE_EXHAUSTED",
                                               "message": "too many streaming calls open (limit 1); retry later",
                                               "retryAfterMs": 1000})

    def test_non_loopback_http_address_without_tls_is_refused_like_address(self):
        server = env_path("TEMPOKEY_SERVER")
        run = subprocess.run([server, "--address", "127.0.0.1:0", "--http_address", "0.0.0.0:0"],
                             capture_output=True, text=True, timeout=CALL_TIMEOUT_SECONDS)

        self.assertEqual(run.returncode, 2)
        self.assertIn("refusing to serve HTTP on non-loopback address 0.0.0.0:0 without TLS", run.stderr)

    def test_http_beside_a_tls_server_is_loopback_only_and_refused_with_client_certificates(self):
        with tempfile.TemporaryDirectory() as work:
            make_certificates(work)
            path = lambda name: os.path.join(work, name)
            tls = ["--tls_cert", path("server.pem"), "--tls_key", path("server.key")]
            with StudioServer(*tls) as server:
                status = post(server.http_url, "GetServerInfo", "{}")[0]
            self.assertEqual(server.exit_code, 0)
            binary = env_path("TEMPOKEY_SERVER")
            remote = subprocess.run([binary, "--address", "127.0.0.1:0", "--http_address", "0.0.0.0:0", *tls],
                                    capture_output=True, text=True, timeout=CALL_TIMEOUT_SECONDS)
            mutual = subprocess.run([binary, "--address", "127.0.0.1:0", "--http_address", "127.0.0.1:0", *tls,
                                     "--tls_client_ca", path("ca.pem")],
                                    capture_output=True, text=True, timeout=CALL_TIMEOUT_SECONDS)

        self.assertEqual(status, 200)
        self.assertEqual(remote.returncode, 2)
        self.assertIn("refusing to serve HTTP on non-loopback address 0.0.0.0:0 without TLS", remote.stderr)
        self.assertEqual(mutual.returncode, 2)
        self.assertIn("--http_address cannot check client certificates", mutual.stderr)


def make_certificates(work):
    """A CA and a server certificate for 127.0.0.1 signed by it (and a client one)."""
    def run(*args):
        subprocess.run(["/usr/bin/openssl", *args], cwd=work, check=True, capture_output=True,
                       timeout=CALL_TIMEOUT_SECONDS)
    with open(os.path.join(work, "server.ext"), "w") as f:
        f.write("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    with open(os.path.join(work, "client.ext"), "w") as f:
        f.write("extendedKeyUsage=clientAuth\n")
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    run("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=studio test CA")
    for serial, name in enumerate(["server", "client"], start=1):
        run("req", *ec, "-keyout", name + ".key", "-out", name + ".csr", "-subj", "/CN=" + name)
        run("x509", "-req", "-in", name + ".csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-set_serial",
            str(serial), "-days", "2", "-out", name + ".pem", "-extfile", name + ".ext")


if __name__ == "__main__":
    unittest.main()
