#!/usr/bin/env python3
"""The studio-pipeline call: a BVH capture in, retimed and key-reduced curves out, as JSON.

Reads a BVH file, sends it to tempokey-server in one stateless Process call with two operations
(a retime, by default half speed between 2 s and 4 s of the source, then a key reduction by the
error-bounded `tolerance` method), and writes the keyed result in the "tempokey.keyed_clip" JSON
schema the C++ tools use. Prints one summary line: source and output frames, keys kept, max error,
and the joints' world-position error (file units and percent of the figure's height).

    python3 -m venv --system-site-packages .venv
    .venv/bin/pip install --no-index --no-build-isolation client/python
    .venv/bin/python client/python/example_pipeline.py \\
        --server 127.0.0.1:50051 ../shared/data/bvh/cmu/131_01.bvh -o 131_01-slow.json

Exit codes, as the `tempokey` CLI: 0 ok; 1 failed (bad file, server refusal, unreachable server),
with one line "error: ..." on stderr; 2 usage (argparse, and an output that is the input file
itself, by any path or link, unless --overwrite is given).
"""

import argparse
import math
import os
import sys
from typing import Callable, List, Optional, Sequence

import tempokey as tk

DEFAULT_SPEED = "0s:1,2s:1,2s:0.5,4s:0.5,4s:1"  # half speed from 2 s to 4 s of the source


def speed_argument(text: str) -> list:
    """--speed as SpeedKnot messages; a malformed list is a usage error (exit 2)."""
    try:
        return tk.parse_speed(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def timeout_argument(text: str) -> float:
    """--timeout in seconds: a finite number > 0 (connect() also refuses over a year)."""
    try:
        seconds = float(text)
    except ValueError:
        seconds = math.nan
    if not (math.isfinite(seconds) and seconds > 0):
        raise argparse.ArgumentTypeError("expected a number of seconds > 0, got %r" % text)
    return seconds


def noise_argument(text: str) -> object:
    """--noise: "auto" or a level in degrees; anything else is a usage error (exit 2)."""
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError("expected a level in degrees or auto, got %r"
                                         % text) from None


def joint_tolerance_argument(text: str) -> str:
    """--joint-tolerance as the CLI reads it: 1 (file units) or 0.5% (of the figure's height)."""
    try:
        tk.parse_joint_tolerance(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return text


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Retime and key-reduce a BVH clip on tempokey-server; write keyed JSON.")
    parser.add_argument("input", help="BVH file to process")
    parser.add_argument("-o", "--output", required=True, help="keyed-clip JSON file to write")
    parser.add_argument("--overwrite", action="store_true",
                        help="allow the output to replace the input file itself")
    parser.add_argument("--server", default="127.0.0.1:50051",
                        help="gRPC target of tempokey-server (default %(default)s)")
    parser.add_argument("--timeout", type=timeout_argument, default=120.0,
                        help="deadline of the call in seconds (default %(default)s)")
    parser.add_argument("--token-file", help="file holding a bearer token for the server")
    parser.add_argument("--speed", default=DEFAULT_SPEED, type=speed_argument,
                        help="speed knots time:speed over source time, times in s or f "
                             "(default %s: half speed from 2 s to 4 s)" % DEFAULT_SPEED)
    parser.add_argument("--tolerance", type=float, default=None,
                        help="largest rotation error kept, degrees (default: the server's, 0.5; "
                             "none with --joint-tolerance)")
    parser.add_argument("--position-tolerance", type=float, default=None,
                        help="largest position error kept, file units (default: the server's, "
                             "0.3 %% of the figure's height)")
    parser.add_argument("--joint-tolerance", type=joint_tolerance_argument, default=None,
                        help="keep every joint within D file units, or D%% of the figure's "
                             "height, of its source position (e.g. 1 or 0.5%%)")
    parser.add_argument("--method", choices=("tolerance", "noise"), default="tolerance",
                        help="reduction: tolerance (within the bounds) or noise (noise-aware, "
                             "levels from --noise)")
    parser.add_argument("--noise", default="auto", type=noise_argument,
                        help="method noise: rotation noise level in degrees or auto "
                             "(default %(default)s: estimated per channel)")
    return parser.parse_args(argv)


def output_is_the_input(args: argparse.Namespace) -> Optional[str]:
    """The CLI's usage error for an output that is the input file itself (the same device and
    inode: the same path, another path to it, a hard or symbolic link), or None. An output that
    does not exist yet, or an input that does not (reading it reports that), is not the input."""
    if args.overwrite:
        return None
    try:
        same = os.path.samefile(args.input, args.output)
    except OSError:
        return None
    if not same:
        return None
    named = "" if args.input == args.output else " " + args.input
    return ("-o %s is the input%s (the same file); choose another output, or give --overwrite "
            "to replace the input" % (args.output, named))


def read_token(path: Optional[str]) -> Optional[str]:
    """The first line of `path`, stripped. Raises OSError, ValueError for an empty file."""
    if path is None:
        return None
    with open(path, encoding="utf-8") as stream:
        token = stream.readline().strip()
    if not token:
        raise ValueError("%s: the token file is empty" % path)
    return token


def progress_printer() -> Optional[Callable[[float, str], None]]:
    """An on_progress callback drawing "  42% reduce 12/96" on a terminal, or None."""
    if not sys.stderr.isatty():
        return None

    def show(fraction: float, stage: str) -> None:
        sys.stderr.write("\r%4.0f%% %-40s" % (100.0 * fraction, stage[:40]))
        sys.stderr.flush()

    return show


def summary_line(source: tk.BvhClip, result: tk.PipelineResult) -> str:
    """"131_01: 994 -> 1234 frames, 3456 of 118464 keys kept (2.92 %), max error 0.4987 at
    LeftHand.Zrotation frame 812, joint error 0.1033 (0.409 % of height) at Head end site frame
    409"."""
    retime = result.retime_report
    reduction = result.reduction_report
    header = result.keyed_clip.header
    worst = tk.channel_label(header, reduction.worst_channel_index)
    share = 100.0 * reduction.key_count / max(1, reduction.sample_count)
    line = ("%s: %d -> %d frames, %d of %d keys kept (%.2f %%), max error %.4g at %s frame %d"
            % (source.name, source.frame_count, retime.output_frame_count, reduction.key_count,
               reduction.sample_count, share, reduction.max_error, worst, reduction.worst_frame))
    world = result.world_error
    if world is not None:
        height = world.figure_height_units
        line += (", joint error %.4g (%.3f %% of height) at %s frame %d"
                 % (world.max_error_units,
                    100.0 * world.max_error_units / height if height > 0 else 0.0,
                    world.worst_point, world.worst_frame))
    return line


def run(args: argparse.Namespace) -> None:
    operations = [tk.retime_operation(speed=args.speed),
                  (tk.reduce_operation(method="noise", noise=args.noise)
                   if args.method == "noise" else
                   tk.reduce_operation(tolerance=args.tolerance,
                                       position_tolerance=args.position_tolerance,
                                       joint_tolerance=args.joint_tolerance))]
    parsed = tk.read_bvh(args.input)
    clip = tk.clip_from_bvh(parsed)
    with tk.connect(args.server, timeout=args.timeout, token=read_token(args.token_file)) as client:
        show = progress_printer()
        result = client.process(clip, operations, on_progress=show)
        if show is not None:
            sys.stderr.write("\r" + " " * 46 + "\r")
    if result.keyed_clip is None or result.reduction_report is None:
        raise ValueError("the server returned no keyed clip")
    tk.write_keyed_clip_json(args.output, result.keyed_clip)
    print(summary_line(parsed, result))


def main(argv: Optional[List[str]] = None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    usage = output_is_the_input(args)
    if usage is not None:
        print("error: %s" % usage, file=sys.stderr)
        return 2
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
