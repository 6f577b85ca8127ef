"""Rebuild the index of a ROS 1 bag cut short (its recorder killed), as ``rosbag reindex`` does.

A ROS 1 bag (format 2.0, wiki.ros.org/Bags/Format/2.0) holds chunk records,
each followed by index data records, and ends with an index section
(connection and chunk info records) that the bag header points at; a
recorder killed before it closes the bag leaves chunks but no index
(``index_pos`` 0), which readers refuse. ``reindex_ros1`` reads the chunks in
order up to the first one that is cut short or corrupt, decompresses each
(within a ``ReadBudget``, as every read of a bag), finds its connection and
message records, and writes a new bag: the same chunk records byte for byte,
fresh index data records after each, then the connection and chunk info
records and the header, laid out as real rosbag lays them out
(``rwt_bag.ros1``).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, BinaryIO

import rosbags.rosbag1.reader as ros1_reader
from rosbags.rosbag1.reader import RecordType
from rosbags.rosbag1.writer import Header, serialize_time

from .errors import BagError
from .inflate import MAX_CHUNK_BYTES, ReadBudget
from .ros1 import MAGIC, record_fields, write_file_header

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["Reindexed", "reindex_ros1"]

_MAX_HEADER = 16 << 20  # a record header past this is corrupt (definitions are kB)
_UINT32 = struct.Struct("<L")


@dataclass(frozen=True)
class Reindexed:
    """What a reindex kept.

    Attributes:
        messages: messages indexed in the new bag.
        chunks: chunks kept (ROS 1), or storage files read (ROS 2).
        dropped_bytes: bytes of the original after the last complete record
            (a record cut short, or corrupt), not carried over.
    """

    messages: int
    chunks: int
    dropped_bytes: int


@dataclass
class _Chunk:
    raw: bytes  # the chunk record as read: header and data
    start: int = 2**63  # ns
    end: int = 0
    index: dict[int, list[tuple[int, int]]] = field(default_factory=dict)  # conn: (ns, offset)


def _time_ns(value: bytes) -> int:
    sec, nsec = struct.unpack("<LL", value)
    return int(sec) * 1_000_000_000 + int(nsec)


def _read_record(file: BinaryIO) -> tuple[bytes, bytes, bytes] | None:
    """``(raw header, data, whole record)`` of the next record, or None if cut short."""
    head = file.read(4)
    if len(head) < 4:
        return None
    (size,) = _UINT32.unpack(head)
    if size > _MAX_HEADER:
        return None
    header = file.read(size)
    size_field = file.read(4)
    if len(header) < size or len(size_field) < 4:
        return None
    (data_size,) = _UINT32.unpack(size_field)
    if data_size > MAX_CHUNK_BYTES:
        return None
    data = file.read(data_size)
    if len(data) < data_size:
        return None
    return header, data, head + header + size_field + data


def _records(data: bytes) -> list[tuple[dict[bytes, bytes], int, bytes]] | None:
    """``(fields, offset, record data)`` of every record in a chunk's data; None if corrupt."""
    found = []
    pos = 0
    while pos < len(data):
        if pos + 4 > len(data):
            return None
        (size,) = _UINT32.unpack_from(data, pos)
        data_at = pos + 4 + size
        if data_at + 4 > len(data):
            return None
        (data_size,) = _UINT32.unpack_from(data, data_at)
        end = data_at + 4 + data_size
        if end > len(data):
            return None
        found.append((record_fields(data[pos + 4 : data_at]), pos, data[data_at + 4 : end]))
        pos = end
    return found


def _chunk(
    fields: dict[bytes, bytes], data: bytes, raw: bytes, connections: dict[int, bytes]
) -> _Chunk | None:
    """A chunk's index, its new connections added to ``connections``; None if corrupt."""
    decompress = ros1_reader.decompressors.get(fields.get(b"compression", b"").decode())
    if decompress is None or len(fields.get(b"size", b"")) != 4:
        return None
    try:
        inner = decompress(data)
    except (OSError, EOFError, ValueError, RuntimeError):  # a compressed chunk cut short
        return None
    if len(inner) != _UINT32.unpack(fields[b"size"])[0]:
        return None
    records = _records(inner)
    if records is None:
        return None
    chunk = _Chunk(raw)
    for record, offset, record_data in records:
        op = record.get(b"op")
        conn = record.get(b"conn", b"")
        if len(conn) != 4:
            continue
        cid = _UINT32.unpack(conn)[0]
        if op == bytes([RecordType.CONNECTION]):
            connections.setdefault(cid, _connection(record, record_data))
        elif op == bytes([RecordType.MSGDATA]) and len(record.get(b"time", b"")) == 8:
            ns = _time_ns(record[b"time"])
            chunk.index.setdefault(cid, []).append((ns, offset))
            chunk.start, chunk.end = min(chunk.start, ns), max(chunk.end, ns)
    return chunk


def _connection(fields: dict[bytes, bytes], data: bytes) -> bytes:
    """A connection record, header and data, ready to write in the index section."""
    header = Header(conn=fields[b"conn"], topic=fields.get(b"topic", b""))
    head = _header_bytes(header, RecordType.CONNECTION)
    return head + _UINT32.pack(len(data)) + data


def _header_bytes(header: Header, op: RecordType) -> bytes:
    fields = bytearray()
    for key, value in {"op": bytes([op]), **header}.items():
        item = key.encode() + b"=" + value
        fields += _UINT32.pack(len(item)) + item
    return _UINT32.pack(len(fields)) + bytes(fields)


def reindex_ros1(path: Path, out: Path) -> Reindexed:
    """Write to ``out`` (a new file) the complete chunks of ``path`` with a fresh index.

    Raises:
        BagError: ``path`` is not a ROS 1 bag (format 2.0), a chunk decompresses
            past the limits (docs/limits.md), or ``out`` exists.
        OSError: reading or writing failed.
    """
    connections: dict[int, bytes] = {}
    chunks: list[_Chunk] = []
    size = path.stat().st_size
    budget = ReadBudget.for_paths([path])
    with path.open("rb") as file:
        if file.read(len(MAGIC)) != MAGIC:
            raise BagError(f"{path} is not a ROS 1 bag (no '#ROSBAG V2.0' line)")
        first = _read_record(file)
        if first is None or record_fields(first[0]).get(b"op") != bytes([RecordType.BAGHEADER]):
            raise BagError(f"{path} has no ROS 1 bag header record")
        kept = file.tell()
        with budget.active():
            while (record := _read_record(file)) is not None:
                fields = record_fields(record[0])
                op = fields.get(b"op")
                if op == bytes([RecordType.CHUNK]):
                    chunk = _chunk(fields, record[1], record[2], connections)
                    if chunk is None:
                        break
                    chunks.append(chunk)
                elif op == bytes([RecordType.CONNECTION]) and len(fields.get(b"conn", b"")) == 4:
                    cid = _UINT32.unpack(fields[b"conn"])[0]
                    connections.setdefault(cid, _connection(fields, record[1]))
                elif op not in (bytes([RecordType.IDXDATA]), bytes([RecordType.CHUNK_INFO])):
                    break  # not a record of a bag's body: corrupt from here
                kept = file.tell()
    try:
        target = out.open("xb")
    except FileExistsError:
        raise BagError(f"{out} exists already") from None
    with target:
        _write(target, chunks, connections)
    messages = sum(len(i) for c in chunks for cid, i in c.index.items() if cid in connections)
    return Reindexed(messages, len(chunks), size - kept)


def _write(file: BinaryIO, chunks: list[_Chunk], connections: dict[int, bytes]) -> None:
    """A bag of ``chunks`` (each followed by its index data records) and its index."""
    file.write(MAGIC)
    write_file_header(file, 0, 0, 0)
    positions = []
    for chunk in chunks:
        positions.append(file.tell())
        file.write(chunk.raw)
        for cid, items in chunk.index.items():
            if cid not in connections:
                continue  # no connection record survived: readers could not use them
            header = Header()
            header.set_uint32("ver", 1)
            header.set_uint32("conn", cid)
            header.set_uint32("count", len(items))
            entries = b"".join(serialize_time(ns) + _UINT32.pack(off) for ns, off in items)
            file.write(_header_bytes(header, RecordType.IDXDATA))
            file.write(_UINT32.pack(len(entries)) + entries)
    index_pos = file.tell()
    for cid in sorted(connections):
        file.write(connections[cid])
    for pos, chunk in zip(positions, chunks, strict=True):
        counts = {cid: len(items) for cid, items in chunk.index.items() if cid in connections}
        header = Header()
        header.set_uint32("ver", 1)
        header.set_uint64("chunk_pos", pos)
        header.set_time("start_time", chunk.start if counts else 0)
        header.set_time("end_time", chunk.end)
        header.set_uint32("count", len(counts))
        data = b"".join(_UINT32.pack(cid) + _UINT32.pack(n) for cid, n in counts.items())
        file.write(_header_bytes(header, RecordType.CHUNK_INFO))
        file.write(_UINT32.pack(len(data)) + data)
    write_file_header(file, index_pos, len(connections), len(chunks))
