#!/usr/bin/env python3
"""The studio-pipeline call: a BVH capture in, retimed and key-reduced curves out, as JSON.

Reads a BVH file, sends it to tempokey-server in one stateless Process call with two operations
(a retime, by default half speed between 2 s and 4 s of the source, then a key reduction by the
error-bounded `tolerance` method), and writes the keyed result in the "tempokey.keyed_clip" JSON
schema the C++ tools use. Prints one summary line: source and output frames, keys kept, max error.

    PYTHONPATH=build/python:client/python python3 client/python/example_pipeline.py \\
        --server 127.0.0.1:50051 ../shared/data/bvh/cmu/131_01.bvh -o 131_01-slow.json

Exit codes, as the `tempokey` CLI: 0 ok; 1 failed (bad file, server refusal, unreachable server),
with one line "error: ..." on stderr; 2 usage (argparse).
"""

import argparse
import json
import os
import sys
import tempfile

import bvh
import tempokey_client as tk

DEFAULT_SPEED = "0s:1,2s:1,2s:0.5,4s:0.5,4s:1"  # half speed from 2 s to 4 s of the source


def speed_argument(text):
    """--speed as SpeedKnot messages; a malformed list is a usage error (exit 2)."""
    try:
        return tk.parse_speed(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def parse_args(argv):
    parser = argparse.ArgumentParser(
        description="Retime and key-reduce a BVH clip on tempokey-server; write keyed JSON.")
    parser.add_argument("input", help="BVH file to process")
    parser.add_argument("-o", "--output", required=True, help="keyed-clip JSON file to write")
    parser.add_argument("--server", default="127.0.0.1:50051",
                        help="gRPC target of tempokey-server (default %(default)s)")
    parser.add_argument("--timeout", type=float, default=120.0,
                        help="deadline of the call in seconds (default %(default)s)")
    parser.add_argument("--token-file", help="file holding a bearer token for the server")
    parser.add_argument("--speed", default=DEFAULT_SPEED, type=speed_argument,
                        help="speed knots time:speed over source time, times in s or f "
                             "(default %s: half speed from 2 s to 4 s)" % DEFAULT_SPEED)
    parser.add_argument("--tolerance", type=float, default=0.5,
                        help="largest rotation error kept, degrees (default %(default)s)")
    parser.add_argument("--position-tolerance", type=float, default=0.5,
                        help="largest position error kept, file units (default %(default)s)")
    parser.add_argument("--method", choices=("tolerance", "noise"), default="tolerance",
                        help="reduction: tolerance (within the bounds) or noise (noise-aware, "
                             "levels from --noise)")
    parser.add_argument("--noise", default="auto",
                        help="method noise: rotation noise level in degrees or auto "
                             "(default %(default)s: estimated per channel)")
    return parser.parse_args(argv)


def read_token(path):
    """The first line of `path`, stripped. Raises OSError, ValueError for an empty file."""
    if path is None:
        return None
    with open(path, encoding="utf-8") as stream:
        token = stream.readline().strip()
    if not token:
        raise ValueError("%s: the token file is empty" % path)
    return token


def clip_from_bvh(parsed):
    """The tempokey.v1.Clip of a parsed BVH file (skeleton, channels, samples, frame time)."""
    joints = [tk.JointSpec(j.name, j.parent_index, j.offset, tuple(j.end_sites))
              for j in parsed.joints]
    channels = [tk.ChannelSpec(kind, joint_index=joint) for joint, kind in parsed.channels]
    return tk.make_clip(parsed.name, parsed.frame_time_seconds, channels, parsed.samples, joints)


def write_json_atomically(path, document):
    """Writes `document` as JSON to a temporary file beside `path`, then renames it into place,
    so a failed run never leaves a half-written file. Raises OSError."""
    directory = os.path.dirname(os.path.abspath(path))
    handle, temporary = tempfile.mkstemp(prefix=".tmp-", suffix=".json", dir=directory)
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            json.dump(document, stream, allow_nan=False)
            stream.write("\n")
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


def progress_printer():
    """An on_progress callback drawing "  42% reduce 12/96" on a terminal, or None."""
    if not sys.stderr.isatty():
        return None

    def show(fraction, stage):
        sys.stderr.write("\r%4.0f%% %-40s" % (100.0 * fraction, stage[:40]))
        sys.stderr.flush()

    return show


def summary_line(source, result):
    """"131_01: 994 -> 1234 frames, 3456 of 118464 keys kept (2.92 %), max error 0.4987 at
    LeftHand.Zrotation frame 812"."""
    retime = result.retime_report
    reduction = result.reduction_report
    header = result.keyed_clip.header
    worst = tk.channel_label(header, reduction.worst_channel_index)
    share = 100.0 * reduction.key_count / max(1, reduction.sample_count)
    return ("%s: %d -> %d frames, %d of %d keys kept (%.2f %%), max error %.4g at %s frame %d"
            % (source.name, source.frame_count, retime.output_frame_count, reduction.key_count,
               reduction.sample_count, share, reduction.max_error, worst, reduction.worst_frame))


def run(args):
    operations = [tk.retime_operation(speed=args.speed),
                  (tk.reduce_operation(method="noise", noise=args.noise)
                   if args.method == "noise" else
                   tk.reduce_operation(tolerance=args.tolerance,
                                       position_tolerance=args.position_tolerance))]
    parsed = bvh.read_bvh(args.input)
    clip = clip_from_bvh(parsed)
    with tk.connect(args.server, timeout=args.timeout, token=read_token(args.token_file)) as client:
        show = progress_printer()
        result = client.process(clip, operations, on_progress=show)
        if show is not None:
            sys.stderr.write("\r" + " " * 46 + "\r")
    if result.keyed_clip is None or result.reduction_report is None:
        raise ValueError("the server returned no keyed clip")
    write_json_atomically(args.output, tk.keyed_clip_to_dict(result.keyed_clip))
    print(summary_line(parsed, result))


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        run(args)
    except tk.TempokeyError as error:
        print("error: server: %s" % error, file=sys.stderr)
        return 1
    except OSError as error:
        where = error.filename if error.filename else args.input
        print("error: %s: %s" % (where, error.strerror or error), file=sys.stderr)
        return 1
    except ValueError as error:  # BvhError, an empty token file
        print("error: %s" % error, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
