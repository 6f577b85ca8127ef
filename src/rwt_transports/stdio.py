"""stdio transport: one session over a pair of file descriptors (D22).

``rwt serve --stdio`` talks one rosbridge session over stdin/stdout, one JSON
text per line each way (CBOR items, if a subscription asks for them, go out as
they are, as on TCP); logs go to stderr only. This suits a parent process that
runs rwt as a child. Pipes, terminals and sockets are polled without threads
(so shutdown never waits on a blocked read); a regular file (or /dev/null) is
read with blocking reads in a worker thread.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from typing import TYPE_CHECKING

import anyio

from rwt_protocol.framing.streams import LineFramer

from .channel import PlainChannel
from .tcp import encode_stream_frames

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rwt_protocol.runtime.commands import CloseCode
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.inframes import FramerEvent
    from rwt_protocol.runtime.outbox import OutFrame

__all__ = ["StdioChannel"]

_READ_SIZE = 65536


def _pollable(fd: int) -> bool:
    """Whether epoll can watch ``fd``: pipes, sockets and terminals, not files or /dev/null."""
    mode = os.fstat(fd).st_mode
    return stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode) or (stat.S_ISCHR(mode) and os.isatty(fd))


class StdioChannel(PlainChannel):
    """A session's frames over two file descriptors (stdin and stdout by default).

    Args:
        read_fd: where frames come from, one JSON text per line.
        write_fd: where frames go.
        max_message_size: the longest line, in bytes.

    Use as a context manager: pollable descriptors are made non-blocking while
    it is open and restored afterwards.
    """

    transport = "stdio"
    awaits_peer_close = False

    def __init__(self, read_fd: int, write_fd: int, max_message_size: int) -> None:
        self.read_fd = read_fd
        self.write_fd = write_fd
        self._framer = LineFramer(max_message_size)
        self._poll_read = _pollable(read_fd)
        self._poll_write = _pollable(write_fd)
        self._saved: list[tuple[int, bool]] = []
        self._ended = False

    def __enter__(self) -> StdioChannel:
        for fd, poll in ((self.read_fd, self._poll_read), (self.write_fd, self._poll_write)):
            if poll and (fd, True) not in self._saved:
                self._saved.append((fd, os.get_blocking(fd)))
                os.set_blocking(fd, False)
        return self

    def __exit__(self, *exc: object) -> None:
        for fd, blocking in self._saved:
            with contextlib.suppress(OSError):
                os.set_blocking(fd, blocking)
        self._saved.clear()

    async def receive(self) -> Sequence[FramerEvent]:
        """Read the next chunk of lines."""
        if self._ended:
            raise anyio.EndOfStream
        data = await self._read()
        if not data:
            self._ended = True
            events = self._framer.receive_eof()
            if events:
                return events
            raise anyio.EndOfStream
        return self._framer.receive_data(data)

    async def _read(self) -> bytes:
        if not self._poll_read:
            return await anyio.to_thread.run_sync(os.read, self.read_fd, _READ_SIZE)
        while True:
            await anyio.wait_readable(self.read_fd)
            try:
                return os.read(self.read_fd, _READ_SIZE)
            except BlockingIOError:
                continue

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Write the frames, a line per JSON frame.

        Raises:
            anyio.BrokenResourceError: the reader of ``write_fd`` went away.
        """
        view = memoryview(encode_stream_frames(frames))
        while view:
            try:
                if self._poll_write:
                    await anyio.wait_writable(self.write_fd)
                    written = os.write(self.write_fd, view)
                else:
                    written = await anyio.to_thread.run_sync(os.write, self.write_fd, view)
            except BlockingIOError:
                continue
            except OSError as exc:
                if exc.errno in (errno.EPIPE, errno.EBADF, errno.ECONNRESET):
                    raise anyio.BrokenResourceError from exc
                raise
            view = view[written:]

    async def close(self, code: CloseCode, reason: str) -> None:
        """Stop: the parent sees the end when the process exits."""
        self._ended = True

    async def background(self, session: ServerSession) -> None:
        """Nothing to do."""
