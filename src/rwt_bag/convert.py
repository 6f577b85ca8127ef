"""``rwt bag convert`` and ``rwt bag filter``: copy a bag into another format, or part of it.

MCAP, sqlite3 and ROS 1 bags are read with rosbags' ``AnyReader`` and written
with its writers; rosbags' converter (``create_connections_converters``, as its
own ``rosbags-convert`` uses) maps each connection and message across ROS
versions: a ROS 1 message loses its header ``seq`` in ROS 2, a ROS 2 one gets
``seq`` 0 in ROS 1, latching becomes transient-local QoS and back. A topic
selection (``TopicSelection``) and a time range pick what is copied.
"""

from __future__ import annotations

import contextlib
import math
import shutil
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from rosbags.convert.converter import create_connections_converters
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer

from .errors import BagError
from .formats import BagFormat, is_ros1_bag
from .inflate import ReadBudget
from .reader import last_ns
from .ros1 import Ros1Writer  # real rosbag's header layout (rosbag reindex, append)
from .selection import TopicSelection

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

__all__ = ["CopyStats", "bag_format", "copy_bag"]


@dataclass
class CopyStats:
    """What a copy wrote.

    Attributes:
        messages: messages written.
        topics: message count per written topic.
    """

    messages: int = 0
    topics: dict[str, int] = field(default_factory=dict)


def bag_format(path: Path) -> BagFormat:
    """The format of an existing bag: ROS 1 by its first line, else its ROS 2 storage.

    Raises:
        BagError: ``path`` is neither a ROS 1 bag file nor a ROS 2 bag folder.
    """
    if path.is_file():
        if is_ros1_bag(path):
            return BagFormat.ROS1
        raise BagError(f"{path} is not a bag (no ROS 1 header, not a ROS 2 bag folder)")
    if path.is_dir():
        if any(path.glob("*.mcap")):
            return BagFormat.MCAP
        if any(path.glob("*.db3")):
            return BagFormat.SQLITE3
        raise BagError(f"{path} is a folder without an .mcap or .db3 file: not a ROS 2 bag")
    raise BagError(f"{path} does not exist")


def _writer(dst: Path, fmt: BagFormat) -> Ros1Writer | Ros2Writer:
    """An open writer of ``fmt`` at ``dst``.

    Raises:
        BagError: ``dst`` exists, its folder is missing, or its name does not fit
            the format (a ROS 1 bag is a ``.bag`` file; a ROS 2 bag a folder).
    """
    if (fmt is BagFormat.ROS1) != (dst.suffix == ".bag"):
        want = "a file named *.bag" if fmt is BagFormat.ROS1 else "a folder, not *.bag"
        raise BagError(f"a {fmt.value} bag is {want}: {dst}")
    if dst.exists():
        raise BagError(f"{dst} exists already; not overwriting it")
    writer: Ros1Writer | Ros2Writer
    if fmt is BagFormat.ROS1:
        writer = Ros1Writer(dst)
    else:
        plugin = StoragePlugin.MCAP if fmt is BagFormat.MCAP else StoragePlugin.SQLITE3
        writer = Ros2Writer(dst, version=9, storage_plugin=plugin)
    try:
        writer.open()
    except Exception as exc:  # rosbags' WriterError, OSError
        raise BagError(f"cannot create {dst}: {exc}") from exc
    return writer


def _seconds(value: float | None, name: str) -> int | None:
    if value is None:
        return None
    if not (math.isfinite(value) and value >= 0):
        raise BagError(f"--{name} must be a finite number of seconds >= 0, not {value}")
    return int(value * 1e9)


def copy_bag(
    srcs: Sequence[Path],
    dst: Path,
    fmt: BagFormat,
    *,
    selection: TopicSelection | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
) -> CopyStats:
    """Copy the messages of ``srcs`` (one bag, or its split parts) into a new bag.

    Args:
        srcs: the bag's files or folders, read as one.
        dst: the bag to create (a ``.bag`` file for ROS 1, a folder for ROS 2).
        fmt: its format.
        selection: the topics to copy; all by default.
        start_s: copy only messages from this many seconds after the bag's first
            message on; None: from the start.
        end_s: copy only messages up to (and at) this many seconds after the
            bag's first message; None: to the end.

    Returns:
        What was written.

    Raises:
        BagError: the source cannot be read (the text names it), the destination
            cannot be created, the range is empty or not a range, or a type cannot
            be converted between ROS versions. A destination left half written is
            removed.
    """
    selection = selection or TopicSelection()
    start_ns, end_ns = _seconds(start_s, "start"), _seconds(end_s, "end")
    if start_ns is not None and end_ns is not None and end_ns < start_ns:
        raise BagError(f"--end {end_s} is before --start {start_s}")
    names = ", ".join(str(p) for p in srcs)
    try:
        reader = AnyReader(list(srcs))
        with ReadBudget.for_paths(list(srcs)).active():
            reader.open()
    except BagError:
        raise
    except Exception as exc:  # rosbags' reader errors, OSError
        raise BagError(f"cannot read {names}: {exc}") from exc
    try:
        connections = [c for c in reader.connections if selection.matches(c.topic)]
        if not connections:
            raise BagError(f"{names}: no topic matches the selection; nothing to write")
        first = int(reader.start_time)
        start = first + (start_ns or 0)
        stop = last_ns(reader) + 1 if end_ns is None else first + end_ns + 1
        writer = _writer(dst, fmt)
        try:
            stats = _copy(reader, writer, connections, start, stop, list(srcs))
            writer.close()
        except BagError:
            _discard(writer, dst)
            raise
        except Exception as exc:  # a corrupt chunk (rosbags, zstd, struct errors), OSError
            _discard(writer, dst)
            raise BagError(f"cannot copy {names} to {dst}: {exc}") from exc
        except BaseException:
            _discard(writer, dst)
            raise
        return stats
    finally:
        reader.close()


def _copy(
    reader: AnyReader,
    writer: Ros1Writer | Ros2Writer,
    connections: list[Any],
    start: int,
    stop: int,
    srcs: list[Path],
) -> CopyStats:
    names = ", ".join(str(p) for p in srcs)
    try:
        connmap, convmap = create_connections_converters(connections, None, reader, writer)
    except Exception as exc:  # a definition the other ROS version cannot take
        raise BagError(f"{names}: cannot convert its types: {exc}") from exc
    stats = CopyStats()
    budget = ReadBudget.for_paths(srcs)
    messages = budget.iterate(reader.messages(connections=connections, start=start, stop=stop))
    for conn, ns, raw in messages:
        try:
            data = convmap[conn.msgtype](raw)
        except Exception as exc:  # a corrupt message, or one that does not convert
            raise BagError(
                f"{names}: a message of {conn.topic} (type {conn.msgtype}) at {ns} ns "
                f"cannot be converted: {exc}"
            ) from exc
        writer.write(connmap[(conn.id, conn.owner)], ns, data)
        stats.messages += 1
        stats.topics[conn.topic] = stats.topics.get(conn.topic, 0) + 1
    return stats


def _discard(writer: Ros1Writer | Ros2Writer, dst: Path) -> None:
    """Close and remove a destination the copy did not finish."""
    with contextlib.suppress(Exception):  # it is removed anyway
        writer.close()
    if dst.is_dir():
        shutil.rmtree(dst, ignore_errors=True)
    else:
        dst.unlink(missing_ok=True)
