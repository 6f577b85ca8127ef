"""The messages of one ROS 1 bag read from its chunks directly (shortcut ``ros1-chunk-read``).

rosbags' ``rosbag1.Reader.messages`` parses every message record through a
``BytesIO``, a header dict and ``struct`` calls per field, and orders the
index entries with a Python ``__lt__``: about 3 us a message, a sixth of
``rwt play``'s cost for a 100 B string (B22). ``chunk_messages`` yields the
same ``(connection, time ns, bytes)`` from the same index, reading each record
in place in the decompressed chunk (ROS 1 bag format 2.0,
wiki.ros.org/Bags/Format/2.0: a record is a 4-byte header length, the header's
``len name=value`` fields, a 4-byte data length and the data). It uses the
reader's private index (``indexes``, ``chunks``, ``bio``), so it is a
shortcut; off (``RWT_NO_SHORTCUTS``), or for split bags and ROS 2 bags,
rosbags reads. Decompression goes through the reader's decompressors, so the
budget of ``rwt_bag.inflate`` applies as before.
"""

from __future__ import annotations

import heapq
import struct
from operator import itemgetter
from typing import TYPE_CHECKING, Any

from rosbags.rosbag1 import Reader as Ros1Reader

from rwt_protocol.shortcuts import enabled

from .errors import BagError

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

    from rosbags.highlevel import AnyReader

__all__ = ["chunk_messages"]

_ENABLED = enabled("ros1-chunk-read")
_U32 = struct.Struct("<I")
_TIME = struct.Struct("<II")
_MSGDATA = 2  # record ops (the format's ``op`` field)
_CONNECTION = 7


def chunk_messages(
    reader: AnyReader, connections: Sequence[Any], start: int | None
) -> Iterator[tuple[Any, int, bytes]] | None:
    """``reader.messages(connections=connections, start=start)`` read from the chunks.

    Args:
        reader: an open rosbags ``AnyReader``.
        connections: the connections to read (of ``reader``).
        start: bag time in ns before which messages are skipped; None: all.

    Returns:
        The messages in rosbags' order, or None when this path does not apply
        (the shortcut is off, the bag is not a single ROS 1 file, or no
        connection is given: rosbags then reads them all).
        The iterator raises ``BagError`` for a record that is not what the
        index says (corrupt bag) and the decompressors' errors as rosbags does.
    """
    if not _ENABLED or not connections or reader.is2 or len(reader.readers) != 1:
        return None
    bag = reader.readers[0]
    if not isinstance(bag, Ros1Reader):
        return None
    return _messages(bag, connections, start)


def _messages(
    bag: Ros1Reader, connections: Sequence[Any], start: int | None
) -> Iterator[tuple[Any, int, bytes]]:
    by_id = {conn.id: conn for conn in bag.connections}
    indexes = [bag.indexes[conn.id] for conn in connections]
    # rosbags merges by time alone (IndexData.__lt__); heapq.merge keeps the
    # connections' order among equal times either way
    entries = indexes[0] if len(indexes) == 1 else heapq.merge(*indexes, key=itemgetter(0))
    chunk_pos, chunk = -1, b""
    u32, time_of = _U32.unpack_from, _TIME.unpack_from
    for entry_time, entry_chunk, offset in entries:
        if start is not None and entry_time < start:
            continue
        if entry_chunk != chunk_pos:
            info = bag.chunks[entry_chunk]
            assert bag.bio is not None
            bag.bio.seek(info.datapos)
            chunk = info.decompressor(bag.bio.read(info.datasize))
            chunk_pos = entry_chunk
        pos = offset
        while True:  # connection records may come first, as rosbags allows
            op, conn_id, secs_nsecs, pos = _header(chunk, pos, u32)
            if op != _CONNECTION:
                break
            pos += 4 + u32(chunk, pos)[0]
        if op != _MSGDATA or conn_id is None or secs_nsecs is None:
            raise BagError(f"expected a message record at offset {offset} of a chunk")
        size = u32(chunk, pos)[0]
        pos += 4
        if pos + size > len(chunk):
            raise BagError(f"a message record at offset {offset} of a chunk is truncated")
        secs, nsecs = time_of(secs_nsecs)
        if secs * 1_000_000_000 + nsecs != entry_time:
            raise BagError(f"a message record at offset {offset} does not match the index")
        yield by_id[conn_id], entry_time, chunk[pos : pos + size]


def _header(chunk: bytes, pos: int, u32: Any) -> tuple[int, int | None, bytes | None, int]:
    """The ``op``, ``conn`` and ``time`` of the record header at ``pos``, and where it ends.

    Raises:
        BagError: the header runs past the chunk or a field has no ``=``.
    """
    end = pos + 4 + u32(chunk, pos)[0]
    if end > len(chunk):
        raise BagError(f"a record header at offset {pos} of a chunk is truncated")
    pos += 4
    op, conn, time = -1, None, None
    while pos < end:
        size = u32(chunk, pos)[0]
        pos += 4
        field = chunk[pos : pos + size]
        pos += size
        name, sep, value = field.partition(b"=")
        if not sep or pos > end:
            raise BagError("a record header field cannot be parsed")
        if name == b"op":
            op = value[0] if len(value) == 1 else -1
        elif name == b"conn":
            conn = u32(value)[0] if len(value) == 4 else None
        elif name == b"time":
            time = value if len(value) == 8 else None
    return op, conn, time, end
