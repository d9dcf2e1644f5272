"""A small, strict BVH reader for the tempokey Python package (tempokey.formats turns its result
into a tempokey.v1 Clip).

Reads the hierarchy (ROOT / JOINT / End Site blocks with OFFSET and CHANNELS, several roots
allowed), then MOTION, "Frames:", "Frame Time:" and one row of numbers per frame. Accepts LF,
CRLF, CR and mixed line endings, tabs, a UTF-8 byte order mark, exponent notation and blank
lines between rows. OFFSET values and channel names must be on their keyword's line, joint
names on the ROOT / JOINT line, each motion row on one line (as the C++ reader requires).

Whitespace and line breaks are the C++ reader's: blanks are space, tab, \v and \f; a line ends
at LF, CRLF or a lone CR (other Unicode separators are not whitespace), and numbers are ASCII.

Errors: BvhError (a ValueError) whose text is one line "<file>:<line>:<column>: <what was
expected>, got <what was found>", lines and columns counted from 1, e.g.
``walk.bvh:5:12: CHANNELS declares 3 channels but 2 names follow``. read_bvh() reads files as
the CLI does and raises BvhFileError (an OSError), "<file>: <what>", for a file it refuses
before parsing: a directory, device or socket, a file over MAX_FILE_BYTES, a FIFO or pipe that
sends more or stays silent for STREAM_IDLE_SECONDS.
"""

import dataclasses
import errno
import math
import os
import re
import select
import stat
from typing import List, Optional, Tuple, Union

__all__ = ["CHANNEL_NAMES", "MAX_FILE_BYTES", "STREAM_IDLE_SECONDS", "BvhClip", "BvhError",
           "BvhFileError", "BvhJoint", "parse_bvh", "read_bvh"]

CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
# Caps that keep a hostile file from exhausting memory or the Python stack.
MAX_DEPTH = 256
MAX_JOINTS = 10000
MAX_SAMPLES = 32 << 20
# read_bvh(): the CLI's caps (client/clip_files.h kMaxInputFileBytes, core kStreamIdleTimeoutMs).
MAX_FILE_BYTES = 256 << 20
STREAM_IDLE_SECONDS = 10.0
_READ_CHUNK_BYTES = 64 << 10  # a binary file is refused after its first chunk

# The C++ reader's character classes (core/src/io/text_scan.h).
_BLANKS = " \t\v\f"
_LINE_BREAK = re.compile(r"\r\n|\r|\n")
_LINE_BREAK_BYTES = re.compile(rb"\r\n|\r|\n")
_NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?\Z")
_COUNT = re.compile(r"[0-9]{1,9}\Z")  # ASCII digits: str.isdigit() also takes "²"
_TOKEN = re.compile(r"[{}]|[^ \t\v\f{}]+")
_FIELD = re.compile(r"[^ \t\v\f]+")
_FRAMES = re.compile(r"Frames[ \t\v\f]*:[ \t\v\f]*(.*)\Z")
_FRAME_TIME = re.compile(r"Frame[ \t\v\f]+Time[ \t\v\f]*:[ \t\v\f]*(.*)\Z")


class BvhError(ValueError):
    """A malformed BVH file; str() is "<file>:<line>:<column>: <message>".

    Attributes: path, line, column (from 1), message."""

    def __init__(self, path: str, line: int, column: int, message: str):
        super().__init__("%s:%d:%d: %s" % (path, line, column, message))
        self.path = path
        self.line = line
        self.column = column
        self.message = message


class BvhFileError(OSError):
    """A file read_bvh() refuses before parsing it; str() is "<file>: <message>", e.g.
    "/dev/zero: is a character device, not a file".

    Attributes: filename (the path as given), strerror (the message), errno: EISDIR a directory,
    EINVAL a device or socket, EFBIG over the size cap, ETIMEDOUT a silent FIFO."""

    def __init__(self, path: str, message: str, code: int):
        super().__init__(code, message, path)

    def __str__(self) -> str:
        return "%s: %s" % (self.filename, self.strerror)


@dataclasses.dataclass
class BvhJoint:
    """One joint: parent index (-1 for a root), offset and End Site offsets in file units, and
    its channel names in file order."""
    name: str
    parent_index: int
    offset: Tuple[float, float, float]
    end_sites: List[Tuple[float, float, float]] = dataclasses.field(default_factory=list)
    channels: List[str] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class BvhClip:
    """A parsed file. `channels` lists (joint index, channel name) in motion-column order;
    `samples` is channel-major: samples[c][f] is channel c at frame f (degrees for rotations,
    file units for positions). `frame_time_seconds` is exactly the number in the file."""
    name: str
    frame_time_seconds: float
    joints: List[BvhJoint]
    channels: List[Tuple[int, str]]
    samples: List[List[float]]

    @property
    def frame_count(self) -> int:
        return len(self.samples[0]) if self.samples else 0


@dataclasses.dataclass
class _Token:
    text: str
    line: int
    column: int


def _quoted(text: str) -> str:
    """`text` in double quotes for a message, cut to 40 characters."""
    return '"%s"' % (text if len(text) <= 40 else text[:37] + "...")


def _describe(token: Optional[_Token]) -> str:
    return "end of file" if token is None else _quoted(token.text)


class _Parser:
    """Recursive descent over the tokens of the hierarchy, then line by line over MOTION."""

    def __init__(self, text: str, path: str):
        self._path = path
        self._lines = _LINE_BREAK.split(text)  # LF, CRLF, CR and mixed
        if len(self._lines) > 1 and not self._lines[-1]:
            self._lines.pop()  # the break ending the last line does not start another
        self._line_index = 0  # next line to tokenize
        self._pending: List[_Token] = []
        self._last_line = 1

    # -- errors --

    def _fail(self, token: Optional[_Token], message: str) -> BvhError:
        if token is None:
            return BvhError(self._path, max(1, len(self._lines)), 1, message)
        return BvhError(self._path, token.line, token.column, message)

    def _expected(self, what: str, token: Optional[_Token]) -> BvhError:
        return self._fail(token, "expected %s, got %s" % (what, _describe(token)))

    # -- tokens --

    def _fill(self) -> bool:
        """Tokenizes lines until some token is pending; False at the end of the file."""
        while not self._pending and self._line_index < len(self._lines):
            number = self._line_index + 1
            self._pending = [_Token(m.group(), number, m.start() + 1)
                             for m in _TOKEN.finditer(self._lines[self._line_index])]
            self._line_index += 1
        return bool(self._pending)

    def _peek(self) -> Optional[_Token]:
        return self._pending[0] if self._fill() else None

    def _next(self) -> Optional[_Token]:
        if not self._fill():
            return None
        token = self._pending.pop(0)
        self._last_line = token.line
        return token

    def _rest_of_line(self) -> List[_Token]:
        """The tokens left on the line of the last token taken."""
        rest, self._pending = self._pending, []
        return rest

    def _keyword(self, word: str) -> _Token:
        token = self._next()
        if token is None or token.text != word:
            raise self._expected('"%s"' % word, token)
        return token

    def _number(self, token: Optional[_Token], what: str) -> float:
        if token is None or not _NUMBER.match(token.text):
            raise self._expected("a number for %s" % what, token)
        value = float(token.text)
        if value in (float("inf"), float("-inf")):
            raise self._fail(token, "%s %s is out of range" % (what, token.text))
        return value

    def _offset(self) -> Tuple[float, float, float]:
        keyword = self._keyword("OFFSET")
        values = self._rest_of_line()
        if len(values) != 3:
            raise self._fail(keyword, "OFFSET needs 3 numbers on its line, got %d" % len(values))
        x, y, z = (self._number(v, "OFFSET") for v in values)
        return (x, y, z)

    def _channels(self, keyword: _Token) -> List[str]:
        items = self._rest_of_line()
        if not items or not _COUNT.match(items[0].text):
            raise self._expected("a channel count after CHANNELS", items[0] if items else None)
        declared = int(items[0].text)
        if not 1 <= declared <= 6:
            raise self._fail(items[0], "CHANNELS count must be 1 to 6, got %d" % declared)
        names = items[1:]
        if len(names) != declared:
            raise self._fail(keyword, "CHANNELS declares %d channels but %d names follow"
                             % (declared, len(names)))
        seen: List[str] = []
        for name in names:
            if name.text not in CHANNEL_NAMES:
                raise self._expected("a channel name (%s)" % ", ".join(CHANNEL_NAMES), name)
            if name.text in seen:
                raise self._fail(name, "channel %s is listed twice" % name.text)
            seen.append(name.text)
        return seen

    # -- hierarchy --

    def _joint(self, keyword: _Token, parent: int, depth: int, joints: List[BvhJoint],
               names: dict) -> None:
        if depth > MAX_DEPTH:
            raise self._fail(keyword, "joints nest deeper than %d levels" % MAX_DEPTH)
        if len(joints) >= MAX_JOINTS:
            raise self._fail(keyword, "more than %d joints" % MAX_JOINTS)
        rest = self._rest_of_line()
        if not rest or rest[0].text in "{}":
            raise self._expected("a joint name after %s" % keyword.text, rest[0] if rest else None)
        name = rest[0]
        if name.text in names:
            raise self._fail(name, 'joint name "%s" is used twice (first on line %d)'
                             % (name.text, names[name.text]))
        names[name.text] = name.line
        self._pending = rest[1:]  # a '{' may follow on the same line
        brace = self._next()
        if brace is None or brace.text != "{":
            raise self._expected("'{' after joint name %s" % name.text, brace)
        index = len(joints)
        joints.append(BvhJoint(name.text, parent, self._offset()))
        while True:
            token = self._next()
            if token is None:
                raise self._expected("'}' closing joint %s" % name.text, None)
            if token.text == "}":
                return
            if token.text == "CHANNELS":
                if joints[index].channels:
                    raise self._fail(token, "joint %s has a second CHANNELS line" % name.text)
                joints[index].channels = self._channels(token)
            elif token.text == "JOINT":
                self._joint(token, index, depth + 1, joints, names)
            elif token.text == "End":
                self._end_site(token, joints[index])
            else:
                raise self._expected("CHANNELS, JOINT, End Site or '}' in joint %s" % name.text,
                                     token)

    def _end_site(self, keyword: _Token, joint: BvhJoint) -> None:
        site = self._next()
        if site is None or site.text != "Site":
            raise self._expected('"Site" after "End"', site)
        self._keyword("{")
        joint.end_sites.append(self._offset())
        closing = self._next()
        if closing is None or closing.text != "}":
            raise self._expected("'}' closing End Site", closing)

    def _hierarchy(self) -> List[BvhJoint]:
        self._keyword("HIERARCHY")
        joints: List[BvhJoint] = []
        names: dict = {}
        while True:
            token = self._next()
            if token is not None and token.text == "ROOT":
                self._joint(token, -1, 1, joints, names)
            elif token is not None and token.text == "MOTION" and joints:
                if self._rest_of_line():
                    raise self._fail(token, "MOTION must be alone on its line")
                return joints
            else:
                raise self._expected("ROOT or MOTION" if joints else "ROOT", token)

    # -- motion --

    def _next_line(self) -> Optional[Tuple[int, str]]:
        """The next non-blank line (number from 1, text without surrounding blanks)."""
        while self._line_index < len(self._lines):
            self._line_index += 1
            text = self._lines[self._line_index - 1].strip(_BLANKS)
            if text:
                return self._line_index, text
        return None

    def _motion_field(self, pattern, what: str) -> Tuple[int, str]:
        found = self._next_line()
        if found is None:
            raise self._expected('"%s:"' % what, None)
        number, text = found
        match = pattern.match(text)
        if not match:
            raise BvhError(self._path, number, 1, 'expected "%s:", got %s' % (what, _quoted(text)))
        return number, match.group(1)

    def _motion(self, channel_count: int) -> Tuple[float, List[List[float]]]:
        line, text = self._motion_field(_FRAMES, "Frames")
        if re.fullmatch(r"[0-9]{10,}", text):  # no int() of thousands of digits
            raise BvhError(self._path, line, 1, "frame count %s is over the limit of %d samples"
                           % (_quoted(text), MAX_SAMPLES))
        if not _COUNT.match(text) or int(text) < 1:
            raise BvhError(self._path, line, 1, "expected a frame count >= 1, got %s"
                           % _quoted(text))
        frames = int(text)
        if frames * max(1, channel_count) > MAX_SAMPLES:
            raise BvhError(self._path, line, 1, "%d frames x %d channels is over the limit of %d "
                           "samples" % (frames, channel_count, MAX_SAMPLES))
        line, text = self._motion_field(_FRAME_TIME, "Frame Time")
        token = _Token(text, line, 1)
        frame_time = self._number(token, "Frame Time")
        if not frame_time > 0:
            raise BvhError(self._path, line, 1, "Frame Time must be > 0, got %s" % text[:40])
        columns: List[List[float]] = [[] for _ in range(channel_count)]
        for row in range(1, frames + 1):
            found = self._next_line()
            if found is None:
                raise BvhError(self._path, max(1, len(self._lines)), 1,
                               "expected %d motion rows (Frames: %d), got %d"
                               % (frames, frames, row - 1))
            self._row(found, row, columns)
        extra = self._next_line()
        if extra is not None:
            raise BvhError(self._path, extra[0], 1, "text after the last motion row (Frames: %d)"
                           % frames)
        return frame_time, columns

    def _row(self, found: Tuple[int, str], row: int, columns: List[List[float]]) -> None:
        number, text = found
        line = self._lines[number - 1]
        values = [_Token(m.group(), number, m.start() + 1) for m in _FIELD.finditer(line)]
        if len(values) != len(columns):
            raise BvhError(self._path, number, 1, "motion row %d has %d values, expected %d"
                           % (row, len(values), len(columns)))
        for column, token in zip(columns, values):
            column.append(self._number(token, "motion row %d" % row))

    def parse(self) -> Tuple[List[BvhJoint], float, List[List[float]]]:
        joints = self._hierarchy()
        channel_count = sum(len(j.channels) for j in joints)
        frame_time, columns = self._motion(channel_count)
        return joints, frame_time, columns


def parse_bvh(text: str, path: str = "<bvh>") -> BvhClip:
    """Parses BVH `text`; `path` names the file in messages and its stem names the clip.

    Raises: BvhError naming line and column (an empty or binary file, an unknown keyword, a
    missing brace or name, a CHANNELS count not matching its names, an unknown or repeated
    channel, a duplicate joint name, a missing MOTION / Frames / Frame Time, a frame count < 1,
    a frame time <= 0, a malformed or out-of-range number, a row with the wrong number of values,
    fewer rows than Frames, text after the last row, nesting or sizes over the caps).
    """
    if not isinstance(text, str):
        raise TypeError("text must be a str, got %s" % type(text).__name__)
    if text.startswith("\ufeff"):
        text = text[1:]
    if not text.strip(_BLANKS + "\r\n"):
        raise BvhError(path, 1, 1, "the file is empty")
    nul = text.find("\0")
    if nul >= 0:
        line, column = _line_and_column(text, nul)
        raise BvhError(path, line, column, _BINARY)
    joints, frame_time, columns = _Parser(text, path).parse()
    channels = [(index, name) for index, joint in enumerate(joints) for name in joint.channels]
    stem = os.path.splitext(os.path.basename(path))[0]
    return BvhClip(stem, frame_time, joints, channels, columns)


_BINARY = "unexpected byte 0x00; the file looks binary, not text"


def _line_and_column(text: Union[str, bytes], offset: int) -> Tuple[int, int]:
    """Line and column (from 1) of `offset` in `text`, lines ending as the parser ends them."""
    pattern = _LINE_BREAK if isinstance(text, str) else _LINE_BREAK_BYTES
    line, start = 1, 0
    for match in pattern.finditer(text, 0, offset):
        line, start = line + 1, match.end()
    return line, offset - start + 1


def _kind_of_file(mode: int) -> str:
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _open_for_reading(path: Union[str, "os.PathLike[str]"], name: str) -> int:
    """A descriptor of `path` opened without waiting for a FIFO's writer or a terminal."""
    try:
        return os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as error:
        if error.errno == errno.ENXIO:  # a socket cannot be opened: say what it is
            try:
                mode = os.stat(path).st_mode
            except OSError:
                raise error from None
            if stat.S_ISSOCK(mode):
                raise BvhFileError(name, "is a socket, not a file", errno.EINVAL) from None
        raise


def _read_bytes(path: Union[str, "os.PathLike[str]"], max_bytes: int,
                idle_seconds: float) -> bytes:
    """All of `path`, read as the CLI reads a text file (core ReadTextFile): a regular file or
    a FIFO / pipe; a NUL byte is refused as soon as its chunk arrives."""
    name = os.fsdecode(path)
    fd = _open_for_reading(path, name)
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise BvhFileError(name, "is a directory, not a file", errno.EISDIR)
        stream = stat.S_ISFIFO(info.st_mode)
        if not stat.S_ISREG(info.st_mode) and not stream:
            # /dev/zero and friends never end; terminals are not files to read whole.
            raise BvhFileError(name, "is %s, not a file" % _kind_of_file(info.st_mode),
                               errno.EINVAL)
        if stat.S_ISREG(info.st_mode) and info.st_size > max_bytes:
            raise BvhFileError(name, "file is %d bytes, over the limit of %d"
                               % (info.st_size, max_bytes), errno.EFBIG)
        poller = None
        if stream:
            # A FIFO stays non-blocking: each read waits a bounded time for data or the end.
            poller = select.poll()
            poller.register(fd, select.POLLIN)
        else:
            os.set_blocking(fd, True)
        data = bytearray()
        while True:
            if poller is not None and not poller.poll(idle_seconds * 1000.0):
                raise BvhFileError(name, "is a FIFO and nothing arrived for %g s (no writer?)"
                                   % idle_seconds, errno.ETIMEDOUT)
            try:
                chunk = os.read(fd, _READ_CHUNK_BYTES)
            except BlockingIOError:
                continue
            if not chunk:
                return bytes(data)
            nul = chunk.find(b"\0")
            if nul >= 0:
                data += chunk[:nul]
                line, column = _line_and_column(data, len(data))
                raise BvhError(name, line, column, _BINARY)
            data += chunk
            if len(data) > max_bytes:
                raise BvhFileError(name, "file is over the limit of %d bytes" % max_bytes,
                                   errno.EFBIG)
    finally:
        os.close(fd)


def read_bvh(path: Union[str, "os.PathLike[str]"], *, max_bytes: int = MAX_FILE_BYTES,
             idle_seconds: float = STREAM_IDLE_SECONDS) -> BvhClip:
    """Reads and parses the BVH file at `path` (UTF-8; undecodable bytes are reported), as the
    CLI reads it: a regular file of at most `max_bytes` (refused from its size, before reading),
    or a FIFO or pipe read to its end, at most `max_bytes`, each wait for data at most
    `idle_seconds`. A FIFO is opened without waiting for a writer.

    Raises: BvhFileError (an OSError) "<file>: <what>" for a directory, a device or socket, a
    file over `max_bytes`, a FIFO silent for `idle_seconds`; other OSErrors when the file
    cannot be read (FileNotFoundError, PermissionError); BvhError as parse_bvh(), and
    "<file>:<line>:<column>: unexpected byte 0x00; ..." for a binary file, after its first
    chunk; ValueError for a `max_bytes` or `idle_seconds` that is not positive."""
    if isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 1:
        raise ValueError("max_bytes must be a whole number >= 1, got %r" % (max_bytes,))
    if (isinstance(idle_seconds, bool) or not isinstance(idle_seconds, (int, float))
            or not math.isfinite(idle_seconds) or idle_seconds <= 0):
        raise ValueError("idle_seconds must be a finite number > 0, got %r" % (idle_seconds,))
    name = os.fsdecode(path)
    data = _read_bytes(path, max_bytes, idle_seconds)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        line, column = _line_and_column(data, error.start)
        raise BvhError(name, line, column,
                       "byte 0x%02x is not UTF-8 text" % data[error.start]) from None
    return parse_bvh(text, name)
