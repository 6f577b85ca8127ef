"""What rwt sends for a sequence of images: over rosbridge (JSON, CBOR) and as video streams.

Shared by the Table I (video) and Table II (depth cloud) benchmarks. The rosbridge
sizes are the frames a subscribed session queues (the server's own encoding
path); the video sizes are the bytes the video server writes for one viewer
(multipart framing or the WebM container included, HTTP chunking left out),
from the same encoder classes the server runs.
"""

from __future__ import annotations

import io
import json
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import av
import numpy as np
from PIL import Image

from rwt_graph.graph import Graph
from rwt_protocol.server.session import Session
from rwt_video.encoders import StillEncoder, multipart_part
from rwt_video.libav import VideoEncoder
from rwt_video.params import StreamParams, StreamType

RATE_HZ = 30.0
KB = 1000.0


def stamp(index: int) -> dict[str, object]:
    """A header for frame ``index`` of a 30 Hz sequence."""
    t = 1_700_000_000 + index / RATE_HZ
    sec = int(t)
    return {"stamp": {"sec": sec, "nanosec": round((t - sec) * 1e9)}, "frame_id": "camera"}


def rosbridge_bytes(type_name: str, msg: dict[str, object]) -> tuple[int, int]:
    """(JSON text bytes, CBOR bytes) of the publish op a subscriber gets for ``msg``."""
    graph = Graph()
    publisher = graph.create_publisher("/bench", type_name)
    plain, cbor = Session(graph.port, "json"), Session(graph.port, "cbor")
    plain.receive_frame(json.dumps({"op": "subscribe", "topic": "/bench"}), 0.0)
    subscribe_cbor = {"op": "subscribe", "topic": "/bench", "compression": "cbor"}
    cbor.receive_frame(json.dumps(subscribe_cbor), 0.0)
    publisher.publish(msg)
    [text] = plain.frames_to_send()
    [binary] = cbor.frames_to_send()
    return len(text.data), len(binary.data)


@dataclass
class StreamResult:
    """One encoded sequence.

    Attributes:
        frames: frames encoded.
        sent_bytes: bytes a viewer receives.
        cpu_s: process CPU time spent encoding (all encoder threads).
        decoded: frames the viewer's decoder produced.
    """

    frames: int = 0
    sent_bytes: int = 0
    cpu_s: float = 0.0
    decoded: int = 0

    @property
    def kb_per_s(self) -> float:
        """Bandwidth at 30 frames a second, KB/s."""
        return self.sent_bytes / max(self.frames, 1) * RATE_HZ / KB

    @property
    def cpu_ms_per_frame(self) -> float:
        return self.cpu_s / max(self.frames, 1) * 1000


#: Called with (frame index, decoded RGB frame) for each frame a viewer decodes.
Inspect = Callable[[int, np.ndarray], None]


def mjpeg(
    messages: Iterable[dict[str, object]], params: StreamParams, inspect: Inspect | None = None
) -> StreamResult:
    """Encode like ``/stream?type=mjpeg``: one JPEG part per message."""
    encoder, result = StillEncoder(params), StreamResult()
    for msg in messages:
        started = time.process_time()
        [part] = encoder.encode(msg)
        result.cpu_s += time.process_time() - started
        result.sent_bytes += len(multipart_part(part))
        if inspect is not None:
            inspect(result.frames, np.asarray(Image.open(io.BytesIO(part.data)).convert("RGB")))
            result.decoded += 1
        result.frames += 1
    return result


def video(
    messages: Iterable[dict[str, object]], params: StreamParams, inspect: Inspect | None = None
) -> StreamResult:
    """Encode like ``/stream?type=vp8`` (or h264) for one viewer, then decode it with PyAV.

    Frames are matched to their index by presentation time (30 Hz from 0).
    """
    assert params.type in (StreamType.VP8, StreamType.H264)
    encoder, result = VideoEncoder(params), StreamResult()
    muxer = None
    chunks: list[bytes] = []
    for msg in messages:
        started = time.process_time()
        packets = encoder.encode(msg)
        result.cpu_s += time.process_time() - started
        result.frames += 1
        for packet in packets:
            muxer = muxer or encoder.muxer()
            chunks.append(muxer.add(packet))
    if muxer is not None:
        chunks.append(muxer.close())
    data = b"".join(chunks)
    result.sent_bytes = len(data)
    if data:
        for frame in av.open(io.BytesIO(data)).decode(video=0):
            result.decoded += 1
            if inspect is not None and frame.time is not None:
                inspect(round(frame.time * RATE_HZ), frame.to_ndarray(format="rgb24"))
    return result


def print_rows(rows: list[dict[str, object]]) -> None:
    """The rows as a table, for running a module alone."""
    for row in rows:
        paper = "-" if row["paper"] is None else f"{row['paper']:.1f}"
        print(
            f"{row['figure']:<9} {row['metric']:<46} paper {paper:>9}  ours {row['ours']:>10.1f}"
            f" {row['unit']:<6} {row['note']}"
        )


def paper_row(
    figure: str, metric: str, paper: float | None, ours: float, note: str, unit: str = "KB/s"
) -> dict[str, object]:
    """One row of the paper runner's table (``benchmarks/paper/__main__.py``)."""
    return {
        "figure": figure,
        "metric": metric,
        "paper": paper,
        "ours": round(ours, 2),
        "unit": unit,
        "note": note,
    }
