#!/usr/bin/env python3
"""Memory and slow-client figures of a tempokey-server binary under hostile requests.

Starts the given server itself on loopback, runs one scenario and prints its figures; the
server's memory is read from /proc/<pid>/status (VmRSS, and VmHWM after resetting it through
/proc/<pid>/clear_refs). Any build can be measured, so figures before and after a change come
from the same script:

    PYTHONPATH=build/python python3 bench/hostile_figures.py --server build/server/tempokey-server all

Scenarios:
  declared   4 uploads, an inline SubmitJob and a Process call, each declaring 3 channels x
             10 000 000 frames and sending one sample at the last frame of each channel: the
             server's peak resident-set growth.
  listjobs   jobs with 26 retimes of --knots knots each, then ListJobs(page_size=100): the
             first page's size, all pages, and the peak resident set while listing.
  deletes    the same jobs deleted: the resident set before, with them, and after.
  metrics    --slow clients each holding half a request on the metrics port, then one scrape:
             how long it took (capped at 120 s).
"""

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import time

import grpc

from tempokey.v1 import clip_pb2
from tempokey.v1 import motion_service_pb2
from tempokey.v1 import motion_service_pb2_grpc
from tempokey.v1 import operations_pb2

DECLARED_FRAMES = 10_000_000
UNLIMITED = [("grpc.max_receive_message_length", -1), ("grpc.max_send_message_length", -1)]


def status_kib(pid, field):
    with open("/proc/%d/status" % pid) as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def reset_peak(pid):
    with open("/proc/%d/clear_refs" % pid, "w") as refs:
        refs.write("5")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """A tempokey-server child on 127.0.0.1 (SIGTERM on exit)."""

    def __init__(self, binary, flags=()):
        self.port = free_port()
        self.log = tempfile.TemporaryFile()
        self.process = subprocess.Popen(
            [binary, "--address=127.0.0.1:%d" % self.port, "--log_level=warn"] + list(flags),
            stdout=subprocess.DEVNULL, stderr=self.log)
        self.channel = grpc.insecure_channel("127.0.0.1:%d" % self.port, options=UNLIMITED)
        grpc.channel_ready_future(self.channel).result(timeout=60)
        self.stub = motion_service_pb2_grpc.MotionServiceStub(self.channel)

    @property
    def pid(self):
        return self.process.pid

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.channel.close()
        self.process.terminate()
        try:
            self.process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


def header(frames, channels):
    joint = clip_pb2.Joint(name="root", parent_index=-1)
    kinds = [clip_pb2.CHANNEL_KIND_Z_ROTATION, clip_pb2.CHANNEL_KIND_X_ROTATION,
             clip_pb2.CHANNEL_KIND_Y_ROTATION]
    return clip_pb2.ClipHeader(
        name="declared", frame_time_seconds=1 / 120, frame_count=frames, joints=[joint],
        channels=[clip_pb2.ChannelInfo(joint_index=0, kind=kinds[c % 3]) for c in range(channels)])


def last_frame(channel):
    return clip_pb2.ChannelSamples(channel_index=channel, first_frame=DECLARED_FRAMES - 1,
                                   samples=[1.0])


def small_clip(frames=200):
    clip = clip_pb2.Clip(header=header(frames, 3))
    for c in range(3):
        clip.samples.add(channel_index=c, first_frame=0, samples=[float(f % 90) for f in range(frames)])
    return clip


def wrap():
    return [operations_pb2.Operation(convert=operations_pb2.ConvertOperation(wrap_rotations=True))]


def code_of(call):
    try:
        call()
        return "OK"
    except grpc.RpcError as error:
        return error.code().name


def declared(binary):
    with Server(binary, ["--workers=1"]) as server:
        stub = server.stub
        warm = motion_service_pb2.SubmitJobRequest(inline_clip=small_clip(), operations=wrap())
        stub.SubmitJob(warm, timeout=60)
        reset_peak(server.pid)
        before = status_kib(server.pid, "VmHWM")
        big = header(DECLARED_FRAMES, 3)

        def upload_messages():
            yield motion_service_pb2.UploadClipRequest(header=big)
            for c in range(3):
                yield motion_service_pb2.UploadClipRequest(samples=last_frame(c))
        uploads = [stub.UploadClip.future(upload_messages(), timeout=600) for _ in range(4)]
        codes = [code_of(u.result) for u in uploads]
        inline = motion_service_pb2.SubmitJobRequest(
            inline_clip=clip_pb2.Clip(header=big, samples=[last_frame(c) for c in range(3)]),
            operations=wrap())
        codes.append(code_of(lambda: stub.SubmitJob(inline, timeout=600)))

        def process_messages():
            yield motion_service_pb2.ProcessRequest(header=big)
            for c in range(3):
                yield motion_service_pb2.ProcessRequest(samples=last_frame(c))
            yield motion_service_pb2.ProcessRequest(
                start=motion_service_pb2.ProcessStart(operations=wrap()))
        codes.append(code_of(lambda: list(stub.Process(process_messages(), timeout=600))))
        peak = status_kib(server.pid, "VmHWM")
        print("declared: inline request %d bytes; codes %s" % (inline.ByteSize(), ",".join(codes)))
        print("declared: peak RSS %.1f MiB -> %.1f MiB (+%.1f MiB)" %
              (before / 1024, peak / 1024, (peak - before) / 1024))


def submit_heavy_jobs(stub, jobs, knots):
    clip_id = stub.UploadClip(iter([
        motion_service_pb2.UploadClipRequest(header=header(200, 3))] + [
        motion_service_pb2.UploadClipRequest(samples=clip_pb2.ChannelSamples(
            channel_index=c, first_frame=0, samples=[float(f % 90) for f in range(200)]))
        for c in range(3)]), timeout=60).clip_id
    operations = []
    for _ in range(26):
        retime = operations_pb2.RetimeOperation()
        for k in range(knots):
            retime.speed_over_source.add(time=operations_pb2.TimePoint(seconds=k * 1e-5), speed=1.0)
        operations.append(operations_pb2.Operation(retime=retime))
    request = motion_service_pb2.SubmitJobRequest(clip_id=clip_id, operations=operations)
    ids = [stub.SubmitJob(request, timeout=600).job_id for _ in range(jobs)]
    for job_id in ids:
        for _ in stub.WatchJob(motion_service_pb2.WatchJobRequest(job_id=job_id), timeout=600):
            pass
    return ids, request.ByteSize()


def listjobs_and_deletes(binary, jobs, knots, scenario):
    with Server(binary) as server:
        stub = server.stub
        baseline = status_kib(server.pid, "VmRSS")
        ids, request_bytes = submit_heavy_jobs(stub, jobs, knots)
        stored = status_kib(server.pid, "VmRSS")
        if scenario in ("listjobs", "all"):
            reset_peak(server.pid)
            before = status_kib(server.pid, "VmHWM")
            token, pages, sizes = "", 0, []
            while True:
                page = stub.ListJobs(motion_service_pb2.ListJobsRequest(page_size=100,
                                                                        page_token=token),
                                     timeout=600)
                pages += 1
                sizes.append(page.ByteSize())
                token = page.next_page_token
                if not token:
                    break
            peak = status_kib(server.pid, "VmHWM")
            print("listjobs: %d jobs of %d bytes submitted each; %d pages, first %.2f MiB, "
                  "largest %.2f MiB, all %.2f MiB; peak RSS while listing +%.1f MiB" %
                  (jobs, request_bytes, pages, sizes[0] / 2**20, max(sizes) / 2**20,
                   sum(sizes) / 2**20, (peak - before) / 1024))
        if scenario in ("deletes", "all"):
            for job_id in ids:
                stub.DeleteJob(motion_service_pb2.DeleteJobRequest(job_id=job_id), timeout=60)
            after = status_kib(server.pid, "VmRSS")
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline and after > baseline + 32 * 1024:
                time.sleep(0.2)
                after = status_kib(server.pid, "VmRSS")
            print("deletes: RSS %.1f MiB at start, %.1f MiB with the jobs, %.1f MiB after "
                  "deleting them all" % (baseline / 1024, stored / 1024, after / 1024))


def metrics(binary, slow_clients):
    port = free_port()
    with Server(binary, ["--metrics_address=127.0.0.1:%d" % port]):
        slow = []
        for _ in range(slow_clients):
            s = socket.create_connection(("127.0.0.1", port))
            s.sendall(b"GET /metr")
            slow.append(s)
        start = time.monotonic()
        with socket.create_connection(("127.0.0.1", port), timeout=120) as scrape:
            scrape.sendall(b"GET /metrics HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
            status = scrape.recv(64).split(b"\r\n")[0].decode(errors="replace")
        took = time.monotonic() - start
        for s in slow:
            s.close()
        print("metrics: %d slow clients holding half a request: scrape answered '%s' after %.2f s"
              % (slow_clients, status, took))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--server", required=True, help="the tempokey-server binary")
    parser.add_argument("--jobs", type=int, default=20)
    parser.add_argument("--knots", type=int, default=10_000)
    parser.add_argument("--slow", type=int, default=8)
    parser.add_argument("scenario", choices=["declared", "listjobs", "deletes", "metrics", "all"])
    args = parser.parse_args()
    if args.scenario in ("declared", "all"):
        declared(args.server)
    if args.scenario in ("listjobs", "deletes", "all"):
        listjobs_and_deletes(args.server, args.jobs, args.knots, args.scenario)
    if args.scenario in ("metrics", "all"):
        for slow in (1, args.slow):
            metrics(args.server, slow)


if __name__ == "__main__":
    sys.exit(main())
