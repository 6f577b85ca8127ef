"""Sans-IO framers for byte-stream transports: bytes in, whole frames out.

D22: TCP carries concatenated JSON values (whitespace or
newlines between them allowed; rosbridge_tcp readers send no delimiter) and
self-delimiting CBOR items, told apart by their first byte (a JSON value starts
with ASCII, a CBOR map or array with a byte in ``0x80-0xbf``, D21); stdio
carries one JSON text per line.

Unlike the reference's brace scanner, which re-parses its whole buffer from
every ``{`` against every ``}`` (O(n^2), REF §1.3), these scanners keep their
state between chunks and look at every byte once, jumping with compiled regular
expressions to the next byte that matters. Every frame is bounded by
``max_frame_bytes`` (D24): a larger JSON value is skipped to its end without
being kept, and reported once as a ``FramingError``; the stream stays in step.
A larger CBOR item ends the stream (a fatal ``FramingError``): its declared
length cannot be trusted, and binary data offers no point to resynchronise (so
a broken CBOR header holds the stream until ``max_frame_bytes`` or its end).
The same holds for a frame whose bytes, while it arrives, do not fit in the
server-wide budget of incomplete messages (``--max-fragment-memory``).

A framer never raises for what the peer sent. Anything that is not JSON (a bare
``}``, a stray word) is passed on as a frame of its own, so the session reports
it as invalid JSON (D1) and the stream carries on with the next value. An
unterminated value would otherwise swallow everything after it, so the scanner
resynchronises at a newline where JSON cannot go on: a raw newline inside a
string (never valid JSON), or a line that starts with ``{"op"`` while an object
is still open (line-oriented clients write one message per line; pretty-printed
JSON never starts a line that way).
"""

from __future__ import annotations

import re
from enum import Enum, auto

from ..runtime.inframes import FramerEvent, FramingError, InFrame
from .fragments import BudgetCharge, FragmentBudget

__all__ = ["JsonStreamFramer", "LineFramer"]

_NOT_SPACE = re.compile(rb"[^ \t\r\n]")
_CONTAINER_STOP = re.compile(rb'[{}\[\]"\n]')
_STRING_STOP = re.compile(rb'["\\\n]')
_TOKEN_STOP = re.compile(rb'[ \t\r\n{}\[\]"]')
_OPENERS = frozenset(b"{[")
_CLOSERS = frozenset(b"}]")
_QUOTE = ord('"')
_BACKSLASH = ord("\\")
_NEWLINE = ord("\n")
_NEXT_OP = b'{"op"'  # a line starting like this starts a new message (resync, see _scan_json)
_CBOR_FIRST = range(0x80, 0xC0)  # CBOR arrays (major type 4) and maps (major type 5)


class _Mode(Enum):
    IDLE = auto()
    CONTAINER = auto()
    STRING = auto()
    TOKEN = auto()
    CBOR = auto()


class JsonStreamFramer:
    """Split a byte stream of concatenated JSON values and CBOR items into frames.

    Args:
        max_frame_bytes: the largest frame kept, in bytes (``--max-message-size``).
        budget: the server-wide budget of incomplete messages
            (``--max-fragment-memory``) that the bytes of a frame still arriving
            are charged to; a frame that does not fit is skipped to its end
            and reported once, as a frame over ``max_frame_bytes`` is. None:
            ``max_frame_bytes`` alone bounds it.

    Feed bytes with ``receive_data``; call ``receive_eof`` when the stream ends,
    or ``release`` when it is dropped. Total work is linear in the bytes
    received, whatever the chunking. Between calls the buffer holds only the
    frame still arriving: a large frame's bytes are freed once it is whole.
    """

    def __init__(self, max_frame_bytes: int, budget: FragmentBudget | None = None) -> None:
        self.max_frame_bytes = max_frame_bytes
        self._charge = BudgetCharge(budget)
        self._buf = bytearray()
        self._pos = 0  # next byte to scan in _buf
        self._start = 0  # start of the current frame in _buf
        self._mode = _Mode.IDLE
        self._depth = 0
        self._in_string = False
        self._skipping = False
        self._dead = False  # an oversized CBOR item: nothing after it can be trusted
        self._cbor = _CborScanner()

    def receive_data(self, data: bytes) -> list[FramerEvent]:
        """Take the next chunk of the stream; return the frames it completed, in order."""
        if self._dead:
            return []
        self._buf += data
        events: list[FramerEvent] = []
        while self._step(events):
            pass
        self._compact()
        self._charge_held(events)
        return events

    def release(self) -> None:
        """Give back what the buffered frame holds of the budget (the stream is dropped)."""
        self._buf.clear()
        self._charge.release()

    def _charge_held(self, events: list[FramerEvent]) -> None:
        """Charge the buffered bytes; skip the frame in progress if they do not fit."""
        charge = self._charge
        if charge.budget is None or charge.hold(len(self._buf)):
            return
        if self._mode is _Mode.CBOR:  # as for an oversized item: no resynchronising
            self._dead = True
            self._buf.clear()
            charge.release()
            events.append(FramingError(charge.budget.refusal("CBOR item"), fatal=True))
            return
        if self._mode is not _Mode.IDLE and not self._skipping:
            self._skipping = True
            events.append(FramingError(charge.budget.refusal("frame")))
        del self._buf[: self._pos]
        self._pos = self._start = 0
        charge.hold(len(self._buf))  # the few unscanned bytes: at most a header's

    def receive_eof(self) -> list[FramerEvent]:
        """The stream ended: return what the last, unterminated value gives.

        A bare token (``5``) at the very end is a whole value; anything else left
        open is reported as an incomplete frame.
        """
        events: list[FramerEvent] = []
        if self._dead:
            return events
        if self._mode is _Mode.TOKEN and not self._skipping:
            events.append(InFrame(bytes(self._buf[self._start :])))
        elif self._mode is not _Mode.IDLE:
            events.append(FramingError("incomplete frame at the end of the stream"))
        self._buf.clear()
        self._charge.release()
        self._pos = self._start = 0
        self._mode = _Mode.IDLE
        return events

    # ---- the scanner ------------------------------------------------------------

    def _step(self, events: list[FramerEvent]) -> bool:
        """Advance the scan; return True while progress is possible."""
        if self._mode is _Mode.IDLE:
            return self._begin(events)
        done = self._scan()
        if self._size() > self.max_frame_bytes and not self._skipping:
            if self._mode is _Mode.CBOR:  # no resynchronising inside binary data
                self._dead = True
                self._buf.clear()
                events.append(
                    FramingError(f"CBOR item larger than {self.max_frame_bytes} bytes", fatal=True)
                )
                return False
            self._skipping = True
            events.append(FramingError(f"frame larger than {self.max_frame_bytes} bytes skipped"))
        if self._skipping:  # forget what was scanned, keeping the scan state
            del self._buf[: self._pos]
            self._pos = self._start = 0
        if not done:
            return False
        if not self._skipping:
            frame = bytes(self._buf[self._start : self._pos])
            events.append(InFrame(frame, binary=self._mode is _Mode.CBOR))
        self._mode = _Mode.IDLE
        self._skipping = False
        self._start = self._pos
        return True

    def _begin(self, events: list[FramerEvent]) -> bool:
        match = _NOT_SPACE.search(self._buf, self._pos)
        if match is None:
            self._pos = self._start = len(self._buf)
            return False
        self._pos = self._start = match.start()
        first = self._buf[self._pos]
        if first in _OPENERS:
            self._mode, self._depth, self._in_string = _Mode.CONTAINER, 1, False
            self._pos += 1
        elif first == _QUOTE:
            self._mode, self._in_string = _Mode.STRING, True
            self._pos += 1
        elif first in _CBOR_FIRST:
            self._mode = _Mode.CBOR
            self._cbor.reset()
        elif first in _CLOSERS:  # a stray closer is a one-byte frame of garbage
            self._pos += 1
            events.append(InFrame(bytes(self._buf[self._start : self._pos])))
            self._start = self._pos
        else:
            self._mode = _Mode.TOKEN
        return True

    def _scan(self) -> bool:
        """Scan from ``_pos`` in the current mode; True when the value ended."""
        if self._mode is _Mode.CBOR:
            self._pos, done = self._cbor.scan(self._buf, self._pos)
            return done
        if self._mode is _Mode.TOKEN:
            match = _TOKEN_STOP.search(self._buf, self._pos)
            if match is None:
                self._pos = len(self._buf)
                return False
            self._pos = match.start()
            return True
        return self._scan_json()

    def _scan_json(self) -> bool:
        """Scan a string or container; True when it ended (or broke off at a newline)."""
        buf = self._buf
        while True:
            stop = _STRING_STOP if self._in_string else _CONTAINER_STOP
            match = stop.search(buf, self._pos)
            if match is None:
                self._pos = len(buf)
                return False
            index = match.start()
            byte = buf[index]
            if byte == _NEWLINE:
                ended = self._newline(index)
                if ended is not None:
                    return ended
                continue
            self._pos = index + 1
            if self._in_string:
                if byte == _BACKSLASH:
                    if index + 1 >= len(buf):
                        self._pos = index  # rescan the escape with its next byte
                        return False
                    self._pos = index + 2
                    continue
                self._in_string = False
                if self._mode is _Mode.STRING:
                    return True
            elif byte == _QUOTE:
                self._in_string = True
            elif byte in _OPENERS:
                self._depth += 1
            else:
                self._depth -= 1
                if self._depth == 0:
                    return True

    def _newline(self, index: int) -> bool | None:
        """A raw newline at ``index``: end the broken frame there, wait, or go on (None)."""
        if not self._in_string:
            following = bytes(self._buf[index + 1 : index + 1 + len(_NEXT_OP)])
            if len(following) < len(_NEXT_OP) and _NEXT_OP.startswith(following):
                self._pos = index  # not enough bytes to tell yet
                return False
            if following != _NEXT_OP:
                self._pos = index + 1
                return None
        self._pos = index  # the frame so far is invalid JSON; the session reports it
        return True

    def _size(self) -> int:
        return self._pos - self._start

    def _compact(self) -> None:
        if self._start:
            del self._buf[: self._start]
            self._pos -= self._start
            self._start = 0


class _CborScanner:
    """Finds where one CBOR item (RFC 8949) ends, resumably, without decoding it.

    The stack holds, for each open array/map/tag, how many items it still needs
    (-1 for an indefinite-length one, closed by a ``break`` byte).
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.stack: list[int] = []
        self.payload_left = 0  # bytes of a byte/text string still to skip

    def scan(self, buf: bytearray, pos: int) -> tuple[int, bool]:
        """Scan ``buf`` from ``pos``; return the new position and whether the item ended."""
        while True:
            if self.payload_left:
                take = min(self.payload_left, len(buf) - pos)
                pos += take
                self.payload_left -= take
                if self.payload_left:
                    return pos, False
                if self._item_done():
                    return pos, True
                continue
            if pos >= len(buf):
                return pos, False
            step = self._header(buf, pos)
            if step is None:
                return pos, False
            pos, finished = step
            if finished:
                return pos, True

    def _header(self, buf: bytearray, pos: int) -> tuple[int, bool] | None:
        """Read one item header at ``pos``; None when more bytes are needed."""
        initial = buf[pos]
        major, info = initial >> 5, initial & 0x1F
        if info < 24:
            argument, size = info, 1
        elif info <= 27:
            width = 1 << (info - 24)
            if pos + 1 + width > len(buf):
                return None
            argument, size = int.from_bytes(buf[pos + 1 : pos + 1 + width], "big"), 1 + width
        elif info == 31:
            return pos + 1, self._indefinite(major)
        else:  # 28-30 are reserved: treat the byte as a complete (invalid) item
            return pos + 1, self._item_done()
        pos += size
        if major in (2, 3):
            self.payload_left = argument
            return pos, False if argument else self._item_done()
        if major in (4, 5, 6):
            count = argument * 2 if major == 5 else (1 if major == 6 else argument)
            if count:
                self.stack.append(count)
                return pos, False
        return pos, self._item_done()

    def _indefinite(self, major: int) -> bool:
        if major == 7:  # break: closes the innermost indefinite container
            if self.stack and self.stack[-1] == -1:
                self.stack.pop()
            return self._item_done()
        if major in (2, 3, 4, 5):
            self.stack.append(-1)
            return False
        return self._item_done()  # invalid: an indefinite integer or tag

    def _item_done(self) -> bool:
        """One item ended: count it against its container; True if the top item ended."""
        while self.stack:
            if self.stack[-1] == -1:
                return False
            self.stack[-1] -= 1
            if self.stack[-1]:
                return False
            self.stack.pop()
        return True


class LineFramer:
    r"""Split a byte stream into lines, one JSON text each (stdio, D22).

    Args:
        max_frame_bytes: the longest line kept, in bytes; a longer one is
            skipped to its newline and reported once.

    Blank lines are ignored; a trailing ``\\r`` is removed.
    """

    def __init__(self, max_frame_bytes: int) -> None:
        self.max_frame_bytes = max_frame_bytes
        self._buf = bytearray()
        self._skipping = False

    def receive_data(self, data: bytes) -> list[FramerEvent]:
        """Take the next chunk of the stream; return the lines it completed."""
        events: list[FramerEvent] = []
        start = 0
        while True:
            end = data.find(b"\n", start)
            if end < 0:
                break
            self._line(data[start:end], events)
            start = end + 1
        rest = data[start:]
        if not self._skipping:
            self._buf += rest
            if len(self._buf) > self.max_frame_bytes:
                self._buf.clear()
                self._skipping = True
                events.append(
                    FramingError(f"line longer than {self.max_frame_bytes} bytes skipped")
                )
        return events

    def receive_eof(self) -> list[FramerEvent]:
        """The stream ended: a last line without a newline is still a frame."""
        events: list[FramerEvent] = []
        self._line(b"", events)
        return events

    def _line(self, tail: bytes, events: list[FramerEvent]) -> None:
        if self._skipping:
            self._skipping = False
            self._buf.clear()
            return
        if self._buf:
            tail = bytes(self._buf) + tail
            self._buf.clear()
        if len(tail) > self.max_frame_bytes:
            events.append(FramingError(f"line longer than {self.max_frame_bytes} bytes skipped"))
            return
        line = tail.strip()
        if line:
            events.append(InFrame(line))
