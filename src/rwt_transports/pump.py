"""The connection pump: one sans-IO session driven over any transport, in any protocol.

Every transport (WebSocket, TCP, UDP, stdio, in-memory) reduces a connection to a
``Channel`` (channel.py): receive a batch of frames, send a batch of frames, close;
every protocol's session (rosbridge's, Foxglove's, a third's) implements
``rwt_protocol.runtime.contract.ServerSession``. The pump runs the rest the same way
for all of them (D22, one dispatcher behind all transports; docs/architecture.md,
"One connection runtime"), in four tasks per connection:

- the reader feeds incoming frames to ``Session.receive_frame``;
- the writer takes bounded batches from the session's outbox and sends them,
  then carries out commands (``CloseConnection``); a publish never awaits a
  socket. While the writer is idle, a channel that can write
  without blocking (``ChannelAbilities.send_now``: a plain socket with nothing
  buffered) is written without it: at the end of the reader's batch that published
  (``flush_deferred``), one write per connection, so a message to ten idle
  subscribers costs no task switch. Whatever the socket cannot take
  at once is left to the writer, so frames keep their order either way.
  This is the ``deferred-send`` shortcut (rwt_protocol/shortcuts.py): off,
  every output wakes the writer;
- the timer task calls ``Session.handle_timer`` when ``get_timer`` says, even
  while the writer is stuck on a peer that does not read: that is how the send
  timeout (D24) can close a stalled connection. If the writer cannot even get
  the close out within ``CLOSE_WAIT_S``, the connection is aborted;
- the job task runs the session's background jobs (a Foxglove client's asset
  files) in a worker thread, ``BACKGROUND_THREADS`` at once over the server, while
  the reader goes on, and hands each outcome back (``finish_job``).

Input is flow-controlled (docs/limits.md), so that a burst reaches a peer that
reads instead of being dropped, and one connection cannot monopolise the loop:

- backpressure with a hold budget: when the frames a reader handled pushed
  another connection's outbox over its high watermark (half
  ``--send-buffer-limit``), the reader stops reading
  (``ChannelAbilities.pause_reading``) until that outbox is back under the low
  watermark (a quarter), within its hold budget, while its peer reads. Who
  congested a batch, how long to wait and who is slow is decided by the
  server's ``rwt_protocol.runtime.flow.FlowControl`` (sans-IO, one per event loop); the pump carries
  it out (``holding.wait_for``). A reader waits for its own outbox only for the
  replies and statuses in it (they are never dropped), so a peer sending
  garbage faster than it reads the answers is slowed, not buffered without
  bound. A link's queue for the other middleware is waited for in the same way,
  and a link's deliveries are held as a reader's, per topic (gates.py);
- fairness: a reader handles at most ``READ_SLICE_FRAMES`` frames or
  ``READ_SLICE_BYTES`` bytes, then yields to the loop for a turn, so a flood
  of tiny frames on one connection does not hold the others up;
- jobs: a frame that left the session a job (a ``png`` op to inflate,
  ``Jobs.take``) stops the slice; the reader waits until the job's
  ``ready_at`` (the connection's own budget), runs it in a worker thread (at
  most ``INFLATE_THREADS`` at once over the server) and hands the result back
  before it handles the next frame, so ops keep their order and only the
  sender waits.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import weakref
from typing import TYPE_CHECKING

import anyio
import anyio.lowlevel
import anyio.to_thread

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.levels import StatusLevel
from rwt_protocol.runtime.commands import CloseCode, CloseConnection
from rwt_protocol.runtime.contract import LossySession
from rwt_protocol.runtime.flow import FlowControl, HoldAccount, Progress, ReadingWindow
from rwt_protocol.runtime.inframes import FramerEvent, FramingError
from rwt_protocol.shortcuts import enabled

from .admission.arrival import Admission, Ticket, current_ticket
from .gather import GATHER_BYTES, Gatherer
from .holding import Held, wait_for

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable, Sequence

    from rwt_protocol.runtime.contract import ServerSession

    from .channel import Channel

__all__ = [
    "CLOSE_WAIT_S",
    "ConnectionPump",
    "drive_timers",
    "flush_deferred",
    "run_connection",
]

logger = logging.getLogger("rwt.server")
_episodes = EpisodeLog(logger)  # a peer can trigger these at will

BATCH_BYTES = 64 * 1024
"""Bytes the writer takes from the outbox at a time: what it holds outside the bound."""

CLOSE_WAIT_S = 5.0
"""Seconds a close may take (sending it, then the peer's end) before the connection is cut."""

READ_SLICE_FRAMES = 256
"""Frames a reader handles before it yields to the event loop (fairness, docs/limits.md)."""

READ_SLICE_BYTES = 256 * 1024
"""Bytes of frames a reader handles before it yields to the event loop (fairness)."""

INFLATE_THREADS = 1
"""Worker threads inflating ``png`` ops at once, over all connections of an event loop:
what a flood of them can take from the loop (Pillow holds the GIL in parts of it)."""

UNWRITTEN_POLL_S = 0.01
"""First wait before the writer asks again whether the transport wrote what a direct
send left in it (``ConnectionPump._until_written``); it doubles up to 1 s."""

BACKGROUND_THREADS = 2
"""Worker threads running background jobs (asset files read, ``png`` messages
deflated) at once, over all connections of an event loop."""

_Limiters = weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, anyio.CapacityLimiter]
_inflate_limiters: _Limiters = weakref.WeakKeyDictionary()
_background_limiters: _Limiters = weakref.WeakKeyDictionary()


def _limiter(limiters: _Limiters, threads: int) -> anyio.CapacityLimiter:
    """The running event loop's limiter of ``limiters`` (made with ``threads`` at first use)."""
    loop = asyncio.get_running_loop()
    limiter = limiters.get(loop)
    if limiter is None:
        limiter = limiters[loop] = anyio.CapacityLimiter(threads)
    return limiter


async def run_connection(pump: ConnectionPump, session: ServerSession, detail: str = "") -> None:
    """Run ``pump`` for ``session``, logging the connection's start and end (structured)."""
    channel = pump.channel
    logger.info(
        "event=connect client=%s transport=%s protocol=%s peer=%s%s",
        session.client_id,
        channel.transport,
        session.protocol,
        session.peer,
        f" {detail}" if detail else "",
    )
    started = anyio.current_time()
    try:
        await pump.run(session)
    finally:
        logger.info(
            "event=disconnect client=%s reason=%r topic_messages=%d dropped=%d expired=%d "
            "frames_sent=%d duration_s=%.1f",
            session.client_id,
            pump.close_reason,
            session.stats.topic_messages,
            session.stats.dropped_frames,
            session.stats.expired_messages,
            session.stats.taken_frames,
            anyio.current_time() - started,
        )


async def drive_timers(session: ServerSession) -> None:
    """Run ``session``'s timers until it closes: for a session no pump runs.

    A 2026-07-28 MCP request's session has no connection to pump, yet its timers
    come due (a call's deadline, a throttled message, the idle watch): this waits
    for ``get_timer``'s time and calls ``handle_timer``, woken by ``on_timer`` when
    an earlier one is set, as the pump's timer task does. ``start`` is the caller's.
    """
    wake = anyio.Event()

    def woken() -> None:
        wake.set()  # the one being waited for (set again per wait)

    session.on_timer = woken
    while not session.closing:
        wake = anyio.Event()
        deadline = session.get_timer()
        delay = None if deadline is None else max(0.0, deadline - anyio.current_time())
        with anyio.move_on_after(delay):
            await wake.wait()
        session.handle_timer(anyio.current_time())


_BROKEN = (
    anyio.BrokenResourceError,
    anyio.ClosedResourceError,
    anyio.EndOfStream,
    OSError,
)


def _clock() -> Callable[[], float]:
    """The event loop's clock, as ``anyio.current_time`` reads it, without its lookups.

    On asyncio (and uvloop) that is ``loop.time``; other backends, and the
    ``loop-clock`` shortcut switched off, keep anyio's.
    """
    if not enabled("loop-clock"):
        return anyio.current_time
    try:
        return asyncio.get_running_loop().time
    except RuntimeError:
        return anyio.current_time


def flush_deferred(flow: FlowControl[Held]) -> None:
    """Write what the idle connections woken since the last flush have queued.

    A reader calls it after each batch of incoming frames, so a publish fanned
    out to idle subscribers goes out before the reader waits again, and the
    many frames of a burst go out in one write per connection (as the writer
    would batch them), not one system call each. Output made outside a reader
    (in-process publishers, links, timers, service tasks) is flushed when the
    loop's gathering ends (gather.py: the next quiet turn, or ``GATHER_S`` into
    a burst). A connection whose socket cannot take the frames at once gets its
    writer woken instead.
    """
    while batch := flow.take_deferred():
        for pump in batch:
            pump.flush_deferred()


class _DeferredOutput:
    """The output of a loop's connections deferred outside a reader (a ``gather.Member``)."""

    __slots__ = ("_flow",)

    def __init__(self, flow: FlowControl[Held]) -> None:
        self._flow = flow

    def queued_bytes(self) -> int:
        """Nothing for the gatherer to weigh: each connection that holds enough goes alone."""
        return 0

    def flush(self) -> None:
        """The gathering ended: write what every connection deferred."""
        flush_deferred(self._flow)


_members: weakref.WeakKeyDictionary[FlowControl[Held], _DeferredOutput] = (
    weakref.WeakKeyDictionary()
)


def _deferred_output(flow: FlowControl[Held]) -> _DeferredOutput:
    member = _members.get(flow)
    if member is None:
        member = _members[flow] = _DeferredOutput(flow)
    return member


class ConnectionPump(Held):
    """Runs one session over one channel until either side ends it.

    Args:
        channel: the connection.
        flow: the server's flow control (``host.SessionHost.flow``); None: one of its
            own (a pump that no server runs).
        admission: the server's starting connections (``host.SessionHost.admission``);
            None: its own (none but this one's).
        hello: the connection's first write, made once its reader listens (a
            WebSocket upgrade response): the peer may send only after it, so its
            first input reaches a reader that waits, and the event loop reports
            it in the order it arrived among every connection's (admission/arrival.py).

    Use ``wake`` as the session's ``on_output`` callback, then ``await run(session)``.
    """

    counts_taken = True  # ``progress``: what it sent, less the socket's send queue

    def __init__(
        self,
        channel: Channel,
        flow: FlowControl[Held] | None = None,
        admission: Admission | None = None,
        hello: Callable[[], Awaitable[None]] | None = None,
    ) -> None:
        super().__init__()  # the outlet readers wait on (``holding``)
        self._hello = hello
        self._listening = anyio.Event()  # the reader is about to wait for input
        self.flow: FlowControl[Held] = FlowControl() if flow is None else flow
        self.admission = Admission() if admission is None else admission
        self._account = HoldAccount(0.0)  # its own hold budget, as a reader (set in ``run``)
        self.channel = channel
        abilities = channel.abilities
        self.close_reason = "peer closed the connection"
        self._writer_wake = anyio.Event()
        self._timer_wake = anyio.Event()
        self._reader_done = anyio.Event()
        self._writer_closed = anyio.Event()
        self._session: ServerSession | None = None
        self._lossy: LossySession | None = None  # the session, if it has a lossy lane (D36)
        self._jobs_wake = anyio.Event()
        self._timer_deadline: float | None = None
        # The ``deferred-send`` shortcut: off, the pump never writes from the publish path.
        self._direct = channel if abilities.send_now and enabled("deferred-send") else None
        self._time: Callable[[], float] = anyio.current_time  # the loop's (``run``): takes' time
        self._writer_idle = False  # waiting for a wake-up, holding no frames
        self._deferred = False  # in the list of ``flush_deferred``
        self._gatherer: Gatherer | None = None  # the loop's (gather.py), at its first use
        self._pausable = abilities.pause_reading
        self._queueing = abilities.unsent_bytes
        self._sent = 0  # bytes of frames handed to the channel (``progress``)
        self._slice_frames = 0  # frames and bytes handled since the reader last yielded
        self._slice_bytes = 0
        self._job_wait: anyio.Event | None = None  # set when the session starts closing
        self._unwritten = False  # a direct send left bytes in the transport (``_until_written``)

    def wake(self) -> None:
        """The session has output (frames or commands; timers come to ``_wake_timers``)."""
        session = self._session
        if session is None:
            self._writer_wake.set()
            return
        flow = self.flow
        gatherer = self._gatherer
        if self._deferred and self._writer_idle and not flow.in_batch and gatherer is not None:
            # a burst outside a reader, per message and client: the fewest steps (a close
            # asked meanwhile goes when the gathering ends: ``_send_now`` leaves it to
            # the writer)
            gatherer.more = True
            if session.stats.queued_bytes >= GATHER_BYTES:
                self.flush_deferred()  # enough for a write of its own
            return
        if session.close_request is not None:
            self._writer_wake.set()
            self._timer_wake.set()  # the timer task sees the closing
            if self._job_wait is not None:
                self._job_wait.set()  # a reader waiting for its budget stops waiting
        elif self._deferred and self._writer_idle:
            pass  # in a reader's batch: written at its end (``flush_deferred``)
        elif self._writer_idle and self._direct is not None:
            self._defer()
        else:
            self._writer_wake.set()
        if session.closing:  # shutting down, closed: the timer task ends the connection
            self._timer_wake.set()
        if flow.in_batch:
            fill = session.stats.fill_bytes
            if fill > self.watch_water and session.wake_above_bytes < self.high_water:
                self._fell_behind(session)
            if flow.congests(self, fill):
                flow.note_congested(self, anyio.current_time())

    def _fell_behind(self, session: ServerSession) -> None:
        """The outbox passed its ``watch_water``: its reading window starts (runtime's flow.py).

        The session wakes this pump again only past the high watermark, until
        the peer is back at its ``watch_water`` (``_took``).
        """
        if self.window is None:  # (a hold may have started one)
            self.window = ReadingWindow.of(self.progress(), anyio.current_time())
        session.wake_above_bytes = self.high_water

    def _took(self, *, sent: bool = True) -> None:
        """The transport took frames: the peer makes progress; wake readers waiting on it.

        Having taken everything queued, the peer caught up (a slow one stays
        slow until its cool-down ends: ``FlowControl.found_slow``); back at
        its ``watch_water``, it is no longer behind: its reading window ends, and
        the session wakes this pump at the next output past the mark. ``sent``:
        the transport wrote them, so they are no longer held (D44).
        """
        session = self._session
        if session is None:
            self.note_take(True)
            return
        if sent:
            session.frames_sent()
        watch = self.watch_water
        if session.stats.fill_bytes <= watch and (
            self.window is not None or session.wake_above_bytes != watch
        ):
            self.window = None
            session.wake_above_bytes = watch
        self.note_take(session.stats.queued_bytes == 0)

    def _defer(self) -> None:
        """Leave the frames for ``flush_deferred`` instead of waking the writer.

        Output made inside a reader's batch is flushed at the batch's end; output
        made outside one (in-process publishers, links, timers) is gathered over
        turns of the loop (gather.py), so a burst published a message a turn
        goes out in few writes.
        """
        flow = self.flow
        if flow.needs_flush_callback():
            try:  # for output made outside a reader; a reader flushes sooner
                loop = asyncio.get_running_loop()
            except RuntimeError:  # no asyncio loop (the direct path needs one)
                self._writer_wake.set()
                return
            Gatherer.for_loop(loop).join(_deferred_output(flow))
        elif not flow.in_batch and self._gatherer is not None:
            self._gatherer.more = True  # more output during a gathering: a burst
        flow.defer(self)
        self._deferred = True

    def flush_deferred(self) -> None:
        """Write what was deferred now, or wake the writer (``FlowControl``'s ``PendingOutput``)."""
        self._deferred = False
        try:
            sent = self._writer_idle and self._send_now()
        except Exception:  # this connection's bug, run from another's task: leave it to
            # this connection's writer, which meets it again and is contained (logged there)
            client = self._session.client_id if self._session is not None else "?"
            logger.debug("event=direct_send_bug client=%s", client, exc_info=True)
            sent = False
        if not sent:
            self._writer_wake.set()

    def _send_now(self) -> bool:
        """Write queued frames from the caller if the channel can take them now.

        Called only while the writer is idle. Returns True when nothing is left
        for the writer: every frame went to the transport and no close is pending.
        What the transport could not write at once still counts as held (the
        memory budget, D44): the writer waits until it is written
        (``_until_written``).
        """
        session = self._session
        channel = self._direct
        if (
            session is None
            or channel is None
            or session.close_request is not None
            or not channel.can_send_now()
        ):
            return False
        queued = session.stats.queued_bytes
        frames = session.frames_to_send(BATCH_BYTES, self._time())
        if frames:
            self._sent += queued - session.stats.queued_bytes
            try:
                channel.send_now(frames)
            except Exception:  # a publish must never fail for another peer's socket
                logger.debug("event=direct_send_failed client=%s", session.client_id)
                return False  # the writer finds the broken stream and ends the connection
            written = channel.can_send_now()  # the transport kept none of it
            self._took(sent=written)
            if not written:
                self._unwritten = True
                return False
        return session.stats.queued_bytes == 0

    def _wake_timers(self) -> None:
        """Wake the timer task only when it has something new to look at.

        Waking it for every queued frame would cost a task switch per message
        per subscriber (the benchmarks' profile); it needs to run again only when the
        earliest deadline changed or the session started closing.
        """
        session = self._session
        if session is None or session.closing or session.get_timer() != self._timer_deadline:
            self._timer_wake.set()

    async def run(self, session: ServerSession) -> None:
        """Serve ``session`` until the peer leaves or the session closes, then close it.

        A bug in the session's handling of a frame, a timer or a job is the
        session's to contain (``SessionBase.contain``): the peer is told and the
        connection goes on. What is left is the transport's: a bug in this
        connection's tasks (reader, writer, timers, the channel's background
        task) is logged with its traceback, the connection is closed (WebSocket:
        1011 ``internal error``) and released, and every other connection goes
        on (docs/limits.md, containment). Never raises for it.
        """
        self._session = session
        self._lossy = session if isinstance(session, LossySession) else None
        # its marks, budget and cool-down (a reconnection: its host's)
        self._account = self.flow.open_connection(
            self, session.peer, session.hold_budget_s, session.water_marks
        )
        session.wake_above_bytes = self.watch_water  # to see the peer fall behind
        session.jobs.transport_runs = True  # ``_run_jobs`` inflates png ops off the loop
        session.jobs.on_background = self._jobs_wake.set
        session.on_timer = self._wake_timers
        with contextlib.suppress(RuntimeError):  # the loop's gathering (gather.py)
            self._gatherer = Gatherer.for_loop(asyncio.get_running_loop())
        self._time = _clock()
        session.start(self._time())
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._writer, session, tg.cancel_scope)
                tg.start_soon(self._timers, session, tg.cancel_scope)
                tg.start_soon(self._background_jobs, session)
                tg.start_soon(self.channel.background, session)
                await self._reader(session)
                self._reader_done.set()
                # The peer's input ended; it may still read (a half-closed TCP
                # stream, stdin at EOF): send what is queued, then close.
                session.request_close(CloseCode.NORMAL, "end of input")
        except Exception:  # ExceptionGroup included: a bug, contained to this connection
            logger.exception("event=bug client=%s: connection closed", session.client_id)
            self.close_reason = "internal error"
            await self._close_after_bug()
        finally:
            try:
                session.close()
            except Exception:
                logger.exception("event=bug client=%s: release failed", session.client_id)
            self._took()  # readers waiting on this outbox stop waiting

    async def _close_after_bug(self) -> None:
        """Tell the peer (best effort, bounded): the connection cannot go on.

        An error status in its protocol's words first (``status_frames``: the only
        word a TCP, stdio or UDP peer gets), then the close (WebSocket: 1011
        ``internal error``).
        """
        with anyio.move_on_after(CLOSE_WAIT_S, shield=True):
            try:
                session = self._session
                if session is not None:
                    last = session.status_frames(StatusLevel.ERROR, "internal error")
                    if last:
                        await self.channel.send(list(last))
            except Exception:  # the channel, or the session, may be what broke
                logger.debug("error status after a bug not sent", exc_info=True)
            try:
                await self.channel.close(CloseCode.INTERNAL_ERROR, "internal error")
            except Exception:  # the channel may be what broke
                logger.debug("close after a bug failed", exc_info=True)

    async def _reader(self, session: ServerSession) -> None:
        # A starting connection's first input goes before what the others got
        # after it (admission/arrival.py): their readers ask this probe.
        ticket = current_ticket()
        channel = self.channel
        if ticket is not None:
            # With a hello (a WebSocket's upgrade response, sent once this reader
            # listens) the peer cannot have sent yet, but with the request (parser).
            early = self._hello is not None and channel.input_pending() is not True
            if channel.abilities.probe_input and not early:
                ticket.watch(channel.input_pending)  # its first input goes first
            else:  # from here the loop sees its input in arrival order
                ticket.release()
                ticket = None
        self._listening.set()  # (no checkpoint before ``receive`` waits: the hello may go)
        try:
            await self._read(session, ticket)
        finally:
            if ticket is not None:
                ticket.release()

    async def _read(self, session: ServerSession, ticket: Ticket | None) -> None:
        clock = _clock()
        while True:
            try:
                events = await self.channel.receive()
            except _BROKEN:
                return
            if self.admission.starting():  # what new connections sent earlier goes first
                await self.admission.wait_for_new(ticket)
            now = clock()  # the batch arrived at once: one clock read for all
            start, count = 0, len(events)
            while True:
                start = self._handle(session, events, start, now)
                # what this slice published goes out now, in one write each
                flush_deferred(self.flow)
                if ticket is not None:
                    ticket.release()
                    ticket = None
                self._wake_timers()  # handlers may have scheduled timers
                await self._apply_backpressure()
                if session.jobs.waiting:
                    await self._run_jobs(session, clock)
                if start >= count:
                    break
                await self._yield_slice()
                now = clock()
            # Handled: a large frame must not stay alive while the next read waits.
            # A full slice yields when the next batch is in hand (``_handle`` stops
            # at once), never here: a reader resuming from a yield with nothing read
            # would read input that came after another connection's and handle it
            # first (arrival order, admission/arrival.py); one holding its input resumes
            # before the input the loop finds meanwhile.
            del events

    def _handle(
        self, session: ServerSession, events: Sequence[FramerEvent], start: int, now: float
    ) -> int:
        """Handle ``events`` from ``start`` until the slice is full; return where it stopped."""
        flow = self.flow
        flow.begin()
        frames, size = self._slice_frames, self._slice_bytes
        index, count = start, len(events)
        jobs, lossy = session.jobs, self._lossy
        try:
            while index < count and frames < READ_SLICE_FRAMES and size < READ_SLICE_BYTES:
                event = events[index]
                index += 1
                frames += 1
                if isinstance(event, FramingError):
                    session.report(StatusLevel.ERROR, event.message)
                    if event.fatal:
                        session.request_close(CloseCode.MESSAGE_TOO_BIG, event.message)
                else:
                    size += len(event.data)
                    if event.lossy and lossy is not None:  # WebRTC's lossy channel (D36)
                        lossy.receive_lossy_frame(event.data, now, binary=event.binary)
                    else:
                        session.receive_frame(event.data, now, binary=event.binary)
                    if jobs.waiting:  # run it before the next frame (order)
                        break
        finally:
            flow.end()
            self._slice_frames, self._slice_bytes = frames, size
        return index

    async def _run_jobs(self, session: ServerSession, clock: Callable[[], float]) -> None:
        """Run the session's jobs in turn: each after its ``ready_at``, in a worker thread.

        The socket is not read meanwhile: the sender waits for its own budget.
        """
        while (job := session.jobs.take()) is not None:
            self._slice_frames = self._slice_bytes = 0  # this waits: the others run
            if self._pausable:
                self.channel.pause_reading()
            delay = job.ready_at - clock()
            if delay > 0 and not session.closing:
                self._job_wait = anyio.Event()
                with anyio.move_on_after(delay):
                    await self._job_wait.wait()
                self._job_wait = None
            if session.closing:  # nothing more is handled; read on, for the peer's close
                while session.jobs.take() is not None:
                    pass
                return
            result: object
            try:
                limiter = _limiter(_inflate_limiters, INFLATE_THREADS)
                result = await anyio.to_thread.run_sync(job.run, limiter=limiter)
            except Exception as exc:  # the session reports it (an RwtError) or logs a bug
                result = exc
            session.finish_job(job, result, clock())
            flush_deferred(self.flow)
            self._wake_timers()
            await self._apply_backpressure()

    async def _background_jobs(self, session: ServerSession) -> None:
        """Run the session's background jobs in worker threads while the reader goes on.

        One at a time per connection, ``BACKGROUND_THREADS`` over the server; each
        outcome goes back to the session (``finish_job``), whose output is written.
        """
        while not session.closing:
            job = session.jobs.take_background()
            if job is None:
                self._jobs_wake = anyio.Event()
                session.jobs.on_background = self._jobs_wake.set
                await self._jobs_wake.wait()
                continue
            result: object
            try:
                limiter = _limiter(_background_limiters, BACKGROUND_THREADS)
                result = await anyio.to_thread.run_sync(job.run, limiter=limiter)
            except Exception as exc:  # the session reports it (an RwtError) or logs a bug
                result = exc
            session.finish_job(job, result, anyio.current_time())
            del result  # (a file's bytes: the session holds them in its outbox now)
            flush_deferred(self.flow)

    async def _yield_slice(self) -> None:
        """Let the other connections run (fairness) for one turn of the loop.

        The socket stays read: a turn reads at most one more chunk, and a socket
        paused here would be read again after the others that got input
        meanwhile, so its frames would lose their place (arrival order,
        admission/arrival.py).
        """
        self._slice_frames = self._slice_bytes = 0
        await anyio.lowlevel.checkpoint()

    async def _apply_backpressure(self) -> None:
        """Wait while the outboxes this reader's last slice filled are over their high watermark.

        Reading is paused meanwhile, so the peer's sends back up in TCP; the
        time is charged to this reader's hold budget, whatever it waits for.
        """
        flow = self.flow
        for held in flow.take_congested():
            own = held is self
            if held.over_water(own=own, mark=held.high_water):
                if self._pausable:
                    self.channel.pause_reading()
                await wait_for(flow, held, own=own, account=self._account)

    def over_water(self, *, own: bool, mark: int) -> bool:
        """Whether this connection's outbox is above ``mark`` for a reader to wait on.

        A reader waits on its own outbox only for what is never dropped (replies,
        statuses); on another connection's for all it queued.
        """
        session = self._session
        if session is None or session.closing:
            return False
        return (session.stats.queued_reply_bytes if own else session.stats.fill_bytes) > mark

    def unsent_bytes(self) -> int | None:
        """The socket's send queue, where the channel can read it (``holding.wait_for``)."""
        return self.channel.unsent_bytes() if self._queueing else None

    def backlog_bytes(self) -> int:
        """What the peer has yet to read: its outbox, what is made for it, the send queue."""
        session = self._session
        queued = 0 if session is None else session.stats.queued_bytes + session.stats.pending_bytes
        return queued + (self.unsent_bytes() or 0)

    def progress(self) -> Progress:
        """What the peer took so far (sent, less the socket's send queue) and has yet to.

        Bytes as the outbox counts them, taken counted from the frames handed to
        the channel less its socket's send queue where the channel can read it
        (sendqueue.py); what a channel buffers itself (a write of at most
        ``BATCH_BYTES`` or so) counts as taken.
        """
        session = self._session
        queued = 0 if session is None else session.stats.queued_bytes
        unsent = self.unsent_bytes()
        held = unsent or 0
        return Progress(self._sent - held, queued + held, unsent)

    async def _writer(self, session: ServerSession, scope: anyio.CancelScope) -> None:
        clock = self._time  # the take's time: a message past its lifespan is not sent (D63)
        try:
            if self._hello is not None:
                await self._listening.wait()
                await self._hello()
            while True:
                if self._writer_wake.is_set():  # a fresh event only after a wake-up
                    self._writer_wake = anyio.Event()
                queued = session.stats.queued_bytes
                frames = session.frames_to_send(BATCH_BYTES, clock())
                if frames:
                    self._sent += queued - session.stats.queued_bytes
                    await self.channel.send(frames)
                    self._unwritten = False  # (its send waited for what came before too)
                    self._took()
                    continue
                for command in session.commands_to_run():
                    if isinstance(command, CloseConnection):
                        await self._close(command, scope)
                        return
                if self._unwritten:
                    await self._until_written(session)
                    continue
                self._writer_idle = True
                try:
                    await self._writer_wake.wait()
                finally:
                    self._writer_idle = False
        except _BROKEN:
            self.close_reason = "connection broken while sending"
            scope.cancel()

    async def _until_written(self, session: ServerSession) -> None:
        """Wait until the transport wrote what a direct send left in it, or output comes.

        Till then it is held and counted (the memory budget, D44). The transport
        tells only whether it is empty: it is asked every ``UNWRITTEN_POLL_S``,
        doubling up to 1 s; new output or a close wakes the writer at once.
        """
        channel, delay = self._direct, UNWRITTEN_POLL_S
        while channel is not None and not channel.can_send_now():
            with anyio.move_on_after(delay):
                await self._writer_wake.wait()
            if self._writer_wake.is_set():
                return  # the writer takes the new output; its send waits for the rest
            delay = min(2 * delay, 1.0)
        self._unwritten = False
        session.frames_sent()

    async def _close(self, command: CloseConnection, scope: anyio.CancelScope) -> None:
        if not self._reader_done.is_set():
            self.close_reason = f"closed by server: {command.reason}"
        await self.channel.close(command.code, command.reason)
        self._writer_closed.set()
        if self.channel.awaits_peer_close and not command.abort:
            with anyio.move_on_after(CLOSE_WAIT_S):
                await self._reader_done.wait()
        scope.cancel()

    async def _timers(self, session: ServerSession, scope: anyio.CancelScope) -> None:
        while not session.closing:
            self._timer_wake = anyio.Event()
            deadline = self._timer_deadline = session.get_timer()
            delay = None if deadline is None else max(0.0, deadline - anyio.current_time())
            with anyio.move_on_after(delay):
                await self._timer_wake.wait()
            session.handle_timer(anyio.current_time())
        # Closing: the writer must get the close out; a peer that reads nothing stops it,
        # and one known not to read (abort) is not waited for.
        request = session.close_request
        with anyio.move_on_after(0 if request is not None and request.abort else CLOSE_WAIT_S):
            await self._writer_closed.wait()
        if not self._writer_closed.is_set():
            _episodes.log(
                logging.WARNING,
                "abort",
                "event=abort client=%s reason=%r",
                session.client_id,
                "close not sent",
            )
            if request is not None and request.abort:
                self.close_reason = f"closed by server: {request.reason}"
            self.close_reason += " (aborted: the peer stopped reading)"
            scope.cancel()
