"""Rebuild a ROS 2 bag cut short: its MCAP summary and footer, and its ``metadata.yaml``.

A rosbag2 bag is a folder of storage files and ``metadata.yaml``. A recorder
killed mid-run can leave an MCAP file without its summary section and footer
(which readers need), or no ``metadata.yaml`` at all (``ros2 bag record``
writes it only when it stops). ``reindex_ros2`` reads what each storage file
really holds, as a stream: MCAP records in file order with the ``mcap``
library, up to the first record cut short or corrupt; sqlite3 rows with
rosbags' storage reader. It then writes the same connections (type, definition,
serialization format, QoS) and messages into a new bag with rosbags' writer,
which writes a complete MCAP summary, footer and ``metadata.yaml``, as ``ros2
bag reindex`` regenerates them.
"""

from __future__ import annotations

from dataclasses import dataclass
from io import BytesIO
from typing import TYPE_CHECKING, Any

from mcap.records import Channel, Chunk, DataEnd, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.metadata import parse_qos
from rosbags.rosbag2.storage_mcap import DECOMPRESSORS
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from .errors import BagError
from .inflate import MAX_CHUNK_BYTES, InflateError, ReadBudget
from .reindex_ros1 import Reindexed

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    from rosbags.interfaces import Connection

__all__ = ["reindex_ros2", "storage_files"]

_SUFFIXES = {".mcap": StoragePlugin.MCAP, ".db3": StoragePlugin.SQLITE3}


@dataclass(frozen=True)
class _Topic:
    topic: str
    msgtype: str
    msgdef: str
    rihs01: str
    serialization_format: str
    qos: str  # rosbag2's offered_qos_profiles YAML


#: What a storage file holds, in order: a topic (message time None), a message
#: ``(topic, ns, data)``, or the bytes of a tail cut short (an int, last).
_Event = tuple[_Topic, int | None, bytes] | int


def storage_files(path: Path) -> tuple[StoragePlugin, list[Path]]:
    """The storage and its files (sorted) of the rosbag2 bag folder ``path``.

    Raises:
        BagError: the folder holds no ``.mcap`` or ``.db3`` file, or both kinds.
    """
    files = sorted(p for p in path.iterdir() if p.suffix in _SUFFIXES and p.is_file())
    kinds = {_SUFFIXES[p.suffix] for p in files}
    if len(kinds) != 1:
        raise BagError(f"{path} is not a ROS 2 bag (no .mcap or .db3 file, or both)")
    return kinds.pop(), files


def reindex_ros2(path: Path, out: Path) -> Reindexed:
    """Write to the new folder ``out`` the messages of the bag folder ``path``, complete.

    Raises:
        BagError: ``path`` is not a ROS 2 bag, a definition cannot be read,
            or ``out`` exists.
        OSError: reading or writing failed.
    """
    storage, files = storage_files(path)
    writer = Writer(out, version=Writer.VERSION_LATEST, storage_plugin=storage)
    try:
        writer.open()
    except Exception as exc:  # rosbags' WriterError: out exists
        raise BagError(f"cannot create {out}: {exc}") from exc
    connections: dict[_Topic, Connection] = {}
    messages = dropped = 0
    try:
        for file in files:
            read = _mcap if storage is StoragePlugin.MCAP else _sqlite3
            for event in read(file):
                if isinstance(event, int):
                    dropped += event
                    continue
                topic, ns, data = event
                connection = connections.get(topic)
                if connection is None:
                    connection = connections[topic] = _connect(writer, topic)
                if ns is not None:
                    writer.write(connection, ns, data)
                    messages += 1
    except BaseException:
        writer.close()
        raise
    writer.close()
    return Reindexed(messages, len(files), dropped)


def _connect(writer: Writer, topic: _Topic) -> Connection:
    return writer.add_connection(
        topic.topic,
        topic.msgtype,
        msgdef=topic.msgdef,
        rihs01=topic.rihs01 or _rihs01(topic.msgtype, topic.msgdef),
        serialization_format=topic.serialization_format,
        offered_qos_profiles=parse_qos(topic.qos) if topic.qos else (),
    )


def _rihs01(msgtype: str, msgdef: str) -> str:
    """The RIHS01 hash of a type from its definition (an MCAP schema does not hold it).

    Raises:
        BagError: the definition cannot be parsed.
    """
    try:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(msgdef, msgtype))
        return store.hash_rihs01(msgtype)
    except Exception as exc:  # rosbags' parse errors
        raise BagError(f"the definition of {msgtype} cannot be read: {exc}") from exc


def _mcap_records(file: Path) -> Iterator[Any]:
    """The records of an MCAP file in order, those of each chunk in place of the chunk.

    Chunks are decompressed within the limits of any read of a bag (rosbags'
    decompressors under a ``ReadBudget``, docs/limits.md). Ends at the data end
    record (the summary repeats what came before), or with the bytes left
    unread (an int) at the first record cut short or corrupt.
    """
    budget = ReadBudget.for_paths([file])
    size = file.stat().st_size
    with file.open("rb") as stream:
        records = StreamReader(stream, emit_chunks=True, record_size_limit=MAX_CHUNK_BYTES).records
        last = stream.tell()
        while True:
            try:
                record: Any = next(records)
                inside = [record]
                if isinstance(record, Chunk):
                    with budget.active():
                        decompress = DECOMPRESSORS[record.compression]
                        inner = decompress(record.data, record.uncompressed_size)
                    inside = _chunk_records(inner)
            except StopIteration:
                return
            except InflateError:
                raise
            except Exception:  # McapError, struct.error, EndOfFile, a bad frame, KeyError...
                yield size - last  # cut short or corrupt from here: the bag ends before
                return
            if isinstance(record, DataEnd):
                return
            yield from inside
            last = stream.tell()


def _chunk_records(inner: bytes) -> list[Any]:
    """The records of a decompressed chunk (it has no footer: stop at its end).

    Raises:
        McapError, struct.error: a record is corrupt.
    """
    stream = BytesIO(inner)
    records = StreamReader(stream, skip_magic=True).records
    found = []
    while stream.tell() < len(inner):
        found.append(next(records))
    return found


def _mcap(file: Path) -> Iterator[_Event]:
    """Each channel, each message (its log time), then the bytes of a tail cut short."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, _Topic] = {}
    for record in _mcap_records(file):
        if isinstance(record, int):
            yield record
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            schema = schemas.get(record.schema_id)
            if schema is None:
                raise BagError(f"{file}: channel {record.topic} has no schema")
            channels[record.id] = _Topic(
                record.topic,
                schema.name,
                schema.data.decode(),
                "",
                record.message_encoding,
                record.metadata.get("offered_qos_profiles", ""),
            )
            yield channels[record.id], None, b""
        elif isinstance(record, Message) and record.channel_id in channels:
            yield channels[record.channel_id], record.log_time, record.data


def _sqlite3(file: Path) -> Iterator[_Event]:
    """Each topic row, then each message row (in time order)."""
    reader = Sqlite3Reader(file)
    try:
        reader.open()
    except Exception as exc:  # rosbags' ReaderError, apsw's errors
        raise BagError(f"{file} is not a readable rosbag2 sqlite3 file: {exc}") from exc
    try:
        topics: dict[int, _Topic] = {}
        for conn in reader.connections:
            qos = reader.dbconn.execute(  # type: ignore[union-attr]
                "SELECT offered_qos_profiles FROM topics WHERE id = ?", (conn.id,)
            ).fetchone()
            topics[conn.id] = _Topic(
                conn.topic,
                conn.msgtype,
                conn.msgdef.data,
                conn.digest,
                conn.ext.serialization_format,  # type: ignore[union-attr]
                qos[0] if qos else "",
            )
            yield topics[conn.id], None, b""
        for conn, ns, data in reader.messages(reader.connections):
            yield topics[conn.id], ns, data
    finally:
        reader.close()
