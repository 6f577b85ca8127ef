"""WebSocket transport: websockets' sans-IO protocol driven from anyio streams.

Why this shape: websockets' ``ServerProtocol`` does the RFC 6455
parsing and framing without I/O, so the connection pump (pump.py) can drive it
like every other transport: a single writer per connection draining the
session's bounded outbox (D24), frames written without a per-subscriber await
in the publish path, the same code over plain TCP or TLS streams (wss), and
anyio's structured cancellation for shutdown. Shortcuts (for the benchmarks;
listed, with their switch, in rwt_protocol/shortcuts.py), each falling back to
websockets or anyio: whole data frames are read ahead of its parser (wsread.py,
``ws-frame-reader``) unless permessage-deflate is on or the client sent frames
with its upgrade request; data frames are framed here (``ws-frame-writer``)
unless permessage-deflate is on; and a plain socket is read and written
through its asyncio transport (direct.py).

Text frames carry JSON, binary frames CBOR (D27). permessage-deflate is off
unless enabled (D30: Node's ``ws`` offers it; we decline). Incoming messages are
limited to ``max_message_size`` bytes (10 MiB default, D24/D30); a larger one
closes the connection with code 1009 (as rosbridge's tornado does, REF §1.1).
Origins and the URL path are checked at the handshake (``--allowed-origins``,
``--url-path``); keepalive pings are optional (``--websocket-ping-interval``).
The protocol is the listener's front end that claims a subprotocol the client
offers (``frontends.FrontEnds``: Foxglove's), else its default (rosbridge); every
one runs on the same pump.
"""

from __future__ import annotations

import contextlib
import fnmatch
import logging
import os
import struct
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final
from urllib.parse import urlsplit

import anyio
from websockets.exceptions import InvalidState
from websockets.extensions.permessage_deflate import ServerPerMessageDeflateFactory
from websockets.frames import Frame, Opcode
from websockets.http11 import Request, Response
from websockets.protocol import State
from websockets.server import ServerProtocol
from websockets.typing import Subprotocol

from rwt_console.site import ConsoleSite, http_response_bytes
from rwt_protocol.framing.fragments import BudgetCharge
from rwt_protocol.framing.messages import FrameKind, MessageAssembler, MessageTooBigError
from rwt_protocol.runtime.commands import CloseCode
from rwt_protocol.runtime.inframes import FramerEvent, InFrame
from rwt_protocol.shortcuts import enabled

from .admission import arrival as admission
from .admission.pending import RETRY_AFTER_S, current_socket
from .channel import ChannelAbilities
from .direct import DirectReader, DirectWriter, asyncio_parts
from .http.endpoint import MAX_HEAD_BYTES, drain_refused
from .pump import CLOSE_WAIT_S, ConnectionPump, run_connection
from .sendqueue import stream_unsent_bytes
from .workers.placement import RECORD_LIMIT_BYTES
from .writes import WRITE_BATCH
from .wsread import FrameReader

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from anyio.abc import ByteStream
    from websockets.datastructures import Headers
    from websockets.extensions.base import ServerExtensionFactory

    from rwt_protocol.credentials import AuthMode, EntryAuth
    from rwt_protocol.framing.fragments import FragmentBudget
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.outbox import OutFrame

    from .frontends import FrontEnd, FrontEnds
    from .host import SessionHost
    from .http.endpoint import HttpEndpoint
    from .workers.placement import Placement

__all__ = ["WebSocketOptions", "serve_websocket_connection"]

logger = logging.getLogger("rwt.websocket")

MiB = 1024 * 1024
_READ_SIZE = 1024 * 1024
"""Most bytes taken from the stream at once: whatever the event loop has read (asyncio
reads 256 KiB at a time), so a large message is parsed in few steps (benchmarks B4)."""
_HANDSHAKE_LIMIT_S = 10.0
_DATA_OPCODES = (Opcode.TEXT, Opcode.BINARY, Opcode.CONT)
_MAX_REASON = 123  # bytes of a close reason (RFC 6455 5.5: a control frame's 125, less the code)


def _parser_held(protocol: ServerProtocol) -> int:
    """Bytes websockets' parser keeps of a frame begun (its reader's buffer; 0 if unseen)."""
    buffer = getattr(getattr(protocol, "reader", None), "buffer", None)
    return len(buffer) if isinstance(buffer, bytearray) else 0


@dataclass(frozen=True, slots=True)
class WebSocketOptions:
    """WebSocket settings of a listener.

    Attributes:
        compression: offer permessage-deflate (``--websocket-compression``).
        url_path: the only path accepted, or None for any path (``--url-path``).
        allowed_origins: fnmatch patterns of accepted ``Origin`` headers; empty
            accepts any origin, as rosbridge does (``--allowed-origins``). A
            request without ``Origin`` (not a browser) is always accepted.
        ping_interval_s: seconds between keepalive pings; 0 sends none
            (``--websocket-ping-interval``, rosbridge's default 0).
        ping_timeout_s: seconds to wait for the pong before closing with 1011
            (``--websocket-ping-timeout``, rosbridge's default 30).
        console: answers plain HTTP GET/HEAD requests (no ``Upgrade``) with the
            web console (docs/console.md). True (the default): the server's own
            console, as ``rwt serve`` has it: on unless ``allowed_origins`` is set
            (``rwt_console.console_for``; ``GraphServer`` builds it from its
            settings). A ``ConsoleSite``: that one, whatever the origins
            (``--console``). False or None: off (``--no-console``), such requests
            fail the handshake.
    """

    compression: bool = False
    url_path: str | None = None
    allowed_origins: tuple[str, ...] = ()
    ping_interval_s: float = 0.0
    ping_timeout_s: float = 30.0
    console: ConsoleSite | bool | None = True


class WebSocketChannel:
    """One accepted WebSocket connection as a pump ``Channel``.

    The reader, the writer and the keepalive all write to the stream, each under
    one lock, always through ``protocol.data_to_send()``: bytes go out in the
    order the protocol made them. On a plain socket, the pump may also write
    from the publish path (``send_now``) while nobody holds the lock.

    A message still arriving (its frame begun, or the first frames of a
    fragmented one) is charged to ``budget`` (``--max-fragment-memory``) after
    every chunk read; past it the connection is closed with 1013 (try again
    later), since websockets cannot skip a frame. ``release`` gives the
    charge back when the connection ends.
    """

    transport = "ws"
    awaits_peer_close = True
    abilities = ChannelAbilities(
        pause_reading=True, probe_input=True, unsent_bytes=True, send_now=True
    )
    """A socket: paused while its reader is held, probed, its send queue read, written at once."""

    def __init__(
        self,
        stream: ByteStream,
        protocol: ServerProtocol,
        options: WebSocketOptions,
        max_message_size: int,
        budget: FragmentBudget | None = None,
    ):
        self.stream = stream
        self.protocol = protocol
        self.options = options
        # fast_acquire: an uncontended lock is taken without a checkpoint (one
        # task switch less per batch); the sends under it still checkpoint.
        self._lock = anyio.Lock(fast_acquire=True)
        self._direct = DirectWriter.for_stream(stream)
        self._reader = DirectReader.for_stream(stream)
        self._probe = admission.stream_probe(stream, self._reader)
        self.sees_input = admission.stream_sees_all(stream, self._reader)
        """Whether ``input_pending`` sees every byte waiting (never None)."""
        # ``ws-frame-writer``: off, websockets frames every data message.
        self._frame_here = enabled("ws-frame-writer")
        self.frames: FrameReader | None = None
        """Reads whole messages ahead of websockets; set once the handshake allows it."""
        self.max_message_size = max_message_size
        self._messages = MessageAssembler(max_message_size)
        self._charge = BudgetCharge(budget)
        self._eof = False  # the peer's end (or the wait for it) is over: read no more
        self._eof_sent = False
        self._pong = anyio.Event()
        self._failed: str | None = None  # a text message was not UTF-8: read no more (1007)
        self._closing_deadline: float | None = None  # set by the first read after our close
        self.early: list[Frame] = []
        """Whole frames the client sent with its upgrade request, parsed with it: read first."""
        self.placement: Placement | None = None
        self.first_topic: Callable[[FramerEvent], str | None] | None = None
        """The front end's reading of a first message's topic (``FrontEnd.first_topic``)."""
        """Where its first topic may move this connection (workers/placement.py); None: stays."""
        self.record: bytearray | None = None
        """Every byte read from the socket until the first message (``placement``'s)."""

    async def receive(self) -> Sequence[FramerEvent]:
        """Read, parse, answer control frames; return the whole data messages."""
        if self._eof or self.protocol.state is State.CLOSED:
            raise anyio.EndOfStream
        if self.early:  # parsed with the request: no read may come before them
            early, self.early = self.early, []
            messages, control = self._take_frames(early)
            if control or self.protocol.state is not State.OPEN:
                await self.flush()
            if self.record is not None and messages and await self._placed(messages):
                raise anyio.EndOfStream
            return messages
        try:
            if self.protocol.state is State.OPEN:
                data = await self._read()
            else:
                data = await self._read_while_closing()
        except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
            self.protocol.receive_eof()
            self._eof = True
            raise anyio.EndOfStream from None
        if self.record is not None:
            self.record += data
            if len(self.record) > RECORD_LIMIT_BYTES:
                self.record = None  # a first message this long is served here
        messages, control = self.read_chunk(data)
        # Only a control frame (a ping to answer, the close handshake) or a failure
        # (1002, 1009) makes the protocol write; data frames alone never do, and
        # taking the lock for nothing costs more than parsing a chunk.
        if control or self.protocol.state is not State.OPEN:
            if self._reader is not None:
                self._reader.pause()  # nothing piles up while the peer is slow to read
            await self.flush()
        if self.record is not None and messages and await self._placed(messages):
            raise anyio.EndOfStream
        return messages

    async def _placed(self, messages: Sequence[FramerEvent]) -> bool:
        """Whether the connection went to the worker owning its first topic (workers/placement.py).

        Decided once, on the first message, before the session sees it. The socket's
        reading stops, and what the loop read ahead goes with the record; a hand-off
        that fails leaves both where they were, and the connection is served here.
        After a hand-off (or one the owner did not confirm) this worker closes its
        descriptor without a byte more: the peer's connection is the owner's.
        """
        record, self.record = self.record, None
        placement, parts = self.placement, asyncio_parts(self.stream)
        if placement is None or self.first_topic is None or record is None or parts is None:
            return False
        topic = self.first_topic(messages[0])
        if topic is None or self.protocol.state is not State.OPEN or self._failed is not None:
            return False
        owner = placement.owner(topic)
        transport, read = parts
        sock = transport.get_extra_info("socket")
        if owner == placement.index or sock is None:
            return False
        transport.pause_reading()  # the next ``receive`` resumes it if the connection stays
        record += b"".join(read.read_queue)
        if len(record) > RECORD_LIMIT_BYTES:
            return False
        taken = await placement.hand_off(owner, sock.fileno(), bytes(record))
        if taken is False:
            return False
        logger.info("event=placed topic=%r owner=%d confirmed=%s", topic, owner, taken is True)
        read.read_queue.clear()
        transport.abort()  # our descriptor only: the owner's keeps the connection
        self._eof = True
        with contextlib.suppress(Exception):
            self.protocol.receive_eof()  # websockets sends nothing more (1006: no close frame)
        return True

    async def _read(self) -> bytes:
        reader = self._reader
        if reader is not None:
            return await reader.receive(_READ_SIZE)
        return await self.stream.receive(_READ_SIZE)

    async def _read_while_closing(self) -> bytes:
        """Read (for websockets to discard) what the peer sends after our close frame.

        The socket stays open until the peer's end, or ``CLOSE_WAIT_S`` after the
        close frame went out. Closing it with unread bytes, while a peer that has
        not yet read our close frame is still sending, makes the kernel reset the
        connection; a client whose write then fails (asyncio's transport) stops
        reading and never sees the close frame (RFC 6455 7.1.1: the server ends the
        TCP connection once the close handshake is done).

        Raises:
            anyio.EndOfStream: the peer's end, or the wait is over.
        """
        if self._closing_deadline is None:
            self._closing_deadline = anyio.current_time() + CLOSE_WAIT_S
        with anyio.move_on_after(self._closing_deadline - anyio.current_time()):
            return await self._read()
        raise anyio.EndOfStream

    def input_pending(self) -> bool | None:
        """Whether input is here already (a new connection's first read, admission/arrival.py).

        Bytes websockets' parser or the frame reader hold count (a client that sent
        frames with its upgrade request). None when none is seen but anyio may hold
        some (``admission.arrival.stream_probe``).
        """
        frames = self.frames
        if self.early or _parser_held(self.protocol) or (frames is not None and frames.held):
            return True
        return self._probe()

    def pause_reading(self) -> None:
        """Stop reading the socket until ``receive`` must wait (input backpressure, pump.py).

        Only the direct reader needs it: anyio's own ``receive`` pauses after each chunk.
        """
        if self._reader is not None:
            self._reader.pause()

    def read_chunk(self, data: bytes) -> tuple[list[FramerEvent], bool]:
        """Parse one received chunk, without I/O.

        Returns the whole data messages it completes, in order, and whether it
        held a control frame (the protocol may then have bytes to send). With
        ``frames`` set, whole messages are read there and the other frames
        passed to websockets in their place in the stream.
        """
        messages: list[FramerEvent] = []
        control = False
        frames = self.frames
        if frames is not None and self.protocol.state is not State.OPEN:
            frames.stop()  # closing: websockets reads (or drops) what is left
        for item in frames.feed(data) if frames is not None else (data,):
            if isinstance(item, InFrame):  # read by ``FrameReader``
                if self._failed is None and self._accept_text(item):
                    messages.append(item)
                elif frames is not None:
                    frames.stop()  # websockets parses the rest, as it would without ``frames``
                continue
            self.protocol.receive_data(item)
            parsed, had_control = self._take_frames(self.protocol.events_received())
            messages += parsed
            control = control or had_control
            if frames is not None and self.protocol.state is not State.OPEN:
                frames.stop()  # websockets failed the connection or got a close frame
        if self._failed is not None and self.protocol.state is State.OPEN:
            # After the chunk, as if websockets had checked it: a failure it found
            # in a later frame of the same chunk comes first either way.
            self.protocol.fail(int(CloseCode.INVALID_DATA), self._failed)
            control = True
        return messages, self._charge_held() or control

    def _take_frames(self, events: Sequence[object]) -> tuple[list[FramerEvent], bool]:
        """The whole data messages websockets' ``events`` complete; whether one was control.

        A control frame (a ping, a close) may leave the protocol bytes to send.
        """
        messages: list[FramerEvent] = []
        control = False
        for event in events:
            if isinstance(event, Frame):
                if event.opcode is Opcode.PONG:
                    self._pong.set()
                control = control or event.opcode not in _DATA_OPCODES
                message = self._assemble(event)
                if message is not None and self._failed is None and self._accept_text(message):
                    messages.append(message)  # none after a failure in this chunk
        return messages, control

    def _charge_held(self) -> bool:
        """Charge what waits to become a message; whether that failed the connection (1013)."""
        charge = self._charge
        if charge.budget is None:
            return False
        if self.protocol.state is not State.OPEN:  # what is still read is dropped
            self._messages.clear()
            self.release()
            return False
        frames = self.frames
        held = self._messages.held + (frames.held if frames is not None else 0)
        if charge.hold(held + _parser_held(self.protocol)):
            return False
        self._messages.clear()
        self.release()
        reason = charge.budget.refusal("message")
        # Failed, websockets drops its buffer and every byte it is given from now on.
        self.protocol.fail(int(CloseCode.TRY_AGAIN_LATER), reason[:_MAX_REASON])
        if frames is not None:
            frames.discard()
        return True

    def release(self) -> None:
        """Give back what this connection's incomplete message holds of the budget."""
        self._charge.release()

    def _accept_text(self, message: InFrame) -> bool:
        """Tell whether ``message`` may be handled.

        A text message that is not UTF-8 fails the connection with 1007 at the
        end of the chunk (RFC 6455 8.1; websockets' sans-IO parser does not check
        text, and ``FrameReader`` reads around it).

        ASCII, the common JSON text, is recognised without decoding.
        """
        data = message.data
        if message.binary or data.isascii():
            return True
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as exc:
            self._failed = f"invalid UTF-8 at position {exc.start}"
            return False
        return True

    async def send(self, frames: Sequence[OutFrame]) -> None:
        """Send data frames; text for JSON, binary for CBOR (D27).

        Without permessage-deflate, frames are framed here: the header is made
        once and kept on the ``OutFrame``, which every subscriber of the same
        form shares (encode once, frame once), and a batch of small
        frames goes out in one write. With deflate, or the ``ws-frame-writer``
        shortcut off, websockets frames each message.
        """
        async with self._lock:
            if self.protocol.state is not State.OPEN:
                # Closing: no data frame may follow the close frame (RFC 6455 5.5.1);
                # the reader waits for the peer's end before the socket is closed.
                return
            if self.protocol.extensions or not self._frame_here:
                self._send_through_protocol(frames)
                await self._flush_locked()
                return
            await self._flush_locked()  # control frames queued by the protocol go first
            await self._write_framed(frames)

    def unsent_bytes(self) -> int | None:
        """Bytes the socket's kernel still holds for the peer (sendqueue.py)."""
        return stream_unsent_bytes(self.stream)

    def can_send_now(self) -> bool:
        """Whether ``send_now`` may write at once.

        True only on a plain socket whose transport has nothing buffered, with
        no other write in progress (the lock is free), the connection open and
        no permessage-deflate (websockets must frame those messages itself).
        """
        direct = self._direct
        return (
            direct is not None
            and not self._lock.locked()
            and self.protocol.state is State.OPEN
            and not self.protocol.extensions
            and direct.ready
        )

    def send_now(self, frames: Sequence[OutFrame]) -> None:
        """Write ``frames`` without awaiting; call only when ``can_send_now`` is True.

        Control frames the protocol queued (pongs) go first, as in ``send``.

        Raises:
            RuntimeError: the transport refused the bytes (it started closing).
            anyio.ClosedResourceError: websockets refused to frame them (closing).
        """
        direct = self._direct
        if direct is None:
            raise RuntimeError("not a plain socket: send through the writer")
        if self._frame_here:
            chunks = [data for data in self.protocol.data_to_send() if data]
            chunks += _framed(frames)
        else:  # queued behind the control frames, as ``send`` does
            self._send_through_protocol(frames)
            chunks = [data for data in self.protocol.data_to_send() if data]
        direct.writev(chunks)

    def _send_through_protocol(self, frames: Sequence[OutFrame]) -> None:
        try:
            for frame in frames:
                data = frame.prefix + frame.data if frame.prefix else frame.data
                if frame.binary:
                    self.protocol.send_binary(data)
                else:
                    self.protocol.send_text(data)
        except InvalidState:
            raise anyio.ClosedResourceError from None

    async def _write_framed(self, frames: Sequence[OutFrame]) -> None:
        direct = self._direct
        if direct is None:
            for chunk in _framed(frames):
                await self.stream.send(chunk)
            return
        # a plain socket: the batch in one gathered write, then anyio waits while the
        # transport holds more than its high-water mark (and raises if it broke)
        await self.stream.send(b"")
        direct.writev(_framed(frames))
        await self.stream.send(b"")

    async def close(self, code: CloseCode, reason: str) -> None:
        """Send a close frame with ``code`` and ``reason``."""
        async with self._lock:
            try:
                self.protocol.send_close(int(code), reason[:120])
            except InvalidState:
                return  # already closing
            await self._flush_locked()

    async def background(self, session: ServerSession) -> None:
        """Keepalive: ping every interval; no pong in time closes the connection (1011)."""
        interval = self.options.ping_interval_s
        if interval <= 0:
            return
        while True:
            await anyio.sleep(interval)
            self._pong = anyio.Event()
            with anyio.move_on_after(self.options.ping_timeout_s):
                async with self._lock:
                    try:
                        self.protocol.send_ping(os.urandom(4))
                    except InvalidState:
                        return
                    await self._flush_locked()
                await self._pong.wait()
            if not self._pong.is_set():
                logger.warning("event=ping_timeout client=%s", session.client_id)
                session.request_close(
                    CloseCode.INTERNAL_ERROR, "keepalive ping timeout", abort=True
                )
                return

    async def flush(self) -> None:
        """Send whatever the protocol has queued (handshake response, control frames)."""
        async with self._lock:
            await self._flush_locked()

    async def _flush_locked(self) -> None:
        for data in self.protocol.data_to_send():
            if data:
                await self.stream.send(data)
            elif not self._eof_sent:  # websockets asks for the TCP connection to end
                # Our side only: the reader goes on until the peer's end (``receive``).
                self._eof_sent = True
                try:
                    await self.stream.send_eof()
                except NotImplementedError:
                    # TLS cannot half-close: end the connection now, as RFC 6455 7.1.1
                    # asks of the server (a client waits for it; 5 s otherwise).
                    self._eof = True
                except (OSError, anyio.BrokenResourceError):
                    pass

    def _assemble(self, frame: Frame) -> InFrame | None:
        """Collect fragmented data frames; return a whole message when complete."""
        kind = FrameKind.of(frame.opcode)
        if kind is None:
            return None
        try:
            return self._messages.add(kind, frame.data, fin=frame.fin)
        except MessageTooBigError:
            self.protocol.fail(int(CloseCode.MESSAGE_TOO_BIG), "message too big")
            return None


def _make_protocol(
    options: WebSocketOptions, max_message_size: int, frontends: FrontEnds
) -> ServerProtocol:
    extensions: list[ServerExtensionFactory] | None = None
    if options.compression:
        extensions = [ServerPerMessageDeflateFactory()]

    def select(protocol: ServerProtocol, offered: Sequence[Subprotocol]) -> Subprotocol | None:
        """The subprotocol of the front end the client chose (``FrontEnds.select``), or none."""
        chosen = frontends.select(offered)[1]
        return None if chosen is None else Subprotocol(chosen)

    return ServerProtocol(
        max_size=max_message_size,
        extensions=extensions,
        select_subprotocol=select if frontends.others else None,
    )


async def _read_head(
    stream: ByteStream, endpoints: Sequence[HttpEndpoint]
) -> tuple[bytes, HttpEndpoint | None] | None:
    """The request's first bytes, and the endpoint that claims them (``claims``), if any.

    None if the peer left first. Reads only until every endpoint can tell (a few
    bytes); the socket's handshake timeout bounds the wait.
    """
    head = b""
    with anyio.move_on_after(_HANDSHAKE_LIMIT_S):
        while True:
            try:
                head += await stream.receive(_READ_SIZE)
            except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
                return None
            answers = [(endpoint, endpoint.claims(head)) for endpoint in endpoints]
            claimed = next((endpoint for endpoint, answer in answers if answer), None)
            if claimed is not None or all(answer is False for _, answer in answers):
                return head, claimed
    return None


async def _claimed(
    stream: ByteStream, endpoints: Sequence[HttpEndpoint], peer: str
) -> bytes | None:
    """Answer a request an HTTP endpoint claims (None), or return the first bytes of another."""
    read = await _read_head(stream, endpoints)
    if read is None:
        return None
    head, claimed = read
    if claimed is not None:
        await claimed.serve(stream, head, peer)
        return None
    return head


async def _handshake(
    stream: ByteStream, protocol: ServerProtocol, head: bytes = b""
) -> tuple[Request, bool, list[Frame], bytearray] | None:
    """Read the upgrade request: it, whether it ended with the bytes read, its frames, the bytes.

    ``head``: the request's first bytes, read already (for a connection another
    worker handed here, every byte it read: workers/placement.py). Only when the bytes read
    end with the request, or with whole messages after it, does the next byte start
    a frame that websockets has not begun to parse, so that ``FrameReader`` may read
    from there. websockets parses frames sent with the request at once, with it:
    they are kept for the connection to read first (frames are handled in the order
    they reached the server, docs/limits.md).

    What it keeps until the request is admitted is charged to the socket's pending
    record, as the HTTP endpoints' requests are (``pending``, D58; the same refusals:
    429 or 503 with ``Retry-After``), and a head over ``MAX_HEAD_BYTES`` gets 431.
    """
    received = bytearray()  # bounded: MAX_HEAD_BYTES, and the pending record's charge
    with anyio.move_on_after(_HANDSHAKE_LIMIT_S):
        while True:
            if head:
                data, head = head, b""
            else:
                try:
                    data = await stream.receive(_READ_SIZE)
                except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
                    return None
            received += data
            protocol.receive_data(data)
            if protocol.handshake_exc is not None:  # not HTTP, not GET, too long, ...
                await _refuse_malformed(stream, protocol)
                return None
            events = protocol.events_received()
            for index, event in enumerate(events):
                if isinstance(event, Request):
                    if protocol.parser_exc is not None:  # a frame sent with it broke the rules
                        await _refuse_malformed(stream, protocol, protocol.parser_exc)
                        return None
                    at_frame_start = _whole_messages(received, received.find(b"\r\n\r\n") + 4)
                    early = [e for e in events[index + 1 :] if isinstance(e, Frame)]
                    return event, at_frame_start, early, received
            if protocol.state is not State.CONNECTING:
                return None
            if await _head_refused(stream, protocol, len(received)):  # not whole yet
                return None
    return None


async def _head_refused(stream: ByteStream, protocol: ServerProtocol, received: int) -> bool:
    """Refuse a request whose ``received`` bytes (its head, not yet whole) are too many.

    431 past ``MAX_HEAD_BYTES``; 429 or 503 when the socket's pending record cannot
    keep them (``admission.pending.PendingSocket.hold``, D58). Whether it was refused (answered).
    """
    refused: tuple[int, str, tuple[tuple[str, str], ...]] | None = None
    if received > MAX_HEAD_BYTES:
        refused = 431, f"the request's head is over {MAX_HEAD_BYTES} bytes", ()
    socket = current_socket()
    refusal = socket.hold(received) if socket is not None and refused is None else None
    if refusal is not None:
        refused = refusal.status, refusal.text, (("Retry-After", str(RETRY_AFTER_S)),)
    if refused is None:
        return False
    if socket is not None:
        socket.refused()  # nothing held for it while what else comes is dropped
    status, text, headers = refused
    response = protocol.reject(status, text + "\n")
    for name, value in headers:
        response.headers[name] = value
    with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        await stream.send(response.serialize())
    await drain_refused(stream, socket)
    return True


def _whole_messages(data: bytearray, at: int) -> bool:
    """Whether ``data`` from ``at`` on is whole frames, each a whole message or control.

    A frame's header says how long it is (RFC 6455 5.2); a fragment (no FIN, or a
    continuation) counts as not whole: its message goes on in websockets' assembler.
    """
    while at < len(data):
        if len(data) - at < 2 or not data[at] & 0x80 or not data[at] & 0x0F:
            return False
        size, head = data[at + 1] & 0x7F, 2
        if size >= 126:
            head = 4 if size == 126 else 10
            if len(data) - at < head:
                return False
            size = int.from_bytes(data[at + 2 : at + head], "big")
        at += head + (4 if data[at + 1] & 0x80 else 0) + size
    return at == len(data)


async def _refuse_malformed(
    stream: ByteStream, protocol: ServerProtocol, frame_exc: Exception | None = None
) -> None:
    """Answer a request websockets cannot parse with a 400 that says why.

    ``frame_exc``: the request was whole, but a frame sent with it broke the
    protocol (too large, not masked): websockets has failed the connection, so it
    is refused before it opens. The peer hears at once instead of waiting for the
    handshake timeout; the caller closes the stream.
    """
    if frame_exc is not None:
        reason = f"a frame sent with the request: {frame_exc}"
    else:
        reason = str(protocol.handshake_exc) or "malformed HTTP request"
    response = protocol.reject(400, f"{reason}\n")
    with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        await stream.send(response.serialize())


def _refusal(request: Request, options: WebSocketOptions) -> tuple[int, str] | None:
    """Why the handshake is refused (HTTP status, text), or None to accept it."""
    path = request.path.split("?", 1)[0]
    if options.url_path is not None and path != options.url_path:
        return 404, f"no rosbridge endpoint at {path}"
    origin = request.headers.get("Origin")
    if (
        origin is not None
        and options.allowed_origins
        and not any(fnmatch.fnmatchcase(origin, p) for p in options.allowed_origins)
    ):
        return 403, f"origin {origin} is not allowed"
    return None


async def serve_websocket_connection(
    stream: ByteStream,
    peer: str,
    host: SessionHost,
    options: WebSocketOptions,
    max_message_size: int,
    budget: FragmentBudget | None = None,
    *,
    frontends: FrontEnds,
    entry: EntryAuth | None = None,
    http: Sequence[HttpEndpoint] = (),
    placement: Placement | None = None,
    resumed: bytes | None = None,
) -> None:
    """Run one WebSocket connection to its end.

    Args:
        stream: the connected byte stream (TCP, or TLS over TCP).
        peer: the peer's address, for logs and the client id.
        host: admits the connection and makes its session once the handshake is
            acceptable.
        options: WebSocket settings.
        max_message_size: the largest incoming message, bytes (``--max-message-size``);
            a larger one closes the connection with 1009 (D24).
        budget: the server-wide budget of incomplete messages that a message still
            arriving is charged to (``--max-fragment-memory``); past it the
            connection is closed with 1013.
        frontends: the protocols this listener speaks: the one a client's offered
            subprotocol selects, else the default (rosbridge); without a default a
            client that offers none is refused with HTTP 400.
        entry: the server's one entry check (``rwt_protocol.credentials``): the
            handshake passes it for the chosen front end's ``AuthMode`` (a URL
            token for a Foxglove client), and a session admitted so starts
            authenticated; a front end of ``AuthMode.OP`` proves it in its
            session. None: no authentication.
        http: the HTTP endpoints on this port, each answering the paths it claims
            (``/version``, ``/webrtc``, ``/mcp``; docs/server.md); the rest are the
            WebSocket's (or the console's).
        placement: where a connection's first topic may move it (a front end that
            reads one, ``FrontEnd.first_topic``: rosbridge's)
            (``--placement topic``, workers/placement.py); None: it stays.
        resumed: the bytes another worker read from this connection before handing it
            here (workers/placement.py): read first, and the upgrade response is not sent
            again; a connection refused now (full) is closed with 1013.

    Never raises for what the peer does; the stream is closed on return.
    """
    async with stream:
        head = resumed
        if head is None:
            head = await _claimed(stream, http, peer) if http else b""
        if head is None:
            return
        # only for a WebSocket: websockets' parser generator makes it a reference cycle
        protocol = _make_protocol(options, max_message_size, frontends)
        handshake = await _handshake(stream, protocol, head)
        if handshake is None:
            return
        request, at_frame_start, early, received = handshake
        if isinstance(options.console, ConsoleSite) and not _is_upgrade(request):
            await _serve_console(stream, request, options.console, peer)
            return
        channel = WebSocketChannel(stream, protocol, options, max_message_size, budget)
        channel.early = early
        # the upgrade response goes once the reader listens (``hello``: arrival order)
        pump = ConnectionPump(channel, host.flow, host.admission, hello=channel.flush)
        session, refusal, frontend = _admit(
            request, options, frontends, entry, host, channel.transport, peer, pump
        )
        _respond(protocol, request, refusal, resumed=resumed is not None)
        if _placeable(placement, frontend, session, protocol):
            assert frontend is not None  # placeable: its front end reads first topics
            channel.placement, channel.record = placement, received
            channel.first_topic = frontend.first_topic
        # deflate's frames are websockets' to read; ``ws-frame-reader`` off: all of them are
        if at_frame_start and not protocol.extensions and enabled("ws-frame-reader"):
            channel.frames = FrameReader(max_message_size)
        # From the response on, what the client sends first goes before others' later input
        ticket = host.admission.hold()  # for frames sent with the request (in the parser)
        if channel.sees_input:  # else it counts as having input until its reader looks
            ticket.watch(channel.input_pending)
        ticket.serve()
        try:
            await _open(channel, pump, session, request)
        finally:
            ticket.release()
            channel.release()


def _placeable(
    placement: Placement | None,
    frontend: FrontEnd | None,
    session: ServerSession | None,
    protocol: ServerProtocol,
) -> bool:
    """Whether the connection may move by its first topic (workers/placement.py).

    A front end that reads one (``FrontEnd.first_topic``: rosbridge's; Foxglove's
    sends on open and reads none), and without permessage-deflate (its compression
    context is this process's).
    """
    return (
        placement is not None
        and session is not None
        and frontend is not None
        and frontend.first_topic is not None
        and not protocol.extensions
    )


def _admit(
    request: Request,
    options: WebSocketOptions,
    frontends: FrontEnds,
    entry: EntryAuth | None,
    host: SessionHost,
    transport: str,
    peer: str,
    pump: ConnectionPump,
) -> tuple[ServerSession | None, tuple[int, str] | None, FrontEnd | None]:
    """The handshake's checks, then admission: (the session, or the refusal; the front end)."""
    refusal = _refusal(request, options)
    frontend, _ = frontends.select(_offered(request))
    if refusal is None and frontend is None:
        refusal = 400, frontends.refusal()
    proven = False
    if refusal is None and entry is not None and frontend is not None and entry.required:
        refusal, proven = _proof(entry, frontend.auth, request, peer)
    session = None
    if refusal is None:
        session = host.open_session(
            transport, peer, pump.wake, frontend=frontend, authenticated=proven
        )
        if session is None:
            refusal = 503, "too many connections"
    if refusal is not None:
        logger.info("event=refused peer=%s status=%d reason=%r", peer, *refusal)
    return session, refusal, frontend


def _respond(
    protocol: ServerProtocol,
    request: Request,
    refusal: tuple[int, str] | None,
    *,
    resumed: bool,
) -> None:
    """Queue the upgrade's response: accepted, or refused with an HTTP status and reason.

    ``resumed``: another worker handed the connection here (workers/placement.py) and sent the
    response; it is made again, for websockets' state, and not sent. A refusal here
    (the server is full) can no longer be an HTTP status: the connection closes with
    1013 (try again later) and the reason.
    """
    if resumed:
        protocol.send_response(protocol.accept(request))
        protocol.data_to_send()  # the response: sent already
        if refusal is not None:
            protocol.fail(int(CloseCode.TRY_AGAIN_LATER), refusal[1][:_MAX_REASON])
        return
    response: Response
    if refusal is not None:
        response = protocol.reject(refusal[0], refusal[1] + "\n")
    else:
        response = protocol.accept(request)
    protocol.send_response(response)


async def _open(
    channel: WebSocketChannel,
    pump: ConnectionPump,
    session: ServerSession | None,
    request: Request,
) -> None:
    """Run the session if the connection was accepted (its pump sends the response).

    Else send the refusal (the handshake's response) and close.
    """
    if session is None or channel.protocol.state is not State.OPEN:
        with contextlib.suppress(anyio.BrokenResourceError, OSError):
            await channel.flush()
        if session is not None:
            session.close()
        return
    await run_connection(pump, session, f"agent={_agent(request.headers)!r}")


def _proof(
    entry: EntryAuth, mode: AuthMode, request: Request, peer: str
) -> tuple[tuple[int, str] | None, bool]:
    """The handshake through the one entry check: (its refusal, or None; whether proven).

    A front end of ``AuthMode.OP`` proves nothing here: its session asks for the op.
    """
    if not mode.at_entry:
        return None, False
    headers = {name.lower(): value for name, value in request.headers.raw_items()}
    query = urlsplit(request.path).query
    refused = entry.check(mode, peer, headers=headers, query=query, now=time.monotonic())
    return (None, True) if refused is None else ((refused.status, refused.text), False)


def _offered(request: Request) -> list[str]:
    """The subprotocols the handshake offers, in the client's order."""
    return [
        name.strip()
        for value in request.headers.get_all("Sec-WebSocket-Protocol")
        for name in value.split(",")
    ]


def _is_upgrade(request: Request) -> bool:
    """Whether ``request`` asks for a WebSocket (RFC 6455 4.2.1: ``Upgrade: websocket``)."""
    return any("websocket" in value.lower() for value in request.headers.get_all("Upgrade"))


async def _serve_console(
    stream: ByteStream, request: Request, console: ConsoleSite, peer: str
) -> None:
    """Answer a plain HTTP request with the console's file (docs/console.md), then close."""
    method = getattr(request, "method", "GET")  # websockets < 15 parses GET only
    reply = console.answer(method, request.path)
    logger.debug("event=console peer=%s path=%r status=%d", peer, request.path, reply.status)
    with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        await stream.send(http_response_bytes(reply))


def _framed(frames: Sequence[OutFrame]) -> list[bytes]:
    """The writes that send ``frames`` as whole WebSocket frames, in order.

    The header is made once and kept on the ``OutFrame``, which every
    subscriber of the same form shares (frame once); with a ``prefix`` it
    frames the prefix and the payload together (a Foxglove frame that clients
    share, ``foxglove-shared-frames``, is so framed once too). Small frames are
    joined into writes of about ``WRITE_BATCH`` bytes and a large payload is
    written as it is, as ``writes.coalesce`` does; this is its loop written out
    for frames, a burst's per-frame cost.

    The last batch that made one write is kept with it: clients that share
    their frames (a fan-out of Foxglove message data) take the same batch one
    after the other, which is then joined once for all of them.
    """
    global _last_batch  # noqa: PLW0603 (one entry, replaced whole: safe across threads)
    batch_frames = frames if isinstance(frames, list) else list(frames)
    last = _last_batch
    if last is not None and batch_frames == last[0]:  # the same frames (or equal: same bytes)
        return last[1]
    writes = _framed_anew(batch_frames)
    if len(writes) == 1 and len(batch_frames) > 1:  # small frames only: little kept alive
        _last_batch = (list(batch_frames), writes)  # a copy: the caller's list may be reused
    return writes


_last_batch: tuple[list[OutFrame], list[bytes]] | None = None
"""``_framed``'s last batch of small frames and its one write (frames compare by value)."""


def _framed_anew(frames: Sequence[OutFrame]) -> list[bytes]:
    """``_framed``'s writes, made."""
    writes: list[bytes] = []
    batch: list[bytes] = []
    size = 0
    for frame in frames:  # per frame of a burst: the fewest steps for a small one
        data = frame.data
        prefix = frame.prefix
        length = len(data)
        header = frame.header
        if header is None:  # made once, shared; a small binary one without a call (per frame)
            size_, binary = len(prefix) + length, frame.binary
            header = frame.header = (
                _SMALL_BINARY[size_] if size_ < 126 and binary else _header(size_, binary)
            )
        if length >= WRITE_BATCH:  # its payload goes alone, not copied
            batch += (header, prefix)
            writes.append(b"".join(batch))
            writes.append(data)
            batch, size = [], 0
            continue
        batch += (header, prefix, data)
        size += len(header) + len(prefix) + length
        if size >= WRITE_BATCH:
            writes.append(b"".join(batch))
            batch, size = [], 0
    if batch:
        writes.append(b"".join(batch))
    return writes


def _header(length: int, binary: bool) -> bytes:
    """The header of a whole unmasked server frame (RFC 6455 5.2): FIN, opcode, length."""
    if length < 126:  # a small message of a burst: the header made once (per frame)
        return (_SMALL_BINARY if binary else _SMALL_TEXT)[length]
    first = 0x82 if binary else 0x81
    if length < 65536:
        return struct.pack("!BBH", first, 126, length)
    return struct.pack("!BBQ", first, 127, length)


_SMALL_TEXT: Final = tuple(bytes((0x81, length)) for length in range(126))
_SMALL_BINARY: Final = tuple(bytes((0x82, length)) for length in range(126))


def _agent(headers: Headers) -> str:
    return headers.get("User-Agent", "unknown")
