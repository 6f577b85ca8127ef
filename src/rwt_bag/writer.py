"""Bag files on disk: ROS 2 (MCAP, sqlite3) and ROS 1, split by size or duration.

``BagWriter`` takes already-serialized messages (CDR for ROS 2 bags, the ROS 1
format for ROS 1 bags) with their receive time and writes them with rosbags'
writers (the ROS 1 one with real rosbag's header layout, ``ros1``), which also
write each type's definition (and its MD5 sum or RIHS01 hash) from the
registry's typestore. A split starts a new bag next to the first:
``run`` then ``run_1``, ``run_2``... (``run.bag``, ``run_1.bag``... for ROS 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer

from rwt_protocol.qos import History
from rwt_protocol.shortcuts import enabled

from .errors import BagError
from .formats import BagFormat, ChunkCompression, Compression, SplitPolicy
from .ros1 import Ros1Writer

if TYPE_CHECKING:
    from collections.abc import Callable

    from rosbags.typesys.store import Typestore

    from rwt_protocol.qos import QosProfile

__all__ = [
    "BagFormat",
    "BagWriter",
    "SplitPolicy",
    "TopicInfo",
    "split_path",
]


@dataclass(frozen=True)
class TopicInfo:
    """What a bag records about one topic.

    Attributes:
        topic: resolved name.
        msgtype: rosbags' name of the type (``std_msgs/msg/String``).
        latched: transient-local (ROS 2 QoS) or latching (ROS 1 connection header).
        offered: the QoS the topic's publishers offer (protocol 2.1.0's, fixed by
            its first registration with one, D62), which a ROS 2 bag stores as
            ``ros2 bag record`` stores its publishers' offered profiles; None: the
            one ``latched`` stands for.
    """

    topic: str
    msgtype: str
    latched: bool
    offered: QosProfile | None = None


#: Bytes written between two looks at the size of the chunk in memory.
_CHECK_BYTES = 64 * 1024

_INFINITE = QosTime(sec=2147483647, nsec=4294967295)


def _qos(info: TopicInfo) -> Qos:
    """The offered QoS of a topic, which a rosbag2 player reads back (to latch it, or not).

    The topic's offer when it has one (every policy, durations as rosbag2 writes
    them), else what ``latched`` stands for.
    """
    offered = info.offered
    if offered is None:
        durability = QosDurability.TRANSIENT_LOCAL if info.latched else QosDurability.VOLATILE
        return Qos(
            history=QosHistory.KEEP_LAST,
            depth=1 if info.latched else 10,
            reliability=QosReliability.RELIABLE,
            durability=durability,
            deadline=_INFINITE,
            lifespan=_INFINITE,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=_INFINITE,
            avoid_ros_namespace_conventions=False,
        )
    keep_all = offered.history is History.KEEP_ALL
    return Qos(
        history=QosHistory.KEEP_ALL if keep_all else QosHistory.KEEP_LAST,
        depth=0 if keep_all else offered.keep,
        reliability=QosReliability.BEST_EFFORT if offered.best_effort else QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL
        if offered.transient_local
        else QosDurability.VOLATILE,
        deadline=_time(offered.deadline_s),
        lifespan=_time(offered.lifespan_s),
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=_INFINITE,
        avoid_ros_namespace_conventions=False,
    )


def _time(seconds: float) -> QosTime:
    """Seconds as rosbag2's QoS time; infinite as its largest."""
    if math.isinf(seconds):
        return _INFINITE
    ns = round(seconds * 1e9)
    return QosTime(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def split_path(path: Path, index: int) -> Path:
    """The path of split file ``index`` (0: ``path`` itself; then ``stem_N.suffix``)."""
    if index == 0:
        return path
    return path.with_name(f"{path.stem}_{index}{path.suffix}")


def _ros2_writer(path: Path, plugin: StoragePlugin, compression: Compression) -> Any:
    """A rosbag2 writer: ``CheckpointWriter`` (readable while it grows), or rosbags' own.

    ``CheckpointWriter`` reaches into rosbags' storage classes (rwt_bag/mcap.py):
    the ``bag-checkpoints`` shortcut (docs/shortcuts.md). Switched off (say, on a
    rosbags release that moved those internals), rosbags' ``Writer`` writes the
    bag, which is readable once it is closed, and MCAP chunks are not compressed.

    Raises:
        BagError: a chunk compression with the shortcut off.
    """
    if enabled("bag-checkpoints"):
        from .mcap import CheckpointWriter  # noqa: PLC0415 - rosbags' internals, only when on

        return CheckpointWriter(path, storage_plugin=plugin, compression=compression)
    if compression.algorithm is not ChunkCompression.NONE:
        raise BagError("MCAP chunk compression needs the bag-checkpoints shortcut (it is off)")
    return Ros2Writer(path, version=9, storage_plugin=plugin)


class _File:
    """One open bag file."""

    def __init__(
        self,
        path: Path,
        fmt: BagFormat,
        typestore: Typestore,
        definitions: Callable[[str], str] | None,
        compression: Compression,
    ) -> None:
        self.path = path
        self.fmt = fmt
        self._typestore = typestore
        self._definitions = definitions
        self.connections: dict[TopicInfo, Any] = {}
        self.bytes = 0
        self.first_ns: int | None = None
        self._unchecked = 0  # bytes written since the chunk's size was last looked at
        self.writer: Any
        try:
            if fmt is BagFormat.ROS1:
                self.writer = Ros1Writer(path)
            else:
                plugin = StoragePlugin.MCAP if fmt is BagFormat.MCAP else StoragePlugin.SQLITE3
                self.writer = _ros2_writer(path, plugin, compression)
            self.writer.open()
        except Exception as exc:  # rosbags' WriterError, OSError: the path is taken or bad
            raise BagError(f"cannot create the bag {path}: {exc}") from exc

    def write(self, info: TopicInfo, ns: int, raw: bytes | memoryview) -> None:
        connection = self.connections.get(info)
        if connection is None:
            connection = self.connections[info] = self._connect(info)
        self.writer.write(connection, ns, raw)
        size = len(raw)
        self.bytes += size
        self._unchecked += size
        if self.first_ns is None:
            self.first_ns = ns

    def _connect(self, info: TopicInfo) -> Any:
        if self.fmt is BagFormat.ROS1:
            msgdef, md5sum = self._typestore.generate_msgdef(info.msgtype)
            if self._definitions is not None:  # the text with comments, as ROS 1 sends it
                msgdef = self._definitions(info.msgtype)
            return self.writer.add_connection(
                info.topic,
                info.msgtype,
                msgdef=msgdef,
                md5sum=md5sum,
                callerid="/rwt_recorder",
                latching=1 if info.latched else 0,
            )
        return self.writer.add_connection(
            info.topic,
            info.msgtype,
            typestore=self._typestore,
            offered_qos_profiles=[_qos(info)],
        )

    @property
    def checkpoint_due(self) -> bool:
        """Whether the MCAP chunk in memory is full, looked at once per ``_CHECK_BYTES``.

        Asking the storage for every message cost as much as writing a small
        one (B20); a chunk closes at most ``_CHECK_BYTES`` (and one message) late.
        """
        if self._unchecked < _CHECK_BYTES:
            return False
        self._unchecked = 0
        return bool(getattr(self.writer, "checkpoint_due", False))

    def checkpoint(self, *, full: bool = True) -> None:
        if hasattr(self.writer, "checkpoint"):  # rosbags' own writers have none
            self.writer.checkpoint(full=full)

    def close(self) -> None:
        self.writer.close()


class BagWriter:
    """Writes serialized messages to a bag, split into files by ``split``.

    Not thread-safe: one thread calls it at a time (the recorder's writer thread).

    Args:
        path: the bag to create (a directory for ROS 2, a ``.bag`` file for ROS 1).
        fmt: the format.
        typestore: a rosbags typestore holding every recorded type
            (``TypeRegistry.typestore()``).
        split: when to start a new file.
        definitions: the full definition text of a rosbags type name
            (``std_msgs/msg/String``) for ROS 1 connection records, the text
            ``rosbag check`` compares with the installed types
            (``MessageType.full_text``); None: rosbags' text, without comments.
        compression: how MCAP chunks are compressed; None: not.
        repeat_latched: start each split part with the last message of every
            latched topic (``rosbag record --repeat-latched``).

    Raises:
        BagError: the bag cannot be created (it exists, or its folder is missing),
            or a compression for a format other than MCAP.
    """

    def __init__(
        self,
        path: Path,
        fmt: BagFormat,
        typestore: Typestore,
        split: SplitPolicy | None = None,
        definitions: Callable[[str], str] | None = None,
        *,
        compression: Compression | None = None,
        repeat_latched: bool = True,
    ) -> None:
        self.path = Path(path)
        self.fmt = fmt
        self._typestore = typestore
        self._split = split or SplitPolicy()
        self._definitions = definitions
        self._compression = (compression or Compression()).check_format(fmt)
        self._repeat_latched = repeat_latched
        self.paths: list[Path] = [self.path]
        self._file: _File | None = _File(self.path, fmt, typestore, definitions, self._compression)
        # the last message of each latched topic, written again at the start of every
        # split part (``repeat_latched``): a part played alone still has its
        # /tf_static and maps
        self._latched: dict[TopicInfo, bytes | memoryview] = {}

    def write(self, info: TopicInfo, ns: int, raw: bytes | memoryview) -> None:
        """Write one message received at ``ns`` (nanoseconds since the epoch).

        Raises:
            BagError: the writer was closed.
            OSError: the disk refused the data.
        """
        file = self._file
        if file is None:
            raise BagError(f"the bag {self.path} is closed")
        if self._should_split(file, ns):
            file = self._next_file(file)
            for kept, data in self._latched.items():
                if kept != info:  # stamped with the part's first time: its range holds them
                    file.write(kept, ns, data)
        file.write(info, ns, raw)
        if info.latched and self._repeat_latched:
            self._latched[info] = raw
        if file.checkpoint_due:
            file.checkpoint(full=False)

    def _should_split(self, file: _File, ns: int) -> bool:
        if file.first_ns is None:
            return False
        limit_bytes, limit_s = self._split.max_bytes, self._split.max_seconds
        if limit_bytes is not None and file.bytes >= limit_bytes:
            return True
        return limit_s is not None and (ns - file.first_ns) >= limit_s * 1e9

    def _next_file(self, file: _File) -> _File:
        file.close()
        path = split_path(self.path, len(self.paths))
        self.paths.append(path)
        self._file = _File(path, self.fmt, self._typestore, self._definitions, self._compression)
        return self._file

    def checkpoint(self) -> None:
        """Make what was written so far readable if the process dies.

        ROS 2 bags read as they are; a ROS 1 bag gets its chunk on disk, to be
        indexed again (``rwt bag reindex``, ``rosbag reindex``).
        """
        if self._file is not None:
            self._file.checkpoint()

    def close(self) -> None:
        """Finish the file (index, summary, metadata); later calls do nothing."""
        file, self._file = self._file, None
        if file is not None:
            file.close()
