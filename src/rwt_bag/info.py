"""``rwt bag info``: what a bag holds, laid out like ``ros2 bag info``."""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from rosbags.highlevel import AnyReader

from rwt_protocol.names import name_problem

from .errors import BagError
from .inflate import ReadBudget, bag_bytes
from .reader import is_latched, last_ns, shown_name, shown_text

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = ["BagInfo", "TopicSummary", "bag_info"]


@dataclass(frozen=True)
class TopicSummary:
    """One topic of a bag: name, type (rosbags' spelling), message count, latched."""

    topic: str
    msgtype: str
    count: int
    latched: bool
    serialization: str


@dataclass(frozen=True)
class BagInfo:
    """A bag's summary.

    Attributes:
        paths: the files read.
        storage: ``mcap``, ``sqlite3`` or ``ros1``.
        size: bytes on disk.
        start_ns, end_ns: times of the first and last message (ns since the epoch).
        messages: message count.
        topics: per topic, sorted by name.
    """

    paths: tuple[Path, ...]
    storage: str
    size: int
    start_ns: int
    end_ns: int
    messages: int
    topics: tuple[TopicSummary, ...]

    @property
    def duration_s(self) -> float:
        """Seconds from the first to the last message."""
        return max(0, self.end_ns - self.start_ns) / 1e9

    def format(self) -> str:
        """The summary as text, one ``Key: value`` per line and a line per topic."""
        rows = [
            f"Files:             {', '.join(str(p) for p in self.paths)}",
            f"Bag size:          {_size(self.size)}",
            f"Storage id:        {self.storage}",
            f"Duration:          {self.duration_s:.3f}s",
            f"Start:             {_when(self.start_ns)}",
            f"End:               {_when(self.end_ns)}",
            f"Messages:          {self.messages}",
            f"Topic information: {len(self.topics)} topics",
        ]
        for t in self.topics:
            latched = " | Latched" if t.latched else ""
            rows.append(
                f"  Topic: {_shown(t.topic, topic=True)} | Type: {_shown(t.msgtype)} | "
                f"Count: {t.count} | Serialization Format: {_shown(t.serialization)}{latched}"
            )
        return "\n".join(rows)


def _shown(text: str, *, topic: bool = False) -> str:
    """``text`` as printed, escaped and cut where a bag could abuse a terminal.

    Control or bidirectional characters, or thousands of characters, are not
    written as they are. A topic name a client could not use is marked: it is
    not played (docs/limits.md).
    """
    if not topic:
        return shown_text(text)
    if name_problem(text) is None:
        return text
    return shown_name(text) + " (invalid name, not played)"


def _size(size: int) -> str:
    value = float(size)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if value < 1024 or unit == "GiB":
            return f"{value:.1f} {unit}" if unit != "B" else f"{size} B"
        value /= 1024
    raise AssertionError  # pragma: no cover - the loop returns


def _when(ns: int) -> str:
    moment = datetime.datetime.fromtimestamp(ns // 10**9, tz=datetime.UTC)
    # integers, not a float: seconds since the epoch in a double keep only microseconds
    seconds, nanos = divmod(ns, 10**9)
    return f"{moment:%Y-%m-%dT%H:%M:%S}.{nanos:09d}+00:00 ({seconds}.{nanos:09d})"


def bag_info(paths: Sequence[Path | str] | Path | str) -> BagInfo:
    """Read the summary of a bag (or of split parts read as one).

    Raises:
        BagError: a file is missing or is not a readable bag, or it decompresses
            past the limits of ``rwt_bag.inflate``.
    """
    files = [Path(paths)] if isinstance(paths, str | Path) else [Path(p) for p in paths]
    try:
        reader = AnyReader(files)
        with ReadBudget.for_paths(files).active():  # a summary-less MCAP is scanned
            reader.open()
        try:
            counts: dict[tuple[str, str], int] = {}
            topics: dict[tuple[str, str], TopicSummary] = {}
            for conn in reader.connections:
                key = (conn.topic, conn.msgtype)
                counts[key] = counts.get(key, 0) + conn.msgcount
                fmt = getattr(conn.ext, "serialization_format", "ros1")
                latched = is_latched(conn.topic, conn.msgtype, conn.ext)
                topics[key] = TopicSummary(conn.topic, conn.msgtype, counts[key], latched, fmt)
            storage = "ros1" if reader.is2 is False else _storage(files[0])
            return BagInfo(
                paths=tuple(files),
                storage=storage,
                size=bag_bytes(files),
                start_ns=int(reader.start_time) if reader.message_count else 0,
                end_ns=last_ns(reader) if reader.message_count else 0,
                messages=int(reader.message_count),
                topics=tuple(sorted(topics.values(), key=lambda t: (t.topic, t.msgtype))),
            )
        finally:
            reader.close()
    except BagError:
        raise
    except Exception as exc:  # rosbags' reader errors, OSError, decoding errors
        reason = str(exc) or type(exc).__name__
        raise BagError(f"cannot read {', '.join(map(str, files))}: {reason}") from exc


def _storage(path: Path) -> str:
    """The storage of a ROS 2 bag: a folder's files, or a bare file's own suffix."""
    if path.is_file():
        return "mcap" if path.suffix == ".mcap" else "sqlite3"
    return "mcap" if any(path.glob("*.mcap")) else "sqlite3"
