"""Topic placement (``rwt serve --workers N --placement topic``): one worker a topic.

A connection moves to the worker that owns its first topic.

Why: a message whose subscribers sit on several workers is decoded, routed and framed
again in each of them (docs/scaling.md, "Where a worker's CPU goes": ``e + (W-1) r``
per message, and a per-delivery cost that grows with the workers). Placing every
connection of a topic on one worker takes W to 1 for that topic: its messages never
cross between workers, and N workers serve N times the topics of one.

The rule (docs/decisions.md D57): each topic has one owner. The first worker to place a
connection by a topic claims it for the next worker in turn (a file in the workers'
state folder, made atomically, so every worker, restarted ones included, reads the same
owner); past ``MAX_CLAIMS`` topics the owner is ``crc32(topic) % N``. A plain WebSocket
connection whose front end reads a topic in its **first message** (``FrontEnd.first_topic``:
rosbridge's ``subscribe``, ``advertise`` or ``publish``) names it; if another worker owns it, the
connection is handed to that worker before its session has seen any message: the
socket's descriptor (``SCM_RIGHTS``) and every byte read from it so far (the upgrade
request, the first message and anything after it, at most ``RECORD_LIMIT_BYTES``) go
over a Unix socket in the workers' private state folder (the parent's, mode 0700).
The owner reads those bytes as if they had just arrived: the same handshake checks,
admission and caps, without sending the upgrade response again (the client has it),
so the client sees one connection, nothing lost or repeated. The worker that handed
it off sends nothing more on it.

Not moved, and served where they landed as before: TLS (its state is this process's),
permessage-deflate (its compression context), another front end (Foxglove sends on
open), a first message that is anything else (``auth``, a service call: what the
session held would be lost), CBOR, or longer than the record allows, and any
connection whose owner cannot be reached at once (restarting: the connection stays and
works over the link as without placement). An owner that is full closes the connection
it was handed with 1013 (try again later): its upgrade was accepted already.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import socket
import struct
import zlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast

import anyio
from anyio.streams.buffered import BufferedByteReceiveStream

from rwt_graph.ratelog import EpisodeLog

from .counts import STATE_PREFIX

if TYPE_CHECKING:
    from collections.abc import Callable

    from anyio.abc import SocketStream, UNIXSocketStream


__all__ = ["RECORD_LIMIT_BYTES", "Placement"]

logger = logging.getLogger("rwt.workers")
_episodes = EpisodeLog(logger)

RECORD_LIMIT_BYTES = 64 * 1024
"""Most bytes read from a connection (upgrade request, first message, what followed) that a
hand-off carries; a connection whose first message completes later is served where it is."""
MAX_CLAIMS = 1024
"""Topics given an owner in turn; later ones are owned by their name's hash (a client that
names topics at will makes at most this many small files)."""
HANDOFF_TIMEOUT_S = 2.0
"""How long a hand-off may take (connect, send, the owner's word), seconds; a live worker
takes one at once. Past it the connection is served where it landed, or closed if the
owner may have taken it (its descriptor left)."""
_HEADER = struct.Struct("!I")  # the record's length, bytes
_TAKEN = b"\x01"


@dataclass(frozen=True)
class Placement:
    """One worker's place among ``count`` workers that place connections by topic.

    Attributes:
        folder: the workers' state folder (the parent's, private to its user).
        index: this worker's index (0 to ``count`` - 1).
        count: the number of workers.
    """

    folder: str
    index: int
    count: int
    _owners: dict[str, int] = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def of_state(cls, state: str, count: int) -> Placement | None:
        """The place of the worker whose ``--worker-state`` file is ``state``; None: not one."""
        folder, name = os.path.split(state)
        number = name.removeprefix(STATE_PREFIX)
        if not folder or number == name or not number.isdigit() or count < 2:
            return None
        return cls(folder, int(number), count)

    def path(self, index: int) -> str:
        """The Unix socket worker ``index`` takes handed-off connections on."""
        return os.path.join(self.folder, f"placement-{index}.sock")

    def owner(self, topic: str) -> int:
        """The worker that owns ``topic`` (the same in every worker).

        The first worker asking claims it for the next worker in turn: the number of
        topics claimed before, modulo ``count`` (two claims at once may pick the same
        worker). The claim is a file named by the topic's hash, linked into place
        atomically, so a claim that lost the race reads the winner's. Past
        ``MAX_CLAIMS`` topics, or without the state folder: ``crc32`` of its name,
        modulo ``count``.
        """
        owner = self._owners.get(topic)
        if owner is not None:
            return owner
        encoded = topic.encode("utf-8", "surrogatepass")
        path = os.path.join(self.folder, "topic-" + hashlib.sha256(encoded).hexdigest()[:32])
        try:
            owner = _claimed(path, self.count)
            if owner is None and len(self._owners) < MAX_CLAIMS:
                owner = _claim(self.folder, path, self.count)
        except OSError:
            owner = None
        if owner is None:
            return zlib.crc32(encoded) % self.count
        self._owners[topic] = owner
        return owner

    async def hand_off(self, owner: int, fd: int, record: bytes) -> bool | None:
        """Give the connection on descriptor ``fd`` to worker ``owner``, with the bytes read.

        Returns True once the owner took it (this worker must not touch it again), False
        when the owner could not be reached (nothing was sent: serve it here), None when
        the descriptor left but the owner did not confirm (close it here: whether the
        owner serves it is unknown).
        """
        sent = False
        try:
            with anyio.fail_after(HANDOFF_TIMEOUT_S):
                stream = await anyio.connect_unix(self.path(owner))
                async with stream:
                    await stream.send_fds(_HEADER.pack(len(record)), [fd])
                    sent = True
                    await stream.send(record)
                    if await stream.receive(1) == _TAKEN:
                        return True
        except (OSError, TimeoutError, anyio.EndOfStream, anyio.BrokenResourceError) as exc:
            _failed(owner, exc)
        return None if sent else False

    async def serve(
        self,
        take: Callable[[socket.socket, bytes], None],
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Take the connections other workers hand here until cancelled.

        ``take(sock, record)`` starts serving one (it must not block): ``record`` is
        what the other worker read from it, to be read first.
        """
        path = self.path(self.index)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)  # this worker's predecessor's (it died)
        listener = await anyio.create_unix_listener(path)
        task_status.started()

        async def one(accepted: SocketStream) -> None:
            stream = cast("UNIXSocketStream", accepted)  # a Unix listener's
            async with stream:
                taken = None
                with anyio.move_on_after(HANDOFF_TIMEOUT_S):
                    taken = await _receive(stream)
                if taken is None:
                    return
                sock, record = taken
                try:
                    await stream.send(_TAKEN)
                except (OSError, anyio.BrokenResourceError):
                    sock.close()  # the giver gave up: it closes its side
                    return
                take(sock, record)

        async with listener:
            await listener.serve(one)


async def _receive(stream: UNIXSocketStream) -> tuple[socket.socket, bytes] | None:
    """The connection another worker hands over: its socket and the bytes read; None if bad."""
    fds: list[int] = []
    try:
        header, fds = await stream.receive_fds(_HEADER.size, 1)
        if len(fds) != 1 or len(header) != _HEADER.size:
            return None
        (size,) = _HEADER.unpack(header)
        if size > RECORD_LIMIT_BYTES:
            return None
        record = await BufferedByteReceiveStream(stream).receive_exactly(size) if size else b""
        sock = socket.socket(fileno=fds.pop())
        if sock.type != socket.SOCK_STREAM:
            sock.close()
            return None
        return sock, record
    except (OSError, anyio.EndOfStream, anyio.IncompleteRead, anyio.BrokenResourceError):
        return None
    finally:
        for fd in fds:
            os.close(fd)


def _claimed(path: str, count: int) -> int | None:
    """The owner a claim file names; None: no claim (or one this many workers cannot own)."""
    try:
        with open(path, "rb") as claim:
            text = claim.read(16)
    except FileNotFoundError:
        return None
    return int(text) if text.isdigit() and int(text) < count else None


def _claim(folder: str, path: str, count: int) -> int | None:
    """Claim the topic of ``path`` for the next worker in turn; the owner, or None (full).

    Raises:
        OSError: the state folder cannot be read or written.
    """
    names = [name for name in os.listdir(folder) if name.startswith("topic-")]
    if len(names) >= MAX_CLAIMS:
        return None
    owner = len(names) % count
    draft = os.path.join(folder, f"draft-{os.getpid()}-{os.path.basename(path)}")
    with open(draft, "wb") as claim:
        claim.write(str(owner).encode())
    try:
        os.link(draft, path)  # atomic: the first claim stays
    except FileExistsError:
        return _claimed(path, count)
    finally:
        os.unlink(draft)
    return owner


def _failed(owner: int, exc: BaseException) -> None:
    """``event=placement_failed``, once per episode: the owner restarting, or stuck."""
    _episodes.log(
        logging.INFO, "placement_failed", "event=placement_failed owner=%d error=%r", owner, exc
    )
