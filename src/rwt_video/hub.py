"""Shared streams: one subscription and one encoder per distinct stream, many viewers.

A ``SharedStream`` exists while some viewer watches its ``StreamParams``. The
graph's callback only keeps the newest message and wakes the stream's encoder
task, which waits for one of the image threads (``ENCODER_THREADS``, shared
with every front end's image work: ``rwt_graph.media.threads``),
then takes the newest message, encodes it there once for all its viewers and
offers the result to every viewer; frames that arrive meanwhile are skipped. A
multipart part's bytes are made in that thread too, so the event loop only
hands the same bytes to each viewer's socket. A viewer never makes the encoder
wait: a still-image viewer keeps only the newest part, a video viewer keeps a
bounded run of packets and, past that, drops them and restarts at the next
keyframe. So a stalled viewer costs a bounded amount of memory and never slows
another, and many streams cannot take more threads than the bound, so the
event loop (every rosbridge client of the process) keeps its share of the CPU
(docs/limits.md, docs/video.md).
"""

from __future__ import annotations

import contextlib
import logging
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Protocol, TypeVar

import anyio
import anyio.to_thread

from rwt_graph.media.threads import IMAGE_THREADS, image_threads
from rwt_graph.ratelog import EpisodeLog

from .encoders import (
    EncodeError,
    FrameEncoder,
    Muxer,
    Part,
    VideoFrameEncoder,
    VideoPacket,
    make_encoder,
)
from .params import StreamParamError, StreamParams

if TYPE_CHECKING:
    from anyio.abc import TaskGroup

    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalSubscription

__all__ = ["ENCODER_THREADS", "PartViewer", "SharedStream", "StreamHub", "VideoViewer"]

logger = logging.getLogger("rwt.video")
_episodes = EpisodeLog(logger)  # a peer can trigger these at will

Message = Mapping[str, object]

#: A video viewer further behind than this drops what it holds and waits for a keyframe.
MAX_PENDING_PACKETS = 60
MAX_PENDING_BYTES = 8 * 1024 * 1024

#: Frames encoded at once, whatever the number of streams: the image threads every
#: front end shares (``rwt_graph.media.threads.IMAGE_THREADS``: half the CPUs, at
#: least one), the video server's streams, the WebRTC tracks' and the MCP tools'
#: images together. Each encoder thread competes with the event loop for the CPU;
#: 16 streams of a 4K camera each encoding in its own thread took the event loop's
#: turn away from the rosbridge clients (docs/video.md).
ENCODER_THREADS = IMAGE_THREADS


class Viewer(Protocol):
    """One HTTP response fed by a shared stream."""

    def offer(self, items: list[Part] | list[VideoPacket]) -> None:
        """Take the stream's newest output; must not block."""
        ...


V = TypeVar("V", bound=Viewer)


class PartViewer:
    """A multipart or snapshot viewer: holds only the newest encoded image.

    Args:
        latest: the stream's last encoded parts, shown at once (may be empty).
    """

    def __init__(self, latest: list[Part] | None = None) -> None:
        self._latest: Part | None = latest[-1] if latest else None
        self._ready = anyio.Event()

    def offer(self, items: list[Part] | list[VideoPacket]) -> None:
        """Replace the held part by the newest one (a slow viewer skips frames)."""
        part = items[-1] if items else None
        if isinstance(part, Part):
            self._latest = part
            self._ready.set()

    async def next_part(self) -> Part:
        """Wait for a part not yet taken."""
        while self._latest is None:
            await self._ready.wait()
            self._ready = anyio.Event()
        part, self._latest = self._latest, None
        return part


class VideoViewer:
    """A video viewer: its own container over the shared packets, from a keyframe on."""

    def __init__(self, stream: SharedStream) -> None:
        self._stream = stream
        self._pending: deque[VideoPacket] = deque()
        self._pending_bytes = 0
        self._muxer: Muxer | None = None
        self._waiting_for_keyframe = True
        self._ready = anyio.Event()

    def offer(self, items: list[Part] | list[VideoPacket]) -> None:
        """Queue packets; drop them all past the bounds and wait for a keyframe."""
        for packet in items:
            if not isinstance(packet, VideoPacket):
                continue
            if self._waiting_for_keyframe and not packet.keyframe:
                continue
            self._waiting_for_keyframe = False
            self._pending.append(packet)
            self._pending_bytes += len(packet.data)
        if len(self._pending) > MAX_PENDING_PACKETS or self._pending_bytes > MAX_PENDING_BYTES:
            self._pending.clear()
            self._pending_bytes = 0
            self._waiting_for_keyframe = True
        if self._pending:
            self._ready.set()

    async def next_chunk(self) -> bytes:
        """Container bytes for the packets queued since the last call (waits for some).

        Raises:
            EncodeError: the muxer failed; the viewer cannot go on.
        """
        while True:
            if self._waiting_for_keyframe and self._muxer is not None:
                self._stream.request_keyframe()  # resynchronise a viewer that fell behind
            await self._ready.wait()
            self._ready = anyio.Event()
            chunks = []
            while self._pending:
                packet = self._pending.popleft()
                self._pending_bytes -= len(packet.data)
                if self._muxer is None:
                    self._muxer = self._stream.muxer()
                chunks.append(self._muxer.add(packet))
            data = b"".join(chunks)
            if data:
                return data

    def close(self) -> None:
        """Free the container."""
        if self._muxer is not None:
            self._muxer.close()


class SharedStream:
    """One topic encoded one way for every viewer that asks for the same params.

    Args:
        params: what the viewers asked for.
        encoder: encodes a message for all of them.
        limiter: the hub's encoder threads; the stream takes one for each frame.
    """

    def __init__(
        self, params: StreamParams, encoder: FrameEncoder, limiter: anyio.CapacityLimiter
    ) -> None:
        self.params = params
        self.encoder = encoder
        self._limiter = limiter
        self.viewers: set[Viewer] = set()
        self.last_parts: list[Part] = []  # for viewers that join between frames
        self.subscription: LocalSubscription | None = None
        self.scope = anyio.CancelScope()
        self._latest: Message | None = None
        self._wake = anyio.Event()

    def on_message(self, msg: Message) -> None:
        """The graph's callback: keep only the newest message and wake the encoder."""
        self._latest = msg
        self._wake.set()

    def request_keyframe(self) -> None:
        """Ask a video encoder for a keyframe at the next frame."""
        if isinstance(self.encoder, VideoFrameEncoder):
            self.encoder.request_keyframe()

    def muxer(self) -> Muxer:
        """A container for a new video viewer.

        Raises:
            EncodeError: not a video stream, or no frame encoded yet.
        """
        if not isinstance(self.encoder, VideoFrameEncoder):
            raise EncodeError(f"{self.params.type} is not a video stream")
        return self.encoder.muxer()

    async def run(self) -> None:
        """Encode the newest message whenever one arrives, until cancelled."""
        with self.scope:
            while True:
                await self._wake.wait()
                self._wake = anyio.Event()
                async with self._limiter:  # a thread's turn first, then the newest frame
                    msg, self._latest = self._latest, None
                    if msg is None:
                        continue
                    try:
                        items = await anyio.to_thread.run_sync(self._encode, msg)
                    except EncodeError as exc:
                        self._log_once(str(exc))
                        continue
                    except Exception as exc:  # a bug, or MemoryError: skip it, keep serving
                        self._log_once(f"encoder failed: {type(exc).__name__}: {exc}")
                        continue
                parts = [item for item in items if isinstance(item, Part)]
                if parts:
                    self.last_parts = parts
                for viewer in list(self.viewers):
                    viewer.offer(items)

    def _encode(self, msg: Message) -> list[Part] | list[VideoPacket]:
        """In the worker thread: the frame encoded, each part's multipart bytes made."""
        items = self.encoder.encode(msg)
        for item in items:
            if isinstance(item, Part):
                _ = item.multipart  # cached on the part, for every viewer
        return items

    def _log_once(self, text: str) -> None:
        # once per episode of skipped frames of this stream, whatever their causes
        _episodes.log(
            logging.WARNING,
            f"frame_skipped {self.params.topic} {self.params.type}",
            "%s (%s): frame skipped: %s",
            self.params.topic,
            self.params.type,
            text,
        )


class StreamHub:
    """The shared streams of one video server.

    Args:
        graph: where topics are subscribed.
        task_group: runs the streams' encoder tasks.
        max_streams: the most distinct streams (encoders) at once; each holds a few
            frames of at most ``params.MAX_PIXELS`` pixels, so this bounds the
            encoders' memory (docs/limits.md).
        encoder_threads: the most frames encoded at once, over all streams; None:
            the image threads of the event loop, shared with every other front end's
            image work (``ENCODER_THREADS`` of them, ``rwt_graph.media.threads``). A
            stream waiting for its turn skips to its newest frame.
        make: the encoder of a new stream, from its params and the topic's type
            (default: the HTTP streams' ``make_encoder``; WebRTC's video tracks
            use ``rtp.make_rtp_encoder``).
        node: the node the streams subscribe as (what rosapi shows).

    Attributes:
        started: streams (encoders) started so far, for the tests and the logs.
    """

    def __init__(
        self,
        graph: Graph,
        task_group: TaskGroup,
        max_streams: int = 16,
        encoder_threads: int | None = None,
        make: Callable[[StreamParams, str], FrameEncoder] | None = None,
        node: str = "/web_video_server",
    ) -> None:
        self.graph = graph
        self.node = node
        self._make = make or (lambda params, _type_name: make_encoder(params))
        self.started = 0
        self._tg = task_group
        self.max_streams = max_streams
        self.encoder_threads = encoder_threads
        self._limiter: anyio.CapacityLimiter | None = None
        self.streams: dict[StreamParams, SharedStream] = {}

    @property
    def limiter(self) -> anyio.CapacityLimiter:
        """The encoder threads the streams take turns on (made on first use, in the loop)."""
        if self._limiter is None:
            threads = self.encoder_threads
            self._limiter = image_threads() if threads is None else anyio.CapacityLimiter(threads)
        return self._limiter

    @contextlib.contextmanager
    def watching(
        self, params: StreamParams, type_name: str, make_viewer: Callable[[SharedStream], V]
    ) -> Iterator[V]:
        """Attach a viewer made by ``make_viewer(stream)`` while the block runs.

        The first viewer of ``params`` subscribes ``params.topic`` as
        ``type_name`` and starts the encoder; the last one to leave stops both.
        The topic subscribed is ``params.source_topic``. A video stream is asked
        for a keyframe so that the new viewer starts soon.

        Raises:
            StreamParamError: ``max_streams`` distinct streams run already (status 503).
            EncodeError: the encoder cannot be made (PyAV missing).
            GraphError, InvalidTypeNameError, UnknownTypeError: the topic cannot be
                subscribed as ``type_name``.
        """
        stream = self.streams.get(params)
        if stream is None:
            stream = self._start(params, type_name)
        viewer = make_viewer(stream)
        stream.viewers.add(viewer)
        stream.request_keyframe()
        try:
            yield viewer
        finally:
            stream.viewers.discard(viewer)
            if isinstance(viewer, VideoViewer):
                viewer.close()
            if not stream.viewers and self.streams.get(params) is stream:
                self._stop(stream)

    def _start(self, params: StreamParams, type_name: str) -> SharedStream:
        if len(self.streams) >= self.max_streams:
            raise StreamParamError(f"{self.max_streams} distinct streams run already", status=503)
        stream = SharedStream(params, self._make(params, type_name), self.limiter)
        stream.subscription = self.graph.create_subscription(
            params.source_topic, stream.on_message, type_name, node=self.node
        )
        self.streams[params] = stream
        self.started += 1
        self._tg.start_soon(stream.run)
        _episodes.log(
            logging.INFO,
            f"stream {params.topic} {params.type}",
            "streaming %s as %s",
            params.topic,
            params.type,
        )
        return stream

    def _stop(self, stream: SharedStream) -> None:
        del self.streams[stream.params]
        if stream.subscription is not None:
            stream.subscription.close()
        stream.scope.cancel()
        _episodes.log(
            logging.INFO,
            f"stream_stopped {stream.params.topic} {stream.params.type}",
            "stopped streaming %s as %s",
            stream.params.topic,
            stream.params.type,
        )
