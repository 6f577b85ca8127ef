"""MCP under ``rwt serve --mcp --workers N``: a request goes to the worker holding its state.

A 2026-07-28 request carries no session, so the worker that accepted its socket
answers it (the workers accept from one listening socket, workers.py; the graph is
one through the workers' links). Two things
stay where they were made: a 2025-era session (its ``Mcp-Session-Id``) and a task
(its ``taskId``: the goal lives on a connection of that worker, and its feedback
and result arrive there). Their ids name the worker that holds them
(``w<index>-<32 hex digits>``, ``McpSiblings.new_id``); a worker given a request for
another's session, or a ``tasks/*`` request naming another's task, passes the
request to that worker over a Unix socket in the workers' private state folder
(the parent's ``--worker-state`` folder, mode 0700) and relays its answer, an
event stream included, until either side closes (docs/mcp.md, "Tasks and
workers").

The owner answers as if the request had come to it: auth, the origin check,
the access rules, its caps, under the peer's address, which the forwarding
worker states first (``RWT-PEER <address>``: only the workers of one parent can
reach the socket). A request is passed once: a forwarded one is answered
where it lands. An owner that cannot be reached (it died: its sessions and tasks
died with it) leaves the request to the worker that got it, which answers as for
any unknown session or task (404, "no task").

The relay is the client's stand-in, and leaves as a client does: when the client
closes, the forwarding worker shuts its side of the Unix socket for writing (the
owner reads the end of the request stream, as from a client that closed) and reads
what the owner still writes, to drop it, until the owner ends its answer
(``DRAIN_S`` at most): the owner's last writes find a reader, not a broken pipe.
Both ends of the Unix socket run on the event loop's transports
(``SocketStream.from_socket``), not anyio's Unix streams: those wait for the socket
with a future that the loop's readiness callback completes, and a read cancelled in
the loop turn that found the socket ready made that callback fail, logged by
asyncio at ERROR (``Exception in callback Future.set_result(None)``); a relay's
reads are cancelled whenever its client or its answer ends.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import socket
import uuid
from dataclasses import dataclass
from typing import TYPE_CHECKING

import anyio
import h11
from anyio.abc import SocketStream

from rwt_graph.ratelog import EpisodeLog

from ..workers.counts import STATE_PREFIX

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable

    from anyio.abc import ByteStream

__all__ = ["DRAIN_S", "PEER_PREAMBLE", "McpSiblings"]

logger = logging.getLogger("rwt.mcp")
_episodes = EpisodeLog(logger)

PEER_PREAMBLE = b"RWT-PEER "
"""What a forwarded request starts with: ``RWT-PEER <peer address>\\r\\n``, then the request."""
_PREAMBLE_MAX = 300  # bytes: the prefix, an address (IPv6 with port), CRLF
_CONNECT_TIMEOUT_S = 2.0  # a live worker accepts at once; a stuck one is not waited on
_PREAMBLE_TIMEOUT_S = 5.0
_READ_SIZE = 65536
_ACCEPT_BACKOFF_S = 0.1  # out of descriptors: the forwarded requests wait in the backlog

DRAIN_S = 5.0
"""Seconds a forwarding worker whose client left reads (and drops) what the owner still
writes, after telling it the request stream ended: the owner ends an answer whose client
left at once, so this bounds only an owner that does not."""
_ID = re.compile(r"w(\d{1,4})-[0-9a-f]{32}")
STATE_KEY = "mcp-request-state.key"
"""The workers' key of 2026-07-28 request states, in their state folder (``state_key``)."""


@dataclass(frozen=True)
class McpSiblings:
    """One worker's place among the workers of one ``rwt serve --workers N``.

    Attributes:
        folder: the workers' state folder (the parent's, private to its user).
        index: this worker's index (0 to N-1).
    """

    folder: str
    index: int

    def state_key(self) -> bytes:
        """The key every worker seals a 2026-07-28 round's request state with (32 bytes).

        Made once, by the first worker that asks, as a file of the private state folder
        (mode 0600, linked into place whole, so a worker reads all of it or none), so
        that the round after a person's answer may land on any worker (D69).
        """
        path = os.path.join(self.folder, STATE_KEY)
        if not os.path.exists(path):
            made = f"{path}.{os.getpid()}"
            descriptor = os.open(made, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(descriptor, "wb") as file:
                file.write(os.urandom(32))
            with contextlib.suppress(FileExistsError):  # another worker's came first
                os.link(made, path)
            os.unlink(made)
        with open(path, "rb") as file:
            return file.read()

    @classmethod
    def of_state(cls, state: str) -> McpSiblings | None:
        """The place of the worker whose ``--worker-state`` file is ``state``; None: not one."""
        folder, name = os.path.split(state)
        number = name.removeprefix(STATE_PREFIX)
        if not folder or number == name or not number.isdigit():
            return None
        return cls(folder, int(number))

    def path(self, index: int) -> str:
        """The Unix socket worker ``index`` takes forwarded MCP requests on."""
        return os.path.join(self.folder, f"mcp-{index}.sock")

    def new_id(self) -> str:
        """A new session or task id naming this worker: ``w<index>-<uuid4 hex>``."""
        return f"w{self.index}-{uuid.uuid4().hex}"

    def owner(self, ident: str) -> int | None:
        """The other worker that made ``ident``; None: this one, or not a worker's id."""
        named = _ID.fullmatch(ident)
        if named is None or int(named.group(1)) == self.index:
            return None
        return int(named.group(1))

    async def forward(
        self,
        owner: int,
        peer: str,
        request: h11.Request,
        body: bytes,
        stream: ByteStream,
    ) -> bool:
        """Pass the request to worker ``owner`` and relay its answer to ``stream``.

        Returns once the answer ended or the client left (True), or at once if the
        worker cannot be reached (False: the caller answers the request itself).
        """
        try:
            with anyio.fail_after(_CONNECT_TIMEOUT_S):
                sibling = await _connect(self.path(owner))
        except (OSError, TimeoutError) as exc:
            _failed(owner, exc)
            return False
        logger.debug("event=mcp_forwarded worker=%d owner=%d peer=%s", self.index, owner, peer)
        async with sibling:
            try:
                await sibling.send(PEER_PREAMBLE + peer.encode("latin-1") + b"\r\n")
                await sibling.send(_request_bytes(request, body))
            except (anyio.BrokenResourceError, OSError) as exc:
                _failed(owner, exc)
                return False
            await _relay(sibling, stream)
        return True

    async def serve(
        self,
        answer: Callable[[ByteStream, bytes, str], Awaitable[None]],
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Take the requests other workers pass here until cancelled.

        ``answer(stream, head, peer)`` answers one (``McpEndpoint.serve``): ``head``
        is what was read after the preamble, ``peer`` the client's address.
        """
        path = self.path(self.index)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)  # this worker's predecessor's (it died)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            listener.bind(path)
            listener.listen()
            listener.setblocking(False)
            task_status.started()

            async def one(sock: socket.socket) -> None:
                try:
                    stream = await SocketStream.from_socket(sock)
                except OSError:  # the sibling left already
                    sock.close()
                    return
                async with stream:
                    read = None
                    with anyio.move_on_after(_PREAMBLE_TIMEOUT_S):
                        read = await _preamble(stream)
                    if read is None:
                        return
                    try:
                        await answer(stream, read[1], read[0])
                    except Exception:  # a bug ends this request only
                        logger.exception("event=bug task=mcp_forwarded peer=%s", read[0])

            async with anyio.create_task_group() as tg:
                while True:
                    tg.start_soon(one, await _accept(listener))
        finally:
            listener.close()


async def _connect(path: str) -> SocketStream:
    """A stream to the Unix socket at ``path`` on the event loop's transports (module text).

    Raises:
        OSError: nothing listens there (the worker died), or the connect failed.
    """
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.setblocking(False)
        while True:
            try:
                sock.connect(path)
                break
            except BlockingIOError:  # the listener's backlog is full: again once it is not
                await anyio.wait_writable(sock)
        return await SocketStream.from_socket(sock)
    except BaseException:
        sock.close()
        raise


async def _accept(listener: socket.socket) -> socket.socket:
    """The next connection of ``listener`` (non-blocking); waits out a lack of descriptors."""
    while True:
        await anyio.wait_readable(listener)
        try:
            sock, _ = listener.accept()
        except BlockingIOError:
            continue
        except OSError as exc:  # EMFILE, ENFILE, ENOBUFS: the sibling waits in the backlog
            _episodes.log(
                logging.WARNING, "mcp_accept_failed", "event=mcp_accept_failed error=%r", exc
            )
            await anyio.sleep(_ACCEPT_BACKOFF_S)
            continue
        return sock


async def _relay(sibling: SocketStream, stream: ByteStream) -> None:
    """Copy the owner's answer from ``sibling`` to the client's ``stream`` until it ends.

    If the client leaves first, the owner is told the request stream ended and what it
    still writes is read and dropped, ``DRAIN_S`` at most (module text).
    """
    gone = anyio.Event()
    async with anyio.create_task_group() as tg:

        async def leave_when_gone() -> None:
            await _until_gone(stream)
            gone.set()
            with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
                await sibling.send_eof()
            await anyio.sleep(DRAIN_S)  # the answer's end cancels this first
            tg.cancel_scope.cancel()

        tg.start_soon(leave_when_gone)
        with contextlib.suppress(
            anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError, OSError
        ):
            async for chunk in sibling:
                if gone.is_set():
                    continue  # read and dropped: the owner's writes find a reader
                try:
                    await stream.send(chunk)
                except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
                    gone.set()  # the client's side broke: its reader learns it too
        tg.cancel_scope.cancel()  # the answer ended: the client's reader too


def _failed(owner: int, exc: BaseException) -> None:
    """``event=mcp_forward_failed``, once per episode: a client names the worker at will."""
    _episodes.log(
        logging.INFO, "mcp_forward_failed", "event=mcp_forward_failed owner=%d error=%r", owner, exc
    )


async def _until_gone(stream: ByteStream) -> None:
    """Return when the client closes (bytes it sends are dropped: one request)."""
    with contextlib.suppress(
        anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError, OSError
    ):
        while True:
            await stream.receive(_READ_SIZE)


async def _preamble(stream: ByteStream) -> tuple[str, bytes] | None:
    """(the peer's address, the request's first bytes), or None: not a preamble.

    At least one byte of the request is read: an empty head would tell h11 the
    stream ended.
    """
    data = b""
    while (end := data.find(b"\n")) in (-1, len(data) - 1):  # and a byte of the request
        if end == -1 and len(data) > _PREAMBLE_MAX:
            return None
        try:
            data += await stream.receive(_READ_SIZE)
        except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
            return None
    line, _, rest = data.partition(b"\n")
    if not line.startswith(PEER_PREAMBLE) or len(line) > _PREAMBLE_MAX:
        return None
    return line[len(PEER_PREAMBLE) :].strip().decode("latin-1"), rest


def _request_bytes(request: h11.Request, body: bytes) -> bytes:
    """The request as sent again: its head, and its body read whole (``Content-Length``)."""
    framing = (b"content-length", b"transfer-encoding")
    headers = [(k, v) for k, v in request.headers if k.lower() not in framing]
    headers.append((b"content-length", str(len(body)).encode()))
    client = h11.Connection(h11.CLIENT)
    again = h11.Request(
        method=request.method, target=request.target, headers=headers, http_version="1.1"
    )
    data = client.send(again) or b""
    if body:
        data += client.send(h11.Data(data=body)) or b""
    return data + (client.send(h11.EndOfMessage()) or b"")
