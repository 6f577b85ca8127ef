"""``rwt bag info``: what a bag holds, laid out like ``ros2 bag info``."""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from rosbags.highlevel import AnyReader

from .errors import BagError
from .reader import is_latched

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
                f"  Topic: {t.topic} | Type: {t.msgtype} | Count: {t.count} | "
                f"Serialization Format: {t.serialization}{latched}"
            )
        return "\n".join(rows)


def _size(size: int) -> str:
    value = float(size)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if value < 1024 or unit == "GiB":
            return f"{value:.1f} {unit}" if unit != "B" else f"{size} B"
        value /= 1024
    raise AssertionError  # pragma: no cover - the loop returns


def _when(ns: int) -> str:
    moment = datetime.datetime.fromtimestamp(ns / 1e9, tz=datetime.UTC)
    return f"{moment.isoformat(timespec='milliseconds')} ({ns / 1e9:.9f})"


def _disk_size(path: Path) -> int:
    if path.is_dir():
        return sum(f.stat().st_size for f in path.iterdir() if f.is_file())
    return path.stat().st_size


def bag_info(paths: Sequence[Path | str] | Path | str) -> BagInfo:
    """Read the summary of a bag (or of split parts read as one).

    Raises:
        BagError: a file is missing or is not a readable bag.
    """
    files = [Path(paths)] if isinstance(paths, str | Path) else [Path(p) for p in paths]
    try:
        with AnyReader(files) as reader:
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
                size=sum(_disk_size(f) for f in files),
                start_ns=int(reader.start_time) if reader.message_count else 0,
                end_ns=int(reader.end_time) if reader.message_count else 0,
                messages=int(reader.message_count),
                topics=tuple(sorted(topics.values(), key=lambda t: (t.topic, t.msgtype))),
            )
    except BagError:
        raise
    except Exception as exc:  # rosbags' reader errors, OSError, decoding errors
        reason = str(exc) or type(exc).__name__
        raise BagError(f"cannot read {', '.join(map(str, files))}: {reason}") from exc


def _storage(path: Path) -> str:
    return "mcap" if any(path.glob("*.mcap")) else "sqlite3"
