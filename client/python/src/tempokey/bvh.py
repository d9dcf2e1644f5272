"""A small, strict BVH reader for the tempokey Python package (tempokey.formats turns its result
into a tempokey.v1 Clip).

Reads the hierarchy (ROOT / JOINT / End Site blocks with OFFSET and CHANNELS, several roots
allowed), then MOTION, "Frames:", "Frame Time:" and one row of numbers per frame. Accepts LF,
CRLF, CR and mixed line endings, tabs, a UTF-8 byte order mark, exponent notation and blank
lines between rows. OFFSET values and channel names must be on their keyword's line, joint
names on the ROOT / JOINT line, each motion row on one line (as the C++ reader requires).

Errors: BvhError (a ValueError) whose text is one line "<file>:<line>:<column>: <what was
expected>, got <what was found>", lines and columns counted from 1, e.g.
``walk.bvh:5:12: CHANNELS declares 3 channels but 2 names follow``.
"""

import dataclasses
import os
import re
from typing import List, Optional, Tuple

__all__ = ["CHANNEL_NAMES", "BvhClip", "BvhError", "BvhJoint", "parse_bvh", "read_bvh"]

CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
# Caps that keep a hostile file from exhausting memory or the Python stack.
MAX_DEPTH = 256
MAX_JOINTS = 10000
MAX_SAMPLES = 32 << 20

_NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?\Z")
_TOKEN = re.compile(r"[{}]|[^\s{}]+")
_FRAMES = re.compile(r"Frames\s*:\s*(.*)\Z")
_FRAME_TIME = re.compile(r"Frame\s+Time\s*:\s*(.*)\Z")


class BvhError(ValueError):
    """A malformed BVH file; str() is "<file>:<line>:<column>: <message>".

    Attributes: path, line, column (from 1), message."""

    def __init__(self, path: str, line: int, column: int, message: str):
        super().__init__("%s:%d:%d: %s" % (path, line, column, message))
        self.path = path
        self.line = line
        self.column = column
        self.message = message


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


def _describe(token: Optional[_Token]) -> str:
    return "end of file" if token is None else '"%s"' % token.text


class _Parser:
    """Recursive descent over the tokens of the hierarchy, then line by line over MOTION."""

    def __init__(self, text: str, path: str):
        self._path = path
        self._lines = text.splitlines()  # LF, CRLF, CR and mixed
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
        if not items or not items[0].text.isdigit():
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
            text = self._lines[self._line_index - 1].strip()
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
            raise BvhError(self._path, number, 1, 'expected "%s:", got "%s"' % (what, text))
        return number, match.group(1)

    def _motion(self, channel_count: int) -> Tuple[float, List[List[float]]]:
        line, text = self._motion_field(_FRAMES, "Frames")
        if not text.isdigit() or int(text) < 1:
            raise BvhError(self._path, line, 1, 'expected a frame count >= 1, got "%s"' % text)
        frames = int(text)
        if frames * max(1, channel_count) > MAX_SAMPLES:
            raise BvhError(self._path, line, 1, "%d frames x %d channels is over the limit of %d "
                           "samples" % (frames, channel_count, MAX_SAMPLES))
        line, text = self._motion_field(_FRAME_TIME, "Frame Time")
        token = _Token(text, line, 1)
        frame_time = self._number(token, "Frame Time")
        if not frame_time > 0:
            raise BvhError(self._path, line, 1, "Frame Time must be > 0, got %s" % text)
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
        values = [_Token(m.group(), number, m.start() + 1) for m in re.finditer(r"\S+", line)]
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
    if text.startswith("\ufeff"):
        text = text[1:]
    if not text.strip():
        raise BvhError(path, 1, 1, "the file is empty")
    nul = text.find("\0")
    if nul >= 0:
        line = text.count("\n", 0, nul) + 1
        raise BvhError(path, line, 1, "unexpected byte 0x00; the file looks binary, not BVH text")
    joints, frame_time, columns = _Parser(text, path).parse()
    channels = [(index, name) for index, joint in enumerate(joints) for name in joint.channels]
    stem = os.path.splitext(os.path.basename(path))[0]
    return BvhClip(stem, frame_time, joints, channels, columns)


def read_bvh(path: str) -> BvhClip:
    """Reads and parses the BVH file at `path` (UTF-8; undecodable bytes are reported).

    Raises: OSError when the file cannot be read; BvhError as parse_bvh()."""
    with open(path, "rb") as stream:
        data = stream.read()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise BvhError(path, line, 1, "byte 0x%02x is not UTF-8 text" % data[error.start]) from None
    return parse_bvh(text, path)
